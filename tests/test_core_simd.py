"""core.simd against scalar NumPy on seeded random data with zeros of both signs, infinities and exact ties,
and a look at the machine code: the helpers must compile to packed vector instructions."""
import platform
import re
from fractions import Fraction

import numpy as np
import pytest
from numba import njit

from core.trace import simd as S

L = S.LANES
DTYPES = [np.float32, np.float64]


def operands(dtype, n=16 * L, seed=0):
    """Two arrays of n values: random normals over many magnitudes, with +-0, +-inf, subnormals, and ties
    (equal values, and +0 against -0) placed lane by lane."""
    rng = np.random.default_rng(seed)
    a = (rng.normal(size=n) * 10.0 ** rng.integers(-3, 4, n)).astype(dtype)
    b = (rng.normal(size=n) * 10.0 ** rng.integers(-3, 4, n)).astype(dtype)
    special = np.array([0.0, -0.0, np.inf, -np.inf, 1.0, -1.0, np.finfo(dtype).tiny / 4, 3.0], dtype)
    a[:L], b[:L] = np.resize(special, L), np.resize(special[::-1], L)
    tie = rng.random(n) < 0.25
    b[tie] = a[tie]
    a[L:2 * L], b[L:2 * L] = np.array([0.0, -0.0] * (L // 2), dtype), np.array([-0.0, 0.0] * (L // 2), dtype)
    return a, b


def same_bits(x, y):
    """Equal values with equal signs of zero (NaN equal to NaN)."""
    x, y = np.asarray(x), np.asarray(y)
    assert x.dtype == y.dtype and x.shape == y.shape
    both_nan = np.isnan(x) & np.isnan(y)
    bits = x.view(np.uint32 if x.dtype == np.float32 else np.uint64) == y.view(
        np.uint32 if y.dtype == np.float32 else np.uint64)
    return bool((both_nan | bits).all())


def binary_kernel(op):
    @njit
    def kernel(a, b, out):
        for i in range(0, a.size, L):
            S.store(out, i, op(S.load(a, i), S.load(b, i)))

    return kernel


def compare_kernel(op):
    @njit
    def kernel(a, b, out):
        for i in range(0, a.size, L):
            bits = S.mask_bits(op(S.load(a, i), S.load(b, i)))
            for k in range(L):
                out[i + k] = (bits >> k) & 1

    return kernel


BINARY = {
    "add": (S.add, lambda a, b: a + b),
    "sub": (S.sub, lambda a, b: a - b),
    "mul": (S.mul, lambda a, b: a * b),
    "div": (S.div, lambda a, b: a / b),
    "vmin": (S.vmin, lambda a, b: np.where(a < b, a, b)),
    "vmax": (S.vmax, lambda a, b: np.where(a > b, a, b)),
}
COMPARES = {
    "lt": (S.lt, np.less), "le": (S.le, np.less_equal), "gt": (S.gt, np.greater),
    "ge": (S.ge, np.greater_equal), "eq": (S.eq, np.equal), "ne": (S.ne, np.not_equal),
}
_kernels = {}


def kernel_for(kind, name):
    if (kind, name) not in _kernels:
        table = BINARY if kind == "binary" else COMPARES
        _kernels[kind, name] = (binary_kernel if kind == "binary" else compare_kernel)(table[name][0])
    return _kernels[kind, name]


@pytest.mark.parametrize("dtype", DTYPES)
@pytest.mark.parametrize("name", sorted(BINARY))
def test_binary_ops_match_numpy_bit_for_bit(name, dtype):
    a, b = operands(dtype)
    out = np.empty_like(a)
    kernel_for("binary", name)(a, b, out)
    with np.errstate(all="ignore"):
        expected = BINARY[name][1](a, b).astype(dtype)
    assert same_bits(out, expected), name


def test_min_max_take_the_second_operand_on_signed_zero_ties():
    a = np.array([0.0, -0.0] * (L // 2), np.float32)
    b = a[::-1].copy()
    for name in ("vmin", "vmax"):
        out = np.empty_like(a)
        kernel_for("binary", name)(a, b, out)
        assert same_bits(out, b), name


@pytest.mark.parametrize("dtype", DTYPES)
@pytest.mark.parametrize("name", sorted(COMPARES))
def test_compares_match_numpy_including_ties_and_signed_zeros(name, dtype):
    a, b = operands(dtype, seed=1)
    a[-L:] = np.nan  # NaN lanes: ordered compares false, ne true, as NumPy
    out = np.empty(a.size, np.int64)
    kernel_for("compare", name)(a, b, out)
    with np.errstate(invalid="ignore"):
        np.testing.assert_array_equal(out, COMPARES[name][1](a, b).astype(np.int64))


@njit
def _fma_kernel(a, b, c, out):
    for i in range(0, a.size, L):
        S.store(out, i, S.fma(S.load(a, i), S.load(b, i), S.load(c, i)))


def test_fma_float64_rounds_once():
    rng = np.random.default_rng(2)
    a, b, c = (rng.normal(size=4 * L) for _ in range(3))
    c[:L] = -a[:L] * b[:L]  # cancellation: only a single rounding keeps the product's low bits
    out = np.empty_like(a)
    _fma_kernel(a, b, c, out)
    exact = [float(Fraction(x) * Fraction(y) + Fraction(z)) for x, y, z in zip(a, b, c)]
    assert same_bits(out, np.array(exact))
    assert (out[:L] != 0).any()


def test_fma_float32_matches_widened_arithmetic():
    """A float32 product is exact in float64, so a * b + c in float64 rounds once before the cast."""
    a, b = operands(np.float32, seed=3)
    c = np.roll(a, 3)
    finite = np.isfinite(a) & np.isfinite(b) & np.isfinite(c)
    a, b, c = (np.where(finite, x, np.float32(1)) for x in (a, b, c))
    out = np.empty_like(a)
    _fma_kernel(a, b, c, out)
    expected = (a.astype(np.float64) * b + c).astype(np.float32)
    assert same_bits(out, expected)


@njit
def _unary_kernel(a, zeros, out_abs, out_rcp, out_sel, out_splat, out_convert):
    for i in range(0, a.size, L):
        v = S.load(a, i)
        S.store(out_abs, i, S.vabs(v))
        S.store(out_rcp, i, S.reciprocal(v))
        S.store(out_sel, i, S.select(S.gt(v, S.load(zeros, 0)), v, S.sub(v, v)))
        S.store(out_splat, i, S.splat_f64(a[i]))
        S.store(out_convert, i, S.to_f64(S.to_f32(S.load(out_splat, i))))


@pytest.mark.parametrize("dtype", DTYPES)
def test_abs_reciprocal_select_splat_and_conversions(dtype):
    a, _ = operands(dtype, seed=4)
    out_abs, out_rcp, out_sel = np.empty_like(a), np.empty_like(a), np.empty_like(a)
    out_splat, out_convert = np.empty(a.size), np.empty(a.size)
    _unary_kernel(a, np.zeros_like(a), out_abs, out_rcp, out_sel, out_splat, out_convert)
    with np.errstate(all="ignore"):
        assert same_bits(out_abs, np.abs(a))
        assert same_bits(out_rcp, (dtype(1) / a).astype(dtype))
        assert same_bits(out_sel, np.where(a > 0, a, a - a))
    assert same_bits(out_splat, np.repeat(a[::L].astype(np.float64), L))
    assert same_bits(out_convert, out_splat.astype(np.float32).astype(np.float64))


@njit
def _mask_kernel(a, b, bits_in, out):
    ma, mb = S.lt(S.load(a, 0), S.load(b, 0)), S.mask_from_bits(bits_in)
    out[0] = S.mask_bits(ma)
    out[1] = S.mask_bits(S.mask_and(ma, mb))
    out[2] = S.mask_bits(S.mask_or(ma, mb))
    out[3] = S.mask_bits(S.mask_andnot(ma, mb))
    out[4] = S.mask_bits(S.mask_not(ma))
    out[5] = S.mask_any(ma)
    out[6] = S.mask_all(ma)
    out[7] = S.mask_bits(mb)
    out[8] = S.count_trailing_zeros(bits_in)
    out[9] = S.count_set_bits(S.mask_bits(ma))


def test_masks_bits_any_all_trailing_zeros_and_set_bits():
    rng = np.random.default_rng(5)
    full = (1 << L) - 1
    for trial in range(200):
        a, b = rng.normal(size=L), rng.normal(size=L)
        if trial % 7 == 0:
            b = a - 1.0  # no lane set
        if trial % 11 == 0:
            b = a + 1.0  # every lane set
        bits_in = int(rng.integers(0, 1 << L)) if trial % 5 else 0
        out = np.empty(10, np.int64)
        _mask_kernel(a, b, bits_in, out)
        m = int(sum(1 << k for k in range(L) if a[k] < b[k]))
        expected = [m, m & bits_in, m | bits_in, m & ~bits_in & full, ~m & full, m != 0, m == full, bits_in,
                    (bits_in & -bits_in).bit_length() - 1 if bits_in else 64, bin(m).count("1")]
        assert out.tolist() == expected, (trial, out.tolist(), expected)


@njit
def _lane_kernel(a, k, x, out):
    v = S.load(a, 0)
    S.store(out, 0, S.with_lane(v, k, x))
    return S.lane(v, k)


def test_lane_and_with_lane():
    a = np.arange(L, dtype=np.float32) - 3.5
    for k in range(L):
        out = np.empty_like(a)
        assert _lane_kernel(a, k, 42.0, out) == a[k]
        expected = a.copy()
        expected[k] = 42.0
        assert same_bits(out, expected)


@njit
def _fma_min_compare(a, b, c, out):
    """A helper shaped like a slab test: (a - b) * c, fma, min, compare and select."""
    x, y, z = S.load(a, 0), S.load(b, 0), S.load(c, 0)
    t = S.fma(S.sub(x, y), z, y)
    S.store(out, 0, S.select(S.lt(t, z), S.vmin(t, x), S.vmax(t, y)))
    return S.mask_bits(S.lt(t, z))


def _host_has(feature):
    from llvmlite import binding
    return binding.get_host_cpu_features().get(feature, False)


@pytest.mark.skipif(platform.machine().lower() not in ("x86_64", "amd64"), reason="x86 machine code only")
def test_helpers_compile_to_packed_vector_instructions():
    if not (_host_has("avx") and _host_has("fma")):
        pytest.skip("host without AVX and FMA")
    a = np.ones(L, np.float32)
    _fma_min_compare(a, a, a, np.empty_like(a))
    asm = _fma_min_compare.inspect_asm(_fma_min_compare.signatures[0])
    ops = set(re.findall(r"\b(v[a-z0-9]+ps)\b", asm))
    assert any(op.startswith("vfmadd") for op in ops), sorted(ops)
    assert {"vsubps", "vminps", "vmaxps"} <= ops, sorted(ops)
    assert re.search(r"%[yz]mm\d+", asm), "no 256- or 512-bit registers"
    assert any(op.startswith("vcmp") for op in ops), sorted(ops)


@njit
def _sum_with_prefetch(values, shaped, ahead):
    total = 0.0
    for i in range(values.size):
        S.prefetch(shaped, i + ahead)  # past the end for the last `ahead` elements: a hint, never a read
        total += values[i]
    return total


def test_prefetch_changes_no_result_even_past_the_data():
    values = np.arange(1000, dtype=np.float32)
    shaped = values.reshape(10, 10, 10)  # the flat index of a multi-dimensional array, as packet_leaf takes it
    assert _sum_with_prefetch(values, shaped, 64) == _sum_with_prefetch(values, shaped, 0) == float(values.sum())
    assert _sum_with_prefetch(values, shaped, 1 << 20) == float(values.sum())


@pytest.mark.skipif(platform.machine().lower() not in ("x86_64", "amd64"), reason="x86 machine code only")
def test_prefetch_compiles_to_a_prefetch_instruction():
    values = np.ones(4, np.float64)
    _sum_with_prefetch(values, values, 1)
    assert re.search(r"\bprefetch", _sum_with_prefetch.inspect_asm(_sum_with_prefetch.signatures[0]))
