"""Rooms seen in one photograph, with truth: the ground truth for the `room` mode (PSDR-Room).

The shell (walls, floor, ceiling, a window, emitting ceiling panels), its materials and the sky
are ``room.py``'s; here each wall is a segment of its own, and the furniture stands at a yaw
on the floor or on top of another piece. One camera looks at the room at a realistic photo
resolution. The renderer gives the photograph, its depth (camera z) and its panoptic ids (the
instance-id AOV: every face's instance id is its segment's id), so the three agree exactly.

Layouts (``ROOM_PHOTO_LAYOUTS``, config ``layout``) differ in size, window wall, lights,
furniture and camera; any key of the config overrides the layout's. Furniture comes from the
asset library (``assets/``: unit-normalised procedural pieces, front towards +z):

    {"name": "sofa", "asset": "sofa_b", "scale": 2.0 (meters, the largest extent; default the
     asset's nominal size), "position": [x, z] (footprint centre), "yaw_deg": a,
     "on": "floor" | another object's name}

World = R_y(yaw) (scale * unit mesh) + position, R_y(a) = [[cos a, 0, sin a], [0, 1, 0],
[-sin a, 0, cos a]] (counter-clockwise seen from above, +Y up); position's y is its support's
top. A lamp's shade emits and its segment is of class ``lamp``.
"""

from __future__ import annotations

import copy
import json
import logging

import numpy as np

from ..assets.library import library
from ..assets.primitives import Primitive, concatenate
from ..scene.atlas import rasterize_atlas, unwrap
from ..scene.room_photo import fov_y_to_x, yaw_matrix
from ..scene.types import Maps, Mesh, Scene
from .room import (
    ENVIRONMENT_DEFAULTS,
    ROOM_DEFAULTS,
    WALLS,
    Material,
    _checker,
    _room_geometry,
    _wood_grain,
    bake_materials,
    merge_config,
    pinhole_camera,
    sky_cube_map,
)

__all__ = [
    "ROOM_PHOTO_DEFAULTS",
    "ROOM_PHOTO_LAYOUTS",
    "make_room_photo",
    "resolve_config",
    "yaw_matrix",
    "write_room_capture",
]

log = logging.getLogger(__name__)

ROOM_PHOTO_DEFAULTS = {
    "seed": 0,
    "layout": "living",  # a name in ROOM_PHOTO_LAYOUTS: its values replace the defaults below
    "size": [5.0, 2.7, 4.0],  # x, y (height), z extents of the room, meters; floor at y = 0
    "window": {"wall": "-z", "center": [0.3, 1.45], "size": [1.8, 1.2]},  # as room.py's
    "lights": [{"center": [0.0, 0.0], "size": [0.7, 0.7]}],  # ceiling panels, as room.py's
    "light_radiance": 10.0,
    "objects": [],
    "jitter": 0.05,  # seeded shift of every floor-standing object's footprint, meters
    "yaw_jitter_deg": 4.0,  # seeded turn of every object
    "cell": 0.25,
    "atlas_resolution": 512,
    "environment": ENVIRONMENT_DEFAULTS,
    # The photo's camera: eye, the point it looks at, and its vertical field of view.
    "camera": {"width": 1024, "height": 768, "fov_y_deg": 55.0, "eye": [2.0, 1.5, 1.6], "target": [-0.8, 1.0, -1.3]},
}

