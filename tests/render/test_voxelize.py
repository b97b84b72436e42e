"""Voxel grid source and voxelizer.

References: Mitsuba's gridvolume convention (voxel centres at (i + 0.5)/N, trilinear, clamped) as a
closed form; exact box-overlap volume fractions for the voxelizer; brute-force maxima for the
majorant grid.
"""
import numpy as np
import pytest

from stages.render.media.grid_medium import GridMedium, grid_lookup, sggx_volume, voxelize
from stages.render.media.medium import HomogeneousMedium
from stages.render.media.tracking import majorants_from_capsules, majorants_from_voxels


def _grid(density, lo=(0.0, 0.0, 0.0), hi=(1.0, 1.0, 1.0), seed=0):
    nz, ny, nx = density.shape
    rng = np.random.default_rng(seed)
    d = rng.normal(size=(nz, ny, nx, 3))
    d /= np.linalg.norm(d, axis=-1, keepdims=True)
    return GridMedium(np.asarray(lo, float), np.asarray(hi, float), density.astype(np.float32),
                      d.astype(np.float32), rng.random((nz, ny, nx, 3)).astype(np.float32),
                      (0.1 + rng.random((nz, ny, nx))).astype(np.float32))


def _trilinear_reference(den, lo, hi, p):
    """Trilinear interpolation between voxel centres with border clamping, written with numpy."""
    nz, ny, nx = den.shape
    u = (np.asarray(p) - lo) / (hi - lo) * np.array([nx, ny, nz]) - 0.5
    u = np.clip(u, 0.0, np.array([nx, ny, nz]) - 1.0)  # clamping the coordinate == clamping indices
    i0 = np.floor(u).astype(int)
    i1 = np.minimum(i0 + 1, np.array([nx, ny, nz]) - 1)
    f = u - i0
    val = 0.0
    for cz in (0, 1):
        for cy in (0, 1):
            for cx in (0, 1):
                w = (f[0] if cx else 1 - f[0]) * (f[1] if cy else 1 - f[1]) * (f[2] if cz else 1 - f[2])
                val += w * den[(i1 if cz else i0)[2], (i1 if cy else i0)[1], (i1 if cx else i0)[0]]
    return val


def test_grid_lookup_voxel_centres_and_trilinear():
    rng = np.random.default_rng(1)
    den = rng.random((3, 4, 5)).astype(np.float32)
    lo, hi = np.array([-1.0, 0.0, 2.0]), np.array([1.0, 3.0, 2.5])
    g = _grid(den, lo, hi)
    # voxel centres return the voxel's own value (and its direction, albedo, roughness)
    for (k, j, i) in [(0, 0, 0), (2, 3, 4), (1, 2, 3)]:
        c = lo + (np.array([i, j, k]) + 0.5) / np.array([5, 4, 3]) * (hi - lo)
        r = grid_lookup(g, *c)
        assert r.den == pytest.approx(den[k, j, i], rel=1e-6)
        np.testing.assert_allclose([r.tx, r.ty, r.tz], g.direction[k, j, i], rtol=1e-6)
        np.testing.assert_allclose([r.albedo_r, r.albedo_g, r.albedo_b], g.albedo[k, j, i], rtol=1e-6)
    # anywhere in the box (including the clamped border half-voxels): the trilinear closed form
    for p in lo + rng.random((200, 3)) * (hi - lo):
        assert grid_lookup(g, *p).den == pytest.approx(_trilinear_reference(den, lo, hi, p), rel=1e-6, abs=1e-9)
    # outside the box there is no medium
    assert grid_lookup(g, 1.01, 1.0, 2.2).den == 0.0


