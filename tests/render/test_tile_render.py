"""fiberpath on a shell-mapped tiling (issue 6 item 5): on a flat rectangle (identity shell map) the
fiberpath integrator (stages.render.integrators.fiberpath) renders the same image through the shell traversal
(a ShellScene, stages.core.shell) as on the fabric realized directly -- the exemplar's periodic copies
in one flat BVH -- with the same seed: same camera samples, same hits, same shadow rays."""
import numpy as np

from pipeline.render_setup import pack_lights
from pipeline.runners.tile import load_tiling, run_tile
from stages.core.geometry.bvh import build_fiber_bvh
from stages.core.shading.material import pack_material_lambert
from stages.render.camera import pack_camera
from stages.render.film import finalize, new_film, tile_grid
from stages.render.integrators.fiberpath import FiberpathIntegrator
from stages.render.meshes import no_meshes
from stages.render.tiles import render_tiles

CFG = """
seed = 5
[yarn]
fibers_per_ply = 3
fiber_radius = 0.002
[weave]
spacing = [0.1, 0.1]
[[exemplars]]
pattern = "twill"
n = 2
m = 1
[tiling]
repeat = [7, 7]
[surface]
kind = "flat"
resolution = [4, 4]
"""


def _render(scene, mat_of_fiber, cam, lights, W, H, spp):
    mats = np.stack([pack_material_lambert(np.array([0.7, 0.5, 0.3]))])
    # up to 3 scattering events: rays also start inside the shell
    integ = FiberpathIntegrator(scene, mat_of_fiber, mats, pack_material_lambert(np.zeros(3)), lights.table(),
                                np.zeros(4), False, no_meshes(), 3, 2, 0, 1e-9)
    img = finalize(render_tiles(integ, cam, 3, spp, 0, spp, tile_grid(W, H, 8), new_film(W, H)), spp)
    return img.rgb, img.alpha * spp, img.rays


def test_shell_render_equals_direct_render(tmp_path):
    (tmp_path / "t.toml").write_text(CFG)
    run_tile(tmp_path / "t.toml", tmp_path / "t.zarr")
    sc, art = load_tiling(tmp_path / "t.zarr")
    P, O, R = art["ex_points"], art["ex_offsets"], art["ex_radius"]
    Wp, Hp = art["ex_period"][0]
    pts, rad, cnt = [], [], []
    for a in range(-2, 9):
        for b in range(-2, 9):
            pts.append(P + np.array([a * Wp, b * Hp, 0.0]))
            rad.append(R)
            cnt.append(np.diff(O))
    bvh, _ = build_fiber_bvh(np.concatenate(pts), np.r_[0, np.cumsum(np.concatenate(cnt))], np.concatenate(rad))
    lights = pack_lights([{"type": "directional",
                           "direction": list(np.array([0.2, 0.1, -1.0]) / np.linalg.norm([0.2, 0.1, -1.0])),
                           "irradiance": [2.0, 2.0, 2.0]}, {"type": "constant", "radiance": [0.3, 0.3, 0.3]}])
    cx, cy = art.summary["flat_size"][0] / 2, art.summary["flat_size"][1] / 2
    cam = pack_camera(np.array([cx + 0.3, cy - 0.4, 2.5]), np.array([cx, cy, 0.0]), np.array([0.0, 1.0, 0.0]),
                      10.0, 24, 24)
    img_s, hits_s, rays_s = _render(sc, np.zeros(int(art["ex_fibers"][-1]), np.int32), cam, lights, 24, 24, 4)
    img_d, hits_d, rays_d = _render(bvh, np.zeros((len(O) - 1) * 121, np.int32), cam, lights, 24, 24, 4)
    assert 0.2 < (hits_d > 0).mean() and img_d.max() > 0.05
    np.testing.assert_array_equal(hits_s, hits_d)
    assert rays_s == rays_d
    np.testing.assert_allclose(img_s, img_d, rtol=1e-6, atol=1e-9)
