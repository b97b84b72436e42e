"""The explicit-fibre path tracer (stages/render/integrators/fiberpath.py) against closed forms, an independent
numerical BCSDF and the white furnace; the `loomlight render --method fiberpath` contract."""
import math

import numpy as np
import pytest
from numba import njit
from scipy import integrate
from scipy.special import erf

from stages.core.geometry.bvh import build_fiber_bvh
from stages.core.geometry.embree import EmbreeScene
from stages.core.shading import bcsdf as B
from stages.core.shading.bcsdf import pack_bcsdf
from stages.core.shading.material import pack_material_bcsdf, pack_material_lambert
from stages.render.camera import pack_camera
from stages.render.film import VARIANCE_CHANNELS, finalize, new_film, tile_grid
from stages.render.integrators.fiberpath import FiberpathIntegrator
from stages.render.lights import LightTable, envmap_tables, pack_light
from stages.render.meshes import no_meshes
from stages.render.tiles import render_tiles

WHOLE_FIBRE = 1 << 40


def render_arrays(pts, offs, rad, mats, mat_of_fiber, light_rows, cam, spp, seed=3, max_depth=10_000, rr_depth=5,
                  ground=None, tile=8, env_img=None, accel="bvh"):
    if accel == "embree":
        with EmbreeScene(pts, offs, rad) as es:
            return _render_on(es.fibers, mats, mat_of_fiber, light_rows, cam, spp, seed, max_depth, rr_depth,
                              ground, tile, env_img)
    bvh, _ = build_fiber_bvh(pts, offs, rad)
    return _render_on(bvh, mats, mat_of_fiber, light_rows, cam, spp, seed, max_depth, rr_depth, ground, tile, env_img)


def _render_on(bvh, mats, mat_of_fiber, light_rows, cam, spp, seed, max_depth, rr_depth, ground, tile, env_img):
    lights = LightTable(np.asarray(light_rows, np.float64), *envmap_tables(env_img))
    W, H = int(cam[13]), int(cam[14])
    g = np.zeros(4) if ground is None else np.asarray(ground, float)
    integ = FiberpathIntegrator(bvh, np.asarray(mat_of_fiber, np.int32), np.asarray(mats, np.float64),
                                pack_material_lambert(g[1:4]), lights, g, ground is not None, no_meshes(), max_depth,
                                rr_depth, WHOLE_FIBRE, 1e-7)
    film = render_tiles(integ, cam, seed, spp, 0, spp, tile_grid(W, H, tile), new_film(W, H))
    img = finalize(film, spp, VARIANCE_CHANNELS)
    return img.rgb.astype(np.float64), img.variance.astype(np.float64), img.alpha.astype(np.float64), img.rays


def fibre_cloud(seed, n_fibres=60, n_points=12, radius=0.05):
    rng = np.random.default_rng(seed)
    pts, offs = [], [0]
    for _ in range(n_fibres):
        p = rng.uniform(-0.5, 0.5, 3)
        step = rng.normal(size=3)
        for _ in range(n_points):
            pts.append(p.copy())
            step = 0.6 * step + 0.4 * rng.normal(size=3)
            p = p + 0.08 * step / np.linalg.norm(step)
        offs.append(len(pts))
    return np.asarray(pts), np.asarray(offs), np.full(len(pts), radius)


def straight_fibre(radius=0.3, n_seg=4, half=2.0):
    x = np.linspace(-half, half, n_seg + 1)
    pts = np.stack([x, np.zeros_like(x), np.zeros_like(x)], -1)
    return pts, np.array([0, n_seg + 1]), np.full(n_seg + 1, radius)


@pytest.mark.parametrize("material,accel", [("bcsdf", "bvh"), ("lambert", "bvh"), ("bcsdf-envmap", "bvh"),
                                            ("bcsdf", "embree"), ("lambert", "embree")])
