"""A room scene directory (mode `room`): the room stages' outputs assembled by
scene/room_scene.assemble_room and written as a version-2 scene seen by the photo's camera.

    room_box/room.json              the box and the photo's camera (required)
    room_lights/lights.json         the area lights, the lamps (optional: no lights without it;
                                    room_materials/lights.json, its refitted radiances, wins)
    room_objects/objects.json       {"objects": [{name, asset, segment, T_obj2world, ...}],
                                     "asset_dirs": [...]} (optional: an empty room without it)
    room_materials/materials.json   {"materials": {name: constants | {"atlas": "file.npz"}},
                                     "kg": "file.npy"} (optional: grey defaults without it)

A material entry is named as assemble_room looks it up (a set: ``floor``, ``ceiling``,
``wall_px``, ``wall``, an object's name; a part: ``{object}.{part}``): constants
{"kd", "ks", "ka", "ke", "kw"}, or ``atlas``: an .npz beside materials.json with arrays kd, ks,
ka, ke, kw of that set's own shape. ``kg``: a (6, N, N, 3) .npy sky (default black: the lights
stand for the windows). The capture's panoptic.json names each object's class (a lamp's).
"""

from __future__ import annotations

import logging
from pathlib import Path

import numpy as np

from ..assets.library import library
from ..scene.atomic import check_output
from ..scene.format import write_scene
from ..scene.room_photo import load_room_photo
from ..scene.room_scene import assemble_room, read_json
from ..scene.types import ATLAS_MAPS, Atlas, SceneError

__all__ = ["run", "read_materials"]

log = logging.getLogger(__name__)


def read_materials(materials_dir) -> tuple[dict, np.ndarray | None]:
    """room_materials/materials.json (module docstring) -> (assemble_room's materials, kg)."""
    path = Path(materials_dir) / "materials.json"
    doc = read_json(path, "the room_materials stage's materials.json")
    out = {}
    for name, entry in (doc.get("materials") or {}).items():
        if isinstance(entry, dict) and "atlas" in entry:
            file = path.parent / entry["atlas"]
            try:
                with np.load(file) as data:
                    out[name] = Atlas(**{m: np.asarray(data[m], np.float32) for m in ATLAS_MAPS})
            except (FileNotFoundError, KeyError) as error:
                raise SceneError(file, f"materials[{name!r}].atlas", f"an .npz with {', '.join(ATLAS_MAPS)} ({error})")
        else:
            out[name] = entry
    kg = None
    if doc.get("kg"):
        kg = np.load(path.parent / doc["kg"])
    return out, kg


def run(
    room_dir,
    out_dir,
    lights_dir=None,
    objects_dir=None,
    materials_dir=None,
    capture_dir=None,
    asset_dirs=(),
    capture_files: dict | None = None,
    texels_per_meter: float = 64.0,
) -> dict:
    """Write the room scene directory ``out_dir``; returns scene.json's metadata."""
    check_output(out_dir, "scene")
    room_json = Path(room_dir) / "room.json"
    room = read_json(room_json, "the room_box stage's room.json")
    # room_materials refits the lights' radiances with the materials (Eq. 4) and writes them
    # beside its materials.json: those, when there, are the scene's lights
    fitted = Path(materials_dir) / "lights.json" if materials_dir is not None else None
    if fitted is not None and fitted.is_file():
        lights_dir = fitted.parent
    lights = read_json(Path(lights_dir) / "lights.json", "the room_lights stage's lights.json") if lights_dir else {}
    objects, dirs = [], list(asset_dirs)
    if objects_dir is not None:
        doc = read_json(Path(objects_dir) / "objects.json", "the room_objects stage's objects.json")
        objects = doc["objects"] if isinstance(doc, dict) else doc
        # user model folders the object stage retrieved from (top level, or its settings)
        listed = (
            (doc.get("asset_dirs") or (doc.get("settings") or {}).get("asset_dirs") or [])
            if isinstance(doc, dict)
            else []
        )
        dirs += [d for d in listed if d not in dirs]
    materials, kg = read_materials(materials_dir) if materials_dir is not None else ({}, None)
    labels = None
    if capture_dir is not None:
        labels = load_room_photo(capture_dir, **(capture_files or {})).labels
    scene = assemble_room(
        room,
        objects,
        lights,
        materials,
        library(dirs),
        labels=labels,
        kg=kg,
        texels_per_meter=texels_per_meter,
        where=str(room_json),
    )
    metadata = {
        "recovered_by": "invrender room_box + "
        + "".join(
            f"{n} + "
            for n, d in (("room_objects", objects_dir), ("room_lights", lights_dir), ("room_materials", materials_dir))
            if d
        )
        + "bake",
        "room": str(room_json),
        "objects": str(Path(objects_dir) / "objects.json") if objects_dir else None,
        "lights": str(Path(lights_dir) / "lights.json") if lights_dir else None,
        "materials": str(Path(materials_dir) / "materials.json") if materials_dir else "grey defaults",
        "capture": str(capture_dir) if capture_dir else None,
        "asset_dirs": [str(d) for d in dirs],
        **scene.metadata,
    }
    write_scene(out_dir, scene, metadata)
    counts = {k: sum(1 for i in scene.metadata["instances"] if i["kind"] == k) for k in ("box", "object", "light")}
    log.info(
        "bake: room box, %d objects, %d lights (%s) -> %s",
        counts["object"],
        counts["light"],
        metadata["materials"],
        out_dir,
    )
    return metadata
