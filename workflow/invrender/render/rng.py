"""Philox-4x32-10 counter-based random numbers: the numpy reference of the kernels' RNG.

Salmon, Moraes, Dror and Shaw, "Parallel random numbers: as easy as 1, 2, 3", SC 2011,
and the Random123 library (github.com/DEShawResearch/random123, include/Random123/philox.h).
The kernel must agree with this file bit for bit (docs/renderer.md, "Random numbers").

One call is a pure function of (seed, ray, sample, bounce, block):

    key     = (seed & 0xffffffff, seed >> 32)           # 64-bit seed, low word first
    counter = (ray, sample, bounce, block)              # four uint32 words
    x       = philox4x32_10(counter, key)               # four uint32 words
    u_j     = (x_j >> 8) * 2^-24                        # float32 in [0, 1 - 2^-24]

The top 24 bits fill a float32 mantissa exactly, so u is exact in float32 and never 1.

C for the kernel (Random123's philox4x32round / philox4x32bumpkey, R = 10):

    uint hi0 = mul_hi(0xD2511F53u, c0), lo0 = 0xD2511F53u * c0;
    uint hi1 = mul_hi(0xCD9E8D57u, c2), lo1 = 0xCD9E8D57u * c2;
    (c0, c1, c2, c3) = (hi1 ^ c1 ^ k0, lo1, hi0 ^ c3 ^ k1, lo0);
    k0 += 0x9E3779B9u; k1 += 0xBB67AE85u;      // between rounds (9 bumps for 10 rounds)
"""

from __future__ import annotations

import numpy as np

# Random123 philox.h: PHILOX_M4x32_0/1 (multipliers), PHILOX_W32_0/1 (Weyl key increments:
# golden ratio and sqrt(3) - 1, as 32-bit fractions).
PHILOX_M0 = np.uint64(0xD2511F53)
PHILOX_M1 = np.uint64(0xCD9E8D57)
PHILOX_W0 = np.uint32(0x9E3779B9)
PHILOX_W1 = np.uint32(0xBB67AE85)
PHILOX_ROUNDS = 10

_MASK32 = np.uint64(0xFFFFFFFF)
_SHIFT32 = np.uint64(32)


def _mulhilo(m: np.uint64, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(hi, lo) 32-bit words of the 64-bit product m * x (Random123 mulhilo32)."""
    p = m * x.astype(np.uint64)  # < 2^64: exact in uint64
    return (p >> _SHIFT32).astype(np.uint32), (p & _MASK32).astype(np.uint32)


def philox4x32(counter, key, rounds: int = PHILOX_ROUNDS) -> np.ndarray:
    """Philox-4x32-R block function, vectorised: counter (..., 4), key (..., 2) -> (..., 4) uint32.

    Leading dimensions of counter and key broadcast. Random123 philox.h, philox4x32_R:
    round, then (bump key, round) R - 1 times.
    """
    counter = np.asarray(counter, dtype=np.uint32)
    key = np.asarray(key, dtype=np.uint32)
    shape = np.broadcast_shapes(counter.shape[:-1], key.shape[:-1])
    c0, c1, c2, c3 = (np.broadcast_to(counter[..., i], shape).copy() for i in range(4))
    k0, k1 = (np.broadcast_to(key[..., i], shape).copy() for i in range(2))
    with np.errstate(over="ignore"):  # uint32 key bumps wrap modulo 2^32 by design
        for r in range(rounds):
            if r > 0:  # philox4x32bumpkey
                k0 = k0 + PHILOX_W0
                k1 = k1 + PHILOX_W1
            hi0, lo0 = _mulhilo(PHILOX_M0, c0)  # philox4x32round
            hi1, lo1 = _mulhilo(PHILOX_M1, c2)
            c0, c1, c2, c3 = hi1 ^ c1 ^ k0, lo1, hi0 ^ c3 ^ k1, lo0
    return np.stack([c0, c1, c2, c3], axis=-1)


def seed_key(seed: int) -> np.ndarray:
    """The Philox key of a 64-bit seed: (low 32 bits, high 32 bits), as (2,) uint32."""
    seed = int(seed) & 0xFFFFFFFFFFFFFFFF
    return np.array([seed & 0xFFFFFFFF, seed >> 32], dtype=np.uint32)


def to_unit_float(x) -> np.ndarray:
    """uint32 -> float32 in [0, 1): (x >> 8) * 2^-24, exact (24 bits fit the mantissa)."""
    x = np.asarray(x, dtype=np.uint32)
    return ((x >> np.uint32(8)).astype(np.float32) * np.float32(2.0**-24)).astype(np.float32)


def uniform4(seed: int, ray, sample, bounce, block=0) -> np.ndarray:
    """Four uniform float32 in [0, 1) for each (ray, sample, bounce, block): shape (..., 4).

    ray, sample, bounce, block are integers or integer arrays (broadcast together) taken
    modulo 2^32; seed is a 64-bit integer. A pure function: the same arguments always give
    the same numbers, on any device.
    """
    words = np.broadcast_arrays(*(np.asarray(v, dtype=np.int64) & 0xFFFFFFFF for v in (ray, sample, bounce, block)))
    counter = np.stack([w.astype(np.uint32) for w in words], axis=-1)
    return to_unit_float(philox4x32(counter, seed_key(seed)))
