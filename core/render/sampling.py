"""Sample points: Owen-scrambled, shuffled Sobol (low discrepancy) or independent random numbers.

Low discrepancy: Burley 2020, "Practical Hash-based Owen Scrambling" (JCGT 9(4)): the 2D Sobol set
Owen-scrambled by a hash-based nested uniform scramble, its sample index shuffled too, both seeded per
pixel and use (AO, each light): pixels and uses decorrelate and every power-of-two prefix stays
stratified. Random: a per-(pixel, sample, use) hash, for comparison. Pure integer arithmetic on
32-bit values in int64, so deterministic.
"""
import numpy as np
from numba import njit

SOBOL = 0
RANDOM = 1
SAMPLERS = ("sobol", "random")

MASK = 0xFFFFFFFF
INV_2_32 = 1.0 / 4294967296.0


def _sobol_dim1_matrix():
    """Direction vectors of Sobol's second dimension (primitive polynomial x + 1)."""
    v = np.empty(32, np.int64)
    v[0] = 1 << 31
    for i in range(1, 32):
        v[i] = v[i - 1] ^ (v[i - 1] >> 1)
    return v


def _byte_tables(v):
    """(4, 256) tables: entry [b, x] is the XOR of the direction vectors v[8b + j] over the bits j set in
    byte value x. The product of the generator matrix with an index is then four lookups, one per byte
    of the index, instead of a loop over its 32 bits (the same XOR, so the same points)."""
    tables = np.zeros((4, 256), np.int64)
    for b in range(4):
        for x in range(256):
            for j in range(8):
                if x >> j & 1:
                    tables[b, x] ^= v[8 * b + j]
    return tables


SOBOL_DIM1 = _byte_tables(_sobol_dim1_matrix())  # what the kernels take as `dim1`


@njit(cache=True, inline="always")
def hash32(x):
    """A strong 32-bit integer hash (Wellons' lowbias32)."""
    x &= MASK
    x ^= x >> 16
    x = (x * 0x7FEB352D) & MASK
    x ^= x >> 15
    x = (x * 0x846CA68B) & MASK
    x ^= x >> 16
    return x


@njit(cache=True, inline="always")
def hash_combine(seed, value):
    return hash32(seed ^ (hash32(value) + 0x9E3779B9 + ((seed << 6) & MASK) + (seed >> 2)))


@njit(cache=True, inline="always")
def reverse_bits(x):
    x &= MASK
    x = ((x >> 1) & 0x55555555) | ((x & 0x55555555) << 1)
    x = ((x >> 2) & 0x33333333) | ((x & 0x33333333) << 2)
    x = ((x >> 4) & 0x0F0F0F0F) | ((x & 0x0F0F0F0F) << 4)
    x = ((x >> 8) & 0x00FF00FF) | ((x & 0x00FF00FF) << 8)
    return ((x >> 16) | (x << 16)) & MASK


@njit(cache=True, inline="always")
def _laine_karras(x, seed):
    """Burley's improved Laine-Karras permutation: an Owen scramble of bit-reversed values."""
    x = (x + seed) & MASK
    x ^= (x * 0x6C50B47C) & MASK
    x ^= (x * 0xB82F1E52) & MASK
    x ^= (x * 0xC7AFE638) & MASK
    x ^= (x * 0x8D22F6E6) & MASK
    return x


@njit(cache=True, inline="always")
def nested_uniform_scramble(x, seed):
    return reverse_bits(_laine_karras(reverse_bits(x), seed))


@njit(cache=True, inline="always")
def sobol_2d(index, dim1):
    """The index-th point of the 2D Sobol set as two 32-bit integers; `dim1` is SOBOL_DIM1's byte tables."""
    i = index & MASK
    y = dim1[0, i & 0xFF] ^ dim1[1, (i >> 8) & 0xFF] ^ dim1[2, (i >> 16) & 0xFF] ^ dim1[3, (i >> 24) & 0xFF]
    return reverse_bits(index), y


@njit(cache=True, inline="always")
def use_seeds(pixel_seed, use):
    """The three scramble seeds of one use (AO, light k, ...) of a pixel: the same for all its samples,
    so a kernel makes them once per pixel and use rather than once per sample (four hashes a sample)."""
    seed = hash_combine(pixel_seed, use)
    return hash_combine(seed, 0x1B873593), hash_combine(seed, 0xCC9E2D51), hash_combine(seed, 0xE6546B64), seed


@njit(cache=True, inline="always")
def seeded_sample_2d(sampler, seeds, index, dim1):
    """sample_2d with the use's seeds (use_seeds) made beforehand."""
    if sampler == RANDOM:
        a = hash_combine(seeds[3], index)
        return a * INV_2_32, hash32(a ^ 0x5BD1E995) * INV_2_32
    x, y = sobol_2d(nested_uniform_scramble(index, seeds[0]), dim1)
    return nested_uniform_scramble(x, seeds[1]) * INV_2_32, nested_uniform_scramble(y, seeds[2]) * INV_2_32


@njit(cache=True, inline="always")
def sample_2d(sampler, pixel_seed, index, use, dim1):
    """Two uniform numbers in [0, 1) for sample `index` of a pixel, for one use (AO, light k, ...)."""
    return seeded_sample_2d(sampler, use_seeds(pixel_seed, use), index, dim1)


@njit(cache=True, inline="always")
def pixel_seed(pixel, seed):
    return hash_combine(hash32(seed), pixel)