def test_white_furnace(material, accel):
    """Reference: a cloud of non-absorbing fibres (BCSDF with C_TT = 1, or Lambertian albedo 1, over a
    white ground) in a uniform environment L shows L everywhere, within 4 standard errors. The uniform
    environment is a constant light, or a uniform lat-long map (sampled through its sin(theta)-weighted
    2D CDF, so the envmap's sampling, pdf and MIS weights are in the loop)."""
    pts, offs, rad = fibre_cloud(1)
    F = len(offs) - 1
    L = 0.7
    lights = [pack_light("constant", [L, L, L])]
    env_img = None
    ground = None
    if material == "bcsdf-envmap":
        env_img = np.full((8, 16, 3), L, np.float32)
        lights = [pack_light("envmap", [1.0, 1.0, 1.0])]
        material = "bcsdf"
    if material == "bcsdf":
        mats = [pack_material_bcsdf(pack_bcsdf([0.185, 0.047, 0.069], [1.0, 1.0, 1.0], 2.141, 10.0, 23.548))]
    else:
        mats = [pack_material_lambert([1.0, 1.0, 1.0])]
        ground = [-0.7, 1.0, 1.0, 1.0]
    cam = pack_camera(np.array([1.2, -1.6, 1.0]), np.zeros(3), np.array([0.0, 0.0, 1.0]), 32.0, 16, 16)
    img, var, alpha, rays = render_arrays(pts, offs, rad, mats, np.zeros(F), lights, cam, spp=16, ground=ground,
                                          env_img=env_img, accel=accel)
    assert alpha.mean() > 0.3  # the camera sees fibres, not only the background
    covered = alpha > 0.99
    se = math.sqrt(var[covered].sum()) / covered.sum()
    for c in range(3):
        assert abs(img[covered, c].mean() - L) < 4 * se + 1e-6, (img[covered, c].mean(), se)
    # per pixel, within 5 standard errors of the mean of that pixel
    z = np.abs(img[..., 0] - L) / np.sqrt(var + 1e-12)
    assert np.mean(z[covered] > 5) < 0.01
    assert rays > 16 * 16 * 16


def _S_reference(p, wi, wo, t):
    """Independent numpy BCSDF from fiber-bcsdf.md: G by scipy quadrature, phi_d from projected vectors."""
    c_r, c_tt = p[0:3], p[3:6]
    beta_r, beta_tt, gamma = p[6], p[7], p[8]
    ti = math.asin(np.clip(wi @ t, -1, 1))
    to = math.asin(np.clip(wo @ t, -1, 1))

    def G(mu, b):
        return integrate.quad(lambda x: (math.exp(-0.5 * ((x - mu) / b) ** 2) / (math.sqrt(2 * math.pi) * b)
                                         * math.cos(x) ** 2),
                              -math.pi / 2, math.pi / 2, points=[mu], epsrel=1e-11)[0]

    def g(x, mu, b):
        return math.exp(-0.5 * ((x - mu) / b) ** 2) / (math.sqrt(2 * math.pi) * b)

    a = -(wi - (wi @ t) * t)   # azimuth of phi_i + pi
    o = wo - (wo @ t) * t
    cphi = np.clip(a @ o / (np.linalg.norm(a) * np.linalg.norm(o)), -1, 1)
    phi_d = math.acos(cphi)
    I = erf(math.pi / (math.sqrt(2) * gamma))
    F = c_r + (1 - c_r) * (1 - abs(math.cos(ti))) ** 5
    M_r = g(to, -ti, beta_r) / G(-ti, beta_r)
    M_tt = g(to, -ti, beta_tt) / G(-ti, beta_tt)
    N_tt = g(phi_d, 0.0, gamma) + (1 - I) / (2 * math.pi)
    return F * M_r / (2 * math.pi) + (1 - F) * c_tt * M_tt * N_tt