def test_voxel_majorants_bound_every_lookup():
    """A majorant cell must bound the trilinear density at every point inside it (brute force)."""
    rng = np.random.default_rng(2)
    den = (rng.random((6, 7, 5)) * (rng.random((6, 7, 5)) > 0.6)).astype(np.float32)
    lo, hi = np.zeros(3), np.array([1.0, 1.4, 1.2])
    g = _grid(den, lo, hi)
    res = np.array([3, 2, 4])
    mu = majorants_from_voxels(den, lo, hi, res)
    cs = (hi - lo) / res
    pts = lo + rng.random((4000, 3)) * (hi - lo)
    for p in pts:
        c = np.minimum(((p - lo) / cs).astype(int), res - 1)
        assert grid_lookup(g, *p).den <= mu[c[2], c[1], c[0]] + 1e-6
    # and it is zero only where the whole cell is empty
    assert mu.max() == pytest.approx(den.max())


def test_capsule_majorants_cover_capsules_and_skip_empty_cells():
    a = np.array([[0.1, 0.1, 0.5], [0.2, 0.8, 0.2]])
    b = np.array([[0.9, 0.2, 0.5], [0.2, 0.9, 0.9]])
    r = np.array([0.05, 0.1])
    bound = np.array([3.0, 7.0])
    lo, hi, res = np.zeros(3), np.ones(3), np.array([10, 10, 10])
    mu = majorants_from_capsules(a, b, r, bound, lo, hi, res)
    rng = np.random.default_rng(3)
    pts = rng.random((20000, 3))
    for k in range(2):
        ab = b[k] - a[k]
        t = np.clip(((pts - a[k]) @ ab) / (ab @ ab), 0, 1)
        inside = np.linalg.norm(pts - (a[k] + t[:, None] * ab), axis=1) <= r[k]
        c = np.minimum((pts[inside] * 10).astype(int), 9)
        assert np.all(mu[c[:, 2], c[:, 1], c[:, 0]] >= bound[k])
    # cells far from both capsules stay empty (exact segment-box distance test)
    assert mu[0, 9, 9] == 0.0 and mu[9, 0, 9] == 0.0
    assert 0 < np.count_nonzero(mu) < mu.size // 4


def test_voxelize_box_overlap_fractions():
    """Voxelizing a homogeneous box gives density x (overlap volume / voxel volume) per voxel (exact for
    supersampling that resolves the box faces: faces on multiples of 1/(N ss))."""
    box = HomogeneousMedium(np.array([0.25, 0.0, 0.125]), np.array([0.75, 0.5, 0.625]), 4.0,
                            np.array([0.0, 0.6, 0.8]), 0.4, np.array([0.2, 0.5, 0.9]))
    lo, hi, res, ss = np.zeros(3), np.ones(3), np.array([8, 4, 4]), 4
    nx, ny, nz = res
    den = np.zeros((nz, ny, nx), np.float32)
    dirs = np.zeros((nz, ny, nx, 3), np.float32)
    alb = np.zeros((nz, ny, nx, 3), np.float32)
    rough = np.zeros((nz, ny, nx), np.float32)
    voxelize(box, lo, hi, res, ss, 0, nz, den, dirs, alb, rough)
    # exact overlap fractions along each axis
    def frac(n, a, b):
        e = np.linspace(0, 1, n + 1)
        return np.clip(np.minimum(e[1:], b) - np.maximum(e[:-1], a), 0, None) * n
    expect = (4.0 * frac(nz, 0.125, 0.625)[:, None, None] * frac(ny, 0.0, 0.5)[None, :, None]
              * frac(nx, 0.25, 0.75)[None, None, :])
    np.testing.assert_allclose(den, expect, rtol=1e-6, atol=1e-6)
    occ = den > 0
    np.testing.assert_allclose(np.abs(dirs[occ] @ np.array([0.0, 0.6, 0.8])), 1.0, rtol=1e-6)
    np.testing.assert_allclose(alb[occ], np.broadcast_to([0.2, 0.5, 0.9], alb[occ].shape), rtol=1e-6)
    np.testing.assert_allclose(rough[occ], 0.4, rtol=1e-6)
    # Mitsuba's SGGX volume of a voxel equals the fibre-like matrix (I - t t^T) + s^2 t t^T
    S = sggx_volume(dirs, rough)[occ][0]
    t = dirs[occ][0].astype(float)
    M = np.eye(3) + (0.4 ** 2 - 1) * np.outer(t, t)
    np.testing.assert_allclose(S, [M[0, 0], M[1, 1], M[2, 2], M[0, 1], M[0, 2], M[1, 2]], rtol=1e-5, atol=1e-6)


