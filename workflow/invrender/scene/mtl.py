"""Wavefront MTL materials, as exporters of textured OBJ scenes write them, in MILO's terms.

Read per ``newmtl``:

| MTL | MILO map | how |
|---|---|---|
| ``Kd`` r g b, ``map_Kd`` image | kd | the image times Kd (the MTL rule: a map scales its colour) |
| ``Ks`` r g b, ``map_Ks`` image | ks | reflectance at normal incidence |
| ``Ns`` exponent | ka | Beckmann alpha^2 = 2 / (Ns + 2) (Walter et al. 2007's Phong-Beckmann match) |
| ``Ke`` r g b, ``map_Ke`` image | ke | radiance |

Colours without a map are constants; a map without its colour uses 1; no Ns means a rough
surface (Ns = 0, alpha^2 = 1). Images are read by scene/images.read_image (PNG/JPEG decoded from
sRGB to linear, EXR as is). Other statements (``d``, ``illum``, ``Ni``, ``bump``, ``map_Ns``) are
ignored: the model has no transparency or refraction. Every problem is a ``SceneError``.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .images import read_image
from .types import SceneError

__all__ = ["MtlMaterial", "read_mtl", "phong_to_beckmann"]

COLOURS = {"Kd": "kd", "Ks": "ks", "Ke": "ke"}
MAPS = {"map_Kd": "kd", "map_Ks": "ks", "map_Ke": "ke"}


def phong_to_beckmann(ns):
    """Beckmann alpha^2 for a Phong exponent: alpha^2 = 2 / (Ns + 2)."""
    return 2.0 / (np.asarray(ns, np.float64) + 2.0)


@dataclass
class MtlMaterial:
    name: str
    colours: dict = field(default_factory=dict)  # kd, ks, ke -> (3,) float32; ns -> float
    maps: dict = field(default_factory=dict)  # kd, ks, ke -> image path

    def image(self, key: str) -> np.ndarray | None:
        """The map's pixels times its colour, (H, W, 3) linear; None without a map."""
        if key not in self.maps:
            return None
        image = read_image(self.maps[key])
        rgb = image[..., :3] if image.shape[2] >= 3 else np.repeat(image[..., :1], 3, axis=2)
        return (rgb * self.colours.get(key, np.ones(3, np.float32))).astype(np.float32)

    def constant(self, key: str) -> np.ndarray:
        """The colour without a map: Kd and Ks default to 0 (MTL's own default for Ks is 0 too),
        Ke to 0; ka from Ns (no Ns: alpha^2 = 1)."""
        if key == "ka":
            return np.float32(phong_to_beckmann(self.colours.get("ns", 0.0)))
        return self.colours.get(key, np.zeros(3, np.float32))


def read_mtl(path) -> dict[str, MtlMaterial]:
    """Every material of an MTL file, by name; map paths resolved against the file's folder."""
    path = Path(path)
    if not path.is_file():
        raise SceneError(path, "(file)", "an existing MTL file (named by the OBJ's mtllib)")
    materials: dict[str, MtlMaterial] = {}
    current = None
    for line_no, line in enumerate(path.read_text(encoding="utf-8", errors="replace").splitlines(), 1):
        words = line.split("#", 1)[0].split()
        if not words:
            continue
        tag = words[0]
        if tag == "newmtl":
            current = MtlMaterial(" ".join(words[1:]))
            materials[current.name] = current
        elif tag in COLOURS or tag == "Ns" or tag in MAPS:
            if current is None:
                raise SceneError(path, f"line {line_no} {tag}", "a newmtl statement before any property")
            _read_property(current, tag, words[1:], path, line_no)
    return materials


def _read_property(material: MtlMaterial, tag: str, values: list[str], path: Path, line_no: int) -> None:
    if tag in MAPS:
        if not values:
            raise SceneError(path, f"line {line_no} {tag}", "an image file name")
        image = path.parent / values[-1]  # options (-s, -o, -bm ...) come before the name
        if not image.is_file():
            raise SceneError(path, f"line {line_no} {tag}", f"an existing image, got {values[-1]!r}")
        material.maps[MAPS[tag]] = image
        return
    try:
        numbers = [float(v) for v in values]
    except ValueError:
        numbers = []
    if tag == "Ns" and len(numbers) == 1 and numbers[0] >= 0:
        material.colours["ns"] = numbers[0]
    elif tag in COLOURS and len(numbers) in (1, 3) and min(numbers) >= 0:
        material.colours[COLOURS[tag]] = np.broadcast_to(np.asarray(numbers, np.float32), (3,)).copy()
    else:
        expected = "one exponent >= 0" if tag == "Ns" else "r g b (or one value), each >= 0"
        raise SceneError(path, f"line {line_no} {tag}", f"{expected}, got {' '.join(values)!r}")
