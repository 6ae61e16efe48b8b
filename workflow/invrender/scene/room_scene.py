"""A room-mode scene (PSDR-Room section 4): the room stages' outputs as one
version-2 scene directory's content, seen by the photo's camera.

``assemble_room(room, objects, lights, materials, assets)`` takes

- ``room``: room_box's room.json (``box`` {center, size, yaw_deg} and ``camera``: ``params`` or
  ``fov_y_deg``, ``width``, ``height``, ``R``, ``t``), or the generator's truth/room.json;
- ``objects``: room_objects' objects.json list (or the truth's ``objects``): per object ``name``,
  ``asset``, ``segment``, and its placement, ``T_obj2world`` (4 x 4, the unit asset to the world)
  or ``position``, ``yaw_deg``, ``scale`` (world = R_y(yaw) (scale * unit mesh) + position);
- ``lights``: room_lights' lights.json (``lights``: quads {kind, name, center, e1, e2, normal,
  radiance}; ``lamps``: {segment, radiance}, the objects whose emissive parts emit);
- ``materials``: optional, by material-set or part name (below): an ``Atlas`` of that set's own
  shape, or constants {"kd", "ks", "ka", "ke", "kw"} (a number or an RGB triple each);
- ``assets``: the asset library (``invrender.assets.library(asset_dirs)``, any iterable of
  assets or a dict by name). The caller passes it: scene/ is the format layer and imports nothing
  else of invrender (tests/test_import_graph.py), so the library is an argument, not an import.

What it builds (every object one material set of the same name):

- the box as six inward-facing quads (front = into the room, two triangles each): ``floor``,
  ``ceiling``, ``wall_px``, ``wall_mx``, ``wall_pz``, ``wall_mz`` (room_lights' wall ``+x`` is
  ``wall_px``: object names may not hold a ``+``). UVs span [0, 1] over the quad and its atlas is
  ``texels_per_meter`` texels per meter along both edges, so a texel is a square of fixed size in
  meters: u * width and v * height are meters from the quad's corner (``metadata["surfaces"]``
  gives each plane as materials/bake.py's (origin, u axis, v axis));
- each object its asset's unit mesh, faces sorted by part (``metadata["parts"]``: the face range
  of each part), unwrapped by xatlas at ``texels_per_meter`` of the placed size with one chart
  group per part; its transform the placement;
- each light a one-sided emitting quad (``emission_sides`` one), moved ``inset`` box heights
  along its normal off the wall or ceiling it lies on, with a 2 x 2 set (kd 0, ke its radiance);
- the photo's camera (``photo``), and a black sky unless ``kg`` is given (the estimated lights
  stand for the windows and the sun).

Material lookup, first found: the set's name (an Atlas or constants for the whole set); for an
object's part ``{object}.{part}`` (constants; the truth's materials are named so); for a wall its
room_lights name (``wall_+x``) then ``wall``; then ``DEFAULT_MATERIAL``. A lamp's emissive parts
get ``ke`` = its radiance from lights.json.

Every object has its own instance id (1, 2, ... in order) and ``metadata["instances"]`` says, per
id, its name, class (``ROOM_CLASSES``), the photo segment it stands for and its kind (box,
object, light): evaluate's mask IoU per class and the edit stage's regions read it.
"""

from __future__ import annotations

import json
import re
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .atlas import bake, rasterize_atlas, unwrap
from .packing import check_transform, pack_scene
from .room_photo import ROOM_CLASSES, yaw_matrix
from .types import Atlas, Camera, Mesh, Scene, SceneError, SceneObject

__all__ = [
    "DEFAULT_MATERIAL",
    "read_json",
    "RoomScene",
    "assemble_room",
    "room_camera",
    "box_surfaces",
    "object_transform_of",
    "truth_lights",
    "safe_name",
]

DEFAULT_MATERIAL = {"kd": 0.5, "ks": 0.04, "ka": 0.25}  # grey, the paper's roughness 0.5 (ka = 0.5^2)
TEXELS_PER_METER = 64
LIGHT_ATLAS = 2  # texels per side of a light's constant set
UP = np.array([0.0, 1.0, 0.0])
_NAME = re.compile(r"[^A-Za-z0-9_.-]")


