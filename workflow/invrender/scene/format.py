"""The scene directory: ``scene.json`` beside the mesh, the parameter maps and the cameras.

    scene/
      scene.json        {"format": "invrender-scene", "version": 1, "units": "meters", "up": "+Y",
                         "mesh": "mesh.ply", "maps": {"kd": "maps/kd.exr", ...}, "cameras": "cameras",
                         "metadata": {...}}
      mesh.ply          vertex x,y,z,s,t; face vertex_indices, instance_id
      maps/kd.exr ...   kd, ks, ke RGB; ka, kw one channel (Y); all H x W
      maps/kg.exr       cube map (6 N, N, 3): faces +X, -X, +Y, -Y, +Z, -Z top to bottom
      cameras/          COLMAP text model (optional: a scene may have no cameras)

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
from .cameras import _check_camera, read_cameras, write_colmap
from .images import read_image, write_exr
from .mesh_io import read_mesh, validate_mesh, write_ply
from .types import ATLAS_MAPS, MAP_CHANNELS, MAP_NAMES, Maps, Scene, SceneError

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
DEFAULT_FILES = {"mesh": "mesh.ply", "maps": {name: f"maps/{name}.exr" for name in MAP_NAMES}, "cameras": "cameras"}


# ---------------------------------------------------------------------------- kg layout


def kg_to_stacked(kg: np.ndarray) -> np.ndarray:
    """(6, N, N, 3) cube map -> (6 N, N, 3), faces +X, -X, +Y, -Y, +Z, -Z top to bottom."""
    kg = np.asarray(kg)
    return kg.reshape(6 * kg.shape[1], kg.shape[2], kg.shape[3])


def kg_from_stacked(stacked: np.ndarray) -> np.ndarray:
    """(6 N, N, 3) -> (6, N, N, 3)."""
    n = stacked.shape[1]
    return np.ascontiguousarray(stacked).reshape(6, n, n, stacked.shape[2])


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


def _check_map(name: str, data: np.ndarray, file) -> np.ndarray:
    """Channel count, finiteness and range of one map in its on-disk layout (H, W[, 3])."""
    field = f"maps.{name}"
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


def validate_maps(maps: dict, files: dict) -> Maps:
    """Check maps given in their on-disk layout (kg stacked (6 N, N, 3)); return ``Maps``.

    ``files[name]`` is the file named in the errors for that map.
    """
    checked = {name: _check_map(name, maps[name], files[name]) for name in MAP_NAMES}
    ref = checked["kd"].shape[:2]
    for name in ATLAS_MAPS:
        shape = checked[name].shape[:2]
        if shape != ref:
            raise SceneError(
                files[name], f"maps.{name}",
                f"the size of maps.kd (map size mismatch: {name} is {shape[0]}x{shape[1]}, kd is {ref[0]}x{ref[1]}, H x W)",
            )
    h, w = checked["kg"].shape[:2]
    if h != 6 * w:
        raise SceneError(
            files["kg"], "maps.kg",
            f"a cube map of 6 N x N texels (faces +X, -X, +Y, -Y, +Z, -Z stacked vertically), got {h}x{w}",
        )
    return Maps(
        kd=checked["kd"], ks=checked["ks"], ka=checked["ka"], ke=checked["ke"], kw=checked["kw"],
        kg=kg_from_stacked(checked["kg"]),
    )


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


def load_scene(directory) -> Scene:
    """Read and validate a scene directory. Raises ``SceneError`` on the first problem."""
    directory = Path(directory)
    doc = read_scene_json(directory)
    file = directory / SCENE_JSON

    # Every referenced file must exist before any is read.
    refs = {"mesh": doc["mesh"], **{f"maps.{k}": v for k, v in doc["maps"].items()}}
    if "cameras" in doc:
        refs["cameras"] = doc["cameras"]
    for field, rel in refs.items():
        target = directory / rel
        if field == "cameras":
            ok = target.exists()
        else:
            ok = target.is_file()
        if not ok:
            raise SceneError(file, field, f"an existing {'path' if field == 'cameras' else 'file'}: {target} does not exist")

    mesh = read_mesh(directory / doc["mesh"], require_uvs=True)
    map_files = {name: directory / doc["maps"][name] for name in MAP_NAMES}
    maps = validate_maps({name: read_image(path) for name, path in map_files.items()}, map_files)
    cameras = read_cameras(directory / doc["cameras"]) if "cameras" in doc else []
    return Scene(mesh=mesh, maps=maps, cameras=cameras, path=directory)


def write_scene(directory, scene: Scene, metadata: dict | None = None) -> None:
    """Validate ``scene`` and write it as a scene directory, atomically.

    The directory is built beside the target and renamed into place, so an existing scene
    is replaced whole and a failure leaves no partial directory. ``metadata`` (JSON-serialisable)
    goes to scene.json's ``metadata``. Cameras are written only if the scene has some.
    """
    directory = Path(directory)
    files = {"mesh": directory / DEFAULT_FILES["mesh"]}
    files.update({name: directory / rel for name, rel in DEFAULT_FILES["maps"].items()})

    validate_mesh(scene.mesh, files["mesh"], require_uvs=True)
    disk_maps = _maps_on_disk_layout(scene.maps, files["kg"])
    validate_maps(disk_maps, files)
    for cam in scene.cameras:
        _check_camera(cam, directory / DEFAULT_FILES["cameras"])

    doc = {
        "format": FORMAT,
        "version": VERSION,
        "units": "meters",
        "up": "+Y",
        "mesh": DEFAULT_FILES["mesh"],
        "maps": dict(DEFAULT_FILES["maps"]),
    }
    if scene.cameras:
        doc["cameras"] = DEFAULT_FILES["cameras"]
    if metadata is not None:
        doc["metadata"] = metadata
    validate_scene_json(doc, directory / SCENE_JSON)
    text = json.dumps(doc, indent=2, allow_nan=False) + "\n"  # fails here, before anything is written

    with atomic_dir(directory) as tmp:
        write_ply(tmp / DEFAULT_FILES["mesh"], scene.mesh)
        for name in MAP_NAMES:
            write_exr(tmp / DEFAULT_FILES["maps"][name], disk_maps[name])
        if scene.cameras:
            write_colmap(tmp / DEFAULT_FILES["cameras"], scene.cameras)
        (tmp / SCENE_JSON).write_text(text, encoding="utf-8")
