"""Procedural fields shared by the materials: lattice hashing, value noise, Perlin gradient noise
and their fBm sums, in torch so that a material's colours and shape parameters, and the
coordinates a field is warped by, get gradients.

Hashing is Perlin's permutation table (Perlin 2002, "Improving Noise"), drawn once from a fixed
seed, so every material evaluates the same pattern on every machine and in every process.
Interpolation uses Perlin's quintic fade 6t^5 - 15t^4 + 10t^3, whose first and second
derivatives vanish at lattice points (no creases in a bump or in a warped pattern).
"""

from __future__ import annotations

import math

import torch

__all__ = ["hash2", "cell_random", "value_noise", "perlin_noise", "fbm", "smoothstep", "soft_step"]

_SEED = 16
_PERIOD = 256  # lattice period of the table; patterns repeat every 256 material units


def _table() -> torch.Tensor:
    g = torch.Generator().manual_seed(_SEED)
    perm = torch.randperm(_PERIOD, generator=g)
    return torch.cat([perm, perm])  # doubled, so perm[perm[x] + y] needs no wrap


PERM = _table()
# Perlin 2002 uses 12 edge directions in 3D; in 2D, eight unit directions at 45 degrees.
_ANGLES = torch.arange(8, dtype=torch.float64) * (math.pi / 4)
GRADIENTS = torch.stack([torch.cos(_ANGLES), torch.sin(_ANGLES)], dim=1)


def hash2(ix: torch.Tensor, iy: torch.Tensor, salt: int = 0) -> torch.Tensor:
    """An integer in [0, 256) per lattice point (ix, iy) (integer tensors); `salt` picks an
    independent stream (a material's second field)."""
    ix = torch.remainder(ix + 37 * salt, _PERIOD)
    iy = torch.remainder(iy + 101 * salt, _PERIOD)
    return PERM[PERM[ix] + iy]


def cell_random(ix: torch.Tensor, iy: torch.Tensor, salt: int = 0) -> torch.Tensor:
    """A uniform number in [0, 1) per lattice cell: per-tile colour variation and the like."""
    h = hash2(ix, iy, salt)
    return (PERM[h + 7].to(torch.float64) * _PERIOD + h) / _PERIOD**2


def _fade(t):
    return t * t * t * (t * (t * 6 - 15) + 10)


def _lattice(p: torch.Tensor):
    cell = torch.floor(p)
    return cell.long(), p - cell


def value_noise(p: torch.Tensor, salt: int = 0) -> torch.Tensor:
    """Value noise in [0, 1] at points p (..., 2): random values at lattice points, blended by
    the quintic fade."""
    i, f = _lattice(p)
    ix, iy = i[..., 0], i[..., 1]
    u, v = _fade(f[..., 0]), _fade(f[..., 1])
    c = lambda dx, dy: cell_random(ix + dx, iy + dy, salt).to(p.dtype)
    return torch.lerp(torch.lerp(c(0, 0), c(1, 0), u), torch.lerp(c(0, 1), c(1, 1), u), v)


def perlin_noise(p: torch.Tensor, salt: int = 0) -> torch.Tensor:
    """Perlin gradient noise at points p (..., 2), zero at lattice points, within about
    [-0.7, 0.7] (the 2D maximum of sqrt(2)/2 with unit gradients)."""
    i, f = _lattice(p)
    ix, iy = i[..., 0], i[..., 1]
    grads = GRADIENTS.to(p.dtype)

    def corner(dx, dy):
        g = grads[hash2(ix + dx, iy + dy, salt) % 8]
        return g[..., 0] * (f[..., 0] - dx) + g[..., 1] * (f[..., 1] - dy)

    u, v = _fade(f[..., 0]), _fade(f[..., 1])
    return torch.lerp(torch.lerp(corner(0, 0), corner(1, 0), u), torch.lerp(corner(0, 1), corner(1, 1), u), v)


def fbm(p: torch.Tensor, octaves: int = 5, persistence=0.5, lacunarity: float = 2.0, basis=perlin_noise, salt: int = 0):
    """Fractal Brownian motion: sum_k persistence^k basis(lacunarity^k p), divided by the sum of
    the weights so that its range does not grow with `persistence` (a differentiable tensor
    is fine: the noise material fits it). Each octave is its own hash stream, and is shifted by
    an irrational offset so that lattice points of the octaves do not line up."""
    total, norm, weight = 0.0, 0.0, 1.0
    for k in range(octaves):
        shift = torch.tensor([0.618034 * k, 0.414214 * k], dtype=p.dtype)
        total = total + weight * basis(p * lacunarity**k + shift, salt + 11 * k)
        norm = norm + weight
        weight = weight * persistence
    return total / norm


def smoothstep(edge0, edge1, x):
    """Hermite step, 0 below edge0 and 1 above edge1 (GLSL's smoothstep)."""
    t = torch.clamp((x - edge0) / (edge1 - edge0), 0.0, 1.0)
    return t * t * (3 - 2 * t)


def soft_step(x, edge, width: float):
    """1 where x > edge, 0 where x < edge, blended over `width`: the anti-aliased and
    differentiable edge of a pattern (a hard step has zero gradient w.r.t. its edge)."""
    return smoothstep(edge - 0.5 * width, edge + 0.5 * width, x)