ROOM_PHOTO_LAYOUTS = {
    "living": {
        "size": [5.0, 2.7, 4.0],
        "window": {"wall": "-z", "center": [0.3, 1.45], "size": [1.8, 1.2]},
        "lights": [{"center": [-0.8, -0.4], "size": [0.7, 0.7]}, {"center": [1.0, 0.6], "size": [0.5, 0.5]}],
        "objects": [
            {"name": "sofa", "asset": "sofa_b", "position": [-1.95, 0.2], "yaw_deg": 90.0},
            {"name": "coffee_table", "asset": "table_a", "scale": 1.1, "position": [-0.6, 0.3], "yaw_deg": 88.0},
            {
                "name": "crate",
                "asset": "box_a",
                "scale": 0.3,
                "position": [-0.6, 0.45],
                "yaw_deg": 20.0,
                "on": "coffee_table",
            },
            {"name": "cabinet", "asset": "cabinet_a", "position": [0.9, -1.65], "yaw_deg": 0.0},
            {"name": "armchair", "asset": "chair_c", "position": [1.0, -0.3], "yaw_deg": 215.0},
            {"name": "floor_lamp", "asset": "lamp_a", "position": [-2.15, -1.6], "yaw_deg": 0.0},
        ],
        "camera": {"eye": [2.0, 1.5, 1.6], "target": [-0.8, 0.9, -1.3], "fov_y_deg": 55.0},
    },
    "bedroom": {
        "size": [3.6, 2.5, 4.2],
        "window": {"wall": "+x", "center": [-0.6, 1.4], "size": [1.2, 1.1]},
        "lights": [{"center": [0.0, -0.3], "size": [0.6, 0.9]}],
        "objects": [
            {"name": "bed", "asset": "bed_b", "position": [-0.85, -0.95], "yaw_deg": 0.0},
            {"name": "nightstand", "asset": "cabinet_c", "scale": 0.5, "position": [0.35, -1.8], "yaw_deg": 0.0},
            {
                "name": "book_box",
                "asset": "box_a",
                "scale": 0.22,
                "position": [0.35, -1.8],
                "yaw_deg": 35.0,
                "on": "nightstand",
            },
            {"name": "desk", "asset": "desk_a", "scale": 1.2, "position": [1.5, 0.9], "yaw_deg": -90.0},
            {"name": "desk_chair", "asset": "chair_a", "position": [0.85, 1.0], "yaw_deg": 100.0},
        ],
        "camera": {"eye": [-1.3, 1.55, 1.8], "target": [0.7, 0.9, -1.0], "fov_y_deg": 62.0},
    },
    "office": {
        "size": [6.0, 3.0, 4.5],
        "window": {"wall": "-x", "center": [-0.5, 1.5], "size": [2.2, 1.4]},
        "lights": [
            {"center": [-1.5, -1.0], "size": [1.2, 0.4]},
            {"center": [1.5, -1.0], "size": [1.2, 0.4]},
            {"center": [-1.5, 1.0], "size": [1.2, 0.4]},
            {"center": [1.5, 1.0], "size": [1.2, 0.4]},
        ],
        "light_radiance": 8.0,
        "objects": [
            {"name": "desk_a", "asset": "desk_b", "position": [-1.3, -1.75], "yaw_deg": 0.0},
            {"name": "chair_a", "asset": "chair_b", "position": [-1.2, -0.95], "yaw_deg": 170.0},
            {"name": "desk_b", "asset": "desk_d", "position": [0.6, -1.6], "yaw_deg": -12.0},
            {"name": "chair_b", "asset": "chair_d", "position": [0.7, -0.95], "yaw_deg": 150.0},
            {"name": "shelf", "asset": "shelf_b", "position": [2.75, 0.6], "yaw_deg": -90.0},
            {
                "name": "printer",
                "asset": "box_a",
                "scale": 0.42,
                "position": [0.5, -1.65],
                "yaw_deg": 10.0,
                "on": "desk_b",
            },
            {"name": "cabinet", "asset": "cabinet_b", "position": [-2.55, 1.2], "yaw_deg": 90.0},
        ],
        "camera": {"eye": [2.2, 1.7, 1.9], "target": [-1.0, 0.6, -1.2], "fov_y_deg": 50.0},
    },
}

SHELL_CLASSES = {"floor": "floor", "ceiling": "ceiling", "window": "window"}
WALL_NAMES = tuple(WALLS)  # "-x", "+x", "-z", "+z"


def resolve_config(config: dict | None = None) -> dict:
    """The defaults, the named layout's values over them, then ``config``'s over those."""
    config = dict(config or {})
    layout = config.get("layout", ROOM_PHOTO_DEFAULTS["layout"])
    if layout not in ROOM_PHOTO_LAYOUTS:
        raise ValueError(f"config.layout: expected one of {sorted(ROOM_PHOTO_LAYOUTS)}, got {layout!r}")
    base = merge_config(ROOM_PHOTO_DEFAULTS, ROOM_PHOTO_LAYOUTS[layout])
    return merge_config(base, config)


# ---------------------------------------------------------------------------- furniture