@dataclass
class RoomScene(Scene):
    """A Scene with what the room stages need to read back: ``metadata`` (instances, surfaces,
    parts; scene.json's metadata when baked)."""

    metadata: dict = field(default_factory=dict)


def read_json(path, what: str) -> dict:
    """A room stage's JSON (room.json, objects.json, lights.json, materials.json), or one
    SceneError naming the file and ``what`` it should be."""
    path = Path(path)
    try:
        return json.loads(path.read_text())
    except FileNotFoundError:
        raise SceneError(path, "(file)", what) from None
    except json.JSONDecodeError as error:
        raise SceneError(path, "(JSON)", f"{what} as JSON ({error})") from None


def safe_name(name: str) -> str:
    """A scene object name (letters, digits, ``_ . -``): ``+`` becomes ``p``, ``-`` at the start
    ``m``, anything else ``_``; room_lights' ``wall_+x`` is ``wall_px``."""
    name = str(name).replace("+", "p")
    name = _NAME.sub("_", name)
    return "m" + name[1:] if name.startswith("-") else (name or "_")


# ---------------------------------------------------------------------------- the camera


def room_camera(room: dict, file="room.json") -> Camera:
    """room.json's camera: room_box's (``params`` fx, fy, cx, cy) or the truth's (``fov_y_deg``,
    square pixels, centred principal point), posed by ``R``, ``t`` (world to camera, OpenCV)."""
    try:
        c = room["camera"]
        width, height = int(c["width"]), int(c["height"])
        if "params" in c:
            params = np.asarray(c["params"], np.float64).reshape(4)
        else:
            f = 0.5 * height / np.tan(np.radians(float(c["fov_y_deg"])) / 2)
            params = np.array([f, f, width / 2, height / 2])
        R = np.asarray(c["R"], np.float64).reshape(3, 3)
        t = np.asarray(c["t"], np.float64).reshape(3)
    except (KeyError, TypeError, ValueError) as error:
        raise SceneError(
            file, "camera", f"width, height, params (or fov_y_deg), R and t of the photo's camera ({error})"
        ) from None
    return Camera("photo", "PINHOLE", width, height, params, R, t)


# ---------------------------------------------------------------------------- the box


def _box(room: dict, file) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(center, size, R) of room.json's box."""
    try:
        b = room["box"]
        center = np.asarray(b["center"], np.float64).reshape(3)
        size = np.asarray(b["size"], np.float64).reshape(3)
        yaw = float(b.get("yaw_deg", 0.0))
    except (KeyError, TypeError, ValueError) as error:
        raise SceneError(file, "box", f"center, size and yaw_deg of the room box ({error})") from None
    if not (np.all(np.isfinite(size)) and np.all(size > 0) and np.all(np.isfinite(center))):
        raise SceneError(file, "box.size", f"three positive extents, got {size.tolist()}")
    return center, size, yaw_matrix(yaw)


def box_surfaces(room: dict, file="room.json") -> list[dict]:
    """The box's six faces, normals into the room: {name, light_name (room_lights' name), class,
    center, e1, e2 (full edges, cross(e1, e2) along the normal), normal}. Walls: e1 horizontal,
    e2 up; floor and ceiling: e1 along the box's x."""
    center, size, R = _box(room, file)
    surfaces = []
    for axis in (0, 2):
        for sign in (-1.0, 1.0):
            n = -sign * R[:, axis]
            e1 = np.cross(UP, n)
            light_name = f"wall_{'+' if sign > 0 else '-'}{'xyz'[axis]}"
            surfaces.append(
                {
                    "name": safe_name(light_name).replace("_-", "_m"),
                    "light_name": light_name,
                    "class": "wall",
                    "center": center + R[:, axis] * sign * size[axis] / 2,
                    "e1": e1 * size[2 - axis],
                    "e2": UP * size[1],
                    "normal": n,
                }
            )
    for name, sign in (("floor", 1.0), ("ceiling", -1.0)):
        n = sign * UP
        surfaces.append(
            {
                "name": name,
                "light_name": name,
                "class": name,
                "center": center - n * size[1] / 2,
                "e1": R[:, 0] * size[0],
                "e2": np.cross(n, R[:, 0]) * size[2],
                "normal": n,
            }
        )
    return surfaces


