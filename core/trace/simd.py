"""Explicit SIMD for Numba kernels: fixed-width vector values and the operations on them.

Numba vectorises loops when LLVM can prove it safe, but a packet traversal (Wald et al. 2001,
"Interactive Rendering with Coherent Ray Tracing") keeps one value per ray of a packet in a register
and branches on the packet as a whole: no loop to vectorise. This module gives kernels those registers
directly. A vector is an LLVM `<LANES x float>` or `<LANES x double>` value and a mask a
`<LANES x i1>`; each operation below is an `@intrinsic` that emits the one LLVM instruction (or
intrinsic call) it names, so it inlines into any kernel and LLVM legalises the width for the target
(AVX2, AVX-512, NEON): one source for every platform.

API (all callable from njit code only; vectors never reach Python):
    load(array, i)            LANES consecutive elements of a float32/float64 array's flat data from i
    store(array, i, v)        the reverse (no bounds checks: the caller keeps i + LANES <= size)
    prefetch(array, i)        ask for the cache line of element i of an array's flat data (llvm.prefetch;
                              a hint: no fault, no effect on results)
    splat_f32(x), splat_f64(x)  x in every lane
    to_f32(v), to_f64(v)      lane-wise conversion (round to nearest / exact widening)
    add, sub, mul, div(a, b)  IEEE lane-wise arithmetic, never contracted into FMAs
    fma(a, b, c)              a * b + c with one rounding (llvm.fma)
    reciprocal(a)             1 / a, an exact IEEE division (not the 12-bit rcpps estimate)
    vabs(a)                   |a| (llvm.fabs)
    vmin(a, b), vmax(a, b)    a if a < b else b / a if a > b else b: compare and select, which x86 runs
                              as one vminps/vmaxps; on ties (+0, -0) and NaN the second operand
    lt, le, gt, ge, eq, ne(a, b)  ordered compares -> mask (ne is unordered: true for NaN)
    select(m, a, b)           a where m else b
    mask_and, mask_or, mask_andnot(a, b) (a and not b), mask_not(a)
    mask_bits(m)              int64 with bit k set for lane k; mask_from_bits(bits) the reverse
    mask_any(m), mask_all(m)  bool
    count_trailing_zeros(x)   of an int64 (llvm.cttz; 64 for 0): the lowest set lane of mask_bits
    count_set_bits(x)         of an int64 (llvm.ctpop): the number of set lanes of mask_bits
    lane(v, k)                element k as a scalar; with_lane(v, k, x) v with element k replaced
Vectors of other element types or widths are not provided; LANES is one constant for the module.
"""
from llvmlite import ir
from numba.core import cgutils, types
from numba.extending import intrinsic, models, register_model

LANES = 8  # float32 lanes of one AVX2 ymm register; float64 vectors of this width take one zmm or two ymm


class VectorType(types.Type):
    """A value of LANES floats of `dtype` (types.float32 or types.float64)."""

    def __init__(self, dtype, lanes):
        self.dtype, self.lanes = dtype, lanes
        super().__init__(name=f"vector({dtype}x{lanes})")


class MaskType(types.Type):
    """LANES booleans, one per vector lane (the result of a vector compare)."""

    def __init__(self, lanes):
        self.lanes = lanes
        super().__init__(name=f"mask(x{lanes})")


f32xN = VectorType(types.float32, LANES)
f64xN = VectorType(types.float64, LANES)
maskN = MaskType(LANES)


@register_model(VectorType)
class _VectorModel(models.PrimitiveModel):
    def __init__(self, dmm, fe_type):
        element = dmm.lookup(fe_type.dtype).get_value_type()
        super().__init__(dmm, fe_type, ir.VectorType(element, fe_type.lanes))


@register_model(MaskType)
class _MaskModel(models.PrimitiveModel):
    def __init__(self, dmm, fe_type):
        super().__init__(dmm, fe_type, ir.VectorType(ir.IntType(1), fe_type.lanes))


def _llvm(context, vector_type):
    return context.get_value_type(vector_type)


def _vector_of(array_type):
    if isinstance(array_type, types.Array) and array_type.layout == "C" and array_type.dtype in (
            types.float32, types.float64):
        return VectorType(array_type.dtype, LANES)
    return None