def _assets(names) -> dict:
    """The library's assets by name, for the names the objects use."""
    found = {asset.name: asset for asset in library()}
    return {name: found[name] for name in names if name in found}


def _footprint(size, yaw_deg, position) -> np.ndarray:
    """The four (x, z) corners of an object's footprint in the world."""
    hx, hz = size[0] / 2, size[2] / 2
    corners = np.array([[-hx, 0, -hz], [hx, 0, -hz], [hx, 0, hz], [-hx, 0, hz]])
    return (corners @ yaw_matrix(yaw_deg).T)[:, [0, 2]] + np.asarray(position)[[0, 2]]


def _place_objects(cfg: dict, rng: np.random.Generator) -> list[dict]:
    """Each object's world placement (position with its support's height, yaw), checked inside
    the room and, for an object on another, inside that one's top."""
    sx, sy, sz = map(float, cfg["size"])
    placed, by_name = [], {}
    assets = _assets({obj.get("asset") for obj in cfg["objects"]})
    for k, obj in enumerate(cfg["objects"]):
        where = f"config.objects[{k}] ({obj.get('name', '?')})"
        if obj.get("asset") not in assets:
            raise ValueError(
                f"{where}.asset: expected an asset of the library (chair_a, table_b, ...), got {obj.get('asset')!r}"
            )
        asset = assets[obj["asset"]]
        scale = float(obj.get("scale", asset.nominal_size))
        if not scale > 0:
            raise ValueError(f"{where}.scale: expected a positive size in meters")
        size = asset.extent * scale
        if obj["name"] in by_name:
            raise ValueError(f"{where}.name: expected each name once")
        support = obj.get("on", "floor")
        # A floor-standing piece is shifted by a seeded amount; a piece on another moves with it.
        shift = rng.uniform(-1, 1, 2) * cfg["jitter"]
        if support != "floor":
            shift = by_name[support]["shift"] if support in by_name else np.zeros(2)
        yaw = float(obj.get("yaw_deg", 0.0)) + rng.uniform(-1, 1) * cfg["yaw_jitter_deg"]
        x, z = np.asarray(obj["position"], np.float64) + shift
        if support == "floor":
            y = 0.0
        elif support in by_name:
            y = by_name[support]["position"][1] + by_name[support]["size"][1]
        else:
            raise ValueError(f"{where}.on: expected 'floor' or the name of an earlier object, got {support!r}")
        position = np.array([x, y, z])
        corners = _footprint(size, yaw, position)
        if np.any(np.abs(corners) > np.array([sx, sz]) / 2 - 0.01):  # the seeded shift never pushes into a wall
            position[[0, 2]] -= shift
            shift = np.zeros(2)
            corners = _footprint(size, yaw, position)
        if np.any(np.abs(corners) > np.array([sx, sz]) / 2 - 0.01) or y + size[1] > sy - 0.05:
            raise ValueError(f"{where}: expected it inside the room (1 cm from the walls, below the ceiling)")
        if support != "floor":
            base = by_name[support]
            local = (corners - base["position"][[0, 2]]) @ yaw_matrix(base["yaw_deg"])[np.ix_([0, 2], [0, 2])]
            if np.any(np.abs(local) > base["size"][[0, 2]] / 2):
                raise ValueError(f"{where}: expected its footprint on top of {support!r}")
        entry = {
            "name": obj["name"],
            "asset": asset,
            "scale": scale,
            "size": size,
            "position": position,
            "yaw_deg": yaw,
            "on": support,
            "shift": shift,
        }
        placed.append(entry)
        by_name[obj["name"]] = entry
    return placed


# ---------------------------------------------------------------------------- segments


def _shell_segment_names(prim: Primitive, names: list[str], cfg: dict) -> list[str]:
    """Each shell face's segment name: a wall face is named by its wall ("wall_-x"), found from
    the plane it lies on; the rest by their room.py part ("floor", "window", "light_0")."""
    sx, _, sz = map(float, cfg["size"])
    centroid = prim.positions[prim.faces].mean(axis=1)
    out = []
    for f, part in enumerate(prim.part):
        name = names[part]
        if name == "wall":
            x, z = centroid[f, 0], centroid[f, 2]
            gaps = {"-x": abs(x + sx / 2), "+x": abs(x - sx / 2), "-z": abs(z + sz / 2), "+z": abs(z - sz / 2)}
            name = "wall_" + min(gaps, key=gaps.get)
        out.append(name)
    return out


