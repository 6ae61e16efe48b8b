"""What every procedural material shares: named continuous parameters with bounds, the 2D
texture transform, and evaluation of the renderer's maps (kd, ks, ka) at UV points.

Conventions:
- kd is linear RGB (no sRGB curve: the renderer's albedo), ks the scalar specular reflectance at
  normal incidence (grey, as a dielectric's), ka the renderer's Beckmann alpha^2 (render/bsdf.py,
  docs/renderer.md), from the parameter `roughness` = alpha: ka = roughness^2.
- A material is defined in its own "material space", where its pattern repeats about once per
  unit (one checker pair, one tile row, one wood ring, one weave cell); the `Transform` maps
  UV (or surface) coordinates into it: p = scale * R(-rotation) @ uv + offset, so that `scale`
  repetitions fit in one UV unit and the pattern appears turned by `rotation` degrees
  counter-clockwise (u right, v up).
- Parameters are a dict name -> torch tensor (shape (3,) for colours, () for scalars), every one
  differentiable; `Param.low`/`high` bound them. kd is capped at 1 - specular, so kd + ks <= 1
  (the energy bound) whatever a pattern's brightening does.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import torch

from ..render.bsdf import KA_MIN

__all__ = ["Param", "Transform", "Material", "COMMON_PARAMS", "DTYPE"]

DTYPE = torch.float32


@dataclass(frozen=True)
class Param:
    """One named continuous parameter: a colour (default a 3-tuple) or a scalar.

    `texture` says whether it changes kd, the only map a photo crop shows directly: the fit from
    a crop moves those; roughness and specular need the renderer (the joint stage, Eq. 4)."""

    name: str
    default: float | tuple[float, float, float]
    low: float
    high: float
    texture: bool = True

    @property
    def is_colour(self) -> bool:
        return isinstance(self.default, tuple)

    def tensor(self, value=None) -> torch.Tensor:
        value = self.default if value is None else value
        t = torch.as_tensor(value, dtype=DTYPE).clone()
        if t.shape != ((3,) if self.is_colour else ()):
            raise ValueError(
                f"parameter {self.name}: expected {'an RGB triple' if self.is_colour else 'a number'}, got {value!r}"
            )
        return t


COMMON_PARAMS = (
    # Roughness 0.5 is the paper's initial value for every material (section 4.4).
    Param("roughness", 0.5, 0.02, 1.0, texture=False),
    # 0.04: the normal-incidence reflectance of glass, plastics and varnish (n = 1.5).
    Param("specular", 0.04, 0.0, 0.08, texture=False),
)


@dataclass(frozen=True)
class Transform:
    """p = scale * R(-rotation_deg) @ uv + offset (module docstring). `scale` may be a torch
    scalar, so that a fit can refine it."""

    scale: float = 1.0
    rotation_deg: float = 0.0
    offset: tuple[float, float] = (0.0, 0.0)

    def apply(self, uv: torch.Tensor) -> torch.Tensor:
        a = math.radians(self.rotation_deg)
        c, s = math.cos(a), math.sin(a)
        # R(-a) = [[c, s], [-s, c]] applied to row vectors uv.
        rot = torch.tensor([[c, -s], [s, c]], dtype=uv.dtype)
        return self.scale * (uv @ rot) + torch.tensor(self.offset, dtype=uv.dtype)

    def as_dict(self) -> dict:
        return {"scale": self.scale, "rotation_deg": self.rotation_deg, "offset": list(self.offset)}


class Material:
    """A procedural material: subclasses set `name`, `PARAMS` (their own; the common roughness
    and specular are appended) and implement `albedo(p, P, footprint) -> kd (N, 3)`."""

    name: str = ""
    PARAMS: tuple[Param, ...] = ()

    @property
    def params(self) -> tuple[Param, ...]:
        return self.PARAMS + COMMON_PARAMS

    def param(self, name: str) -> Param:
        for p in self.params:
            if p.name == name:
                return p
        raise KeyError(f"{self.name} has no parameter {name!r}; it has {[p.name for p in self.params]}")

    def defaults(self, **values) -> dict[str, torch.Tensor]:
        """Every parameter as a tensor: the defaults, overridden by `values`."""
        unknown = set(values) - {p.name for p in self.params}
        if unknown:
            raise KeyError(f"{self.name} has no parameter {sorted(unknown)}; it has {[p.name for p in self.params]}")
        return {p.name: p.tensor(values.get(p.name)) for p in self.params}

    def complete(self, params: dict | None) -> dict[str, torch.Tensor]:
        """`params` (tensors or numbers, possibly partial) with the defaults filled in; tensors
        are kept as they are, so gradients reach them."""
        params = params or {}
        full = self.defaults(**{k: v for k, v in params.items() if not torch.is_tensor(v)})
        full.update({k: v for k, v in params.items() if torch.is_tensor(v)})
        return full

    def albedo(self, p: torch.Tensor, P: dict[str, torch.Tensor], footprint: float) -> torch.Tensor:
        raise NotImplementedError

    def evaluate(self, uv, params=None, transform: Transform = Transform(), footprint: float = 0.0):
        """kd (N, 3), ks (N,), ka (N,) at UV points uv (N, 2). `footprint` is the size of a
        sample in material units (a pixel or texel): pattern edges are blurred over at least
        that much, so that a pattern finer than the sampling does not alias. Computed in float32,
        or in float64 if uv is (then pass float64 parameters too)."""
        uv = torch.as_tensor(uv)
        if uv.dtype != torch.float64:  # float64 stays (the finite-difference tests use it)
            uv = uv.to(DTYPE)
        P = self.complete(params)
        p = transform.apply(uv)
        # kd + ks <= 1 per channel (the material model's energy bound, render/losses.py): a
        # brightened tile or grain streak is capped below 1 - specular.
        kd = torch.minimum(torch.clamp(self.albedo(p, P, float(footprint)), min=0.0), 1.0 - P["specular"])
        n = len(uv)
        ks = P["specular"].expand(n)
        ka = torch.clamp(P["roughness"] ** 2, min=KA_MIN).expand(n)
        return kd, ks, ka

    def image(
        self, height: int, params=None, transform: Transform = Transform(), width: int | None = None
    ) -> torch.Tensor:
        """kd as an image (height, width, 3) whose width spans one UV unit (a crop's width is
        the unit its transform's scale counts repetitions in), pixel centres sampled, row 0 at
        the top (largest v), as the atlas maps are stored (scene/atlas.py)."""
        width = height if width is None else width
        uv = pixel_uvs(height, width)
        footprint = float(torch.as_tensor(transform.scale).detach()) / width
        kd, _, _ = self.evaluate(uv.reshape(-1, 2), params, transform, footprint)
        return kd.reshape(height, width, 3)


def mean_albedo(material: Material, params=None, size: int = 128, repeats: int = 16) -> torch.Tensor:
    """The material's mean kd (3,) over `repeats` whole periods each way: its colour as seen from
    afar, independent of where a crop cuts the pattern (a checker crop of 3.5 squares is not
    half and half)."""
    return material.image(size, params, Transform(scale=float(repeats))).mean(dim=(0, 1))


def pixel_uvs(height: int, width: int) -> torch.Tensor:
    """(height, width, 2) UVs of pixel centres, one UV unit across the width, row 0 at the top."""
    pixel = 1.0 / width
    u = (torch.arange(width, dtype=DTYPE) + 0.5) * pixel
    v = (height - 0.5 - torch.arange(height, dtype=DTYPE)) * pixel
    vv, uu = torch.meshgrid(v, u, indexing="ij")
    return torch.stack([uu, vv], dim=-1)


def to_unit(material: Material, params: dict[str, torch.Tensor]) -> dict[str, torch.Tensor]:
    """Each parameter mapped to [0, 1] by its bounds (the fit's coordinates)."""
    out = {}
    for p in material.params:
        out[p.name] = (params[p.name] - p.low) / (p.high - p.low)
    return out


def from_unit(material: Material, unit: dict[str, torch.Tensor]) -> dict[str, torch.Tensor]:
    return {p.name: p.low + (p.high - p.low) * unit[p.name] for p in material.params}


class single_thread:
    """Run torch on one thread inside the block, restoring the caller's count after.

    The materials' tensors are small (a 64 x 64 crop, a few thousand UV points), where the
    thread pool's synchronisation costs more than a second core saves: on this 2-core machine
    under load, one Gram-network pass took 0.48 s with 2 threads and 0.022 s with 1 (measured)."""

    def __enter__(self):
        self.saved = torch.get_num_threads()
        torch.set_num_threads(1)

    def __exit__(self, *exc):
        torch.set_num_threads(self.saved)
