"""prt's global visibility through other folds of the cloth (stages/render/integrators/prt.py ``global_visibility``,
the layer transmittance of stages/precompute/layer.py) on a tiling wrapped round a cylinder of 300 degrees, so
that shadow rays from one side of the tube cross the other side.

Reference: a brute force over every boundary face of the shell (numpy ray-triangle tests, no BVH): the faces the
shadow ray enters, in order of distance, each passing tau of the exemplar of the block it enters, read at the
ray's angle in that face's tetrahedron's flat space (``stages.core.layer.tau_at``, tested on its own in
tests/precompute/test_layer.py); without a layer table (an IIRTF made before the table existed) any face blocks,
the paper's opaque shell."""
import math

import numpy as np
import pytest

from stages.core.layer import FROM_ABOVE, FROM_BELOW, tau_at
from stages.core.shell.top import base_point, top_point
from stages.render.integrators.prt import MAX_LAYERS, global_visibility
from tests.render.test_prt import DIRECTIONAL, SCENE, TILING as SWATCH_TILING

# the prt swatch's two exemplars, wrapped round the tube
TILING = SWATCH_TILING[:SWATCH_TILING.index("[tiling]")].format(seed=5, fibers=1) + """[tiling]
repeat = [6, 2]
block_map = [[0, 1], [1, 0]]
[surface]
kind = "cylinder"
radius = 0.4
angle = 300
length = 1.0
resolution = [24, 4]
"""

# the prt swatch's scene (yarn materials, a light); only its integrator is built here, so its camera does not matter
TUBE_SCENE = SCENE.format(lights=DIRECTIONAL.format(d="0.0, -1.0, 0.0"), weft_bcsdf="cotton")


@pytest.fixture(scope="module")
def tube(tmp_path_factory):
    from pipeline.cli import main
    from pipeline.renderers.prt import film_setup
    from pipeline.scene import load_scene

    d = tmp_path_factory.mktemp("prt_tube")
    (d / "tiling.toml").write_text(TILING)
    (d / "scene.toml").write_text(TUBE_SCENE)
    for args in (["tile", d / "tiling.toml", "-o", d / "tiling.zarr"],
                 ["precompute", "svf", d / "tiling.zarr", "-o", d / "svf.zarr", "--resolution", "8", "--components",
                  "2", "--threads", "2"],
                 ["precompute", "iirtf", d / "tiling.zarr", "-o", d / "iirtf.zarr", "--scene", d / "scene.toml",
                  "--order", "0", "--paths", "2", "--mfp-paths", "50", "--layer-paths", "200", "--layer-bins", "4",
                  "--cell-factor", "8", "--threads", "2"]):
        assert main([str(a) for a in args]) == 0
    options = {"fibers": str(d / "tiling.zarr"), "width": 8, "height": 8,
               "extra": {"svf": str(d / "svf.zarr"), "iirtf": str(d / "iirtf.zarr")}}
    return film_setup(load_scene(d / "scene.toml"), options).integ


def _entries(sc, o, w, eps):
    """(t, face) of every boundary face the ray o + t w enters at t >= eps, nearest first (Moller-Trumbore on all
    faces; a face met at the same distance as the one before, a shared edge, counts once)."""
    tri = sc.btri
    e1 = tri[:, 1] - tri[:, 0]
    e2 = tri[:, 2] - tri[:, 0]
    p = np.cross(w, e2)
    det = np.einsum("ij,ij->i", e1, p)
    ok = np.abs(det) > 1e-15
    inv = np.where(ok, 1.0 / np.where(ok, det, 1.0), 0.0)
    s = o - tri[:, 0]
    u = np.einsum("ij,ij->i", s, p) * inv
    q = np.cross(s, e1)
    v = (q @ w) * inv
    t = np.einsum("ij,ij->i", e2, q) * inv
    hit = ok & (u >= -1e-9) & (v >= -1e-9) & (u + v <= 1 + 1e-9) & (t >= eps) & (sc.bnrm @ w < 0.0)
    out = []
    for f in np.flatnonzero(hit)[np.argsort(t[hit], kind="stable")]:
        if out and t[f] < out[-1][0] + eps:
            continue
        out.append((t[f], f))
    return out


def _brute(it, u, v, w):
    sc = it.scene
    ok, x, y, z, nx, ny, nz = top_point(it.top, u, v)
    n = np.array([nx, ny, nz])
    side = 1.0
    if w @ n <= 0.0:
        if not it.below:
            return None
        ok, x, y, z, *_n = base_point(it.top, u, v)     # light from below: from the base surface, downwards
        side = -1.0
    o = np.array([x, y, z]) + side * it.eps * n
    tau = np.ones(3)
    hits = _entries(sc, o, w, it.eps)
    if not hits:
        return tau, 0
    if it.layer_tau.shape[0] == 0 or len(hits) > MAX_LAYERS:
        return np.zeros(3), len(hits)
    for t, f in hits:
        tet = sc.btet[f]
        p = o + t * w
        X, Y = (sc.w2f[tet, :2, :3] @ p + sc.w2f[tet, :2, 3])
        i, j = int(math.floor(X / sc.block_size[0])), int(math.floor(Y / sc.block_size[1]))
        e = sc.block_map[i % sc.block_map.shape[0], j % sc.block_map.shape[1]]
        lf = sc.w2f[tet, :, :3] @ w
        lf /= np.linalg.norm(lf)
        tau *= tau_at(it.layer_tau[e], FROM_ABOVE if lf[2] > 0 else FROM_BELOW, abs(lf[2]))
    return tau, len(hits)


def test_shadow_rays_through_other_folds_pass_their_transmittance(tube):
    """Exact agreement with the brute force (1e-12) at 300 random points of the tube and directions towards
    random points round it, from the top surface or (light from below the tangent plane, as with an IIRTF for
    light from both sides) from the base, with the tiling's layer table and with none (the opaque shell: 0
    wherever a face is crossed); the sample must hold rays that cross a layer and rays that cross none
    (measured 150 and 150)."""
    it = tube._replace(below=True)   # as with a two-sided IIRTF: rays from the base into the tube cross it
    assert it.layer_tau.shape[0] == 2 and np.all(it.layer_tau > 0) and np.all(it.layer_tau < 1)
    opaque = it._replace(layer_tau=np.zeros((0, 2, 1, 3)))
    rng = np.random.default_rng(3)
    crossed = {0: 0, 1: 0, 2: 0}
    n_ok = 0
    while n_ok < 300:
        u, v = rng.random(2)
        ok, *pn = top_point(it.top, u, v)
        w = rng.uniform([-1.2, -1.2, -0.5], [1.2, 1.2, 1.5]) - np.array(pn[:3])   # towards a point round the tube
        w /= np.linalg.norm(w)
        ref = _brute(it, u, v, w)
        if ref is None:
            continue
        n_ok += 1
        tau, k = ref
        crossed[min(k, 2)] += 1
        np.testing.assert_allclose(global_visibility(it, u, v, w), tau, rtol=0, atol=1e-12)
        np.testing.assert_allclose(global_visibility(opaque, u, v, w), np.zeros(3) if k else np.ones(3), atol=0)
    assert crossed[0] >= 10 and crossed[1] >= 10, crossed