def test_single_fibre_directional_against_numerical_bcsdf():
    """Reference: each pixel integrated numerically (6 x 6 sub-pixel rays, analytic ray-cylinder coverage)
    of E S(wi, wo) cos(theta_o) with the independent numpy BCSDF; directional light, direct lighting only
    (light from behind reaches the camera through the TT lobe: the fibre does not shadow itself)."""
    from stages.render.camera import camera_ray

    p = pack_bcsdf([0.4, 0.3, 0.2], [0.9, 0.6, 0.3], 8.0, 15.0, 30.0)
    pts, offs, rad = straight_fibre(radius=0.3)
    W = H = 12
    cam = pack_camera(np.array([0.3, -1.2, 4.0]), np.zeros(3), np.array([0.0, 1.0, 0.0]), 22.0, W, H)
    E = 2.0
    travel = np.array([0.35, 0.25, 0.9])  # from below: TT dominates on the camera side
    travel /= np.linalg.norm(travel)
    img, var, alpha, _ = render_arrays(pts, offs, rad, [pack_material_bcsdf(p)], [0],
                                       [pack_light("directional", [E, E, E], travel)], cam, spp=64, max_depth=1)
    t = np.array([1.0, 0.0, 0.0])
    wl = -travel
    ref = np.zeros((H, W))
    cover = np.zeros((H, W))
    n_sub = 6
    for i in range(H):
        for j in range(W):
            acc = 0.0
            for a in range(n_sub):
                for b in range(n_sub):
                    o, d = camera_ray(cam, i, j, (b + 0.5) / n_sub, (a + 0.5) / n_sub)
                    # infinite cylinder y^2 + z^2 = r^2 (the fibre spans the view)
                    A = d[1] ** 2 + d[2] ** 2
                    B = o[1] * d[1] + o[2] * d[2]
                    C = o[1] ** 2 + o[2] ** 2 - 0.09
                    h = B * B - A * C
                    if h < 0:
                        continue
                    cover[i, j] += 1
                    acc += E * _S_reference(p, -d, wl, t)[0] * math.cos(math.asin(wl @ t))
            ref[i, j] = acc / n_sub ** 2
            cover[i, j] /= n_sub ** 2
    inner = cover == 1.0
    assert inner.sum() >= 12 and ref[inner].min() > 0
    np.testing.assert_allclose(img[inner, 0], ref[inner], rtol=0.03)
    np.testing.assert_allclose(alpha[inner], 1.0)
    assert img[..., 0].sum() == pytest.approx(ref.sum(), rel=0.03)


def test_single_fibre_constant_environment_closed_form():
    """Reference: a lone fibre (absorbing silk preset) in a uniform environment L reflects
    L (F_R(theta_i) + (1 - F_R(theta_i)) C_TT) per channel (the BCSDF's albedo), all bounces."""
    from pipeline.bcsdf_presets import load_bcsdf_preset
    from stages.core.shading.bcsdf import bcsdf_albedo
    from stages.render.camera import camera_ray

    p = load_bcsdf_preset("silk")
    pts, offs, rad = straight_fibre(radius=0.35)
    W = H = 10
    cam = pack_camera(np.array([-1.0, -0.8, 3.0]), np.zeros(3), np.array([0.0, 0.0, 1.0]), 20.0, W, H)
    L = 1.5
    img, var, alpha, _ = render_arrays(pts, offs, rad, [pack_material_bcsdf(p)], [0],
                                       [pack_light("constant", [L, L, L])], cam, spp=64)
    inner = alpha == 1.0
    assert inner.sum() >= 10
    for i, j in zip(*np.nonzero(inner)):
        _, d = camera_ray(cam, i, j, 0.5, 0.5)
        expect = L * bcsdf_albedo(p, math.asin(-d[0]))
        np.testing.assert_allclose(img[i, j], expect, rtol=0.03, atol=4 * math.sqrt(var[i, j]))


@njit
def _sg_quadrature(p, t, wi, axis, lam, norm, n_theta, n_phi):
    """int S(wi, wo) cos(theta_o) L_sg(wo) dwo by a midpoint rule in the fibre frame's (theta_o, phi_o)."""
    acc = 0.0
    y0, y1, y2, z0, z1, z2 = B.fiber_frame(t)
    wo = np.empty(3)
    for a in range(n_theta):
        th = -0.5 * math.pi + (a + 0.5) * math.pi / n_theta
        for b in range(n_phi):
            ph = -math.pi + (b + 0.5) * 2.0 * math.pi / n_phi
            ct = math.cos(th)
            for k in range(3):
                wo[k] = math.sin(th) * t[k] + ct * (math.cos(ph) * (y0, y1, y2)[k] + math.sin(ph) * (z0, z1, z2)[k])
            f0, f1, f2 = B.bcsdf_eval(p, t, wi, wo)
            c = wo[0] * axis[0] + wo[1] * axis[1] + wo[2] * axis[2]
            acc += f0 * math.exp(lam * (c - 1.0)) * norm * ct
    return acc * (math.pi / n_theta) * (2.0 * math.pi / n_phi)


