"""Full realization of the procedural fibres as fabric-space polylines (seed 000 §3.2, Eq. 7).

Every regular fibre of every ply of every yarn is cut into pieces at the ends of its mutated
(loop) migration cycles: runs of regular cycles become kind-1 polylines, each mutated cycle a
kind-2 polyline; pieces of one fibre share their end points (R = rho_min R_j there under both
formulas). Every hair is a kind-3 polyline. A piece is sampled uniformly in its yarn-space
parameter (z for regular and loop pieces, t for hairs) with steps no longer than ``spacing`` in
z (hairs: in yarn-space arc length, bounded by the hair's speed), and each vertex is mapped by
Eq. 7 with the rotation-minimising frame. The random numbers and tables are the ones the lookups
use (tables.py), so the realized fibres and the lookups describe the same fabric. Fibres are
ordered as the lookups rank them: yarn, ply, regular/loop pieces (by fibre index) before hairs
(by hair index), so "the lowest covering fibre" is the lookup's answer.

``realize_plan`` lists the pieces (no geometry) so the size is known before anything is
allocated; ``realize_fill`` writes the vertices of a plan. A render's fibre cache realizes windows
of yarns only (``window_pieces``, ``realize_fill_window``): runs of the same pieces' vertices, the
same floats, so its segments are a subset of the full realization's.
"""
import math

import numpy as np
from numba import njit

from stages.core.curves.frames import curve_frame_at
from stages.core.dispatch import runtime_value
from stages.core.threads import chunk_kernel, for_chunks
from stages.core.yarn.model import (
    ALPHA,
    FIBER_RADIUS,
    PLY_RADIUS,
    S_MIG,
    TWO_PI,
    USE_MIGRATION,
    YARN_ALPHA,
    cycle_of,
    fibre_counts,
    hair_params,
    hair_point,
    loop_unit_radius,
    migration_phase,
    regular_xy,
)
from stages.core.yarn.tables import fibre_row

STEP_SLACK = 1e-9   # a piece's length / spacing this little above a whole number (rounding) takes no extra step


@njit(cache=True)
def _z_of_phase(tp, th0, ph):
    return (ph - th0) * tp[ALPHA] / (tp[S_MIG] * TWO_PI)


@njit(cache=True)
def _fiber_pieces(tp, yseed, k, j, Rj, th, th0, L, out_z0, out_z1, out_kind, n0):
    """Append the pieces of one fibre at n0; returns the new count."""
    n = n0
    if tp[USE_MIGRATION] == 0.0:
        out_z0[n] = 0.0
        out_z1[n] = L
        out_kind[n] = 1
        return n + 1
    c0 = cycle_of(migration_phase(tp, th0, 0.0))
    c1 = cycle_of(migration_phase(tp, th0, L))
    zs = 0.0
    cur = 1
    for c in range(c0, c1 + 1):
        U = loop_unit_radius(tp, yseed, k, j, Rj, th, th0, c)
        kind = 2 if U > 0.0 else 1
        if kind != cur:
            za = max(0.0, _z_of_phase(tp, th0, TWO_PI * c - math.pi))
            if za > zs:
                out_z0[n] = zs
                out_z1[n] = za
                out_kind[n] = cur
                n += 1
                zs = za
            cur = kind
    out_z0[n] = zs
    out_z1[n] = L
    out_kind[n] = cur
    return n + 1


@njit(cache=True)
def _yarn_setup(tab, c, L):
    """(type t, its parameters tp, plies P, fibres per ply N, yarn seed, migration cycles bound) of yarn c, length L:
    what ``yarn_plan`` and ``yarn_counts`` start from."""
    t = tab.yarn_type[c]
    tp = tab.tparams[t]
    P, N = fibre_counts(tp)
    yseed = np.uint64(tab.yarn_seed[c])
    ncyc = 3
    if tp[USE_MIGRATION] != 0.0:
        ncyc = int(L * tp[S_MIG] / tp[ALPHA]) + 4
    return t, tp, P, N, yseed, ncyc


@njit(cache=True)
def _piece_vertices(a0, a1, spacing):
    """Vertices of a regular or loop piece over z in [a0, a1]: steps no longer than ``spacing``, at least 2."""
    return max(2, int(math.ceil((a1 - a0) / spacing - STEP_SLACK)) + 1)


@njit(cache=True)
def _hair_vertices(tp, yseed, k, h, ze, spacing):
    """Vertices of hair h of ply k (z extent ze): steps no longer than ``spacing`` in yarn-space arc length,
    bounded by the hair's speed; at least 2."""
    r0, r1, th1, pe = hair_params(tp, yseed, k, h)
    rm = max(r0, r1) + tp[PLY_RADIUS]
    speed = abs(ze) * (1.0 + rm * TWO_PI / tp[YARN_ALPHA]) + abs(r1 - r0) + max(r0, r1) * abs(pe)
    return max(2, int(math.ceil(speed / spacing)) + 1)


