"""Materials of explicit-fibre scenes: a scattering model and its parameters packed in one row.

An integrator that shades fibres (or the ground) holds a table of rows, float64[MAT_SIZE] each:

    0       model: MAT_BCSDF (the fibre BCSDF of Khungurn et al. 2015, ``stages.core.shading.bcsdf``),
            MAT_LAMBERT (an opaque Lambertian surface, ``stages.core.shading.lambert``) or MAT_DIELECTRIC
            (a rough dielectric interface, ``stages.core.shading.microfacet``: meshes' rows only, shaded
            by ``stages.render.meshes``, which knows the triangle's outward side; the four functions
            below take BCSDF and Lambert rows)
    1:11    packed BCSDF (BCSDF_SIZE values)          -- MAT_BCSDF
    1, 2    eta (inside over outside), roughness      -- MAT_DIELECTRIC
    11:14   albedo (rgb)                              -- MAT_LAMBERT

``pack_material_bcsdf(bcsdf_params)`` / ``pack_material_lambert(albedo)`` build rows. The integrator
asks a row four things at a scattering vertex (tangent t and outward normal n of the hit, wi towards
the viewer, wo towards the light):

    material_is_curve(mat)                          True: a curve model (BCSDF) that integrates over the
                                                    fibre's cross-section -- rays leave from the hit and
                                                    skip the fibre; False: an opaque surface -- rays
                                                    leave just off the surface and test everything
    material_prepare(mat, t, n, wi, ctx)            per-vertex context (float64[CTX_SIZE]: what depends
                                                    on wi only), filled once per vertex
    material_eval_pdf(mat, ctx, t, n, wi, wo)       (f cos r, g, b, pdf of material_sample)
    material_sample(mat, ctx, t, n, wi, u0, u1, u2, wo)  direction into wo; (weight r, g, b, pdf), pdf 0 on
                                                    failure; u0 picks a lobe, u1 and u2 the direction

A new shading model is a file in this package with eval / pdf / sample (the interface its neighbours
have), a model number here and a branch in each of the four functions.
"""
import numpy as np
from numba import njit

from stages.core.shading import bcsdf as B
from stages.core.shading.lambert import lambert_eval, lambert_pdf, lambert_sample_into

MAT_SIZE = 14
MAT_BCSDF = 0
MAT_LAMBERT = 1
MAT_DIELECTRIC = 2
CTX_SIZE = B.CTX_SIZE


def pack_material_bcsdf(bcsdf_params):
    row = np.zeros(MAT_SIZE)
    row[0] = MAT_BCSDF
    row[1:11] = bcsdf_params
    return row


def pack_material_lambert(albedo):
    row = np.zeros(MAT_SIZE)
    row[0] = MAT_LAMBERT
    row[11:14] = albedo
    return row


def pack_material_dielectric(eta, roughness):
    """A rough dielectric row: the index of the mesh's inside relative to its outside (the side its triangles'
    normals, counter-clockwise, point to) and the GGX roughness alpha."""
    row = np.zeros(MAT_SIZE)
    row[0] = MAT_DIELECTRIC
    row[1] = eta
    row[2] = roughness
    return row


@njit(cache=True, inline="always")
def material_is_curve(mat):
    return int(mat[0]) == MAT_BCSDF


@njit(cache=True, inline="always")
def material_prepare(mat, t, n, wi, ctx):
    if int(mat[0]) == MAT_BCSDF:
        B.bcsdf_context(mat[1:11], t, wi, ctx)


@njit(cache=True, inline="always")
def material_eval_pdf(mat, ctx, t, n, wi, wo):
    if int(mat[0]) == MAT_BCSDF:
        return B.bcsdf_eval_pdf_ctx(mat[1:11], ctx, t, wo)
    f0, f1, f2 = lambert_eval(mat[11:14], n, wi, wo)
    return f0, f1, f2, lambert_pdf(mat[11:14], n, wi, wo)


@njit(cache=True, inline="always")
def material_sample(mat, ctx, t, n, wi, u0, u1, u2, wo):
    if int(mat[0]) == MAT_BCSDF:
        return B.bcsdf_sample_ctx(mat[1:11], ctx, t, u0, u1, u2, wo)
    return lambert_sample_into(mat[11:14], n, wi, u1, u2, wo)
