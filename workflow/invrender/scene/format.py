"""The scene directory: ``scene.json`` beside the meshes, the parameter maps and the cameras.

Version 1, one mesh and one atlas:

    scene/
      scene.json        {"format": "invrender-scene", "version": 1, "units": "meters", "up": "+Y",
                         "mesh": "mesh.ply", "maps": {"kd": "maps/kd.exr", ...}, "cameras": "cameras",
                         "metadata": {...}}
      mesh.ply          vertex x,y,z,s,t; face vertex_indices, instance_id
      maps/kd.exr ...   kd, ks, ke RGB; ka, kw one channel (Y); all H x W
      maps/kg.exr       cube map (6 N, N, 3): faces +X, -X, +Y, -Y, +Z, -Z top to bottom
      cameras/          COLMAP text model (optional: a scene may have no cameras)

Version 2, objects (a mesh in its own frame, a 4x4 transform, a material set) and material sets
(each an atlas of its own size); objects naming one mesh file and one set are instances:

    scene/
      scene.json        {..., "version": 2, "objects": [{"name", "mesh", "transform", "material",
                         "instance_id", "emission_sides"}, ...], "materials": {name: {"kd": ..., ...}},
                         "kg": "maps/kg.exr", "cameras": "cameras"}
      meshes/<object>.ply            one per distinct mesh
      materials/<set>/kd.exr ...     kd, ks, ka, ke, kw of each set
      maps/kg.exr

A v2 scene loads packed (scene/packing.py): ``Scene.mesh`` and ``Scene.maps`` are the one
world-space mesh and packed atlas the renderer reads, as for v1. docs/scene-format.md describes
every field.

``load_scene`` validates everything before returning and raises one ``SceneError`` naming the
file, the field and what was expected. ``write_scene`` validates the in-memory scene with the
same checks, then writes the whole directory atomically (replacing any previous one whole).
The schema is ``workflow/schemas/scene.schema.json``.
"""

from __future__ import annotations

import functools
import json
from pathlib import Path

import numpy as np

from .atomic import atomic_dir
from .cameras import check_camera, read_cameras, write_colmap
from .cubemap import kg_from_stacked, kg_to_stacked
from .images import read_image, write_exr
from .mesh_io import read_mesh, validate_mesh, write_ply
from .packing import check_transform, pack_scene, validate_objects
from .types import ATLAS_MAPS, MAP_CHANNELS, MAP_NAMES, Atlas, Maps, Scene, SceneError, SceneObject

__all__ = [
    "FORMAT",
    "VERSION",
    "SCHEMA_PATH",
    "MAP_NAMES",
    "MAP_RANGES",
    "load_scene",
    "read_scene_json",
    "write_scene",
    "validate_maps",
    "validate_atlas",
    "validate_kg",
    "check_transform",
    "kg_to_stacked",
    "kg_from_stacked",
]

FORMAT = "invrender-scene"
VERSION = 1
SCENE_JSON = "scene.json"
SCHEMA_PATH = Path(__file__).resolve().parents[2] / "schemas" / "scene.schema.json"
CHANNELS = {**MAP_CHANNELS, "kg": 3}
CHANNEL_NAMES = {1: "Y", 3: "R,G,B"}
# (low, low inclusive, high, high inclusive) per map: MILO Eq. 2-3.
MAP_RANGES = {
    "kd": (0.0, True, 1.0, True),
    "ks": (0.0, True, 1.0, True),
    "ka": (0.0, False, 1.0, True),
    "ke": (0.0, True, np.inf, False),
    "kw": (0.0, True, 1.0, True),
    "kg": (0.0, True, np.inf, False),
}
V2_KG = "maps/kg.exr"
DEFAULT_FILES = {"mesh": "mesh.ply", "maps": {name: f"maps/{name}.exr" for name in MAP_NAMES}, "cameras": "cameras"}


# ---------------------------------------------------------------------------- scene.json


@functools.lru_cache(maxsize=1)
def _validator():
    import jsonschema

    schema = json.loads(SCHEMA_PATH.read_text(encoding="utf-8"))
    cls = jsonschema.validators.validator_for(schema)
    cls.check_schema(schema)
    return cls(schema)


def _json_path(parts) -> str:
    out = ""
    for p in parts:
        out += f"[{p}]" if isinstance(p, int) else (f".{p}" if out else str(p))
    return out


def _short(value) -> str:
    text = json.dumps(value)
    return text if len(text) <= 60 else text[:57] + "..."