def _quad_mesh(center, e1, e2, normal) -> Mesh:
    """Two triangles, counter-clockwise seen from ``normal``'s side; UV (0, 0) at the corner
    center - e1/2 - e2/2, u along e1, v along e2."""
    center, e1, e2 = (np.asarray(a, np.float64) for a in (center, e1, e2))
    uvs = np.array([[0, 0], [1, 0], [1, 1], [0, 1]], np.float64)
    corners = center + (uvs[:, :1] - 0.5) * e1 + (uvs[:, 1:] - 0.5) * e2
    faces = np.array([[0, 1, 2], [0, 2, 3]])
    if np.cross(e1, e2) @ np.asarray(normal, np.float64) < 0:
        faces = faces[:, ::-1]
    return Mesh(corners.astype(np.float32), faces.astype(np.int32), uvs.astype(np.float32))


def _texels(length: float, texels_per_meter: float) -> int:
    return max(2, int(round(length * texels_per_meter)))


# ---------------------------------------------------------------------------- materials


def _constants(desc: Mapping, shape, where: str) -> dict[str, np.ndarray]:
    """A constants dict's maps at ``shape``, the defaults under it."""
    values = {**DEFAULT_MATERIAL, "ke": 0.0, "kw": 0.0, **{k: v for k, v in desc.items() if k in Atlas.__annotations__}}
    out = {}
    for name, value in values.items():
        channels = 1 if name in ("ka", "kw") else 3
        try:
            array = np.broadcast_to(np.asarray(value, np.float32), (channels,) if channels == 3 else ())
        except ValueError:
            raise SceneError(
                where, name, f"a number{' or an RGB triple' if channels == 3 else ''}, got {value!r}"
            ) from None
        out[name] = np.broadcast_to(array, (*shape, channels) if channels == 3 else shape).copy()
    return out


def _uniform(desc: Mapping, shape, where: str) -> Atlas:
    return Atlas(**_constants(desc, shape, where))


def _given(materials: Mapping, names, shape, where: str):
    """The first of ``names`` in ``materials``: an Atlas of ``shape`` as it is, constants as an
    Atlas; None if none is given."""
    for name in names:
        if name in materials:
            value = materials[name]
            if isinstance(value, Atlas):
                if tuple(value.atlas_shape) != tuple(shape):
                    raise SceneError(
                        where,
                        f"materials[{name!r}]",
                        f"an atlas of {shape[0]} x {shape[1]} texels, got {value.atlas_shape}",
                    )
                return value
            if isinstance(value, Mapping):
                return _uniform(value, shape, where)
            raise SceneError(where, f"materials[{name!r}]", "an Atlas or a dict of kd, ks, ka, ke, kw")
    return None


# ---------------------------------------------------------------------------- objects


def _asset_table(assets) -> dict:
    if isinstance(assets, Mapping):
        return dict(assets)
    return {asset.name: asset for asset in (assets or ())}


def object_transform_of(obj: Mapping, where: str) -> np.ndarray:
    """An object's unit-asset-to-world 4 x 4: ``T_obj2world`` if given, else from ``position``,
    ``yaw_deg`` and ``scale`` (the generator's R_y(yaw) (scale * mesh) + position)."""
    if "T_obj2world" in obj:
        return check_transform(obj["T_obj2world"], where, "T_obj2world")
    try:
        T = np.eye(4)
        T[:3, :3] = yaw_matrix(float(obj.get("yaw_deg", 0.0))) * float(obj["scale"])
        T[:3, 3] = np.asarray(obj["position"], np.float64).reshape(3)
    except (KeyError, TypeError, ValueError) as error:
        raise SceneError(where, "T_obj2world", f"a 4 x 4 placement, or position, yaw_deg and scale ({error})") from None
    return check_transform(T, where, "position/yaw_deg/scale")


