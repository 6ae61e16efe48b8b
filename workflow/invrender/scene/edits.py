"""Scene edits (MILO section 4): insert an object, relight, change the sky, repaint a region.

Every edit takes a `Scene` (v1 or v2) and returns a new one; the input is left untouched (its
arrays are copied where they change, shared where they do not). The renderer reads
`scene.mesh` and `scene.maps` (one mesh, one packed atlas), and so the edits work on those:

- an inserted object becomes an object with a material set of its own, packed beside the
  scene's sets by `scene/packing.py`: the result is a v2 scene (a v1 scene's mesh and atlas
  become its object "scene" and set "scene"), so edits compose and `write_scene` writes them;
- regions are (H, W) bool masks over the packed atlas; `emitter_regions` numbers the lamps
  (connected emitting surfaces) by their texels, so that "switch off lamp 2" can be said.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from .format import _check_map, validate_kg
from .packing import pack_scene
from .regions import face_texels
from .types import ATLAS_MAPS, MAP_CHANNELS, Atlas, Maps, Mesh, Scene, SceneError, SceneObject

__all__ = [
    "MATERIAL_DEFAULTS",
    "sphere_mesh",
    "uniform_material",
    "insert_object",
    "scale_emission",
    "set_sky",
    "edit_material",
    "emitter_regions",
    "region_surfaces",
]

# An inserted object's material where a key is not given: black, not shiny, not emitting, and the
# smallest roughness MILO's templates use for emitters (ka is never 0: format.MAP_RANGES).
MATERIAL_DEFAULTS = {"kd": 0.0, "ks": 0.0, "ka": 0.1, "ke": 0.0, "kw": 0.0}
WHERE = "(edit)"  # the `file` of a SceneError about an edit made in memory


def sphere_mesh(center, radius: float, segments: int = 32) -> Mesh:
    """A UV sphere: `segments` columns of longitude, segments // 2 rows of latitude, triangles
    counter-clockwise seen from outside, and UVs (u = longitude, v = latitude, v up) that cover
    [0, 1]^2, so a uniform material set of any size holds all of it. The seam column and the
    poles repeat their positions exactly (one vertex per UV), so no ray leaks through: closed for
    shadows. Each pole row is one triangle per column, not a degenerate quad."""
    if not (np.isfinite(radius) and radius > 0):
        raise SceneError(WHERE, "radius", f"a positive number of meters, got {radius!r}")
    columns, rows = max(int(segments), 3), max(int(segments) // 2, 2)
    theta = np.pi * np.arange(rows + 1) / rows  # polar angle from +Y
    phi = 2.0 * np.pi * np.arange(columns + 1) / columns
    t, p = np.meshgrid(theta, phi, indexing="ij")  # (rows + 1, columns + 1)
    unit = np.stack([np.sin(t) * np.cos(p), np.cos(t), -np.sin(t) * np.sin(p)], -1)
    unit[0], unit[-1] = (0.0, 1.0, 0.0), (0.0, -1.0, 0.0)  # exact poles: sin(pi) is not 0 in floats
    unit[:, -1] = unit[:, 0]  # the seam: the same positions bit for bit
    positions = (np.asarray(center, np.float64) + radius * unit).reshape(-1, 3).astype(np.float32)
    u, v = np.meshgrid(np.arange(columns + 1) / columns, 1.0 - np.arange(rows + 1) / rows)
    uvs = np.stack([u, v], -1).reshape(-1, 2).astype(np.float32)
    index = np.arange((rows + 1) * (columns + 1)).reshape(rows + 1, columns + 1)
    a, b = index[:-1, :-1], index[:-1, 1:]  # a quad's upper corners (towards +Y), phi increasing
    c, d = index[1:, :-1], index[1:, 1:]
    # (a, c, d) and (a, d, b) are counter-clockwise seen from outside (tests/scene/test_edits.py
    # checks the signed volume and every face normal).
    upper = np.stack([a, c, d], -1)[:-1]  # in the last row, c and d are both the south pole
    lower = np.stack([a, d, b], -1)[1:]  # in row 0, a and b are both the north pole
    faces = np.concatenate([upper.reshape(-1, 3), lower.reshape(-1, 3)]).astype(np.int32)
    return Mesh(positions=positions, faces=faces, uvs=uvs)


def _material_value(name: str, value, shape, field: str) -> np.ndarray:
    """A float (or an RGB triple for kd, ks, ke) broadcast to a map of `shape`, checked against
    the map's range (format.MAP_RANGES) with the message every scene map gets."""
    channels = MAP_CHANNELS[name]
    try:
        array = np.asarray(value, np.float32)
    except (TypeError, ValueError):
        array = np.zeros(0)
    if array.shape not in {(), (channels,)}:
        raise SceneError(WHERE, field, f"a number{' or an RGB triple' if channels == 3 else ''}, got {value!r}")
    full = np.broadcast_to(array, (*shape, channels) if channels == 3 else shape).copy()
    return _check_map(name, full, WHERE, field)