def _segment_class(name: str, lamps: set[str]) -> str:
    if name.startswith("wall_"):
        return "wall"
    if name.startswith("light_") or name in lamps:
        return "lamp"
    return SHELL_CLASSES.get(name, "object")


# ---------------------------------------------------------------------------- the scene


def _shell(cfg: dict, rng: np.random.Generator):
    """room.py's shell (no furniture) for this room: (Primitive, part names, materials by part)."""
    room_cfg = merge_config(
        ROOM_DEFAULTS,
        {
            "seed": cfg["seed"],
            "size": cfg["size"],
            "window": cfg["window"],
            "lights": cfg["lights"],
            "light_radiance": cfg["light_radiance"],
            "cell": cfg["cell"],
            "furniture": [],
        },
    )
    prim, names, _, materials = _room_geometry(room_cfg, rng)
    return prim, names, materials, room_cfg


PALETTE = np.array(
    [
        [0.55, 0.22, 0.15],
        [0.20, 0.35, 0.55],
        [0.30, 0.50, 0.25],
        [0.65, 0.55, 0.25],
        [0.45, 0.45, 0.48],
        [0.60, 0.40, 0.50],
    ]
)


WOOD_PARTS = {"legs", "top", "frame", "shelves", "base", "pole", "arms"}
METAL_PARTS = {"handles"}
LAMP_RADIANCE = 6.0  # ke of a lamp's shade (times the lights' colour)


def _part_material(asset, part_name: str, color: np.ndarray, room_cfg: dict) -> tuple[Material, dict]:
    """One part's material and its truth description: wood for structural parts, a metal for
    handles, an emitting shade for a lamp, the object's checkered colour for the rest."""
    if part_name in asset.emissive_parts:
        ke = (LAMP_RADIANCE * np.asarray(room_cfg["light_color"])).tolist()
        return (
            Material(kd=0.8, ks=0.0, ka=room_cfg["emitter_ka"], ke=ke),
            {"kind": "emitter", "kd": [0.8] * 3, "ke": ke},
        )
    if part_name in WOOD_PARTS:
        return (
            Material(kd=_wood_grain(), ks=room_cfg["table_ks"], ka=room_cfg["table_ka"]),
            {"kind": "wood_grain", "kd": [0.30, 0.18, 0.10], "ks": room_cfg["table_ks"], "ka": room_cfg["table_ka"]},
        )
    if part_name in METAL_PARTS:
        return (Material(kd=0.05, ks=0.6, ka=0.02), {"kind": "plain", "kd": [0.05] * 3, "ks": 0.6, "ka": 0.02})
    return (
        Material(kd=_checker(color), ks=room_cfg["ks"], ka=room_cfg["ka"]),
        {
            "kind": "checker",
            "kd": color.tolist(),
            "cell": 0.15,
            "contrast": 0.7,
            "ks": room_cfg["ks"],
            "ka": room_cfg["ka"],
        },
    )


SHELL_MATERIALS = {  # truth descriptions of room.py's shell materials
    "floor": {"kind": "wood_planks", "kd": [0.50, 0.32, 0.17], "plank_width": 0.18, "plank_length": 1.3},
    "wall": {
        "kind": "striped_wall",
        "kd": [0.80, 0.76, 0.67],
        "kd_dark": [0.68, 0.64, 0.57],
        "wainscot_kd": [0.42, 0.50, 0.56],
        "stripe": 0.15,
        "wainscot": 0.9,
    },
    "ceiling": {"kind": "plain", "kd": [0.85, 0.85, 0.83]},
    "window": {"kind": "window", "kw": 1.0},
}


def _photo_camera(cfg: dict):
    cam = cfg["camera"]
    width, height = int(cam["width"]), int(cam["height"])
    fov_x = fov_y_to_x(float(cam["fov_y_deg"]), width, height)
    sx, sy, sz = map(float, cfg["size"])
    eye = np.asarray(cam["eye"], np.float64)
    if np.any(np.abs(eye[[0, 2]]) >= np.array([sx, sz]) / 2) or not 0 < eye[1] < sy:
        raise ValueError("config.camera.eye: expected it inside the room")
    return pinhole_camera("photo.exr", eye, cam["target"], width, height, fov_x)