@njit(cache=True)
def yarn_plan(tab, c, L, spacing):
    """Pieces of yarn c: arrays (ply, index, kind, a0, a1, hair_z1, hair_ze, nverts)."""
    t, tp, P, N, yseed, ncyc = _yarn_setup(tab, c, L)
    g0 = tab.yarn_ply_off[c]
    nh = 0
    for k in range(P):
        nh += tab.hair_count[g0 + k]
    cap = P * N * (2 * ncyc + 2) + nh + 1
    ply = np.empty(cap, np.int16)
    idx = np.empty(cap, np.int32)
    kind = np.empty(cap, np.int8)
    a0 = np.empty(cap)
    a1 = np.empty(cap)
    hz1 = np.zeros(cap)
    hze = np.zeros(cap)
    nv = np.empty(cap, np.int64)
    n = 0
    for k in range(P):  # order: ply, regular (and loop) pieces before hairs, fibre index
        for j in range(N):
            f = fibre_row(tab, t, tp, k, j)
            m = _fiber_pieces(tp, yseed, k, j, tab.fib_R[f], tab.fib_th[f], tab.fib_th0[f], L, a0, a1, kind, n)
            for q in range(n, m):
                ply[q] = k
                idx[q] = j
                nv[q] = _piece_vertices(a0[q], a1[q], spacing)
            n = m
        g = g0 + k
        base = tab.hair_off[g]
        for h in range(tab.hair_count[g]):
            z1 = tab.hair_z1[base + h]
            ze = tab.hair_ze[base + h]
            ply[n] = k
            idx[n] = h
            kind[n] = 3
            a0[n] = 0.0
            a1[n] = 1.0
            hz1[n] = z1
            hze[n] = ze
            nv[n] = _hair_vertices(tp, yseed, k, h, ze, spacing)
            n += 1
    return ply[:n], idx[:n], kind[:n], a0[:n], a1[:n], hz1[:n], hze[:n], nv[:n]


@njit(cache=True)
def yarn_counts(tab, c, L, spacing):
    """Size of yarn c's realization without listing its pieces: (vertices, pieces) per kind 1, 2, 3
    (as yarn_plan would count them)."""
    t, tp, P, N, yseed, ncyc = _yarn_setup(tab, c, L)
    cap = 2 * ncyc + 2
    a0 = np.empty(cap)
    a1 = np.empty(cap)
    kind = np.empty(cap, np.int8)
    verts = np.zeros(4, np.int64)
    pieces = np.zeros(4, np.int64)
    g0 = tab.yarn_ply_off[c]
    for k in range(P):
        for j in range(N):
            f = fibre_row(tab, t, tp, k, j)
            m = _fiber_pieces(tp, yseed, k, j, tab.fib_R[f], tab.fib_th[f], tab.fib_th0[f], L, a0, a1, kind,
                              runtime_value(0))
            for q in range(m):
                verts[kind[q]] += _piece_vertices(a0[q], a1[q], spacing)
                pieces[kind[q]] += 1
        g = g0 + k
        base = tab.hair_off[g]
        for h in range(tab.hair_count[g]):
            ze = tab.hair_ze[base + h]
            verts[3] += _hair_vertices(tp, yseed, k, h, ze, spacing)
            pieces[3] += 1
    return verts, pieces


def realize_fill(cv, tab, yarn, ply, idx, kind, a0, a1, hz1, hze, offsets, points, radius):
    """Vertices of every planned piece (pieces on threads), fabric space via Eq. 7."""
    offsets = np.asarray(offsets, np.int64)
    realize_fill_window(cv, tab, yarn, ply, idx, kind, a0, a1, hz1, hze, np.zeros(len(yarn), np.int64),
                        np.ascontiguousarray(offsets[1:] - offsets[:-1]), offsets, points, radius)


def realize_fill_window(cv, tab, yarn, ply, idx, kind, a0, a1, hz1, hze, first, nfull, offsets, points, radius):
    """Vertices first[q] .. first[q] + (offsets[q + 1] - offsets[q]) - 1 of planned piece q, a piece of
    nfull[q] vertices (pieces on threads: ``stages.core.threads``): the same floats as the whole piece's
    vertices there, so a window of a piece is a run of the full realization's segments (``window_pieces``)."""
    for_chunks(_fill_pieces, yarn.shape[0], cv, tab, yarn, ply, idx, kind, a0, a1, hz1, hze, first, nfull, offsets,
               points, radius)


