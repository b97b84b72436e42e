"""Tables (seed 000 §4.3-4.4) and the lookup command.

References: brute force over every fibre trajectory for the azimuth bins (footnote 2), the artifact
contract of ``loomlight lookup`` (keys, dtypes, shapes), the self-contained tables artifact (lookups
from its own curve copy equal lookups from a freshly built pair), byte-identical rebuilds.
"""
import json
import math

import numpy as np
import pytest

from pipeline import presets
from pipeline.runners.tables import build, load_tables
from stages.core.yarn import model as M, tables as layout
from stages.core.yarn.lookup import lookup_points
from stages.procedural import tables as T
from tests.helpers import compiled_typings

SCENE = """
[fabric]
source = "generator"
[fabric.generator]
kind = "woven"
pattern = "plain"
ends = 2
picks = 1
spacing = 0.25
yarn_radius = 0.03
crimp = 0.4
samples_per_cell = 6
[yarns.warp]
preset = "silk2"
[yarns.weft]
preset = "rayon2"
color = [0.2, 0.3, 0.6]
"""


@pytest.fixture(scope="module")
def built(tmp_path_factory):
    from pipeline.cli import main

    d = tmp_path_factory.mktemp("tables")
    (d / "s.toml").write_text(SCENE)
    assert main(["ingest", str(d / "s.toml"), "-o", str(d / "yarns.zarr")]) == 0
    assert main(["tables", str(d / "yarns.zarr"), "-o", str(d / "tables.zarr"), "--seed", "5"]) == 0
    return d


def _dist_point_segment_2d(p, a, b):
    ab = b - a
    t = np.clip(((p - a) @ ab) / max(ab @ ab, 1e-300), 0, 1)
    return np.linalg.norm(p - (a + t * ab))


@pytest.mark.parametrize("name", ["cotton1", pytest.param("rayon3", marks=pytest.mark.slow)])
def test_azimuth_bins_list_every_nearby_trajectory(name):
    """Every fibre whose trajectory comes within the margin of a unit-disc point is in that point's bin
    with the point inside its radial interval (brute force over all fibres)."""
    tp = presets.pack(presets.load_preset(name))
    K, B = 2.0, 24
    R, th, th0, rlo, rhi, start, items, mask = T.regular_tables(tp, 99, K, B)
    P, N = int(tp[M.PLY_NUM]), int(tp[M.FIBER_NUM])
    m = K * tp[M.FIBER_RADIUS] / min(tp[M.E_SHORT], tp[M.E_LONG])
    lo = tp[M.RHO_MIN] * R
    hi = tp[M.RHO_MAX] * R  # loops beyond it are listed per yarn (test_loop_lists_hold_every_mutated_cycle)
    st = np.concatenate([[0], start])  # regular_tables gives each bin's end
    for k in range(P):  # the bit masks say the same as the bin lists
        for b in range(B):
            g = k * B + b
            bits = {j for j in range(N) if int(mask[k * N + j]) >> b & 1}
            assert bits == set(items[st[g]:st[g + 1]].tolist())
    rng = np.random.default_rng(0)
    checked = 0
    for _ in range(3000):
        k = int(rng.integers(P))
        r = math.sqrt(rng.uniform()) * tp[M.RHO_MAX] * tp[M.R_MAX] * 1.05
        a = rng.uniform(0, 2 * math.pi)
        p = np.array([r * math.cos(a), r * math.sin(a)])
        b = min(int(a / (2 * math.pi) * B), B - 1)
        g = k * B + b
        listed = set(items[st[g]:st[g + 1]].tolist())
        for j in range(N):
            f = k * N + j
            d = np.array([math.cos(th[f]), math.sin(th[f])])
            if _dist_point_segment_2d(p, lo[f] * d, hi[f] * d) < m:
                checked += 1
                assert j in listed
                assert rlo[f] <= r <= rhi[f]
    assert checked > 1000


