"""A v2 scene's objects and material sets -> the one mesh and one atlas the kernels read, and back.

The kernels see one world-space triangle soup and one packed atlas (render/scene_buffers.py).
`pack_scene` builds both from the objects:

- every material set's atlas becomes a rectangle of the packed atlas (shelf packing, tallest
  first), surrounded by `PADDING` texels that repeat its edge: a nearest-texel lookup
  (render/scene_buffers.atlas_lookup, kernels/textures.h) that float rounding puts a fraction of
  a texel outside the rectangle reads the set's own edge, never a neighbour's. A scene with one
  material set needs no padding (the lookup clamps at the atlas border): its atlas is packed as is;
- each object's UVs are moved into its set's rectangle, so a lookup at the packed UV finds the
  texel a lookup at the object's own UV finds in the set's atlas;
- positions go through the object's transform (float64, rounded once to float32; an identity
  transform leaves them bit for bit); normals follow from the triangles, as they always do;
- objects are concatenated in their order: faces, vertices, instance ids and sidedness.

Instances (objects that share a material set) share its rectangle, so the gradients of every copy
add up in the same texels; `Packing.unpack` cuts a packed-atlas array (maps, gradient maps) back
into per-set arrays.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .mesh_io import validate_mesh
from .types import ATLAS_MAPS, EMISSION_SIDES, Atlas, Maps, Mesh, Scene, SceneError, SceneObject

__all__ = [
    "PADDING",
    "Rect",
    "Packing",
    "layout",
    "pack_scene",
    "flatten",
    "object_transform",
    "check_transform",
    "validate_objects",
]

PADDING = 1  # texels around each rectangle: a lookup is off by far less than one texel


@dataclass(frozen=True)
class Rect:
    """A material set's texels in the packed atlas: rows [row, row + height), cols [col, col + width)."""

    row: int
    col: int
    height: int
    width: int


@dataclass
class Packing:
    """Where each material set lies in the packed atlas of shape (H, W)."""

    shape: tuple[int, int]
    rects: dict[str, Rect]
    padding: int

    def pack(self, arrays: dict[str, np.ndarray]) -> np.ndarray:
        """Per-set arrays (h, w, ...) -> one (H, W, ...) array; padding repeats each set's edge."""
        first = next(iter(arrays.values()))
        out = np.zeros((*self.shape, *first.shape[2:]), first.dtype)
        p = self.padding
        for name, rect in self.rects.items():
            cell = np.pad(np.asarray(arrays[name]), [(p, p), (p, p)] + [(0, 0)] * (first.ndim - 2), mode="edge")
            out[rect.row - p : rect.row + rect.height + p, rect.col - p : rect.col + rect.width + p] = cell
        return out

    def unpack(self, array: np.ndarray) -> dict[str, np.ndarray]:
        """A packed-atlas array (H, W, ...) -> each set's (h, w, ...) array (copies)."""
        array = np.asarray(array)
        if array.shape[:2] != tuple(self.shape):
            raise ValueError(f"unpack: expected a ({self.shape[0]}, {self.shape[1]}, ...) array, got {array.shape}")
        return {name: array[r.row : r.row + r.height, r.col : r.col + r.width].copy() for name, r in self.rects.items()}

    def pack_atlas(self, materials: dict[str, Atlas]) -> Atlas:
        return Atlas(**{m: self.pack({name: getattr(a, m) for name, a in materials.items()}) for m in ATLAS_MAPS})

    def unpack_atlas(self, atlas: Atlas) -> dict[str, Atlas]:
        """The packed maps (Maps or Atlas, or a dict of gradient maps) -> one Atlas per set."""
        get = atlas.get if isinstance(atlas, dict) else lambda m: getattr(atlas, m)
        cut = {m: self.unpack(get(m)) for m in ATLAS_MAPS}
        return {name: Atlas(**{m: cut[m][name] for m in ATLAS_MAPS}) for name in self.rects}

    def remap_uvs(self, uvs: np.ndarray, material: str) -> np.ndarray:
        """UVs in a set's own atlas -> UVs of the same texels in the packed atlas (v up: row
        floor((1 - v) h) of the set is row r0 + that of the packed atlas)."""
        rect, (H, W) = self.rects[material], self.shape
        if (rect.row, rect.col, rect.height, rect.width) == (0, 0, H, W):
            return np.asarray(uvs, np.float32)  # the set is the whole atlas: untouched
        uv = np.asarray(uvs, np.float64)
        u = (rect.col + uv[:, 0] * rect.width) / W
        v = 1.0 - (rect.row + (1.0 - uv[:, 1]) * rect.height) / H
        return np.stack([u, v], axis=1).astype(np.float32)