@chunk_kernel
def _fill_pieces(cv, tab, yarn, ply, idx, kind, a0, a1, hz1, hze, first, nfull, offsets, points, radius, q0, q1):
    """``realize_fill_window`` for pieces q0 .. q1 - 1.
    17 parameters: a ``for_chunks`` chunk kernel: the fabric, the pieces' plan (nine arrays), the three output
    arrays and the chunk's range."""
    for q in range(q0, q1):
        c = yarn[q]
        t = tab.yarn_type[c]
        tp = tab.tparams[t]
        yseed = np.uint64(tab.yarn_seed[c])
        k = ply[q]
        j = idx[q]
        lo = offsets[q]
        n = offsets[q + 1] - lo
        m0 = first[q]
        nf = nfull[q]
        rf = tp[FIBER_RADIUS]
        if kind[q] == 3:
            r0, r1, th1, pe = hair_params(tp, yseed, k, j)
            for m in range(n):
                u = (m0 + m) / (nf - 1)
                x, y, z = hair_point(tp, k, r0, r1, th1, pe, hz1[q], hze[q], u)
                pos, tan, nn, bn = curve_frame_at(cv, c, z)
                for d in range(3):
                    points[lo + m, d] = pos[d] + x * nn[d] + y * bn[d]
                radius[lo + m] = rf
        else:
            f = fibre_row(tab, t, tp, k, j)
            for m in range(n):
                z = a0[q] + (a1[q] - a0[q]) * ((m0 + m) / (nf - 1))
                x, y, kd = regular_xy(tp, yseed, k, j, tab.fib_R[f], tab.fib_th[f], tab.fib_th0[f], z)
                pos, tan, nn, bn = curve_frame_at(cv, c, z)
                for d in range(3):
                    points[lo + m, d] = pos[d] + x * nn[d] + y * bn[d]
                radius[lo + m] = rf


@njit(cache=True)
def window_pieces(kind, a0, a1, hz1, hze, nv, w0, w1, spacing, length, period):
    """The runs of one yarn's planned pieces (``yarn_plan``) that a fibre cache realizes: for windows
    [w0[i], w1[i]] of the yarn's arc length (sorted, disjoint), every segment of a regular or loop
    piece with an end in a window (its vertices first .. first + count - 1), and every hair whose
    z range [z1, z1 + ze] meets a window widened by ``spacing`` (whole; an open yarn's hair range
    clamped to [0, length] first, as its frames are). ``period`` > 0: a closed yarn's length (hair
    ranges are compared shifted by +-period too). Returns (piece, first, count)
    in plan order, windows in order within a piece: the cache ranks its fibres as the full
    realization does."""
    P = kind.shape[0]
    W = w0.shape[0]
    cap = P * W + 1
    piece = np.empty(cap, np.int64)
    first = np.empty(cap, np.int64)
    count = np.empty(cap, np.int64)
    n = 0
    for q in range(P):
        if kind[q] == 3:
            za = min(hz1[q], hz1[q] + hze[q])
            zb = max(hz1[q], hz1[q] + hze[q])
            if period == 0.0:
                za = min(max(za, 0.0), length)
                zb = min(max(zb, 0.0), length)
            za -= spacing
            zb += spacing
            hit = False
            for i in range(W):
                for sh in (-period, 0.0, period):
                    if za + sh <= w1[i] and zb + sh >= w0[i]:
                        hit = True
            if hit:
                piece[n] = q
                first[n] = 0
                count[n] = nv[q]
                n += 1
            continue
        dz = (a1[q] - a0[q]) / (nv[q] - 1)
        for i in range(W):
            if w1[i] < a0[q] or w0[i] > a1[q]:
                continue
            m0 = max(0, int(math.floor((w0[i] - a0[q]) / dz)) - 1)
            m1 = min(nv[q] - 1, int(math.ceil((w1[i] - a0[q]) / dz)) + 1)
            if m1 > m0:
                piece[n] = q
                first[n] = m0
                count[n] = m1 - m0 + 1
                n += 1
    return piece[:n], first[:n], count[:n]


def realize_plan(tab, curve_length, spacing):
    """The pieces of all yarns (flat arrays, no geometry): yarn, ply, index, kind, a0, a1, hair z1/ze,
    vertex counts."""
    parts = [yarn_plan(tab, c, float(curve_length[c]), spacing) for c in range(len(tab.yarn_type))]
    yarn = np.concatenate([np.full(len(p[0]), c, np.int32)
                           for c, p in enumerate(parts)]) if parts else np.zeros(0, np.int32)
    cols = [np.concatenate([p[i] for p in parts]) for i in range(8)]
    return (yarn, *cols)


def chord_error(points, offsets):
    """Largest sagitta estimate l theta / 8 of the realized polylines (l: mean length of the two
    segments at a vertex, theta: their turning angle): the distance a polyline can lie from the
    smooth curve through its vertices (kappa l^2 / 8 with kappa = theta / l)."""
    P = np.asarray(points, np.float64)
    seg = P[1:] - P[:-1]
    ln = np.linalg.norm(seg, axis=1)
    valid = np.ones(len(seg), bool)
    valid[offsets[1:-1] - 1] = False  # segments that straddle two polylines
    a, b = seg[:-1], seg[1:]
    la, lb = ln[:-1], ln[1:]
    both = valid[:-1] & valid[1:] & (la > 0) & (lb > 0)
    cosang = np.einsum("ij,ij->i", a[both], b[both]) / (la[both] * lb[both])
    theta = np.arccos(np.clip(cosang, -1, 1))
    if theta.size == 0:
        return 0.0, 0.0
    return float(np.max(0.5 * (la[both] + lb[both]) * theta / 8.0)), float(np.max(theta))