def test_single_fibre_sg_light_against_quadrature():
    """Reference: a lone fibre under a spherical Gaussian light (power P, sharpness 15): each pixel equals
    int S cos(theta_o) L_sg d wo by 2D quadrature over the sphere (all bounces; the fibre does not shadow
    itself), so light sampling, BCSDF sampling and their MIS weights must combine without bias."""
    from stages.render.camera import camera_ray
    from stages.render.lights import sg_normaliser

    p = pack_bcsdf([0.3, 0.3, 0.3], [0.8, 0.8, 0.8], 6.0, 12.0, 25.0)
    pts, offs, rad = straight_fibre(radius=0.35)
    W = H = 8
    cam = pack_camera(np.array([-0.6, -1.0, 3.0]), np.zeros(3), np.array([0.0, 0.0, 1.0]), 18.0, W, H)
    axis = np.array([0.5, -0.3, 0.8])
    axis /= np.linalg.norm(axis)
    lam, P = 15.0, 4.0
    img, var, alpha, _ = render_arrays(pts, offs, rad, [pack_material_bcsdf(p)], [0],
                                       [pack_light("sg", [P, P, P], axis, lam)], cam, spp=512)
    inner = np.argwhere(alpha == 1.0)
    assert len(inner) >= 12
    t = np.array([1.0, 0.0, 0.0])
    ref = np.empty(len(inner))
    for k, (i, j) in enumerate(inner):
        _, d = camera_ray(cam, i, j, 0.5, 0.5)
        ref[k] = P * _sg_quadrature(p, t, -d, axis, lam, 1.0 / sg_normaliser(lam), 300, 300)
    got = img[inner[:, 0], inner[:, 1], 0]
    se = math.sqrt(var[inner[:, 0], inner[:, 1]].sum()) / len(inner)
    # mean over the covered pixels: 3 standard errors plus 0.5% for the pixel footprint (reference at the centre)
    assert abs(got.mean() - ref.mean()) < 3 * se + 0.005 * ref.mean(), (got.mean(), ref.mean(), se)
    assert se < 0.012 * ref.mean()  # the check is sharp: a 5% bias would fail it


@pytest.mark.parametrize("accel", ["bvh", "embree"])
def test_same_bytes_whatever_the_thread_count(accel):
    """Contract: counter-based random numbers per pixel sample make the image independent of threads."""
    import numba

    pts, offs, rad = fibre_cloud(4, n_fibres=10)
    cam = pack_camera(np.array([1.2, -1.6, 1.0]), np.zeros(3), np.array([0.0, 0.0, 1.0]), 50.0, 12, 10)
    args = (pts, offs, rad, [pack_material_bcsdf(pack_bcsdf([0.5] * 3, [0.8] * 3, 5, 10, 25))], np.zeros(10),
            [pack_light("sg", [3.0, 2.0, 1.0], [0.2, 0.1, 1.0], 8.0), pack_light("directional", [1.0] * 3, [0, 0, -1])],
            cam)
    n0 = numba.get_num_threads()
    try:
        numba.set_num_threads(1)
        a = render_arrays(*args, spp=4, tile=4, accel=accel)[0]
        numba.set_num_threads(max(2, n0) if numba.config.NUMBA_NUM_THREADS >= 2 else 1)
        b = render_arrays(*args, spp=4, tile=4, accel=accel)[0]
    finally:
        numba.set_num_threads(n0)
    assert a.tobytes() == b.tobytes()
    assert a.max() > 0