def make_room_photo(config: dict | None = None) -> tuple[Scene, dict]:
    """The room scene (one mesh whose instance ids are the segment ids, the maps, the photo's
    camera) and its metadata, with ``metadata["room"]`` the truth (room.json) and
    ``metadata["segments"]`` the label table."""
    cfg = resolve_config(config)
    rng = np.random.default_rng(cfg["seed"])
    shell, part_names, materials, room_cfg = _shell(cfg, rng)
    objects = _place_objects(cfg, rng)
    camera = _photo_camera(cfg)

    # Parts: room.py's shell parts, then one per object; segments: one per wall, shell part, object.
    segment_of_face = _shell_segment_names(shell, part_names, cfg)
    pieces, parts = [shell], [shell.part]
    truth_materials = {}
    for k, obj in enumerate(objects):
        asset = obj["asset"]
        world = np.eye(4)
        world[:3, :3], world[:3, 3] = yaw_matrix(obj["yaw_deg"]) * obj["scale"], obj["position"]
        mesh = asset.mesh.transformed(world)
        color = PALETTE[k % len(PALETTE)]
        for p, part_name in enumerate(asset.part_names):  # one material group per (object, part)
            part_names.append(f"{obj['name']}.{part_name}")
            materials[len(part_names) - 1], truth_materials[part_names[-1]] = _part_material(
                asset, part_name, color, room_cfg
            )
        first = len(part_names) - len(asset.part_names)
        pieces.append(mesh)
        parts.append((first + mesh.part).astype(np.int32))
        segment_of_face += [obj["name"]] * len(mesh.faces)
    prim = concatenate(pieces)
    part = np.concatenate(parts)

    order_names = ["floor", "ceiling", *(f"wall_{w}" for w in WALL_NAMES), "window"]
    order_names += [n for n in part_names if n.startswith("light_")] + [o["name"] for o in objects]
    lamps = {o["name"] for o in objects if o["asset"].emissive_parts}
    seen = set(segment_of_face)
    segment_names = [n for n in order_names if n in seen]
    segment_id = {name: i + 1 for i, name in enumerate(segment_names)}
    face_segment = np.array([segment_id[n] for n in segment_of_face], np.int32)

    # Faces grouped by part (one xatlas group per material), as room.py does.
    order = np.argsort(part, kind="stable")
    faces, part, face_segment = prim.faces[order], part[order], face_segment[order]
    atlas = unwrap(prim.positions, faces, resolution=int(cfg["atlas_resolution"]), padding=2, groups=part)
    mesh = Mesh(
        positions=atlas.positions.astype(np.float32), faces=atlas.faces, uvs=atlas.uvs, instance_ids=face_segment
    )
    texels = rasterize_atlas(mesh, atlas.height, atlas.width)
    maps = Maps(**bake_materials(texels, part, materials, dilation=2), kg=sky_cube_map(cfg["environment"]))
    scene = Scene(mesh=mesh, maps=maps, cameras=[camera])

    segments = [{"id": segment_id[n], "class": _segment_class(n, lamps), "name": n} for n in segment_names]
    truth = _truth(cfg, room_cfg, objects, segment_id, camera, truth_materials)
    metadata = {
        "generator": "invrender.synthesize.room_photo",
        "kind": "room_photo",
        "seed": int(cfg["seed"]),
        "config": cfg,
        "triangle_count": int(len(faces)),
        "segments": segments,
        "fov_y_deg": float(cfg["camera"]["fov_y_deg"]),
        "room": truth,
    }
    return scene, metadata