def test_loop_lists_hold_every_mutated_cycle():
    """tables.yarn_loops against brute force: every (fibre, migration cycle) of a ply whose
    yarn_model.loop_unit_radius says 'mutated' anywhere along the yarn, with its z range, once;
    and the fixed-width z-bins list every loop whose (grown) range meets them."""
    tp = presets.pack(presets.load_preset("cotton1"))
    R, th, th0, *_ = T.regular_tables(tp, 5, 2.0, 16)
    N = int(tp[M.FIBER_NUM])
    L, seed, k = 1.7, np.uint64(987654321), 1
    fib, U, z0, z1, cyc = T.yarn_loops(tp, seed, k, R[k * N:(k + 1) * N], th[k * N:(k + 1) * N],
                                       th0[k * N:(k + 1) * N], L)
    w = tp[M.S_MIG] * 2 * math.pi / tp[M.ALPHA]
    ref = []
    for j in range(N):
        f = k * N + j
        for c in range(-2, int(w * L / (2 * math.pi)) + 3):
            a, b = (2 * math.pi * c - math.pi - th0[f]) / w, (2 * math.pi * c + math.pi - th0[f]) / w
            if b <= 0 or a >= L:
                continue
            u = M.loop_unit_radius(tp, seed, k, j, R[f], th[f], th0[f], c)
            if u > 0:
                ref.append((j, u, max(a, 0.0), min(b, L), c))
    assert len(ref) > 10
    assert [(int(a), float(b), int(c)) for a, b, c in zip(fib, U, cyc)] == [(r[0], r[1], r[4]) for r in ref]
    np.testing.assert_allclose(np.c_[z0, z1], [(r[2], r[3]) for r in ref], rtol=0, atol=1e-12)
    nb, start, items = T.uniform_zbins(z0 - 0.01, z1 + 0.01, L, 0.1)
    for b in range(nb):
        meets = {i for i in range(len(fib)) if z0[i] - 0.01 <= (b + 1) * 0.1 and z1[i] + 0.01 >= b * 0.1}
        assert set(items[start[b]:start[b + 1]].tolist()) >= meets


def test_scan_bounds_hold_their_items(built):
    """The lookups' derived shortcuts (tables.scan_bounds, hair_box) against the items they
    summarise: each ply's radius range holds every fibre's [r_lo, r_hi], each loop z-bin's range
    every listed loop's (r_lo, U_loop), each hair's box its sampled z and radius; and fib_v bounds
    the transverse speed of regular_xy, finite differences along each fibre's regular cycles."""
    cv, tab, _ = load_tables(built / "tables.zarr")
    for t in range(len(tab.type_K)):
        P, N = int(tab.tparams[t, M.PLY_NUM]), int(tab.tparams[t, M.FIBER_NUM])
        for k in range(P):
            f = slice(tab.type_fib_off[t] + k * N, tab.type_fib_off[t] + (k + 1) * N)
            assert tab.ply_rr[t, k, 0] <= tab.fib_rlo[f].min() and tab.fib_rhi[f].max() <= tab.ply_rr[t, k, 1]
    nloops = 0
    for c in range(len(tab.yarn_type)):
        t = tab.yarn_type[c]
        N = int(tab.tparams[t, M.FIBER_NUM])
        for k in range(int(tab.tparams[t, M.PLY_NUM])):
            g = tab.yarn_ply_off[c] + k
            for zb in range(tab.lz_off[g], tab.lz_off[g + 1]):
                le = tab.lp_off[g] + tab.lz_items[tab.lz_start[zb]:tab.lz_start[zb + 1]]
                nloops += len(le)
                fi = tab.type_fib_off[t] + k * N + tab.lp_fib[le]
                assert np.all(tab.lz_rr[zb, 0] <= tab.fib_rlo[fi]) and np.all(tab.lp_U[le] <= tab.lz_rr[zb, 1])
    assert nloops > 0
    ts = np.linspace(0.0, 1.0, 33)
    assert len(tab.hair_box) == len(tab.hair_z1) > 0
    for h in range(0, len(tab.hair_z1), 7):
        z = tab.hair_z1[h] + tab.hair_ze[h] * ts
        R = tab.hair_r0[h] + (tab.hair_r1[h] - tab.hair_r0[h]) * ts
        lo, hi, rlo, rhi = tab.hair_box[h]
        assert lo <= z.min() + 1e-12 and z.max() <= hi + 1e-12 and rlo <= R.min() + 1e-12 and R.max() <= rhi + 1e-12
    c = 0
    t = tab.yarn_type[c]
    tp = tab.tparams[t]
    N = int(tp[M.FIBER_NUM])
    zs = np.linspace(0.0, tab.yarn_length[c], 4001)
    hz = zs[1] - zs[0]
    worst, checked = 0.0, 0
    for j in range(0, N, 5):
        fi = tab.type_fib_off[t] + j
        xy = np.array([M.regular_xy(tp, np.uint64(tab.yarn_seed[c]), 0, j, tab.fib_R[fi], tab.fib_th[fi],
                                    tab.fib_th0[fi], z) for z in zs])
        regular = (xy[1:, 2] == 1) & (xy[:-1, 2] == 1)
        speed = np.hypot(*np.diff(xy[:, :2], axis=0).T)[regular] / hz
        if len(speed):
            checked += len(speed)
            worst = max(worst, float((speed / tab.fib_v[fi]).max()))
    assert checked > 10000 and 0.3 < worst <= 1.0