def _object_mesh(asset, scale: float, texels_per_meter: float):
    """The unit mesh with faces sorted by part, unwrapped at ``texels_per_meter`` of its placed
    size (one chart group per part): (Mesh, atlas (h, w), face part ids, {part: [start, stop)})."""
    prim = asset.mesh
    order = np.argsort(np.asarray(prim.part), kind="stable")
    faces, part = np.asarray(prim.faces)[order], np.asarray(prim.part)[order]
    uv = unwrap(np.asarray(prim.positions) * scale, faces, texels_per_meter=texels_per_meter, padding=2, groups=part)
    mesh = Mesh((uv.positions / scale).astype(np.float32), uv.faces, uv.uvs)
    ranges = {}
    for p, name in enumerate(asset.part_names):
        idx = np.flatnonzero(part == p)
        if len(idx):
            ranges[name] = [int(idx[0]), int(idx[-1]) + 1]
    return mesh, (uv.height, uv.width), part, ranges


def _object_atlas(obj_name, asset, mesh, shape, part, materials, emission, where) -> Atlas:
    """The object's set: materials[name] whole, else per part constants (``{name}.{part}``),
    the lamp's emission on its emissive parts; texels outside every chart get their neighbours'."""
    whole = _given(materials, [obj_name], shape, where)
    if whole is not None:
        return whole
    per_part = []
    emitting = set(asset.emissive_parts) or set(asset.part_names)
    for p, name in enumerate(asset.part_names):
        desc = materials.get(f"{obj_name}.{name}", DEFAULT_MATERIAL)
        if not isinstance(desc, Mapping):
            raise SceneError(where, f"materials[{obj_name}.{name!r}]", "a dict of kd, ks, ka, ke, kw for a part")
        if emission is not None and name in emitting:
            desc = {**desc, "ke": emission}
        per_part.append(_constants(desc, (), where))
    texels = rasterize_atlas(mesh, *shape)
    maps = {}
    for key in ("kd", "ks", "ka", "ke", "kw"):
        table = np.stack([np.reshape(c[key], -1) for c in per_part])  # (parts, channels)
        shade = lambda tri, pos, nrm, table=table: table[part[tri]]  # noqa: E731
        # texels no chart reaches (nor its 4-texel dilation) are never read; they hold the first
        # part's value, not 0, which the format refuses as a roughness
        background = float(table[0].mean()) if key in ("kd", "ks", "ka") else 0.0
        maps[key] = bake(texels, shade, table.shape[1], dilation=4, background=background)
    return Atlas(**maps)


# ---------------------------------------------------------------------------- lights


def _light_quads(lights: Mapping, where: str) -> list[dict]:
    try:
        quads = [
            {
                "kind": str(q.get("kind", "light")),
                "name": str(q.get("name") or q.get("kind", "light")),
                **{k: np.asarray(q[k], np.float64).reshape(3) for k in ("center", "e1", "e2", "normal")},
                "radiance": np.broadcast_to(np.asarray(q.get("radiance", 1.0), np.float64), (3,)).copy(),
                "segment": q.get("segment"),
            }
            for q in lights.get("lights", [])
        ]
    except (KeyError, TypeError, ValueError) as error:
        raise SceneError(where, "lights", f"quads with center, e1, e2, normal and radiance ({error})") from None
    for k, q in enumerate(quads):
        if not (np.all(np.isfinite(q["radiance"])) and np.all(q["radiance"] >= 0)):
            raise SceneError(
                where, f"lights[{k}].radiance", f"finite, non-negative values, got {q['radiance'].tolist()}"
            )
    return quads


