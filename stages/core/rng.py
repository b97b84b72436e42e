"""Consistent, counter-based random numbers.

Every random number in loomlight is a pure function of integer keys (seed, object index,
dimension), never of a shared generator state, so any query and any thread sees the same value
and renders are byte-identical whatever the thread count.

- ``hash_u64(a, b, c)``: SplitMix64-style finaliser over three 64-bit keys.
- ``uniform(seed, index, dim)``: a double in [0, 1) from 53 hash bits.
- ``van_der_corput(i)``: base-2 radical inverse, the QMC sequence seed 000 §5.3 indexes by yarn
  and fibre (element N(i-1)+k for the k-th of yarn i's N numbers), optionally scrambled by a key.
- ``normal(seed, index, dim)``: a standard normal from two uniforms (Box-Muller).
"""
import math

from numba import njit, uint64

_M1 = uint64(0xBF58476D1CE4E5B9)
_M2 = uint64(0x94D049BB133111EB)
_GOLD = uint64(0x9E3779B97F4A7C15)


@njit(cache=True, inline="always")
def _mix(z):
    z = (z ^ (z >> uint64(30))) * _M1
    z = (z ^ (z >> uint64(27))) * _M2
    return z ^ (z >> uint64(31))


@njit(cache=True, inline="always")
def hash_u64(a, b, c):
    h = _mix(uint64(a) + _GOLD)
    h = _mix(h ^ (uint64(b) + _GOLD * uint64(2)))
    h = _mix(h ^ (uint64(c) + _GOLD * uint64(3)))
    return h


@njit(cache=True, inline="always")
def uniform(seed, index, dim):
    """Uniform double in [0, 1), a pure function of (seed, index, dim)."""
    return float(hash_u64(seed, index, dim) >> uint64(11)) * (1.0 / 9007199254740992.0)


@njit(cache=True, inline="always")
def normal(seed, index, dim):
    """Standard normal variate from (seed, index, dim) and (seed, index, dim + 1)."""
    u1 = uniform(seed, index, dim)
    u2 = uniform(seed, index, dim + 1)
    return math.sqrt(-2.0 * math.log(1.0 - u1)) * math.cos(2.0 * math.pi * u2)


@njit(cache=True)
def van_der_corput(i, scramble=0):
    """Base-2 radical inverse of i (bit reversal), XOR-scrambled by ``scramble``; in [0, 1)."""
    x = uint64(i)
    x = ((x >> uint64(1)) & uint64(0x5555555555555555)) | ((x & uint64(0x5555555555555555)) << uint64(1))
    x = ((x >> uint64(2)) & uint64(0x3333333333333333)) | ((x & uint64(0x3333333333333333)) << uint64(2))
    x = ((x >> uint64(4)) & uint64(0x0F0F0F0F0F0F0F0F)) | ((x & uint64(0x0F0F0F0F0F0F0F0F)) << uint64(4))
    x = ((x >> uint64(8)) & uint64(0x00FF00FF00FF00FF)) | ((x & uint64(0x00FF00FF00FF00FF)) << uint64(8))
    x = ((x >> uint64(16)) & uint64(0x0000FFFF0000FFFF)) | ((x & uint64(0x0000FFFF0000FFFF)) << uint64(16))
    x = (x >> uint64(32)) | (x << uint64(32))
    x = x ^ uint64(scramble)
    return float(x >> uint64(11)) * (1.0 / 9007199254740992.0)
