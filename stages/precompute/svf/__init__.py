"""Segment visibility functions (seed 001 §4.1): binary visibility images, their SSDFs, the PCA of the
SSDFs and sums of spherical Gaussians, for the fibre segments of one exemplar.

The SVF V_k(w) of segment k is 1 when the ray from its midpoint mu_k in direction w hits no fibre but
segment k's own, else 0 (§4.1); the ray starts where it leaves segment k's capsule, on the side facing
w (*Rays from a segment* in ``stages.precompute.periodic``: the procedural fibres overlap). It is traced
in the flat fabric made of the exemplar repeated without end (``stages.precompute.periodic``), in
exemplar space (z up).

Pixel grid (every function takes ``res_theta`` x ``res_phi``; the paper uses 128 x 128)
---------------------------------------------------------------------------------------
Pixel (r, c) is centred at theta = (r + 1/2) pi / res_theta (from +z), phi = (c + 1/2) 2 pi / res_phi,
direction (sin theta cos phi, sin theta sin phi, cos theta) (``pixel_direction``); its solid angle is
(cos(r pi/res_theta) - cos((r+1) pi/res_theta)) 2 pi/res_phi. Images are stored bit-packed, row-major
(r then c), in ``np.packbits`` order (pixel i = r res_phi + c is bit 7 - i % 8 of byte i // 8):
``(S, ceil(D / 8))`` uint8 with D = res_theta res_phi, 1 = visible.

1. Visibility images (chunk level): ``visibility_images(psc, k, z_lo, z_hi, mids, fibres, ...)``
   One ray per pixel centre from mu_k (from its capsule's surface: ``capsules``; ``max_dist`` counts
   from mu_k), skipping the segment's whole fibre (and its periodic copies),
   until it leaves the slab z_lo <= z <= z_hi or has run ``max_dist`` (default 32 max(W, H)); a ray
   that hits nothing there is visible. The answer is ``periodic_hit_outside(...).t == inf`` (identical bits
   in the tests) by an any-hit walk over whole exemplar periods through the same wrapped capsules (a hit is any capsule
   root in (0, L), wherever it lies), which first tries the capsule that blocked the previous pixel of
   the row and the one that blocked the pixel above (image coherence; pixels are visited in
   serpentine order). ``tests/precompute/test_svf.py`` compares it with ``periodic_hit_outside`` pixel by pixel.
   The walk reads only exemplar k's fibres, never the block map: ``psc`` may be ``periodic_scene(sc,
   k)`` or the tiling's ``ShellScene`` itself.

2. SSDF (chunk level): ``ssdf_images(packed, res_theta, res_phi)`` -> (S, D) float32.
   Metric: the true angle (great-circle distance, radians) between pixel centres. The renderer turns
   d_k into visibility as 1/2 [erf(sqrt(lam/2) d_k(xi)) + 1] (§5.2.2), whose width sqrt(2/lam) is an
   angle on the sphere, so d_k must be one too (a distance in (theta, phi) pixels would stretch it by
   1/sin theta near the poles). gamma(p) = angle from p's centre to the nearest centre of a pixel of
   the opposite value, found exactly: a row pass gives, per row and column, the column distance to the
   nearest 0 and nearest 1 of that row (phi wraps; two sweeps), so the nearest candidate of each row
   is known; among the rows, the nearest maximises the dot product p . q, which for a fixed column is
   linear in the target's (cos theta, sin theta): an upper convex hull of the rows' candidates per
   column, swept once as theta grows (``ssdf_of_image``), O(D) per image; the chord^2 of the chosen
   candidate is evaluated as 2 - 2 cos(theta - theta') + 4 sin theta sin theta' sin^2(dphi / 2).
   Value: d = +-max(gamma - delta/2, gamma/2), delta = pi / res_theta, + visible, - occluded; a fully
   visible image is +pi everywhere, a fully occluded one -pi. Why: the image's boundary runs between
   the centres of unlike neighbours; a pixel whose nearest unlike centre is the next row's (gamma =
   delta) is delta/2 from it, a farther pixel about gamma - delta/2, so |d| approximates the angular
   distance to the boundary (what the erf above wants); two unlike row neighbours both get +-delta/2,
   so the bilinear zero crossing lies midway between them; and |d| > 0 everywhere, so sign(d)
   reproduces the image exactly (at pixel centres). gamma/2 takes over where unlike centres are closer
   than delta (along the short rows near the poles, sin theta 2 pi / res_phi apart), keeping |d| > 0.
   Between unlike neighbours whose |d| differ (their nearest unlike pixels are not each other) the
   bilinear zero crossing moves towards the smaller |d|, always staying between the two centres.

3. PCA (global): ``ssdf_pca(packed, res_theta, res_phi, n_components=48, seed=0, ...)`` -> ``SsdfPca``
   (mean (D,) float32, basis (n, D) float32 with orthonormal rows, eigenvalues (n,) float64, the
   variance of the SSDFs per segment and the number of segments). Randomised subspace iteration on the
   covariance C = X_c^T X_c (Halko et al. 2011): Z_0 = orth(Omega), Omega (D, p) standard normals from
   ``stages.core.rng.normal(seed, d, 2 j)``, p = n + oversample (8); Z_{i+1} = orth(C Z_i) for
   ``power_iters`` (2) passes over the data; then Rayleigh-Ritz: eigh(Z^T C Z) (p x p, numpy) gives the
   basis rows (Z U)^T, each turned so its largest entry is positive. On 3000 segments of the demo's
   damask (128 x 128, 48 components) the RMS error is 1.085, 1.008, 1.0016 times the optimum (exact
   SVD) at 1, 2, 3 power iterations. Every pass streams the images in chunks (recomputing their SSDFs
   from the packed bits, cheap next to the products) or, with ``hold=True``, keeps the (u, D) float32
   SSDF matrix (``svf_memory_estimate`` gives the peak of either); both give the same bytes.
   Identical images are processed once (``unique_images``: distinct images in lexicographic order of
   their bytes, weighted by their counts): in the demo's damask about 60 % of the segments see
   nothing at all (half of all midpoints lie inside another fibre's capsule, whose ray "meets it on
   the way out"), so this more than halves the PCA and the projection.
   Determinism: every reduction is a numba loop with a fixed order (each output entry sums the
   distinct images in their order, in parallel only over output entries); tall matrices are
   orthonormalised by modified Gram-Schmidt (twice) in numba; only the p x p eigenproblem goes to
   LAPACK. The result is the same at any thread count, chunk size or order of the segments.
   ``ssdf_project(packed_chunk, res_theta, res_phi, mean, basis)`` (chunk level) -> (coeffs (s, n)
   float32, error partials (7,) float64); add the partials of all chunks (in chunk order) and pass them
   to ``pca_error_report`` for the RMS error, the RMS relative to the RMS of the SSDFs, the fraction of
   pixels whose reconstructed sign differs from the image, the same outside the one-pixel band along
   the image's boundary (pixels with an opposite 8-neighbour, phi wrapping), and the visible fraction.

4. Sums of SGs (chunk level): ``sg_fit(packed, seg_ids, res_theta, res_phi, n_sg=48, seed=0)`` ->
   (angle (S,) float32, weights (S, Q) float32). Axes xi_{k,q} = R_k xi'_q (``stages.core.sg.
   spherical_fibonacci_axes``: the paper's spherical Fibonacci points, upper hemisphere, turned about z),
   the angle of R_k = 2 pi uniform(seed, global segment id, SG_ANGLE_DIM) (rounded to float32 before the
   axes are built, so the stored angle rebuilds the same axes); w_{k,q} = total solid angle of the
   visible pixels whose centre is nearer xi_{k,q} than any other axis (largest dot product; ties to
   the lower q), so sum_q w_{k,q} is the visible solid angle.

5. Renderer helpers (``stages.core.svf``, where the renderer reads them): ``ssdf_reconstruct``, ``ssdf_at``,
   ``image_at``, ``ssdf_visible``, ``ssg_visibility``, and the pixel grid (``pixel_direction``, ``pixel_solid_angle``).

Chunking: everything per segment (1, 2, 4, projection) depends only on the segment (its midpoint,
fibre and global id), so a runner splits the segments into contiguous chunks computed independently;
the PCA is the one global step between the visibility images and the projection.

Modules: ``pixels`` (packing), ``visibility`` (1), ``ssdf`` (2), ``pca`` (3), ``sgs`` (4).
"""
from stages.precompute.svf.pca import (
    SsdfPca,
    pca_error_report,
    ssdf_pca,
    ssdf_project,
    svf_memory_estimate,
    unique_images,
)
from stages.precompute.svf.pixels import pack_images, packed_bytes, unpack_images
from stages.precompute.svf.sgs import SG_ANGLE_DIM, sg_angle, sg_axes, sg_fit
from stages.precompute.svf.ssdf import ssdf_images, ssdf_of_image
from stages.precompute.svf.visibility import (
    MAX_DIST_PERIODS,
    ExemplarSegments,
    default_max_dist,
    exemplar_segments,
    periodic_any_hit,
    segment_image,
    visibility_images,
)

__all__ = ["MAX_DIST_PERIODS", "SG_ANGLE_DIM", "ExemplarSegments", "SsdfPca", "default_max_dist", "exemplar_segments",
           "pack_images", "packed_bytes", "pca_error_report", "periodic_any_hit", "segment_image", "sg_angle",
           "sg_axes", "sg_fit", "ssdf_images", "ssdf_of_image", "ssdf_pca", "ssdf_project", "svf_memory_estimate",
           "unique_images", "unpack_images", "visibility_images"]