@pytest.mark.parametrize("material", ["bcsdf", "lambert"])
def test_embree_and_bvh_render_the_same_image(material):
    """The same fibres through Embree (--set accel=embree, the default) and loomlight's BVH: the two images
    agree within noise (per channel, the mean within 4 standard errors of the difference; both carry
    their own noise, independent of each other only where a path's hits differ), and most pixels are
    identical bytes (the same random numbers meet the same hits)."""
    pts, offs, rad = fibre_cloud(7, n_fibres=40)
    mats = [pack_material_bcsdf(pack_bcsdf([0.3] * 3, [0.8, 0.7, 0.6], 5, 10, 25)) if material == "bcsdf"
            else pack_material_lambert([0.8, 0.7, 0.6])]
    lights = [pack_light("constant", [0.5, 0.5, 0.5]), pack_light("directional", [2.0] * 3, [0.3, 0.2, -1.0])]
    cam = pack_camera(np.array([1.2, -1.6, 1.0]), np.zeros(3), np.array([0.0, 0.0, 1.0]), 40.0, 24, 20)
    a, va, _, _ = render_arrays(pts, offs, rad, mats, np.zeros(len(offs) - 1), lights, cam, spp=16, accel="bvh")
    b, vb, _, _ = render_arrays(pts, offs, rad, mats, np.zeros(len(offs) - 1), lights, cam, spp=16, accel="embree")
    n = a.shape[0] * a.shape[1]
    se = math.sqrt((va.sum() + vb.sum())) / n
    for c in range(3):
        assert abs(a[..., c].mean() - b[..., c].mean()) < 4 * se, (a[..., c].mean(), b[..., c].mean(), se)
    same = np.all(np.isclose(a, b, rtol=1e-9, atol=1e-12), axis=-1)
    assert same.mean() > 0.9, same.mean()
    assert a.max() > 0


# ------------------------------------------------------------------------------------------------
# bad input (render_setup) and the command line
def test_bad_presets_and_fibres(tmp_path):
    """Unknown preset, negative widths, colours outside [0, 1], empty fibres: one-line LoomErrors naming the value."""
    from pipeline.bcsdf_presets import load_bcsdf_preset
    from pipeline.errors import LoomError
    from pipeline.render_setup import fibers_from_arrays

    with pytest.raises(LoomError, match="velvet.*known: cotton, fleece, gabardine, polyester, silk"):
        load_bcsdf_preset("velvet")
    bad = tmp_path / "bad.toml"
    bad.write_text('c_r = [0.1, 0.1, 0.1]\nc_tt = [0.5, 0.5, 0.5]\nbeta_r = -2.0\nbeta_tt = 10.0\ngamma_tt = 20.0\n')
    with pytest.raises(LoomError, match=r"beta_r.*-2\.0"):
        load_bcsdf_preset(str(bad))
    bad.write_text('c_r = [0.1, 1.4, 0.1]\nc_tt = [0.5, 0.5, 0.5]\nbeta_r = 2.0\nbeta_tt = 10.0\ngamma_tt = 20.0\n')
    with pytest.raises(LoomError, match=r"c_r\[1\].*1\.4"):
        load_bcsdf_preset(str(bad))
    with pytest.raises(LoomError, match="empty"):
        fibers_from_arrays(np.zeros((0, 3)), np.zeros(0), np.array([0]))
    with pytest.raises(LoomError, match="no segments"):
        fibers_from_arrays(np.zeros((2, 3)), np.ones(2), np.array([0, 1, 2]))
    with pytest.raises(LoomError, match=r"point_radius\[1\]"):
        fibers_from_arrays(np.zeros((2, 3)), np.array([0.1, -0.1]), np.array([0, 2]))


SCENE = """
[fabric]
source = "generator"
[fabric.generator]
kind = "woven"
pattern = "plain"
[yarns.default]
bcsdf = "{bcsdf}"
[camera]
origin = [1.2, -1.6, 1.0]
target = [0.0, 0.0, 0.0]
width = 16
height = 12
[[lights]]
type = "constant"
radiance = 0.5
[[lights]]
type = "directional"
direction = [0.2, 0.3, -1.0]
irradiance = 2.0
[render]
spp = 2
max_depth = 8
"""