def test_fringe_occupancy_covers_loops_and_hairs(built):
    """tables.fringe_occupancy against brute force: every point within fringe_reach (yarn space) of
    a loop's fibre (densely sampled over the loop's cycle grown by fringe_window) has its loop bit
    set, of a hair (densely sampled) its hair bit, and lies inside the gate (tables.chord_gates) of
    every chord whose lookup bracket holds it; and beyond type_rcore from the axis every ply's
    unit-disc radius exceeds its ply_rr (no regular fibre of any ply is in reach)."""
    cv, tab, _ = load_tables(built / "tables.zarr")
    rng = np.random.default_rng(3)
    checked = {"loop": 0, "hair": 0}

    def probe(c, kind, x, y, z, r):
        d = rng.normal(size=(8, 3))
        d *= (r * 0.999 * rng.uniform(0, 1, (8, 1)) ** (1 / 3)) / np.linalg.norm(d, axis=1, keepdims=True)
        for px, py, pz in np.array([x, y, z]) + d:
            pz = min(max(pz, 0.0), tab.yarn_length[c])
            lb, hb = layout.fringe_bits(tab, c, pz, px, py, math.hypot(px, py))
            assert (lb if kind == "loop" else hb), (c, kind, px, py, pz)
            # and inside the gate of every chord whose lookup bracket holds pz (chord_gates)
            k0, k1 = tab.kn_off[c], tab.kn_off[c + 1]
            for q in range(k0, k1 - 1):
                if tab.kn_s[max(q - 1, k0)] <= pz <= tab.kn_s[min(q + 2, k1 - 1)]:
                    assert math.hypot(px, py) < tab.kn_rgate[q], (c, q, kind)
            checked[kind] += 1

    for c in range(len(tab.yarn_type)):
        t = tab.yarn_type[c]
        tp = tab.tparams[t]
        rf, eps, gmin = tp[M.FIBER_RADIUS], tab.yarn_eps[c], tab.yarn_gmin[c]
        r = layout.fringe_reach(rf, eps, gmin)
        win = layout.fringe_window(tab.type_K[t], tab.type_mz[t], rf, eps, gmin)
        ys = np.uint64(tab.yarn_seed[c])
        for k in range(int(tp[M.PLY_NUM])):
            g = tab.yarn_ply_off[c] + k
            for e in range(tab.lp_off[g], tab.lp_off[g + 1], 3):
                j, fi, z0, z1 = layout.loop_fibre(tab, tp, c, k, e)
                for z in np.linspace(max(0.0, z0 - win), min(tab.yarn_length[c], z1 + win), 97):
                    x, y, _ = M.regular_xy(tp, ys, k, j, tab.fib_R[fi], tab.fib_th[fi], tab.fib_th0[fi], z)
                    probe(c, "loop", x, y, z, r)
            for h in range(tab.hair_off[g], tab.hair_off[g] + tab.hair_count[g], 5):
                for u in np.linspace(0.0, 1.0, 41):
                    x, y, z = M.hair_point(tp, k, tab.hair_r0[h], tab.hair_r1[h], tab.hair_th1[h], tab.hair_pe[h],
                                           tab.hair_z1[h], tab.hair_ze[h], u)
                    probe(c, "hair", x, y, z, r)
        # the core radius: any point beyond it is outside every ply's radius range
        for _ in range(200):
            a = rng.uniform(0, 2 * np.pi)
            rho = tab.type_rcore[t] * (1.0 + 1e-9) + rng.exponential(tab.type_rcore[t] * 0.2)
            z = rng.uniform(0, tab.yarn_length[c])
            x, y = rho * np.cos(a), rho * np.sin(a)
            for k in range(int(tp[M.PLY_NUM])):
                cx, cy, drx, dry = M.ply_frame(tp, k, z)
                u = ((x - cx) * drx + (y - cy) * dry) / tp[M.E_SHORT]
                v = (-(x - cx) * dry + (y - cy) * drx) / tp[M.E_LONG]
                assert math.hypot(u, v) > tab.ply_rr[t, k, 1]
    assert checked["loop"] > 1000 and checked["hair"] > 1000, checked


