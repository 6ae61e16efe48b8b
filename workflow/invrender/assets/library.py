"""The asset library: the bundled procedural furniture plus every model in the user's folders.

A user folder holds OBJ, PLY or USD (.usd, .usda, .usdc, .usdz) models, in sub-folders or not.
A model's category is its first sub-folder's name (``chairs/eames.obj`` -> ``chairs``), or for a
model at the top the leading letters of its file name (``Sofa_02.ply`` -> ``sofa``). Its parts
(material ids) are the OBJ's ``usemtl`` groups, the USD's bound materials, or one ``surface``
for a PLY. Each model is unit-normalised like the bundled ones; its nominal size is its largest
extent in the file's units, taken as meters. Unreadable models stop with the file's SceneError.
"""

from __future__ import annotations

import functools
import re
from pathlib import Path

import numpy as np

from ..scene.mesh_io import read_obj_parts, read_triangles
from ..scene.types import SceneError
from ..scene.usd_mesh import read_usd_parts
from .asset import Asset, normalised
from .furniture import VARIANTS, bundled
from .primitives import Primitive

__all__ = ["MODEL_SUFFIXES", "library", "user_assets", "read_model"]

MODEL_SUFFIXES = (".obj", ".ply", ".usd", ".usda", ".usdc", ".usdz")


@functools.lru_cache(maxsize=4)
def _bundled(variants: int) -> tuple[Asset, ...]:
    return tuple(bundled(variants))


def library(user_dirs=(), variants: int = VARIANTS) -> list[Asset]:
    """The bundled furniture (``variants`` of each category) and the models of ``user_dirs``."""
    assets = list(_bundled(variants))
    for folder in user_dirs:
        assets += user_assets(folder)
    seen = set()
    for asset in assets:
        if asset.name in seen:
            raise SceneError(asset.source, "(asset name)", f"a name no other asset has, got {asset.name!r} twice")
        seen.add(asset.name)
    return assets


def user_assets(folder) -> list[Asset]:
    folder = Path(folder)
    if not folder.is_dir():
        raise SceneError(folder, "(folder)", "an existing folder of OBJ, PLY or USD models")
    files = sorted(p for p in folder.rglob("*") if p.is_file() and p.suffix.lower() in MODEL_SUFFIXES)
    if not files:
        raise SceneError(folder, "(models)", f"at least one model file ({', '.join(MODEL_SUFFIXES)})")
    return [read_model(path, folder) for path in files]


def category_of(path: Path, root: Path) -> str:
    relative = path.relative_to(root)
    if len(relative.parts) > 1:
        return relative.parts[0].lower()
    letters = re.match(r"[A-Za-z]+", path.stem)
    return letters.group(0).lower() if letters else "model"


def _model_parts(path: Path) -> list[tuple[str, np.ndarray, np.ndarray]]:
    suffix = path.suffix.lower()
    if suffix == ".obj":
        parts, _ = read_obj_parts(path)
        return [(name or "surface", m.positions, m.faces) for name, m in parts]
    if suffix == ".ply":
        m = read_triangles(path)
        return [("surface", m.positions, m.faces)]
    return read_usd_parts(path)


def read_model(path, root=None) -> Asset:
    """One user model as an asset named ``{root folder}/{path inside it, no suffix}``."""
    path = Path(path)
    root = Path(root) if root is not None else path.parent
    parts = _model_parts(path)
    offsets = np.cumsum([0] + [len(p) for _, p, _ in parts[:-1]])
    mesh = Primitive(
        np.concatenate([np.asarray(p, np.float64) for _, p, _ in parts]),
        np.concatenate([np.asarray(f, np.int64) + o for (_, _, f), o in zip(parts, offsets)]).astype(np.int32),
        np.concatenate([np.full(len(f), k, np.int32) for k, (_, _, f) in enumerate(parts)]),
    )
    if not np.all(np.isfinite(mesh.positions)):
        raise SceneError(path, "vertex positions", "finite numbers")
    try:
        unit, size = normalised(mesh)
    except ValueError:
        raise SceneError(path, "vertex positions", "a model with a non-zero extent") from None
    name = f"{root.name}/{path.relative_to(root).with_suffix('').as_posix()}"
    return Asset(name, category_of(path, root), unit, tuple(n for n, _, _ in parts), size, source=str(path))