def _function(builder, name, return_type, argument_types):
    """Declare (once) and return the LLVM function `name` in the module being built."""
    fnty = ir.FunctionType(return_type, argument_types)
    return cgutils.get_or_insert_function(builder.module, fnty, name)


def _suffix(llvm_vector):
    width = llvm_vector.element.width if isinstance(llvm_vector.element, ir.IntType) else (
        32 if isinstance(llvm_vector.element, ir.FloatType) else 64)
    kind = "i" if isinstance(llvm_vector.element, ir.IntType) else "f"
    return f"v{llvm_vector.count}{kind}{width}"


def _vector_pointer(context, builder, array_type, array, index, index_type, vector_type):
    ary = context.make_array(array_type)(context, builder, array)
    i = context.cast(builder, index, index_type, types.intp)
    return builder.bitcast(builder.gep(ary.data, [i]), _llvm(context, vector_type).as_pointer())


# -- memory -------------------------------------------------------------------------------------------

@intrinsic
def load(typingctx, array, index):
    """LANES elements of the array's flat (C-ordered) data starting at `index`, as a vector."""
    vt = _vector_of(array)
    if vt is None or not isinstance(index, types.Integer):
        return None

    def codegen(context, builder, sig, args):
        ptr = _vector_pointer(context, builder, sig.args[0], args[0], args[1], sig.args[1], vt)
        return builder.load(ptr, align=vt.dtype.bitwidth // 8)

    return vt(array, index), codegen


@intrinsic
def store(typingctx, array, index, value):
    """Write the vector `value` to the array's flat data at index..index + LANES - 1."""
    vt = _vector_of(array)
    if vt is None or value != vt or not isinstance(index, types.Integer):
        return None

    def codegen(context, builder, sig, args):
        ptr = _vector_pointer(context, builder, sig.args[0], args[0], args[1], sig.args[1], vt)
        builder.store(args[2], ptr, align=vt.dtype.bitwidth // 8)
        return context.get_dummy_value()

    return types.none(array, index, value), codegen


@intrinsic
def prefetch(typingctx, array, index):
    """A read prefetch of the cache line holding element `index` of the array's flat (C-ordered) data
    (llvm.prefetch, kept in every cache level). A hint only: an address past the data does not fault."""
    if not (isinstance(array, types.Array) and array.layout == "C") or not isinstance(index, types.Integer):
        return None

    def codegen(context, builder, sig, args):
        ary = context.make_array(sig.args[0])(context, builder, args[0])
        i = context.cast(builder, args[1], sig.args[1], types.intp)
        byte = ir.IntType(8).as_pointer()
        i32 = ir.IntType(32)
        fn = _function(builder, "llvm.prefetch.p0i8", ir.VoidType(), [byte, i32, i32, i32])
        builder.call(fn, [builder.bitcast(builder.gep(ary.data, [i]), byte), ir.Constant(i32, 0), ir.Constant(i32, 3),
                          ir.Constant(i32, 1)])
        return context.get_dummy_value()

    return types.none(array, index), codegen


# -- construction and conversion ---------------------------------------------------------------------

def _splat_to(dtype):
    vt = VectorType(dtype, LANES)

    def typer(typingctx, x):
        if not isinstance(x, (types.Float, types.Integer)):
            return None

        def codegen(context, builder, sig, args):
            scalar = context.cast(builder, args[0], sig.args[0], dtype)
            vector = builder.insert_element(ir.Constant(_llvm(context, vt), ir.Undefined), scalar,
                                            ir.Constant(ir.IntType(32), 0))
            zeros = ir.Constant(ir.VectorType(ir.IntType(32), LANES), [0] * LANES)
            return builder.shuffle_vector(vector, ir.Constant(_llvm(context, vt), ir.Undefined), zeros)

        return vt(x), codegen

    return typer


splat_f32 = intrinsic(_splat_to(types.float32))
splat_f32.__doc__ = "A float32 vector holding x (converted with round to nearest) in every lane."
splat_f64 = intrinsic(_splat_to(types.float64))
splat_f64.__doc__ = "A float64 vector holding x in every lane."


@intrinsic
def to_f64(typingctx, v):
    """float32 lanes widened to float64 (exact)."""
    if v != f32xN:
        return None
    return f64xN(v), lambda context, builder, sig, args: builder.fpext(args[0], _llvm(context, f64xN))


@intrinsic
def to_f32(typingctx, v):
    """float64 lanes rounded to float32 (to nearest)."""
    if v != f64xN:
        return None
    return f32xN(v), lambda context, builder, sig, args: builder.fptrunc(args[0], _llvm(context, f32xN))


# -- arithmetic -------------------------------------------------------------------------------------

def _binary(emit, kind=None):
    """The typer of a lane-wise operation on two values of one type, a vector (or a `kind`) type."""
    kind = kind or VectorType

    def typer(typingctx, a, b):
        if not isinstance(a, kind) or a != b:
            return None
        return a(a, b), lambda context, builder, sig, args: emit(builder, *args)

    return typer


add = intrinsic(_binary(lambda builder, a, b: builder.fadd(a, b)))
add.__doc__ = "a + b lane-wise."
sub = intrinsic(_binary(lambda builder, a, b: builder.fsub(a, b)))
sub.__doc__ = "a - b lane-wise."
mul = intrinsic(_binary(lambda builder, a, b: builder.fmul(a, b)))
mul.__doc__ = "a * b lane-wise."
div = intrinsic(_binary(lambda builder, a, b: builder.fdiv(a, b)))
div.__doc__ = "a / b lane-wise (IEEE division)."
vmin = intrinsic(_binary(lambda builder, a, b: builder.select(builder.fcmp_ordered("<", a, b), a, b)))
vmin.__doc__ = "a if a < b else b, lane-wise (b on ties and NaN; x86: one vminps)."
vmax = intrinsic(_binary(lambda builder, a, b: builder.select(builder.fcmp_ordered(">", a, b), a, b)))
vmax.__doc__ = "a if a > b else b, lane-wise (b on ties and NaN; x86: one vmaxps)."


@intrinsic
def fma(typingctx, a, b, c):
    """a * b + c lane-wise with a single rounding (llvm.fma; a hardware FMA where the target has one)."""
    if not isinstance(a, VectorType) or not a == b == c:
        return None

    def codegen(context, builder, sig, args):
        vt = _llvm(context, sig.return_type)
        return builder.call(_function(builder, f"llvm.fma.{_suffix(vt)}", vt, [vt, vt, vt]), args)

    return a(a, b, c), codegen


@intrinsic
def vabs(typingctx, a):
    """|a| lane-wise (clears the sign bit: vabs(-0.0) is +0.0)."""
    if not isinstance(a, VectorType):
        return None

    def codegen(context, builder, sig, args):
        vt = _llvm(context, sig.return_type)
        return builder.call(_function(builder, f"llvm.fabs.{_suffix(vt)}", vt, [vt]), args)

    return a(a), codegen


@intrinsic
def reciprocal(typingctx, a):
    """1 / a lane-wise, an exact IEEE division: the same bits as the scalar 1.0 / x."""
    if not isinstance(a, VectorType):
        return None

    def codegen(context, builder, sig, args):
        one = ir.Constant(_llvm(context, sig.return_type), [1.0] * LANES)
        return builder.fdiv(one, args[0])

    return a(a), codegen


# -- compares, masks and selection -------------------------------------------------------------------

def _compare(op, ordered=True):
    def typer(typingctx, a, b):
        if not isinstance(a, VectorType) or a != b:
            return None

        def codegen(context, builder, sig, args):
            return (builder.fcmp_ordered if ordered else builder.fcmp_unordered)(op, *args)

        return MaskType(a.lanes)(a, b), codegen

    return typer


lt = intrinsic(_compare("<"))
lt.__doc__ = "Mask of a < b (false where either is NaN)."
le = intrinsic(_compare("<="))
le.__doc__ = "Mask of a <= b (false where either is NaN)."
gt = intrinsic(_compare(">"))
gt.__doc__ = "Mask of a > b (false where either is NaN)."
ge = intrinsic(_compare(">="))
ge.__doc__ = "Mask of a >= b (false where either is NaN)."
eq = intrinsic(_compare("=="))
eq.__doc__ = "Mask of a == b (+0 equals -0; false where either is NaN)."
ne = intrinsic(_compare("!=", ordered=False))
ne.__doc__ = "Mask of a != b (true where either is NaN, as Python's !=)."


@intrinsic
def select(typingctx, mask, a, b):
    """a where mask else b, lane-wise (a blend; on AVX-512 a masked move)."""
    if not isinstance(mask, MaskType) or not isinstance(a, VectorType) or a != b:
        return None
    return a(mask, a, b), lambda context, builder, sig, args: builder.select(*args)


mask_and = intrinsic(_binary(lambda builder, a, b: builder.and_(a, b), MaskType))
mask_and.__doc__ = "Lanes set in both masks."
mask_or = intrinsic(_binary(lambda builder, a, b: builder.or_(a, b), MaskType))
mask_or.__doc__ = "Lanes set in either mask."
mask_andnot = intrinsic(_binary(lambda builder, a, b: builder.and_(a, builder.not_(b)), MaskType))
mask_andnot.__doc__ = "Lanes set in a and not in b."


@intrinsic
def mask_not(typingctx, a):
    """Lanes not set in a."""
    if not isinstance(a, MaskType):
        return None
    return a(a), lambda context, builder, sig, args: builder.not_(args[0])


def _bits(builder, mask):
    return builder.zext(builder.bitcast(mask, ir.IntType(LANES)), ir.IntType(64))


@intrinsic
def mask_bits(typingctx, mask):
    """The mask as an int64 with bit k set for lane k (x86: vmovmskps or kmov)."""
    if mask != maskN:
        return None
    return types.int64(mask), lambda context, builder, sig, args: _bits(builder, args[0])


@intrinsic
def mask_from_bits(typingctx, bits):
    """The mask whose lane k is bit k of the integer `bits` (the inverse of mask_bits)."""
    if not isinstance(bits, types.Integer):
        return None

    def codegen(context, builder, sig, args):
        low = builder.trunc(context.cast(builder, args[0], sig.args[0], types.int64), ir.IntType(LANES))
        return builder.bitcast(low, ir.VectorType(ir.IntType(1), LANES))

    return maskN(bits), codegen


@intrinsic
def mask_any(typingctx, mask):
    """Whether any lane is set."""
    if mask != maskN:
        return None

    def codegen(context, builder, sig, args):
        return builder.icmp_unsigned("!=", _bits(builder, args[0]), ir.Constant(ir.IntType(64), 0))

    return types.boolean(mask), codegen


@intrinsic
def mask_all(typingctx, mask):
    """Whether every lane is set."""
    if mask != maskN:
        return None

    def codegen(context, builder, sig, args):
        full = ir.Constant(ir.IntType(64), (1 << LANES) - 1)
        return builder.icmp_unsigned("==", _bits(builder, args[0]), full)

    return types.boolean(mask), codegen


@intrinsic
def count_trailing_zeros(typingctx, x):
    """The number of trailing zero bits of an integer (as int64; 64 for 0): with mask_bits, the first
    set lane. llvm.cttz takes its full two-argument type (value, is-zero-poison = false)."""
    if not isinstance(x, types.Integer):
        return None

    def codegen(context, builder, sig, args):
        value = context.cast(builder, args[0], sig.args[0], types.int64)
        i64 = ir.IntType(64)
        cttz = _function(builder, "llvm.cttz.i64", i64, [i64, ir.IntType(1)])
        return builder.call(cttz, [value, ir.Constant(ir.IntType(1), 0)])

    return types.int64(x), codegen


@intrinsic
def count_set_bits(typingctx, x):
    """The number of set bits of an integer (as int64; llvm.ctpop): with mask_bits, the lanes set."""
    if not isinstance(x, types.Integer):
        return None

    def codegen(context, builder, sig, args):
        value = context.cast(builder, args[0], sig.args[0], types.int64)
        i64 = ir.IntType(64)
        return builder.call(_function(builder, "llvm.ctpop.i64", i64, [i64]), [value])

    return types.int64(x), codegen


# -- lanes ------------------------------------------------------------------------------------------

@intrinsic
def lane(typingctx, v, k):
    """Element k of the vector v as a scalar (k need not be a constant)."""
    if not isinstance(v, VectorType) or not isinstance(k, types.Integer):
        return None

    def codegen(context, builder, sig, args):
        return builder.extract_element(args[0], context.cast(builder, args[1], sig.args[1], types.int32))

    return v.dtype(v, k), codegen


@intrinsic
def with_lane(typingctx, v, k, x):
    """v with element k replaced by the scalar x (converted to v's element type)."""
    if not isinstance(v, VectorType) or not isinstance(k, types.Integer):
        return None

    def codegen(context, builder, sig, args):
        scalar = context.cast(builder, args[2], sig.args[2], sig.return_type.dtype)
        return builder.insert_element(args[0], scalar, context.cast(builder, args[1], sig.args[1], types.int32))

    return v(v, k, x), codegen


# -- min-max binning of reference boxes (core/build/split_binned.py; seed 000 §3.3's SIMD binning) -------
# A separate block: 8 lanes here are one box's six bounds (two duplicates), not LANES rays.

_BOX_LANE_AXES = (0, 1, 2, 0, 2, 0, 1, 2)  # the lanes' coordinates: floats 0-3 and 2-5 of a box row
_BOX_LANE_BOUNDS = (0, 1, 2, 3, 6, 7)  # lanes holding lo x, y, z, hi x, y, z


@intrinsic
def box_bin_indices(typingctx, boxes, i, lo0, lo1, lo2, s0, s1, s2, top):
    """The six min-max bin indices (lo x, y, z, hi x, y, z) of row i of a C-contiguous (N, 6) float32
    box array: int((bound - lo[axis]) * s[axis]) clamped to [0, top], the scalar arithmetic lane for
    lane (float32 difference, exactly widened, float64 product, truncation). Two 4-float loads (floats
    0-3 and 2-5 of the row) never read past the row. lo*: float32, s*: float64, top: an integer."""
    if not (isinstance(boxes, types.Array) and boxes.ndim == 2 and boxes.layout == "C"
            and boxes.dtype == types.float32 and isinstance(i, types.Integer) and isinstance(top, types.Integer)):
        return None
    sig = types.UniTuple(types.intp, 6)(boxes, i, lo0, lo1, lo2, s0, s1, s2, top)

    def codegen(context, builder, sig, args):
        intp = context.get_value_type(types.intp)
        f4, f8, d8 = ir.VectorType(ir.FloatType(), 4), ir.VectorType(ir.FloatType(), 8), ir.VectorType(
            ir.DoubleType(), 8)
        i8 = ir.VectorType(intp, 8)
        ary = context.make_array(sig.args[0])(context, builder, args[0])
        row = builder.mul(context.cast(builder, args[1], sig.args[1], types.intp), ir.Constant(intp, 6))
        low = builder.load(builder.bitcast(builder.gep(ary.data, [row]), f4.as_pointer()), align=4)
        high = builder.load(builder.bitcast(builder.gep(ary.data, [builder.add(row, ir.Constant(intp, 2))]),
                                            f4.as_pointer()), align=4)
        bounds = builder.shuffle_vector(low, high, ir.Constant(ir.VectorType(ir.IntType(32), 8), list(range(8))))
        los = [context.cast(builder, args[2 + k], sig.args[2 + k], types.float32) for k in range(3)]
        scales = [context.cast(builder, args[5 + k], sig.args[5 + k], types.float64) for k in range(3)]
        lo, scale = ir.Constant(f8, ir.Undefined), ir.Constant(d8, ir.Undefined)
        for lane_index, axis in enumerate(_BOX_LANE_AXES):
            lo = builder.insert_element(lo, los[axis], ir.Constant(ir.IntType(32), lane_index))
            scale = builder.insert_element(scale, scales[axis], ir.Constant(ir.IntType(32), lane_index))
        product = builder.fmul(builder.fpext(builder.fsub(bounds, lo), d8), scale)
        index = builder.fptosi(product, i8)
        zero = ir.Constant(i8, [0] * 8)
        top_scalar = context.cast(builder, args[8], sig.args[8], types.intp)
        highest = builder.shuffle_vector(
            builder.insert_element(ir.Constant(i8, ir.Undefined), top_scalar, ir.Constant(ir.IntType(32), 0)),
            ir.Constant(i8, ir.Undefined), ir.Constant(ir.VectorType(ir.IntType(32), 8), [0] * 8))
        index = builder.select(builder.icmp_signed("<", index, zero), zero, index)
        index = builder.select(builder.icmp_signed(">", index, highest), highest, index)
        lanes = [builder.extract_element(index, ir.Constant(ir.IntType(32), k)) for k in _BOX_LANE_BOUNDS]
        return context.make_tuple(builder, sig.return_type, lanes)

    return sig, codegen