def _fibers_artifact(path, empty=False):
    from pipeline.artifacts import ArtifactWriter
    pts, offs, rad = fibre_cloud(2, n_fibres=8)
    if empty:
        pts, offs, rad = np.zeros((0, 3)), np.array([0]), np.zeros(0)
    F = len(offs) - 1
    with ArtifactWriter(path, kind="fibers", stage="realize", params={"test": True}) as w:
        w.write("points", pts.astype(np.float32))
        w.write("point_radius", rad.astype(np.float32))
        w.write("fiber_offsets", offs.astype(np.int64))
        w.write("fiber_yarn", np.zeros(F, np.int32))
        w.write("fiber_ply", np.zeros(F, np.int16))
        w.write("fiber_kind", np.ones(F, np.int8))
        w.write("yarn_albedo", np.full((1, 3), 0.6, np.float32))
        w.summary.update(kind="fibers", fibers=F, vertices=len(pts), yarns=1, spacing=0.08, max_chord_error=0.0,
                         bytes={"total": int(pts.nbytes), "regular": int(pts.nbytes), "loop": 0, "hair": 0})
    return path


def test_cli_usage_errors(cli, tmp_path):
    """Unknown method (lists the known ones), non-positive size or spp: exit code 2, one line."""
    scene = tmp_path / "s.toml"
    scene.write_text(SCENE.format(bcsdf="cotton"))
    code, _, err = cli("render", scene, "--method", "raytrace", "-o", tmp_path / "o.exr")
    assert code == 2 and "fiberpath" in err and "raytrace" in err
    for opt in ("--spp", "--width", "--height"):
        code, _, err = cli("render", scene, "--method", "fiberpath", "-o", tmp_path / "o.exr", opt, "0")
        assert code == 2 and opt in err
    code, _, err = cli("render", scene, "--method", "fiberpath", "--no-build", "-o", tmp_path / "o.exr")
    assert code == 2 and "--fibers" in err
    assert not (tmp_path / "o.exr").exists()


def test_cli_accel_bvh_and_embree_unavailable(cli, tmp_path, monkeypatch):
    """--set accel=bvh renders with loomlight's BVH (same image as Embree within noise: the statistics
    record the accel); an unknown accel, or Embree missing, is a one-line error naming the setting,
    exit 2, nothing written."""
    import stages.core.geometry.embree as E
    from pipeline.artifacts import Artifact

    fib = _fibers_artifact(tmp_path / "fibers.zarr")
    scene = tmp_path / "s.toml"
    scene.write_text(SCENE.format(bcsdf="cotton"))
    for accel in ("embree", "bvh"):
        code, _, err = cli("render", scene, "--method", "fiberpath", "--fibers", fib, "-o", tmp_path / f"{accel}.exr",
                           "--set", f"accel={accel}")
        assert code == 0, err
        assert Artifact(tmp_path / f"{accel}.zarr", kind="render").summary["method_stats"]["accel"] == accel
    code, _, err = cli("render", scene, "--method", "fiberpath", "--fibers", fib, "-o", tmp_path / "x.exr",
                       "--set", "accel=optix")
    assert code == 2 and "accel" in err and "optix" in err and len(err.strip().splitlines()) == 1
    monkeypatch.setattr(E, "_LIB", None)
    monkeypatch.setattr(E.importlib.util, "find_spec", lambda name, *a: None)
    code, _, err = cli("render", scene, "--method", "fiberpath", "--fibers", fib, "-o", tmp_path / "x.exr")
    assert code == 2 and "embreex" in err and "accel=bvh" in err and len(err.strip().splitlines()) == 1, err
    assert not (tmp_path / "x.exr").exists() and not (tmp_path / "x.zarr").exists()