def layout(shapes: dict[str, tuple[int, int]], padding: int = PADDING) -> Packing:
    """Shelf packing of rectangles (h, w) each grown by `padding` on every side: tallest first
    (ties in the given order), shelves as wide as the widest cell or the square root of the total
    area, whichever is more. One set alone is the whole atlas, without padding."""
    if len(shapes) == 1:
        ((name, (h, w)),) = shapes.items()
        return Packing((int(h), int(w)), {name: Rect(0, 0, int(h), int(w))}, 0)
    cells = {name: (int(h) + 2 * padding, int(w) + 2 * padding) for name, (h, w) in shapes.items()}
    width = max(max(w for _, w in cells.values()), int(np.ceil(np.sqrt(sum(h * w for h, w in cells.values())))))
    rects, row, col, shelf = {}, 0, 0, 0
    for name in sorted(cells, key=lambda n: -cells[n][0]):  # sorted() is stable: ties keep their order
        h, w = cells[name]
        if col + w > width:
            row, col, shelf = row + shelf, 0, 0
        rects[name] = Rect(row + padding, col + padding, h - 2 * padding, w - 2 * padding)
        col, shelf = col + w, max(shelf, h)
    ordered = {name: rects[name] for name in shapes}  # the sets' own order, for unpack
    return Packing((row + shelf, width), ordered, padding)


def check_transform(transform, file, field: str) -> np.ndarray:
    """A 4x4 object-to-world matrix [[A, t], [0, 1]] with det A > 0 (no mirror: it would turn the
    triangles' fronts inside out); returned as float64."""
    try:
        T = np.asarray(transform, np.float64)
    except (TypeError, ValueError):
        T = np.zeros(0)
    if T.shape != (4, 4) or not np.isfinite(T).all() or not np.array_equal(T[3], [0, 0, 0, 1]):
        raise SceneError(file, field, "a row-major 4x4 matrix [[A, t], [0, 0, 0, 1]] of finite numbers")
    if not np.linalg.det(T[:3, :3]) > 0:
        raise SceneError(
            file, field, f"a transform that keeps orientation (det > 0), got det {np.linalg.det(T[:3, :3]):g}"
        )
    return T


def validate_objects(objects: list[SceneObject], materials, file) -> None:
    """What the schema cannot say about a v2 scene's objects: unique names, known material sets,
    valid meshes (with UVs) and transforms."""
    seen = set()
    for k, obj in enumerate(objects):
        field = f"objects[{k}]"
        if obj.name in seen:
            raise SceneError(file, f"{field}.name", f"a name no other object has, got {obj.name!r} twice")
        seen.add(obj.name)
        if obj.material not in materials:
            raise SceneError(
                file, f"{field}.material", f"one of the material sets {sorted(materials)}, got {obj.material!r}"
            )
        if obj.emission_sides not in EMISSION_SIDES:
            raise SceneError(file, f"{field}.emission_sides", f"one of {EMISSION_SIDES}, got {obj.emission_sides!r}")
        check_transform(obj.transform, file, f"{field}.transform")
        validate_mesh(obj.mesh, f"{file}: {field}.mesh ({obj.name})", require_uvs=True)
    if not objects:
        raise SceneError(file, "objects", "at least one object")


def object_transform(positions: np.ndarray, transform: np.ndarray) -> np.ndarray:
    """Object-space positions to world space; an identity transform leaves them bit for bit."""
    T = np.asarray(transform, np.float64)
    if np.array_equal(T, np.eye(4)):
        return np.asarray(positions, np.float32)
    return (np.asarray(positions, np.float64) @ T[:3, :3].T + T[:3, 3]).astype(np.float32)


def flatten(objects: list[SceneObject], packing: Packing) -> Mesh:
    """The objects as one world-space mesh with packed UVs (module docstring)."""
    positions, faces, uvs, ids, sides, offset = [], [], [], [], [], 0
    for obj in objects:
        mesh, count = obj.mesh, len(obj.mesh.faces)
        positions.append(object_transform(mesh.positions, obj.transform))
        faces.append(np.asarray(mesh.faces, np.int64) + offset)
        uvs.append(packing.remap_uvs(mesh.uvs, obj.material))
        if obj.instance_id is not None:
            ids.append(np.full(count, obj.instance_id, np.int32))
        else:
            ids.append(
                np.zeros(count, np.int32) if mesh.instance_ids is None else np.asarray(mesh.instance_ids, np.int32)
            )
        sides.append(np.full(count, obj.emission_sides == "one"))
        offset += len(mesh.positions)
    one_sided = np.concatenate(sides)
    return Mesh(
        positions=np.concatenate(positions),
        faces=np.concatenate(faces).astype(np.int32),
        uvs=np.concatenate(uvs),
        instance_ids=np.concatenate(ids),
        one_sided=one_sided if one_sided.any() else None,
    )


def pack_scene(
    objects: list[SceneObject],
    materials: dict[str, Atlas],
    kg: np.ndarray,
    cameras=(),
    path=None,
    padding: int = PADDING,
) -> Scene:
    """A v2 scene: its objects, and the mesh and maps the renderer reads (module docstring).
    `materials` maps each set's name to its atlas (any size); `kg` is the scene's (6, N, N, 3) sky."""
    validate_objects(objects, materials, "(scene in memory)")
    packing = layout({name: atlas.atlas_shape for name, atlas in materials.items()}, padding)
    atlas = packing.pack_atlas(materials)
    maps = Maps(**{m: getattr(atlas, m) for m in ATLAS_MAPS}, kg=np.asarray(kg, np.float32))
    return Scene(
        mesh=flatten(objects, packing),
        maps=maps,
        cameras=list(cameras),
        path=path,
        objects=list(objects),
        packing=packing,
    )
