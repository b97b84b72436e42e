"""A ray, or a point, against the four child boxes of a wide BVH node at once, in SIMD registers.

``box4_enter(box, w, sx, sy, sz, ox, oy, oz, ix, iy, iz, tmin, tmax)`` returns the entry distances
(t0, t1, t2, t3) of the ray o + t d (``i*`` = 1 / d, ``s*`` the near-plane offsets of
``bvh.direction_signs``) into the four child boxes of row ``w`` of a wide-node box table (float32,
24 columns: lo x of children 0-3, lo y, lo z, hi x, hi y, hi z), ``inf`` for a child the ray misses,
leaves before ``tmin`` or enters beyond ``tmax``: the slab test of Kay and Kajiya (1986) with the near
plane of each axis picked by the direction's sign (Williams et al. 2005), so no min / max per axis.

``box4_contains(box, w, x, y, z)`` is the point query's test: a 4-bit mask, bit q set when child q's
box holds the point (bounds included), the point queries of ``stages.render.media.realized_medium``.

numba compiles the same tests written per child to scalar code (a float32 load, a conversion, a
subtraction and a multiplication per plane and child, one child after another); this is one LLVM
intrinsic that loads each plane's four float32 bounds as one vector, widens them to float64 and does
the arithmetic and the comparisons four lanes at a time. The operations and their order are those of
the scalar test (a plane's distance replaces the running near distance only when strictly larger,
as ``if t > tn: tn = t`` does), so the results are the same bits: every query answers exactly as
before, and images do not change.
"""
from llvmlite import ir
from numba import types
from numba.core import cgutils
from numba.extending import intrinsic

LANES = 4


@intrinsic
def box4_enter(typingctx, box, w, sx, sy, sz, ox, oy, oz, ix, iy, iz, tmin, tmax):
    """Entry distances of the ray into the four child boxes of wide node ``w`` (module doc)."""
    if not (isinstance(box, types.Array) and box.dtype == types.float32 and box.ndim == 2 and box.layout == "C"):
        return None
    f64 = types.float64
    sig = types.UniTuple(f64, LANES)(box, w, sx, sy, sz, ox, oy, oz, ix, iy, iz, tmin, tmax)

    def codegen(context, builder, signature, args):
        box_v, w_v, sx_v, sy_v, sz_v = args[:5]
        w_v, sx_v, sy_v, sz_v = [context.cast(builder, v, t, types.intp)
                                 for v, t in zip((w_v, sx_v, sy_v, sz_v), signature.args[1:5])]
        o = [context.cast(builder, v, t, f64) for v, t in zip(args[5:8], signature.args[5:8])]
        inv = [context.cast(builder, v, t, f64) for v, t in zip(args[8:11], signature.args[8:11])]
        lo_t = context.cast(builder, args[11], signature.args[11], f64)
        hi_t = context.cast(builder, args[12], signature.args[12], f64)
        ary = context.make_array(signature.args[0])(context, builder, value=box_v)
        ncols = cgutils.unpack_tuple(builder, ary.shape, 2)[1]
        row = builder.mul(w_v, ncols)
        intp = context.get_value_type(types.intp)
        vf32 = ir.VectorType(ir.FloatType(), LANES)
        vf64 = ir.VectorType(ir.DoubleType(), LANES)

        def splat(x):
            v = ir.Constant(vf64, ir.Undefined)
            for k in range(LANES):
                v = builder.insert_element(v, x, ir.Constant(ir.IntType(32), k))
            return v

        def plane(col, origin, inverse):
            """(bounds of 4 children at column col - origin) * inverse, widened to float64 first."""
            ptr = builder.gep(ary.data, [builder.add(row, col)])
            vec = builder.load(builder.bitcast(ptr, vf32.as_pointer()), align=4)
            return builder.fmul(builder.fsub(builder.fpext(vec, vf64), splat(origin)), splat(inverse))

        def col(base, s, sign):
            return builder.add(ir.Constant(intp, base), s) if sign > 0 else builder.sub(ir.Constant(intp, base), s)

        tn = plane(col(0, sx_v, 1), o[0], inv[0])
        tf = plane(col(12, sx_v, -1), o[0], inv[0])
        for axis, s in ((1, sy_v), (2, sz_v)):
            t0 = plane(col(4 * axis, s, 1), o[axis], inv[axis])
            t1 = plane(col(12 + 4 * axis, s, -1), o[axis], inv[axis])
            tn = builder.select(builder.fcmp_ordered(">", t0, tn), t0, tn)
            tf = builder.select(builder.fcmp_ordered("<", t1, tf), t1, tf)
        hit = builder.and_(builder.and_(builder.fcmp_ordered(">=", tf, tn),
                                        builder.fcmp_ordered(">=", tf, splat(lo_t))),
                           builder.fcmp_ordered("<=", tn, splat(hi_t)))
        res = builder.select(hit, tn, splat(ir.Constant(ir.DoubleType(), float("inf"))))
        return cgutils.pack_array(builder, [builder.extract_element(res, ir.Constant(ir.IntType(32), k))
                                            for k in range(LANES)])
    return sig, codegen


@intrinsic
def box4_contains(typingctx, box, w, x, y, z):
    """Bit q set when child q of wide node ``w`` holds the point (x, y, z), bounds included (module doc)."""
    if not (isinstance(box, types.Array) and box.dtype == types.float32 and box.ndim == 2 and box.layout == "C"):
        return None
    f64 = types.float64
    sig = types.int64(box, w, x, y, z)

    def codegen(context, builder, signature, args):
        w_v = context.cast(builder, args[1], signature.args[1], types.intp)
        p = [context.cast(builder, v, t, f64) for v, t in zip(args[2:5], signature.args[2:5])]
        ary = context.make_array(signature.args[0])(context, builder, value=args[0])
        row = builder.mul(w_v, cgutils.unpack_tuple(builder, ary.shape, 2)[1])
        intp = context.get_value_type(types.intp)
        vf32 = ir.VectorType(ir.FloatType(), LANES)
        vf64 = ir.VectorType(ir.DoubleType(), LANES)

        def bounds(col):
            ptr = builder.gep(ary.data, [builder.add(row, ir.Constant(intp, col))])
            return builder.fpext(builder.load(builder.bitcast(ptr, vf32.as_pointer()), align=4), vf64)

        inside = None
        for axis in range(3):
            v = ir.Constant(vf64, ir.Undefined)
            for k in range(LANES):
                v = builder.insert_element(v, p[axis], ir.Constant(ir.IntType(32), k))
            both = builder.and_(builder.fcmp_ordered("<=", bounds(4 * axis), v),
                                builder.fcmp_ordered("<=", v, bounds(12 + 4 * axis)))
            inside = both if inside is None else builder.and_(inside, both)
        mask = builder.bitcast(inside, ir.IntType(LANES))
        return builder.zext(mask, context.get_value_type(types.int64))
    return sig, codegen
