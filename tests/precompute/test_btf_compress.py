"""The tabulated BTF's local PCA (stages/precompute/btf_compress.py) and its decoding and lookup
(stages/core/btf.py: ``decode_texels``, ``table_rgb``). Each test names its reference:
- a texture made from an analytic BRDF (Lafortune lobes, ``texel_f1``; a Lambertian one) is reproduced to float
  precision, in the decoded table and by ``table_rgb`` at the grid's directions;
- the error falls with the component count and equals the error of the truncated reconstruction computed
  independently (numpy);
- local PCA against its alternative, one global PCA: on rows drawn from two subspaces, two clusters reconstruct
  them to the noise, one does not;
- the same bytes on 1 and 2 threads; counts out of range are refused.
"""
import numba
import numpy as np
import pytest

from stages.core.btf import decode_texels, hemisphere_grid, table_rgb, texel_f1
from stages.precompute.btf_compress import compress_texels, rank_bound

VIEWS = hemisphere_grid(4, 8)
LIGHTS = hemisphere_grid(4, 6)


def _lafortune_rows(n_texels, seed=0):
    """(T, V L 3) float32 rows of ``texel_f1`` at every grid (view, light) of texels whose lobes are one of three
    (so the rows span at most three directions), and their parameters."""
    rng = np.random.default_rng(seed)
    kinds = []
    for _ in range(3):
        rho = rng.uniform(0.05, 0.3, 3)
        lobes = np.zeros((1, 3, 4))
        lobes[0, :, 0:2] = -rng.uniform(0.6, 1.0, (3, 2))
        lobes[0, :, 2] = rng.uniform(0.6, 1.0, 3)
        lobes[0, :, 3] = rng.uniform(2.0, 12.0, 3)
        frame = np.array([[0.0, 0.0, 1.0], [1.0, 0.0, 0.0]])
        kinds.append((rho, lobes, frame))
    rows = np.empty((n_texels, len(VIEWS), len(LIGHTS), 3))
    for t in range(n_texels):
        rho, lobes, frame = kinds[t % 3]
        for i, v in enumerate(VIEWS):
            for j, lt in enumerate(LIGHTS):
                for c in range(3):
                    rows[t, i, j, c] = texel_f1(rho, lobes, frame, c, *lt, *v)
    return rows.reshape(n_texels, -1).astype(np.float32), kinds


def _decode(tab, k=None):
    K = tab.basis.shape[1] if k is None else k
    out = np.empty((len(tab.weights), tab.mean.shape[1]), np.float32)
    decode_texels(tab.cluster, tab.mean, np.ascontiguousarray(tab.basis[:, :K]),
                  np.ascontiguousarray(tab.weights[:, :K]), out, False)
    return out


def test_lafortune_texture_reproduced_to_float_precision():
    """Reference: the analytic model. Rows of three Lafortune texels (rank 2 after centring) compressed with one
    cluster and two components decode to the rows within float32 rounding; ``table_rgb`` of the decoded table
    at a grid view and a grid light equals ``texel_f1`` there; with three clusters (one per kind) the means alone
    hold them."""
    X, kinds = _lafortune_rows(12)
    scale = float(np.abs(X).max())
    tab = compress_texels(X, 1, 2)
    Y = _decode(tab)
    assert np.max(np.abs(Y - X)) <= 1e-5 * scale
    assert tab.rel_rmse < 1e-5
    R = Y.reshape(len(Y), len(VIEWS), len(LIGHTS), 3)
    for t, i, j in ((0, 5, 7), (4, 30, 2), (8, 17, 20)):
        rho, lobes, frame = kinds[t % 3]
        got = table_rgb(R, t, 4, 6, *LIGHTS[j], 4, 8, *VIEWS[i])
        want = [texel_f1(rho, lobes, frame, c, *LIGHTS[j], *VIEWS[i]) for c in range(3)]
        assert np.allclose(got, want, rtol=1e-5, atol=1e-6 * scale)
    tab3 = compress_texels(X, 3, 1)
    assert len(set(tab3.cluster.tolist())) == 3
    assert tab3.rel_rmse_by_components[0] < 1e-6            # the cluster means are the three kinds


def test_error_falls_with_the_component_count():
    """Reference: numpy. On rows of rank 6 plus noise, ``rel_rmse_by_components`` falls at every added
    component, steeply up to the rank and then to the noise; each entry equals the relative error of the
    reconstruction from that many components computed by decoding the stored parameters (float32 rounding)."""
    rng = np.random.default_rng(1)
    X = (rng.random((200, 6)) @ rng.random((6, 300)) + 1e-3 * rng.standard_normal((200, 300))).astype(np.float32)
    tab = compress_texels(X, 1, 9)
    curve = tab.rel_rmse_by_components
    assert np.all(np.diff(curve) < 0)
    assert curve[6] < 0.02 * curve[1] and curve[9] < 2e-3
    x2 = np.sum(X.astype(np.float64) ** 2)
    for k in range(10):
        err = np.sqrt(np.sum((_decode(tab, k).astype(np.float64) - X) ** 2) / x2)
        assert abs(err - curve[k]) <= 1e-4 * curve[0] + 1e-3 * curve[k]
    assert abs(tab.rel_rmse - curve[9]) <= 1e-4 * curve[0]


def test_two_clusters_beat_one_on_two_subspaces():
    """Reference: the construction. Half the rows in one 3-dimensional subspace and half in another (offset)
    one: local PCA with two clusters and 3 components separates them (each cluster one half) and reconstructs
    to the noise; global PCA (one cluster) with the same 3 components cannot (error > 10x)."""
    rng = np.random.default_rng(2)
    a = rng.random((150, 3)) @ rng.random((3, 240))
    b = rng.random((150, 3)) @ rng.random((3, 240)) + 2.0
    X = (np.concatenate([a, b]) + 1e-3 * rng.standard_normal((300, 240))).astype(np.float32)
    two, one = compress_texels(X, 2, 3), compress_texels(X, 1, 3)
    assert sorted(np.bincount(two.cluster).tolist()) == [150, 150]
    assert len(set(two.cluster[:150].tolist())) == 1
    assert two.rel_rmse < 1e-3
    assert one.rel_rmse > 10 * two.rel_rmse


def test_same_bytes_on_one_and_two_threads():
    """Reference: the same call on 1 thread. Every array of the result, byte for byte."""
    rng = np.random.default_rng(3)
    X = (rng.random((120, 5)) @ rng.random((5, 96)) + 0.05 * rng.random((120, 96))).astype(np.float32)
    before = numba.get_num_threads()
    try:
        numba.set_num_threads(1)
        r1 = compress_texels(X, 3, 4, seed=7)
        numba.set_num_threads(min(2, numba.config.NUMBA_NUM_THREADS))
        r2 = compress_texels(X, 3, 4, seed=7)
    finally:
        numba.set_num_threads(before)
    for name in ("cluster", "mean", "basis", "weights", "rel_rmse_by_components"):
        assert np.asarray(getattr(r1, name)).tobytes() == np.asarray(getattr(r2, name)).tobytes(), name


@pytest.mark.parametrize("clusters,components,needle", [(1, 0, "components"), (1, 12, "components"),
                                                        (0, 2, "clusters"), (13, 2, "clusters")])
def test_counts_out_of_range_are_refused(clusters, components, needle):
    """Contract: 1 <= components <= the rank bound min(T - 1, D) (12 rows: 11), 1 <= clusters <= T."""
    X = np.ones((12, 40), np.float32)
    assert rank_bound(12, 40) == 11
    with pytest.raises(ValueError, match=needle):
        compress_texels(X, clusters, components)