def test_cli_renders_exr_png_artifact(cli, tmp_path):
    """Contract: EXR (RGB + A, depth, variance), PNG preview, render artifact with statistics; bad
    preset / empty fibres exit 2 naming the value and leave no output."""
    from pipeline.artifacts import Artifact
    from pipeline.images import read_exr

    fib = _fibers_artifact(tmp_path / "fibers.zarr")
    scene = tmp_path / "s.toml"
    scene.write_text(SCENE.format(bcsdf="cotton"))
    out = tmp_path / "img" / "fp.exr"
    code, so, err = cli("render", scene, "--method", "fiberpath", "--fibers", fib, "-o", out, "--seed", "5")
    assert code == 0, err
    rgb, ch = read_exr(out)
    assert rgb.shape == (12, 16, 3) and {"A", "depth", "variance"} <= set(ch)
    assert out.with_suffix(".png").exists()
    art = Artifact(out.with_suffix(".zarr"), kind="render")
    np.testing.assert_array_equal(art["image"], rgb)
    s = art.summary
    assert s["method"] == "fiberpath" and s["spp"] == 2 and s["rays"] > 16 * 12 * 2 and s["rays_per_s"] > 0
    assert s["paths_per_s"] > 0 and s["peak_memory_bytes"] > 0 and s["wall_time_s"] >= s["render_time_s"]
    # the inspector draws the artifact
    code, _, err = cli("inspect", out.with_suffix(".zarr"), "--png", tmp_path / "insp.png")
    assert code == 0 and (tmp_path / "insp.png").stat().st_size > 0, err
    # same seed, same bytes
    out2 = tmp_path / "fp2.exr"
    assert cli("render", scene, "--method", "fiberpath", "--fibers", fib, "-o", out2, "--seed", "5")[0] == 0
    assert np.array_equal(read_exr(out2)[0], rgb)
    # unknown preset named in the scene
    scene.write_text(SCENE.format(bcsdf="velvet"))
    code, _, err = cli("render", scene, "--method", "fiberpath", "--fibers", fib, "-o", tmp_path / "x.exr")
    assert code == 2 and "velvet" in err and not (tmp_path / "x.exr").exists()
    # a preset file (resolved against the scene) with a negative lobe width, then one with a colour above 1
    (tmp_path / "bad.toml").write_text('c_r = [0.1, 0.1, 0.1]\nc_tt = [0.5, 0.5, 0.5]\nbeta_r = -3.0\n'
                                       'beta_tt = 10.0\ngamma_tt = 20.0\n')
    scene.write_text(SCENE.format(bcsdf="bad.toml"))
    code, _, err = cli("render", scene, "--method", "fiberpath", "--fibers", fib, "-o", tmp_path / "x.exr")
    assert code == 2 and "beta_r" in err and "-3.0" in err and len(err.strip().splitlines()) == 1
    (tmp_path / "bad.toml").write_text('c_r = [0.1, 0.1, 0.1]\nc_tt = [0.5, 2.5, 0.5]\nbeta_r = 3.0\n'
                                       'beta_tt = 10.0\ngamma_tt = 20.0\n')
    code, _, err = cli("render", scene, "--method", "fiberpath", "--fibers", fib, "-o", tmp_path / "x.exr")
    assert code == 2 and "c_tt[1]" in err and "2.5" in err and not (tmp_path / "x.exr").exists()
    # dyed to the yarn's colour (the default; a grey 0.6 here): the reflection uncoloured and C_TT the same in
    # every channel, so under white lights the picture is grey; tint=none keeps gabardine's tabulated red
    scene.write_text(SCENE.format(bcsdf="gabardine"))
    assert cli("render", scene, "--method", "fiberpath", "--fibers", fib, "-o", tmp_path / "g.exr",
               "--set", "tint=none")[0] == 0
    assert cli("render", scene, "--method", "fiberpath", "--fibers", fib, "-o", tmp_path / "gt.exr")[0] == 0
    (g, g_extra), gt = read_exr(tmp_path / "g.exr"), read_exr(tmp_path / "gt.exr")[0]
    np.testing.assert_array_equal(gt[..., 0], gt[..., 1])
    np.testing.assert_array_equal(gt[..., 1], gt[..., 2])
    cloth = g_extra["A"] == 1.0
    assert cloth.sum() >= 10 and g[cloth, 0].sum() > 1.5 * g[cloth, 1].sum()
    # empty fibers artifact
    scene.write_text(SCENE.format(bcsdf="cotton"))
    empty = _fibers_artifact(tmp_path / "empty.zarr", empty=True)  # the fibers schema allows 0 fibres
    code, _, err = cli("render", scene, "--method", "fiberpath", "--fibers", empty, "-o", tmp_path / "y.exr")
    assert code == 2 and "empty" in err