def truth_lights(truth: Mapping) -> dict:
    """The generator's truth lights (truth/room.json) as lights.json quads: each ceiling panel
    (its mean radiance: ke falls from the centre to (1 - falloff) at the rim, mean over the
    rectangle 1 - falloff * E[min(r^2, 1)]) and each window (radiance 1: its light is the sky's,
    which evaluate integrates). Lamps as lights.json's ``lamps`` with their shade's ke."""
    sx, sy, sz = np.asarray(truth["box"]["size"], np.float64)
    quads, lamps = [], []
    u = (np.arange(64) + 0.5) / 32 - 1  # midpoint rule over [-1, 1]^2
    mean_r2 = float(np.minimum(u[:, None] ** 2 + u[None, :] ** 2, 1.0).mean())
    for light in truth.get("lights", []):
        kind = light.get("kind")
        if kind == "ceiling_panel":
            (lx, lz), colour = light["size"], np.asarray(light.get("color", [1, 1, 1]), np.float64)
            radiance = float(light["radiance"]) * (1 - float(light.get("falloff", 0.0)) * mean_r2) * colour
            quads.append(
                {
                    "kind": "ceiling",
                    "name": f"panel_{light.get('segment')}",
                    "segment": light.get("segment"),
                    "center": list(map(float, light["center"])),
                    "e1": [float(lx), 0.0, 0.0],
                    "e2": [0.0, 0.0, float(lz)],
                    "normal": [0.0, -1.0, 0.0],
                    "radiance": radiance.tolist(),
                }
            )
        elif kind == "window":
            wall = light["wall"]
            axis, sign = "xyz".index(wall[1]), 1.0 if wall[0] == "+" else -1.0
            along = 2 if axis == 0 else 0
            normal, e1 = np.zeros(3), np.zeros(3)
            normal[axis] = -sign
            center = np.zeros(3)
            center[axis] = sign * (sx if axis == 0 else sz) / 2
            center[along], center[1] = light["center"]
            e1[along] = light["size"][0]
            quads.append(
                {
                    "kind": "window",
                    "name": f"window_{light.get('segment')}",
                    "segment": light.get("segment"),
                    "center": center.tolist(),
                    "e1": e1.tolist(),
                    "e2": [0.0, float(light["size"][1]), 0.0],
                    "normal": normal.tolist(),
                    "radiance": [1.0, 1.0, 1.0],
                }
            )
        elif kind == "lamp":
            lamps.append({"segment": light["segment"], "name": light.get("object"), "radiance": light["ke"]})
    return {"lights": quads, "lamps": lamps}


# ---------------------------------------------------------------------------- the scene


@dataclass
class _Room:
    """The scene being assembled: its objects, their sets, the instances table, the metadata."""

    where: str
    objects: list = field(default_factory=list)
    sets: dict = field(default_factory=dict)
    metadata: dict = field(default_factory=lambda: {"surfaces": {}, "parts": {}, "instances": []})

    def add(self, name, mesh, atlas, cls, kind, segment=None, transform=None, sides="two", **extra) -> None:
        """One object, its own set of the same name, the next instance id."""
        if name in self.sets:
            raise SceneError(self.where, "name", f"a name no other object of the room has, got {name!r} twice")
        iid = len(self.objects) + 1
        T = np.eye(4) if transform is None else transform
        self.objects.append(SceneObject(name, mesh, name, T, iid, sides))
        self.sets[name] = atlas
        self.metadata["instances"].append(
            {"instance_id": iid, "name": name, "class": cls, "kind": kind, "segment": segment, **extra}
        )


def _add_box(out: _Room, room: Mapping, materials: Mapping, texels_per_meter: float) -> None:
    """The six faces, each texels_per_meter along both edges, and their planes in the metadata."""
    for s in box_surfaces(room, out.where):
        width, height = float(np.linalg.norm(s["e1"])), float(np.linalg.norm(s["e2"]))
        shape = (_texels(height, texels_per_meter), _texels(width, texels_per_meter))
        atlas = _given(materials, [s["name"], s["light_name"], s["class"]], shape, out.where)
        atlas = atlas or _uniform(DEFAULT_MATERIAL, shape, out.where)
        out.add(s["name"], _quad_mesh(s["center"], s["e1"], s["e2"], s["normal"]), atlas, s["class"], "box")
        out.metadata["surfaces"][s["name"]] = {
            "origin": (s["center"] - s["e1"] / 2 - s["e2"] / 2).tolist(),
            "u_axis": (s["e1"] / width).tolist(),
            "v_axis": (s["e2"] / height).tolist(),
            "size": [width, height],
        }