def uniform_material(material: dict, resolution: int = 8, field: str = "material") -> Atlas:
    """A material set of resolution^2 texels, every one with `material`'s values (keys of
    MATERIAL_DEFAULTS; missing ones take the default)."""
    unknown = sorted(set(material) - set(MATERIAL_DEFAULTS))
    if unknown:
        raise SceneError(WHERE, f"{field}.{unknown[0]}", f"one of the keys {list(MATERIAL_DEFAULTS)}")
    values = {**MATERIAL_DEFAULTS, **material}
    shape = (int(resolution), int(resolution))
    return Atlas(**{m: _material_value(m, values[m], shape, f"{field}.{m}") for m in ATLAS_MAPS})


def _next_instance_id(scene: Scene) -> int:
    ids = scene.mesh.instance_ids
    return 1 + (int(np.max(ids)) if ids is not None and len(ids) else 0)


def insert_object(scene: Scene, mesh: Mesh, material: dict, name: str = "inserted", resolution: int = 8) -> Scene:
    """A new v2 scene: `scene` plus `mesh` (world space, UVs in [0, 1]) as an object `name` with
    a uniform material in a resolution^2 material set of its own (also `name`) and a new instance
    id (one above the largest), so that its pixels can be told apart. A v1 scene's mesh and atlas
    become its object(s) and material set "scene" (`v1_objects`); scene/packing.py lays the sets
    out and flattens the objects. The cameras and kg are kept; the input is not changed."""
    atlas = uniform_material(material, resolution)
    if scene.objects:
        objects, materials = list(scene.objects), scene.packing.unpack_atlas(scene.maps)
    else:
        objects, materials = v1_objects(scene), {V1_SET: scene.maps.atlas}
    if name in materials or any(o.name == name for o in objects):
        taken = sorted({*materials, *(o.name for o in objects)})
        raise SceneError(WHERE, "name", f"a name no object or material set of the scene has ({taken}), got {name!r}")
    new = SceneObject(name=name, mesh=mesh, material=name, instance_id=_next_instance_id(scene))
    return pack_scene([*objects, new], {**materials, name: atlas}, scene.maps.kg.copy(), scene.cameras)


V1_SET = "scene"  # the material set (and object) a v1 scene becomes when an object is inserted


def v1_objects(scene: Scene) -> list[SceneObject]:
    """A v1 scene's mesh as v2 objects over the material set "scene": one object, or, if some of
    its faces emit one-sided (Mesh.one_sided; v2 says sidedness per object), the two-sided faces
    as "scene" and the one-sided ones as "scene_one_sided" (same vertices, same texels)."""
    mesh = scene.mesh
    one_sided = np.zeros(len(mesh.faces), bool) if mesh.one_sided is None else np.asarray(mesh.one_sided, bool)
    ids = np.zeros(len(mesh.faces), np.int32) if mesh.instance_ids is None else np.asarray(mesh.instance_ids)
    parts = [(V1_SET, ~one_sided, "two"), (f"{V1_SET}_one_sided", one_sided, "one")]
    return [
        SceneObject(name, Mesh(mesh.positions, mesh.faces[keep], mesh.uvs, ids[keep]), V1_SET, emission_sides=sides)
        for name, keep, sides in parts
        if keep.any()
    ]


def _with_maps(scene: Scene, **changed) -> Scene:
    """The same scene (mesh, objects, packing, cameras shared) with some maps replaced."""
    maps = Maps(**{m: changed.get(m, getattr(scene.maps, m)) for m in (*ATLAS_MAPS, "kg")})
    return replace(scene, maps=maps, cameras=list(scene.cameras), objects=list(scene.objects))