def test_lookup_command_contract(built, cli):
    d = built
    pts = np.random.default_rng(3).uniform([-0.3, -0.2, -0.05], [0.3, 0.2, 0.05], (4000, 3))
    np.save(d / "pts.npy", pts)
    code, out, err = cli("lookup", d / "tables.zarr", "--points", d / "pts.npy", "-o", d / "res.npz")
    assert code == 0, err
    res = np.load(d / "res.npz")
    assert res["inside"].dtype == bool and res["inside"].shape == (4000,)
    assert res["yarn"].dtype.kind == "i" and res["kind"].dtype.kind == "i"
    assert res["direction"].shape == (4000, 3) and res["density"].shape == (4000,)
    ins = res["inside"]
    assert ins.any() and (~ins).any()
    assert np.all(res["yarn"][~ins] == -1) and np.all(res["kind"][~ins] == 0) and np.all(res["density"][~ins] == 0)
    assert np.all(np.isin(res["kind"][ins], [1, 2, 3])) and np.all(res["density"][ins] > 0)
    np.testing.assert_allclose(np.linalg.norm(res["direction"][ins], axis=1), 1.0, rtol=1e-9)
    # weft (yarn type with a colour) answers with that albedo
    cv, tab, art = load_tables(d / "tables.zarr")
    weft = np.nonzero(tab.yarn_albedo[:, 0] == 0.2)[0]
    assert len(weft) and np.all(np.isin(res["yarn"][ins & np.isin(res["yarn"], weft)], weft))


def test_tables_artifact_is_self_contained_and_deterministic(built, cli):
    d = built
    cv, tab, art = load_tables(d / "tables.zarr")
    cv2, tab2, _, _, _ = build(d / "yarns.zarr", seed=5)
    pts = np.random.default_rng(4).uniform([-0.3, -0.2, -0.05], [0.3, 0.2, 0.05], (3000, 3))
    for a, b in zip(lookup_points(cv, tab, pts), lookup_points(cv2, tab2, pts)):
        assert np.array_equal(a, b)
    code, out, err = cli("tables", d / "yarns.zarr", "-o", d / "again.zarr", "--seed", "5")
    assert code == 0, err
    code, out, err = cli("info", d / "again.zarr", "--json")
    again = json.loads(out)
    assert again["content_hash"] == art.meta["content_hash"]
    b = again["bytes"]
    assert b["tables"] == b["regular"] + b["hair"] + b["loop"] + b["per_yarn"] and b["loop"] > 0


def test_seed_changes_the_fabric(built):
    d = built
    _, tab_a, _, _, _ = build(d / "yarns.zarr", seed=5)
    _, tab_b, _, _, _ = build(d / "yarns.zarr", seed=6)
    assert not np.array_equal(tab_a.fib_R, tab_b.fib_R)


