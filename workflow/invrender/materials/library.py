"""The library: the six material types and named presets of them (starting points for
retrieval, as the paper's database of procedural graphs with their default parameters)."""

from __future__ import annotations

from dataclasses import dataclass, field

from .base import Material, Transform
from .checker import Checker
from .fabric import Fabric
from .noise import Noise
from .plain import Plain
from .tiles import Tiles
from .wood import Wood

__all__ = ["MATERIALS", "Preset", "PRESETS", "material", "preset"]

MATERIALS: dict[str, Material] = {m.name: m for m in (Plain(), Checker(), Tiles(), Wood(), Fabric(), Noise())}


@dataclass(frozen=True)
class Preset:
    """A named material with parameter values (the rest at their defaults) and the transform its
    thumbnail is drawn with."""

    name: str
    material: str
    values: dict = field(default_factory=dict)
    thumbnail: Transform = Transform(scale=2.0)

    @property
    def type(self) -> Material:
        return MATERIALS[self.material]

    def params(self):
        return self.type.defaults(**self.values)


PRESETS: tuple[Preset, ...] = (
    Preset("plain_grey", "plain"),
    Preset("checker_bw", "checker"),
    Preset("tiles_square", "tiles", {"tile_colour": (0.75, 0.75, 0.72), "grout_colour": (0.35, 0.35, 0.33)}),
    Preset(
        "tiles_brick",
        "tiles",
        {
            "tile_colour": (0.45, 0.15, 0.08),
            "grout_colour": (0.5, 0.48, 0.45),
            "aspect": 2.0,
            "bond": 0.5,
            "variation": 0.3,
        },
        Transform(scale=3.0),
    ),
    Preset("wood_oak", "wood"),
    Preset(
        "wood_walnut",
        "wood",
        {"light": (0.3, 0.17, 0.09), "dark": (0.12, 0.06, 0.03), "grain": 0.35, "distortion": 0.7},
    ),
    Preset("fabric_denim", "fabric", {"warp": (0.06, 0.1, 0.25), "weft": (0.55, 0.55, 0.55)}, Transform(scale=6.0)),
    Preset(
        "fabric_linen",
        "fabric",
        {"warp": (0.6, 0.55, 0.45), "weft": (0.55, 0.5, 0.4), "fuzz": 0.3, "thread_width": 0.9},
        Transform(scale=6.0),
    ),
    Preset("noise_stone", "noise"),
    Preset(
        "noise_plaster",
        "noise",
        {"colour_a": (0.75, 0.72, 0.68), "colour_b": (0.6, 0.58, 0.55), "persistence": 0.65, "value_mix": 0.6},
    ),
)


def material(name: str) -> Material:
    if name not in MATERIALS:
        raise KeyError(f"no material {name!r}; the library has {sorted(MATERIALS)}")
    return MATERIALS[name]


def preset(name: str) -> Preset:
    for p in PRESETS:
        if p.name == name:
            return p
    raise KeyError(f"no preset {name!r}; the library has {[p.name for p in PRESETS]}")