def _region(scene: Scene, region, field: str = "region") -> np.ndarray:
    """An (H, W) bool mask over the packed atlas; None is every texel."""
    shape = scene.maps.atlas_shape
    if region is None:
        return np.ones(shape, bool)
    mask = np.asarray(region)
    if mask.shape != tuple(shape) or mask.dtype != bool:
        raise SceneError(
            WHERE, field, f"a bool mask of the atlas's shape {tuple(shape)}, got {mask.dtype} {mask.shape}"
        )
    return mask


def scale_emission(scene: Scene, factor, region=None) -> Scene:
    """Relight: ke *= factor (a number >= 0, or an RGB triple) on `region` (all texels if None)."""
    scale = np.asarray(factor, np.float32)
    if scale.shape not in {(), (3,)} or not np.all(np.isfinite(scale)) or np.any(scale < 0):
        raise SceneError(WHERE, "emission_scale", f"a finite number >= 0 or an RGB triple of them, got {factor!r}")
    mask = _region(scene, region)
    ke = scene.maps.ke.copy()
    ke[mask] *= scale
    return _with_maps(scene, ke=ke)


def set_sky(scene: Scene, kg) -> Scene:
    """A new outdoor radiance kg: a number or an RGB triple (a uniform sky at the scene's cube-map
    size), or a (6, N, N, 3) cube map of any N."""
    array = np.asarray(kg, np.float32)
    if array.ndim == 4:
        from .cubemap import kg_to_stacked

        if array.shape[0] != 6 or array.shape[1] != array.shape[2] or array.shape[3] != 3:
            raise SceneError(WHERE, "sky", f"a (6, N, N, 3) cube map, got {array.shape}")
        return _with_maps(scene, kg=validate_kg(kg_to_stacked(array), WHERE, "sky"))
    if array.shape not in {(), (3,)}:
        raise SceneError(WHERE, "sky", f"a number, an RGB triple or a (6, N, N, 3) cube map, got shape {array.shape}")
    full = np.broadcast_to(array, scene.maps.kg.shape).copy()
    _check_map("kg", full.reshape(-1, full.shape[2], 3), WHERE, "sky")
    return _with_maps(scene, kg=full)


def edit_material(scene: Scene, region_mask, values: dict) -> Scene:
    """Set maps (kd, ks, ka, ke, kw: numbers, or RGB triples for kd, ks, ke) on the texels of
    `region_mask`; the values are checked against the maps' ranges."""
    unknown = sorted(set(values) - set(ATLAS_MAPS))
    if unknown or not values:
        raise SceneError(WHERE, "values", f"some of the maps {list(ATLAS_MAPS)}, got {sorted(values)}")
    mask = _region(scene, region_mask)
    changed = {}
    for name, value in values.items():
        array = getattr(scene.maps, name).copy()
        array[mask] = _material_value(name, value, (1, 1), f"values.{name}")[0, 0]
        changed[name] = array
    return _with_maps(scene, **changed)


def emitter_regions(scene: Scene, threshold: float = 0.0) -> tuple[np.ndarray, int]:
    """(labels, count): the scene's lamps as regions of atlas texels whose largest ke channel is
    above `threshold`, labelled 1..count in raster order of their first texel (row by row from
    the top); 0 is a texel that does not emit (or that no face reads).

    A region is a connected piece of emitting *surface*: the faces that read an emitting texel
    (scene/regions.face_texels, the rule the exports use), joined when they share a vertex
    position, and the texels they read. Connectivity in the atlas alone would not do: an
    unwrapper packs the charts of two lamps side by side and the dilated borders join them, while
    one lamp cut into several charts is one lamp. Emitting texels no face reads (a chart's dilated
    border, a packed set's padding) join the region of an emitting neighbour in their own set."""
    mesh, shape = scene.mesh, scene.maps.atlas_shape
    emitting = scene.maps.ke.max(-1) > threshold
    face_ids, texel_ids = face_texels(mesh.uvs, mesh.faces, shape)
    keep = emitting.ravel()[texel_ids]
    face_ids, texel_ids = face_ids[keep], texel_ids[keep]
    component = _surface_components(mesh, np.unique(face_ids))
    labels = np.full(emitting.size, -1, np.int64)
    np.maximum.at(labels, texel_ids, component[face_ids])  # a texel two lamps share: the later one
    labels = labels.reshape(shape)
    for rows, cols in _set_blocks(scene):
        labels[rows, cols] = _grow_labels(labels[rows, cols], emitting[rows, cols])
    # 1..count by first texel in raster order
    flat = labels.ravel()
    present, first = np.unique(flat, return_index=True)
    present, first = present[present >= 0], first[present >= 0]
    order = np.zeros(int(flat.max()) + 2, np.int32)
    order[present[np.argsort(first)] + 1] = np.arange(1, len(present) + 1, dtype=np.int32)
    return order[labels + 1], len(present)