@pytest.mark.parametrize("args,needle", [
    (["--preset", "nylon"], "unknown preset 'nylon'"), (["--radius", "0"], "--radius"),
    (["--radius", "-2"], "--radius"), (["--hair-mode", "bald"], "--hair-mode"), (["--bins", "0"], "--bins"),
])
def test_tables_bad_options_exit_2(built, cli, args, needle):
    d = built
    code, out, err = cli("tables", d / "yarns.zarr", "-o", d / "bad.zarr", *args)
    assert code == 2 and needle in err
    assert not (d / "bad.zarr").exists()


def test_lookup_bad_points_exit_2(built, cli):
    d = built
    np.save(d / "bad.npy", np.zeros((5, 2)))
    code, out, err = cli("lookup", d / "tables.zarr", "--points", d / "bad.npy", "-o", d / "r.npz")
    assert code == 2 and "(N, 3)" in err


def test_cross_section_inspector(built, cli):
    """The cross-section holds every regular fibre of every ply (P N centres) and the plot is written."""
    from pipeline.inspectors.tables import cross_section

    d = built
    cv, tab, _ = load_tables(d / "tables.zarr")
    pts, kinds, plies = cross_section(tab, 0, 0.1)
    t = int(tab.yarn_type[0])
    P, N = int(tab.tparams[t, M.PLY_NUM]), int(tab.tparams[t, M.FIBER_NUM])
    assert (kinds != 3).sum() == P * N and set(np.unique(plies)) == set(range(P))
    code, out, err = cli("inspect", d / "tables.zarr", "--png", d / "xs.png", "--z", "0.1")
    assert code == 0, err
    assert (d / "xs.png").stat().st_size > 10_000
    code, out, err = cli("inspect", d / "tables.zarr", "--png", d / "xs2.png", "--z", "99")
    assert code == 2 and "--z" in err


def test_accel_estimate_counts_what_loading_derives(built):
    """The render's memory estimate of loading tables (runners.tables.accel_estimate) against the
    arrays derive_lookup_accel makes: frame_sample_count equals sample_all's count at the same steps
    exactly, and the estimate of the derived parts holds their bytes without exceeding them twice."""
    from pipeline.artifacts import Artifact
    from pipeline.runners.tables import accel_estimate, frame_sample_count
    from stages.core.yarn.accel import frame_steps
    from stages.core.yarn.frame_samples import sample_all

    cv, tab, _ = load_tables(built / "tables.zarr")
    art = Artifact(built / "tables.zarr", kind="tables")
    Y = len(tab.yarn_type)
    rf = tab.tparams[tab.yarn_type, M.FIBER_RADIUS]
    for scale in (1.0, 0.2):  # the first-guess steps (breakpoints decide) and finer ones (steps decide)
        step = scale * frame_steps(tab.yarn_kappa, tab.yarn_extent, cv.radius[:Y], rf)
        off, _, _, _ = sample_all(cv, step, tab.yarn_extent)
        assert frame_sample_count(art, step) == off[-1]
    parts = {label: b for label, b, _ in accel_estimate(art, "test").parts}
    derived = {"frame samples": ("fs_s", "fs_frame"), "chord grid": ("fg_yarn", "fg_a", "fg_b", "fg_start"),
               "fringe and bounds": ("fo_bits", "hair_box")}
    for label, fields in derived.items():
        held = sum(getattr(tab, f).nbytes for f in fields)
        assert held <= parts[label] <= 2.0 * held + 2**20, (label, held, parts[label])


def test_lookups_compile_once_for_every_caller(built):
    """lookup_point is the costliest kernel to compile (about a minute): the batch lookups and volpath's
    medium (with and without a fibre to skip) must call it with one typing, or every process compiles it
    again (a literal -1 for ``skip`` once did that)."""
    from stages.core.yarn.lookup import lookup_point
    from stages.render.media.procedural_medium import ProceduralMedium, procedural_lookup

    cv, tab, _ = load_tables(built / "tables.zarr")
    pts = np.random.default_rng(8).uniform([-0.3, -0.2, -0.05], [0.3, 0.2, 0.05], (500, 3))
    r = lookup_points(cv, tab, pts)
    med = ProceduralMedium(cv, tab)
    for i in np.nonzero(r.inside)[0][:20]:
        x, y, z = pts[i]
        assert procedural_lookup(med, x, y, z).den == r.density[i]
        assert procedural_lookup(med, x, y, z, -1).den == r.density[i]
    assert len(compiled_typings(lookup_point)) == 1, compiled_typings(lookup_point)