def _truth(cfg, room_cfg, objects, segment_id, camera, truth_materials) -> dict:
    """room.json (ROOM_API.md): the box, the objects, the lights and the materials."""
    sx, sy, sz = map(float, cfg["size"])
    out_objects = []
    for obj in objects:
        support = obj["on"] if obj["on"] == "floor" else str(segment_id[obj["on"]])
        out_objects.append(
            {
                "segment": segment_id[obj["name"]],
                "name": obj["name"],
                "asset": obj["asset"].name,
                "category": obj["asset"].category,
                "position": obj["position"].tolist(),
                "yaw_deg": float(obj["yaw_deg"]),
                "scale": float(obj["scale"]),
                "size": obj["size"].tolist(),
                "support": support,
            }
        )
    lights = []
    for i, light in enumerate(cfg["lights"]):
        lights.append(
            {
                "kind": "ceiling_panel",
                "segment": segment_id[f"light_{i}"] if f"light_{i}" in segment_id else None,
                "center": [float(light["center"][0]), sy, float(light["center"][1])],
                "size": [float(light["size"][0]), float(light["size"][1])],
                "radiance": float(room_cfg["light_radiance"]),
                "falloff": float(room_cfg["light_falloff"]),
                "color": list(map(float, room_cfg["light_color"])),
            }
        )
    for obj in objects:  # a floor lamp's shade
        for part in obj["asset"].emissive_parts:
            lights.append(
                {
                    "kind": "lamp",
                    "segment": segment_id[obj["name"]],
                    "object": obj["name"],
                    "part": part,
                    "ke": truth_materials[f"{obj['name']}.{part}"]["ke"],
                }
            )
    win = cfg["window"]
    lights.append(
        {
            "kind": "window",
            "segment": segment_id.get("window"),
            "wall": win["wall"],
            "center": list(map(float, win["center"])),
            "size": list(map(float, win["size"])),
        }
    )
    lights.append({"kind": "environment", **copy.deepcopy(cfg["environment"])})
    materials = {
        name: dict(desc, ks=room_cfg["ks"], ka=room_cfg["ka"]) if name != "window" else dict(desc)
        for name, desc in SHELL_MATERIALS.items()
    }
    materials.update(truth_materials)
    return {
        "box": {"center": [0.0, sy / 2, 0.0], "size": [sx, sy, sz], "yaw_deg": 0.0},
        "camera": {
            "width": camera.width,
            "height": camera.height,
            "fov_y_deg": float(cfg["camera"]["fov_y_deg"]),
            "eye": camera.center.tolist(),
            "target": list(map(float, cfg["camera"]["target"])),
            "R": np.asarray(camera.R).tolist(),
            "t": np.asarray(camera.t).tolist(),
        },
        "objects": out_objects,
        "lights": lights,
        "materials": materials,
    }


# ---------------------------------------------------------------------------- the capture


def write_room_capture(scene: Scene, metadata: dict, out_dir, renderer_factory=None, spp: int = 64, seed: int = 0):
    """Render the photo and write the room capture (scene/room_photo.py's layout) atomically:
    photo.exr (+ photo.png preview), depth.exr (camera z, meters), panoptic.png + panoptic.json,
    camera.json, and truth/scene/ (the scene directory) + truth/room.json."""
    from ..scene.atomic import atomic_dir, check_output
    from ..scene.format import write_scene
    from ..scene.room_photo import write_room_photo
    from .capture import _default_renderer

    (camera,) = scene.cameras
    out_dir = check_output(out_dir, "capture")
    renderer = (renderer_factory or _default_renderer)(scene)
    out = renderer.render(camera, spp=spp, seed=seed)
    radiance = np.asarray(out["radiance"], np.float32)
    if not np.all(np.isfinite(radiance)):
        raise RuntimeError("renderer: non-finite radiance in the room photo")
    depth = np.asarray(out["depth"], np.float32)
    depth = np.where(np.isfinite(depth), depth, 0.0)  # a miss (through nothing: the room is closed)
    ids = np.asarray(out["instance_id"])
    labels = {s["id"]: (s["class"], s["name"]) for s in metadata["segments"]}
    with atomic_dir(out_dir, kind="capture") as tmp:
        write_room_photo(tmp, radiance, depth, ids.astype(np.uint16), labels, metadata["fov_y_deg"])
        (tmp / "truth").mkdir()
        write_scene(tmp / "truth" / "scene", scene, {k: v for k, v in metadata.items() if k != "room"})
        (tmp / "truth" / "room.json").write_text(json.dumps(metadata["room"], indent=1) + "\n")
    log.info("wrote %s: %d x %d at %d spp", out_dir, camera.width, camera.height, spp)