def region_surfaces(scene: Scene, labels: np.ndarray, count: int) -> tuple[np.ndarray, np.ndarray]:
    """(areas (count,) in m^2, centroids (count, 3) in meters, NaN for a region no face reads) of
    the surface under each region of `labels` (from `emitter_regions`): every face that reads a
    texel of region i, once, weighted by its area. Independent of the atlas's resolution, so two
    atlases of one room place their lamps alike."""
    mesh = scene.mesh
    face_ids, texel_ids = face_texels(mesh.uvs, mesh.faces, labels.shape)
    region = np.asarray(labels).ravel()[texel_ids]
    pairs = np.unique(np.stack([face_ids, region], 1)[region > 0], axis=0)  # (face, region) once each
    tri = np.asarray(mesh.positions, np.float64)[np.asarray(mesh.faces)[pairs[:, 0]]]
    area = 0.5 * np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1)
    areas = np.bincount(pairs[:, 1], area, count + 1)[1:]
    sums = np.stack([np.bincount(pairs[:, 1], area * tri[:, :, a].mean(1), count + 1)[1:] for a in range(3)], 1)
    with np.errstate(invalid="ignore", divide="ignore"):
        return areas, np.where(areas[:, None] > 0, sums / areas[:, None], np.nan)


def _surface_components(mesh: Mesh, faces: np.ndarray) -> np.ndarray:
    """(F,) the connected component of each of `faces` (-1 elsewhere): faces are joined by a
    vertex position they share (a UV seam's two vertices are one point)."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    out = np.full(len(mesh.faces), -1, np.int64)
    if not len(faces):
        return out
    _, welded = np.unique(np.asarray(mesh.positions), axis=0, return_inverse=True)
    corners = welded.ravel()[np.asarray(mesh.faces)[faces]].ravel()
    n, v = len(faces), int(welded.max()) + 1
    rows = np.repeat(np.arange(n), 3)  # face node i -- vertex node n + corner: faces meet at vertices
    graph = coo_matrix((np.ones(3 * n), (rows, n + corners)), shape=(n + v, n + v))
    _, component = connected_components(graph, directed=False)
    out[faces] = component[:n]
    return out


def _grow_labels(labels: np.ndarray, emitting: np.ndarray) -> np.ndarray:
    """Give unlabelled (-1) emitting texels the label of a labelled 8-neighbour, pass after pass
    through emitting texels only, until none is left or none changes."""
    labels = labels.copy()
    h, w = labels.shape
    while True:
        todo = emitting & (labels < 0)
        if not todo.any():
            return labels
        padded = np.pad(labels, 1, constant_values=-1)
        grown = labels.copy()
        for dr in (-1, 0, 1):
            for dc in (-1, 0, 1):
                neighbour = padded[1 + dr : 1 + dr + h, 1 + dc : 1 + dc + w]
                take = todo & (grown < 0) & (neighbour >= 0)
                grown[take] = neighbour[take]
        if np.array_equal(grown, labels):
            return labels
        labels = grown


def _set_blocks(scene: Scene) -> list[tuple[slice, slice]]:
    """Each material set's texels and padding in the packed atlas (the whole atlas for v1)."""
    if not scene.objects:
        return [(slice(None), slice(None))]
    p = scene.packing.padding
    return [
        (slice(r.row - p, r.row + r.height + p), slice(r.col - p, r.col + r.width + p))
        for r in scene.packing.rects.values()
    ]