def test_voxelize_cli_grid_artifact_export_and_render(tmp_path, cli):
    """loomlight voxelize: a schema-checked grid artifact whose voxels are the mean of the procedural
    lookups (brute-force recomputation of a few voxels), raw numpy volumes identical to it, a skip
    when unchanged, exit 2 on bad input; the grid renders with --source grid."""
    from pipeline.artifacts import Artifact
    from pipeline.runners.tables import load_tables
    from stages.render.media.procedural_medium import ProceduralMedium, procedural_lookup

    scene = tmp_path / "s.toml"
    scene.write_text(GRID_SCENE)
    assert cli("ingest", scene, "-o", tmp_path / "y.zarr")[0] == 0
    assert cli("tables", tmp_path / "y.zarr", "-o", tmp_path / "t.zarr")[0] == 0
    code, out, err = cli("voxelize", tmp_path / "t.zarr", "-o", tmp_path / "g.zarr", "--res", 6, 5, 4,
                         "--supersample", 3, "--export-npy", tmp_path / "npy")
    assert code == 0, err
    g = Artifact(tmp_path / "g.zarr", kind="grid")
    den = g["density"]
    assert den.shape == (4, 5, 6) and g["direction"].shape == (4, 5, 6, 3)
    assert g.summary["resolution"] == [6, 5, 4] and 0 < g.summary["occupied_fraction"] <= 1
    np.testing.assert_array_equal(np.load(tmp_path / "npy" / "density.npy"), den)
    np.testing.assert_array_equal(np.load(tmp_path / "npy" / "sggx.npy"), sggx_volume(g["direction"], g["roughness"]))
    lo, hi = np.load(tmp_path / "npy" / "grid_bounds.npy")
    # brute force: the mean of 3^3 lookups at the stratified points of the densest voxel
    cv, tab, _ = load_tables(tmp_path / "t.zarr")
    med = ProceduralMedium(cv, tab)
    k, j, i = np.unravel_index(np.argmax(den), den.shape)
    cs = (hi - lo) / np.array([6, 5, 4])
    vals = [procedural_lookup(med, *(lo + (np.array([i, j, k]) + (np.array([a, b, c]) + 0.5) / 3) * cs)).den
            for a in range(3) for b in range(3) for c in range(3)]
    assert den[k, j, i] == pytest.approx(np.mean(vals), rel=1e-6)
    # unchanged inputs: skipped
    code, out, _ = cli("voxelize", tmp_path / "t.zarr", "-o", tmp_path / "g.zarr", "--res", 6, 5, 4, "--supersample", 3)
    assert code == 0 and "up to date" in out
    # bad input
    code, _, err = cli("voxelize", tmp_path / "t.zarr", "-o", tmp_path / "h.zarr", "--res", 0, 5, 4)
    assert code == 2 and "--res" in err
    code, _, err = cli("voxelize", tmp_path / "nothing.zarr", "-o", tmp_path / "h.zarr", "--res", 2, 2, 2)
    assert code == 2 and "not found" in err
    assert not (tmp_path / "h.zarr").exists()
    # the grid source renders
    code, out, err = cli("render", scene, "--method", "volpath", "--source", "grid",
                         "--set", f"grid={tmp_path / 'g.zarr'}",
                         "-o", tmp_path / "r.exr", "--width", 6, "--height", 6, "--spp", 2)
    assert code == 0, err
    assert Artifact(tmp_path / "r.zarr").summary["method_stats"]["medium_lookups"] > 0


GRID_SCENE = """
[fabric]
source = "generator"

[fabric.generator]
kind = "woven"
pattern = "plain"
ends = 2
picks = 2
spacing = 0.1
yarn_radius = 0.045
samples_per_cell = 4

[camera]
origin = [0.0, -0.1, 0.6]
target = [0.0, 0.0, 0.0]
fov = 20.0

[[lights]]
type = "constant"
radiance = 1.0
"""