def test_paged_tables_derive_the_same_numbers(built):
    """Paged frame samples (stages.core.yarn.frame_pool): tables derived paged, in chunks of a few yarns'
    samples, hold every derived array the resident derive makes, to the bit, but the resident samples
    themselves (none); samples made again for any yarns (``resident``) equal the resident derive's."""
    from stages.core.yarn.accel import derive_lookup_accel
    from stages.core.yarn.frame_pool import is_paged, resident

    cv, tab, _ = load_tables(built / "tables.zarr")
    paged = derive_lookup_accel(cv, tab, paged=True, chunk_samples=50)
    assert is_paged(paged) and not is_paged(tab)
    assert len(paged.fs_s) == 0 and (paged.fs_at == -1).all()
    for f in layout.DERIVED_FIELDS:
        if f not in ("fs_at", "fs_s", "fs_frame"):
            assert np.array_equal(getattr(paged, f), getattr(tab, f)), f
    Y = len(tab.yarn_type)
    for ys in ([Y - 1], list(range(Y))):
        some = resident(cv, paged, ys)
        for c in ys:
            a, b = some.fs_at[c], tab.fs_at[c]
            n = tab.fs_n[c]
            assert np.array_equal(some.fs_frame[a:a + n], tab.fs_frame[b:b + n])
            assert np.array_equal(some.fs_s[a:a + n], tab.fs_s[b:b + n])
        assert (np.delete(some.fs_at, ys) == -1).all()


def test_frame_pool_pages_in_the_yarns_lookups_reach(built):
    """Lookups on paged tables ask for the yarns whose samples they need (fs_want, fs_miss) and leave them
    out; after ``FramePool.page_in`` rounds until nothing misses, every answer equals the resident
    tables' exactly, and only yarns whose chord-grid capsules reach a point were paged in. A round that
    wants nothing new is refused."""
    from stages.core.yarn.accel import derive_lookup_accel
    from stages.core.yarn.frame_pool import FramePool

    cv, tab, _ = load_tables(built / "tables.zarr")
    pool = FramePool(cv, derive_lookup_accel(cv, tab, paged=True))
    # points about the middle of yarn 0's axis, within its extent
    c = 0
    mid = tab.kn_off[c] + (tab.kn_off[c + 1] - tab.kn_off[c]) // 2
    rng = np.random.default_rng(4)
    pts = tab.kn_pos[mid] + rng.uniform(-1.0, 1.0, (400, 3)) * tab.yarn_extent[c]
    want = lookup_points(cv, tab, pts)
    for _ in range(len(tab.yarn_type) + 1):
        pool.tables.fs_miss[0] = 0
        got = lookup_points(cv, pool.tables, pts)
        if pool.tables.fs_miss[0] == 0:
            break
        pool.page_in()
    assert pool.tables.fs_miss[0] == 0 and pool.rounds >= 1
    assert want.inside.any()
    for f in ("inside", "yarn", "kind", "direction", "density", "albedo"):
        assert np.array_equal(getattr(got, f), getattr(want, f)), f
    # paged in: yarn 0 and yarns whose coarse chords come within extent + eps + sag of a point
    paged_in = np.flatnonzero(pool.tables.fs_at >= 0)
    assert c in paged_in and pool.yarns_in == len(paged_in)
    for y in paged_in:
        k0, k1 = tab.kn_off[y], tab.kn_off[y + 1]
        reach = tab.yarn_extent[y] + 2.0 * tab.yarn_eps[y] + tab.kn_sag[k0:k1].max()
        d = np.linalg.norm(pts[:, None, :] - tab.kn_pos[None, k0:k1], axis=2).min()
        assert d <= reach + np.max(np.linalg.norm(np.diff(tab.kn_pos[k0:k1], axis=0), axis=1)), y
    with pytest.raises(RuntimeError, match="no yarn was wanted"):
        pool.page_in()