def _schema_error(file: Path, error) -> SceneError:
    """Turn one jsonschema ValidationError into a SceneError naming the JSON path of the field."""
    parts = list(error.absolute_path)
    kind = error.validator
    if kind == "required":
        missing = [k for k in error.validator_value if k not in error.instance]
        field = _json_path(parts + missing[:1])
        return SceneError(file, field, "this required field (it is missing)")
    if kind == "additionalProperties":
        known = sorted(error.schema.get("properties", {}))
        extra = sorted(k for k in error.instance if k not in known)
        field = _json_path(parts + extra[:1])
        return SceneError(file, field, f"no such field: allowed fields are {', '.join(known)}")
    field = _json_path(parts) or "(document)"
    if kind == "const":
        return SceneError(file, field, f"{_short(error.validator_value)}, got {_short(error.instance)}")
    if kind == "enum":
        options = ", ".join(_short(v) for v in error.validator_value)
        return SceneError(file, field, f"one of {options}, got {_short(error.instance)}")
    if kind == "type":
        return SceneError(file, field, f"a JSON {error.validator_value}, got {_short(error.instance)}")
    if kind in ("pattern", "minLength") and error.schema == _validator().schema["$defs"]["relative_path"]:
        return SceneError(
            file, field, f"a relative path inside the scene directory (no '..'), got {_short(error.instance)}"
        )
    return SceneError(file, field, error.message)


def validate_scene_json(doc, file) -> None:
    """Check a scene.json document against the schema; raise the most relevant error."""
    from jsonschema.exceptions import best_match

    error = best_match(_validator().iter_errors(doc))
    if error is not None:
        raise _schema_error(Path(file), error)


def read_scene_json(directory) -> dict:
    """Read and schema-check ``directory/scene.json`` (e.g. to get its metadata)."""
    directory = Path(directory)
    file = directory / SCENE_JSON
    if not directory.is_dir():
        raise SceneError(directory, "(directory)", "an existing scene directory")
    if not file.is_file():
        raise SceneError(file, "(file)", "a scene.json file in the scene directory")
    try:
        doc = json.loads(file.read_text(encoding="utf-8"))
    except json.JSONDecodeError as exc:
        raise SceneError(file, "(document)", f"valid JSON ({exc})") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise SceneError(file, "(file)", f"a readable UTF-8 file ({exc})") from None
    validate_scene_json(doc, file)
    return doc


# ---------------------------------------------------------------------------- map checks


def _texel(index: tuple, channels: int) -> str:
    row, col = int(index[0]), int(index[1])
    text = f"texel (row {row}, col {col}"
    if channels > 1 and len(index) > 2:
        text += f", channel {'RGB'[int(index[2])]}"
    return text + ")"


def _check_map(name: str, data: np.ndarray, file, field: str | None = None) -> np.ndarray:
    """Channel count, finiteness and range of one map in its on-disk layout (H, W[, 3])."""
    field = field or f"maps.{name}"
    want = CHANNELS[name]
    a = np.asarray(data)
    if a.ndim == 3 and a.shape[2] == 1 and want == 1:
        a = a[:, :, 0]
    got = 1 if a.ndim == 2 else (a.shape[2] if a.ndim == 3 else None)
    if got != want:
        desc = f"shape {a.shape}" if got is None else f"{got} channel(s)"
        raise SceneError(file, field, f"{want} channel(s) ({CHANNEL_NAMES[want]}), got {desc}")
    if a.shape[0] == 0 or a.shape[1] == 0:
        raise SceneError(file, field, f"a non-empty image, got {a.shape[0]}x{a.shape[1]}")
    a = a.astype(np.float32, copy=False)
    bad = ~np.isfinite(a)
    if bad.any():
        idx = tuple(np.argwhere(bad)[0])
        raise SceneError(file, field, f"finite values, {_texel(idx, want)} is {a[idx]} ({int(bad.sum())} bad values)")
    lo, lo_inc, hi, hi_inc = MAP_RANGES[name]
    bad = (a < lo if lo_inc else a <= lo) | (a > hi if hi_inc else a >= hi)
    if bad.any():
        idx = tuple(np.argwhere(bad)[0])
        interval = f"{'[' if lo_inc else '('}{lo:g}, {hi:g}{']' if hi_inc else ')'}"
        raise SceneError(
            file, field, f"values in {interval}, {_texel(idx, want)} is {a[idx]:g} ({int(bad.sum())} out of range)"
        )
    return a


def validate_atlas(maps: dict, files: dict, prefix: str = "maps") -> Atlas:
    """Check the five atlas maps (each map's channels, values and the common size); return them.
    ``files[name]`` is the file named in the errors, ``prefix`` the JSON field above the maps."""
    checked = {name: _check_map(name, maps[name], files[name], f"{prefix}.{name}") for name in ATLAS_MAPS}
    ref = checked["kd"].shape[:2]
    for name in ATLAS_MAPS:
        shape = checked[name].shape[:2]
        if shape != ref:
            raise SceneError(
                files[name],
                f"{prefix}.{name}",
                f"the size of {prefix}.kd (map size mismatch: {name} is {shape[0]}x{shape[1]}, "
                f"kd is {ref[0]}x{ref[1]}, H x W)",
            )
    return Atlas(**checked)