def _add_objects(out, objects, table, materials, lamp_radiance, labels, texels_per_meter) -> None:
    """Each placed asset: its unit mesh unwrapped at its placed size, its set, its class."""
    for k, obj in enumerate(objects):
        field_ = f"objects[{k}]"
        if obj.get("asset") not in table:
            raise SceneError(out.where, f"{field_}.asset", f"an asset of the library, got {obj.get('asset')!r}")
        asset = table[obj["asset"]]
        T = object_transform_of(obj, f"{out.where}: {field_}")
        segment = None if obj.get("segment") is None else int(obj["segment"])
        name = safe_name(obj.get("name") or f"object_{segment if segment is not None else k}")
        mesh, shape, part, ranges = _object_mesh(asset, float(np.cbrt(np.linalg.det(T[:3, :3]))), texels_per_meter)
        atlas = _object_atlas(name, asset, mesh, shape, part, materials, lamp_radiance.get(segment), out.where)
        cls = labels[segment][0] if segment in labels else ("lamp" if segment in lamp_radiance else "object")
        if cls not in ROOM_CLASSES:
            raise SceneError(out.where, f"labels[{segment}]", f"one of {', '.join(ROOM_CLASSES)}, got {cls!r}")
        out.add(name, mesh, atlas, cls, "object", segment, T, asset=asset.name)
        out.metadata["parts"][name] = ranges


def _add_lights(out: _Room, lights: Mapping, offset: float) -> None:
    """Each light a one-sided emitting quad ``offset`` off its wall or ceiling, a 2 x 2 set."""
    for q in _light_quads(lights, out.where):
        name = safe_name(f"light_{q['name']}")
        while name in out.sets:
            name += "_"
        atlas = _uniform({"kd": 0.0, "ks": 0.0, "ka": 1.0, "ke": q["radiance"]}, (LIGHT_ATLAS, LIGHT_ATLAS), out.where)
        mesh = _quad_mesh(q["center"] + q["normal"] * offset, q["e1"], q["e2"], q["normal"])
        cls = "window" if q["kind"] == "window" else "lamp"
        out.add(name, mesh, atlas, cls, "light", q["segment"], sides="one")


def assemble_room(
    room: Mapping,
    objects: Iterable[Mapping] = (),
    lights: Mapping | None = None,
    materials: Mapping | None = None,
    assets=(),
    *,
    labels: Mapping | None = None,
    kg: np.ndarray | None = None,
    texels_per_meter: float = TEXELS_PER_METER,
    inset: float = 1e-3,
    where: str = "room",
) -> RoomScene:
    """The room scene (module docstring). ``labels``: the photo's segment id -> (class, name)
    (``RoomPhoto.labels``), which names each object's class; without it an object whose segment
    lights.json lists as a lamp is a ``lamp``, any other an ``object``."""
    materials, lights, labels = dict(materials or {}), dict(lights or {}), dict(labels or {})
    _, size, _ = _box(room, where)
    camera = room_camera(room, where)
    out = _Room(where)
    out.metadata["box"] = room["box"]
    lamps = {int(lamp["segment"]): lamp.get("radiance") for lamp in lights.get("lamps", []) if "segment" in lamp}
    _add_box(out, room, materials, texels_per_meter)
    _add_objects(out, objects, _asset_table(assets), materials, lamps, labels, texels_per_meter)
    _add_lights(out, lights, inset * size[1])
    kg = np.zeros((6, 8, 8, 3), np.float32) if kg is None else np.asarray(kg, np.float32)
    scene = pack_scene(out.objects, out.sets, kg, [camera])
    fields = ("mesh", "maps", "cameras", "path", "objects", "packing")
    return RoomScene(**{f: getattr(scene, f) for f in fields}, metadata=out.metadata)