def validate_kg(stacked: np.ndarray, file, field: str = "maps.kg") -> np.ndarray:
    """Check a cube map in its on-disk layout (6 N, N, 3); return it as (6, N, N, 3)."""
    checked = _check_map("kg", stacked, file, field)
    h, w = checked.shape[:2]
    if h != 6 * w:
        raise SceneError(
            file,
            field,
            f"a cube map of 6 N x N texels (faces +X, -X, +Y, -Y, +Z, -Z stacked vertically), got {h}x{w}",
        )
    return kg_from_stacked(checked)


def validate_maps(maps: dict, files: dict) -> Maps:
    """Check maps given in their on-disk layout (kg stacked (6 N, N, 3)); return ``Maps``.

    ``files[name]`` is the file named in the errors for that map.
    """
    atlas = validate_atlas(maps, files)
    return Maps(**{name: getattr(atlas, name) for name in ATLAS_MAPS}, kg=validate_kg(maps["kg"], files["kg"]))


def _maps_on_disk_layout(maps: Maps, kg_file) -> dict:
    """In-memory maps -> on-disk layout: kg (6, N, N, 3) stacked to (6 N, N, 3)."""
    out = {name: getattr(maps, name) for name in ATLAS_MAPS}
    kg = np.asarray(maps.kg)
    if kg.ndim == 4 and kg.shape[0] == 6 and kg.shape[1] == kg.shape[2]:
        out["kg"] = kg_to_stacked(kg)
    elif kg.ndim == 3:  # already stacked: validate_maps checks the 6 N x N shape
        out["kg"] = kg
    else:
        raise SceneError(kg_file, "maps.kg", f"a cube map of shape (6, N, N, 3), got {kg.shape}")
    return out


# ---------------------------------------------------------------------------- load / write


def _check_refs(directory: Path, file: Path, refs: dict) -> None:
    """Every referenced file (the cameras: path) exists, before any is read."""
    for field, rel in refs.items():
        target = directory / rel
        ok = target.exists() if field == "cameras" else target.is_file()
        if not ok:
            raise SceneError(
                file, field, f"an existing {'path' if field == 'cameras' else 'file'}: {target} does not exist"
            )


def load_scene(directory) -> Scene:
    """Read and validate a scene directory (version 1 or 2). Raises ``SceneError`` on the first problem."""
    directory = Path(directory)
    doc = read_scene_json(directory)
    if doc["version"] == 2:
        return _load_v2(directory, doc)
    file = directory / SCENE_JSON
    refs = {"mesh": doc["mesh"], **{f"maps.{k}": v for k, v in doc["maps"].items()}}
    if "cameras" in doc:
        refs["cameras"] = doc["cameras"]
    _check_refs(directory, file, refs)

    mesh = read_mesh(directory / doc["mesh"], require_uvs=True)
    map_files = {name: directory / doc["maps"][name] for name in MAP_NAMES}
    # finite=False: _check_map refuses non-finite texels itself, naming the map's field
    maps = validate_maps({name: read_image(path, finite=False) for name, path in map_files.items()}, map_files)
    cameras = read_cameras(directory / doc["cameras"]) if "cameras" in doc else []
    return Scene(mesh=mesh, maps=maps, cameras=cameras, path=directory)


def _load_v2(directory: Path, doc: dict) -> Scene:
    file = directory / SCENE_JSON
    refs = {f"objects[{k}].mesh": entry["mesh"] for k, entry in enumerate(doc["objects"])}
    for name, files in doc["materials"].items():
        refs.update({f"materials.{name}.{m}": rel for m, rel in files.items()})
    refs["kg"] = doc["kg"]
    if "cameras" in doc:
        refs["cameras"] = doc["cameras"]
    _check_refs(directory, file, refs)

    meshes = {}  # one Mesh per file: objects naming the same file are instances of one mesh
    for rel in dict.fromkeys(entry["mesh"] for entry in doc["objects"]):
        meshes[rel] = read_mesh(directory / rel, require_uvs=True)
    materials = {}
    for name, rels in doc["materials"].items():
        files = {m: directory / rel for m, rel in rels.items()}
        materials[name] = validate_atlas(
            {m: read_image(path, finite=False) for m, path in files.items()}, files, f"materials.{name}"
        )
    objects = [
        SceneObject(
            name=entry["name"],
            mesh=meshes[entry["mesh"]],
            material=entry["material"],
            transform=check_transform(entry.get("transform", np.eye(4).tolist()), file, f"objects[{k}].transform"),
            instance_id=entry.get("instance_id"),
            emission_sides=entry.get("emission_sides", "two"),
        )
        for k, entry in enumerate(doc["objects"])
    ]
    validate_objects(objects, materials, file)
    kg = validate_kg(read_image(directory / doc["kg"], finite=False), directory / doc["kg"], "kg")
    cameras = read_cameras(directory / doc["cameras"]) if "cameras" in doc else []
    return pack_scene(objects, materials, kg, cameras, path=directory)


def write_scene(directory, scene: Scene, metadata: dict | None = None) -> None:
    """Validate ``scene`` and write it as a scene directory, atomically: version 2 if it has
    objects (its material sets unpacked from ``scene.maps``: what is rendered is what is
    written), else version 1.

    The directory is built beside the target and renamed into place, so an existing scene
    is replaced whole and a failure leaves no partial directory. ``metadata`` (JSON-serialisable)
    goes to scene.json's ``metadata``. Cameras are written only if the scene has some.
    """
    directory = Path(directory)
    if scene.objects:
        return _write_v2(directory, scene, metadata)
    files = {"mesh": directory / DEFAULT_FILES["mesh"]}
    files.update({name: directory / rel for name, rel in DEFAULT_FILES["maps"].items()})

    validate_mesh(scene.mesh, files["mesh"], require_uvs=True)
    disk_maps = _maps_on_disk_layout(scene.maps, files["kg"])
    validate_maps(disk_maps, files)
    for cam in scene.cameras:
        check_camera(cam, directory / DEFAULT_FILES["cameras"])

    doc = {
        "format": FORMAT,
        "version": VERSION,
        "units": "meters",
        "up": "+Y",
        "mesh": DEFAULT_FILES["mesh"],
        "maps": dict(DEFAULT_FILES["maps"]),
    }
    _write_dir(
        directory,
        scene,
        doc,
        metadata,
        {DEFAULT_FILES["mesh"]: scene.mesh},
        {DEFAULT_FILES["maps"][name]: disk_maps[name] for name in MAP_NAMES},
    )


def _write_dir(directory: Path, scene: Scene, doc: dict, metadata, meshes: dict, images: dict) -> None:
    """Finish scene.json (cameras, metadata), check it, then write every file atomically."""
    if scene.cameras:
        doc["cameras"] = DEFAULT_FILES["cameras"]
    if metadata is not None:
        doc["metadata"] = metadata
    validate_scene_json(doc, directory / SCENE_JSON)
    text = json.dumps(doc, indent=2, allow_nan=False) + "\n"  # fails here, before anything is written

    with atomic_dir(directory, kind="scene") as tmp:
        for rel, mesh in meshes.items():
            write_ply(tmp / rel, mesh)
        for rel, image in images.items():
            write_exr(tmp / rel, image)
        if scene.cameras:
            write_colmap(tmp / DEFAULT_FILES["cameras"], scene.cameras)
        (tmp / SCENE_JSON).write_text(text, encoding="utf-8")


def _write_v2(directory: Path, scene: Scene, metadata) -> None:
    file = directory / SCENE_JSON
    materials = scene.packing.unpack_atlas(scene.maps)
    validate_objects(scene.objects, materials, file)
    images, mesh_files, entries = {}, {}, []
    for name, atlas in materials.items():
        rels = {m: f"materials/{name}/{m}.exr" for m in ATLAS_MAPS}
        validate_atlas(
            {m: getattr(atlas, m) for m in ATLAS_MAPS}, {m: directory / r for m, r in rels.items()}, f"materials.{name}"
        )
        images.update({rels[m]: getattr(atlas, m) for m in ATLAS_MAPS})
    for obj in scene.objects:
        if id(obj.mesh) not in mesh_files:  # a mesh shared by objects is written once
            mesh_files[id(obj.mesh)] = (f"meshes/{obj.name}.ply", obj.mesh)
            validate_mesh(obj.mesh, directory / mesh_files[id(obj.mesh)][0], require_uvs=True)
        entry = {
            "name": obj.name,
            "mesh": mesh_files[id(obj.mesh)][0],
            "transform": np.asarray(obj.transform, np.float64).tolist(),
            "material": obj.material,
        }
        if obj.instance_id is not None:
            entry["instance_id"] = int(obj.instance_id)
        entries.append({**entry, "emission_sides": obj.emission_sides})
    kg_file = directory / V2_KG
    images[V2_KG] = _maps_on_disk_layout(scene.maps, kg_file)["kg"]
    validate_kg(images[V2_KG], kg_file, "kg")
    for cam in scene.cameras:
        check_camera(cam, directory / DEFAULT_FILES["cameras"])
    doc = {
        "format": FORMAT,
        "version": 2,
        "units": "meters",
        "up": "+Y",
        "objects": entries,
        "materials": {name: {m: f"materials/{name}/{m}.exr" for m in ATLAS_MAPS} for name in materials},
        "kg": V2_KG,
    }
    _write_dir(directory, scene, doc, metadata, dict(mesh_files.values()), images)
