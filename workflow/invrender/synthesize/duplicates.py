"""Several copies of one textured object at known 6-DoF poses: the ground truth for the
duplicates (Structure from Duplicates) mode.

Two objects (config ``object.kind``):

- ``"can"`` (the default): a capped cylinder with a printed label on its side (stripes, a disc
  and an L-shaped mark) and metallic-ish caps with an off-centre tab. The shape is rotationally
  symmetric about its axis (+Y); only the label tells the turn about it: the hard case.
- ``"box"``: the paper's "color box", a cuboid with three different edges (``object.size``,
  x y z), each face its own colour with a printed letter, blobs and stripes, none of them
  symmetric, so every face and its turn can be told apart.

Copies rest on (or float just above) a tiled floor quad; there are no walls, so every ray that
misses escapes to kg. ``placement.orientations`` lists how copies lie ("upright", "upside_down",
"lying", or "random": uniform on SO(3)); copy i takes entry i mod len, turned about the floor
normal by a uniform yaw. The last ``placement.touching`` copies each touch an earlier one (zero
distance between the two meshes, found exactly by the separating-axis test); the others keep
``gap`` between bounding spheres. ``preset`` (a name in ``DUPLICATES_PRESETS``) replaces the
defaults with a named fixture, which the rest of the config then overrides key by key.

Shared atlas. All copies read the same texels: the object is unwrapped once, packed in one
xatlas atlas beside the floor, and every copy gets the object's UVs. This is the SfD model
(one shared mesh and one shared material), so an optimiser updates one material from all
copies at once, and the export can instance one mesh. The object's positions are scaled up
for the unwrap so it gets ``object_texel_share`` of the atlas area instead of its tiny
fraction of the surface area.

Poses: ``T_obj2world`` row-major 4 x 4, p_world = T [p_obj, 1]; the object frame is centred at
the object's centroid (can: axis +Y, label seam at +X; box: edges along x, y, z), as written to
``ground_truth/object.ply``.
"""

from __future__ import annotations

import numpy as np

from ..assets.primitives import BOX_SIDES, CYLINDER_PARTS, PLANE_AXES, axis_grid, box, cylinder, subdivide_breaks
from ..scene.atlas import rasterize_atlas, triangle_areas, unwrap
from ..scene.cameras import project_points
from ..scene.types import Maps, Mesh, Scene
from .room import ENVIRONMENT_DEFAULTS, Material, bake_materials, merge_config, pinhole_camera, sky_cube_map

__all__ = [
    "DUPLICATES_DEFAULTS",
    "DUPLICATES_PRESETS",
    "OBJECT_KINDS",
    "ORIENTATIONS",
    "make_duplicates",
    "resolve_config",
    "build_object",
    "object_mesh",
    "convex_gap",
    "ConvexShape",
    "POSES_CONVENTION",
]

DUPLICATES_DEFAULTS = {
    "seed": 0,
    "preset": "",  # a name in DUPLICATES_PRESETS: its values replace these defaults
    "count": 6,
    "object": {
        "kind": "can",  # "can" or "box"
        "radius": 0.033,  # can
        "height": 0.122,  # can
        "segments": 32,  # can
        "rings": 3,  # can
        "size": [0.08, 0.10, 0.06],  # box: x, y, z edges (three different: no shape turns into itself but by 180 deg)
    },
    "floor": {"size": [1.0, 0.8], "cell": 0.1, "tile": 0.1},  # x, z extents; centred at the origin
    "placement": {
        "extent": [0.5, 0.36],  # centres are drawn in this x, z rectangle around the origin
        "max_lift": 0.03,  # lowest point of a copy is 0 .. max_lift above the floor
        "gap": 0.01,  # least clearance between two copies' bounding spheres (but a touching pair)
        "margin_px": 2,  # every vertex of every copy projects this far inside the image
        "attempts": 2000,  # draws of a pose, for all copies together
        "orientations": ["random"],  # copy i lies as entry i mod len: upright, upside_down, lying, random
        "touching": 0,  # the last this many copies each touch an earlier copy
        "max_yaw_deg": 180.0,  # resting copies turn about the floor normal within +- this
    },
    "camera": {"width": 96, "height": 72, "fov_deg": 60.0, "distance": 0.8, "elevation_deg": 55.0, "azimuth_deg": 0.0},
    "ks": 0.04,
    "ka": 0.3,
    "cap_ks": 0.8,  # the metallic-ish top and bottom
    "cap_ka": 0.03,
    "atlas_resolution": 256,
    "atlas_padding": 2,
    "object_texel_share": 0.5,  # fraction of the atlas' chart area given to the object
    "environment": {**ENVIRONMENT_DEFAULTS, "sun_elevation_deg": 50.0, "sun_azimuth_deg": 130.0},
}

OBJECT_KINDS = ("can", "box")
ORIENTATIONS = ("upright", "upside_down", "lying", "random")

_FRAMES = {
    "can": "the can centred at its centroid, axis +Y, label seam at +X",
    "box": "the box centred at its centroid, edges along x, y, z (object.size), faces +x -x +y -y +z -z",
}
# What the evaluation needs to split a rotation error: the can's shape turns into itself about
# its axis (only the label tells the turn), the box's does not (its prints tell every face).
_SYMMETRY = {
    "can": {"type": "axis", "axis": [0.0, 1.0, 0.0], "note": "continuous rotation about +Y; the label breaks it"},
    "box": {"type": "none", "axis": None, "note": "three different edges and a different print on every face"},
}


def _poses_convention(kind: str) -> str:
    return (
        "p_world = T_obj2world @ [p_obj, 1]; T_obj2world row-major 4x4; world = the capture's COLMAP world "
        f"(meters, +Y up, floor at y = 0); object frame = ground_truth/object.ply ({_FRAMES[kind]})"
    )


POSES_CONVENTION = _poses_convention("can")

FLOOR, OBJECT = 0, 1  # part labels of the template: the floor, then the object's parts from 1


def _preset(kind: str, count: int, hd: bool) -> dict:
    """A benchmark fixture (docs/duplicates-fixtures.md): ``count`` copies of ``kind``, upright,
    upside down and lying in turn, turned about the floor normal, some touching, under a camera
    60 degrees above the floor.
    The CI (320 x 240) and HD (1600 x 1200) versions are the same scene: every pixel length
    (margin included) scales by 5, so the placement draws the same poses."""
    scale = 5 if hd else 1
    # Camera distance and the drawing rectangle per count: at 1600 x 1200 a copy spans about
    # 120-250 px; the floor covers the whole view.
    distance, extent, floor = {
        6: (1.05, [0.9, 0.75], [1.4, 1.2]),
        10: (1.1, [1.0, 0.8], [1.5, 1.3]),
        20: (1.35, [1.25, 1.0], [1.8, 1.6]),
    }[count]
    return {
        "count": count,
        "object": {"kind": kind},
        "floor": {"size": floor, "cell": 0.1, "tile": 0.1},
        "placement": {
            "extent": extent,
            "max_lift": 0.002,  # resting on the floor, a hair above it (no coplanar faces)
            "gap": 0.01,
            "margin_px": 4 * scale,
            "attempts": 20000,
            "orientations": ["upright", "upside_down", "lying"],
            "touching": {6: 2, 10: 3, 20: 5}[count],
        },
        "camera": {
            "width": 320 * scale,
            "height": 240 * scale,
            "fov_deg": 50.0,
            "distance": distance,
            "elevation_deg": 60.0,
            "azimuth_deg": 0.0,
        },
        "atlas_resolution": 2048 if hd else 512,
    }


DUPLICATES_PRESETS = {
    f"{kind}-{count}-{size}": _preset(kind, count, size == "hd")
    for kind in OBJECT_KINDS
    for count in (6, 10, 20)
    for size in ("ci", "hd")
}


def resolve_config(config: dict | None = None) -> dict:
    """The generator's full config: the defaults, then the preset ``config["preset"]`` names (if
    any), then ``config`` itself, key by key."""
    cfg = merge_config(DUPLICATES_DEFAULTS, config)
    name = cfg["preset"]
    if not name:
        return cfg
    if name not in DUPLICATES_PRESETS:
        raise ValueError(f"config.preset: unknown preset {name!r}; expected one of {sorted(DUPLICATES_PRESETS)}")
    base = merge_config(DUPLICATES_DEFAULTS, DUPLICATES_PRESETS[name])
    return merge_config(base, config)


def build_object(config: dict | None = None):
    """The object in its frame: (positions (V, 3) float64, faces (F, 3) int32, part (F,)):
    a can with parts ``primitives.CYLINDER_PARTS`` (side/label, top, bottom) or a box with
    parts ``primitives.BOX_SIDES``."""
    cfg = resolve_config(config)["object"]
    if cfg["kind"] not in OBJECT_KINDS:
        raise ValueError(f"config.object.kind: {cfg['kind']!r}; expected one of {list(OBJECT_KINDS)}")
    if cfg["kind"] == "box":
        half = np.asarray(cfg["size"], np.float64) / 2
        return box(-half, half)
    return cylinder(cfg["radius"], cfg["height"], int(cfg["segments"]), int(cfg["rings"]))


def _part_names(kind: str) -> tuple[str, ...]:
    return BOX_SIDES if kind == "box" else CYLINDER_PARTS


def _label(radius: float, height: float):
    """The printed label: red, a white band, a yellow disc, a blue L and a barcode-like patch,
    laid out over angle phi (from +X towards -Z) and height y: no rotational symmetry."""
    red, white, yellow, blue, black = (
        np.array(c)
        for c in ([0.72, 0.08, 0.06], [0.9, 0.9, 0.88], [0.95, 0.78, 0.1], [0.1, 0.2, 0.65], [0.05, 0.05, 0.05])
    )

    def shader(pos, nrm):
        phi = np.mod(np.arctan2(-pos[:, 2], pos[:, 0]), 2 * np.pi)
        y = pos[:, 1] / height  # -0.5 .. 0.5
        arc = phi * radius  # meters along the label
        out = np.broadcast_to(red, (len(pos), 3)).copy()
        out[(y > -0.28) & (y < -0.18)] = white
        disc = (arc - 0.3 * radius) ** 2 + ((y - 0.15) * height) ** 2 < 0.018**2
        out[disc] = yellow
        la, ly = arc - 2.2 * radius, (y + 0.05) * height  # an L: a vertical bar and a foot
        ell = ((la > 0) & (la < 0.006) & (ly > 0) & (ly < 0.04)) | ((la > 0) & (la < 0.025) & (ly > 0) & (ly < 0.006))
        out[ell] = blue
        bars = (phi > 3.6) & (phi < 5.0) & (y > 0.05) & (y < 0.35) & (np.floor(phi / 0.09).astype(np.int64) % 3 != 0)
        out[bars] = black
        return out

    return shader


def _cap(radius: float, tab: bool):
    """Brushed-metal grey with a darker rim ring and (on top) an off-centre pull tab."""

    def shader(pos, nrm):
        r = np.hypot(pos[:, 0], pos[:, 2]) / radius
        out = np.full((len(pos), 3), 0.55)
        out[r > 0.85] = 0.3
        if tab:
            tx, tz = pos[:, 0] / radius - 0.35, pos[:, 2] / radius
            out[(tx / 0.3) ** 2 + (tz / 0.18) ** 2 < 1] = 0.15
        return out

    return shader


# 5 x 4 bitmaps of letters that no turn or mirror maps onto themselves (or onto each other).
_GLYPHS = {
    "F": ("####", "#...", "###.", "#...", "#..."),
    "R": ("###.", "#..#", "###.", "#.#.", "#..#"),
    "G": (".###", "#...", "#.##", "#..#", ".###"),
    "P": ("###.", "#..#", "###.", "#...", "#..."),
    "J": ("..##", "...#", "...#", "#..#", ".##."),
    "L": ("#...", "#...", "#...", "#...", "####"),
}
# One base colour per face (BOX_SIDES order) and the glyph printed on it.
_BOX_FACES = (
    ([0.70, 0.10, 0.08], "F"),
    ([0.10, 0.45, 0.15], "R"),
    ([0.12, 0.22, 0.62], "G"),
    ([0.85, 0.70, 0.10], "P"),
    ([0.85, 0.40, 0.08], "J"),
    ([0.45, 0.15, 0.50], "L"),
)
_INKS = np.array([[0.9, 0.9, 0.88], [0.05, 0.05, 0.05], [0.95, 0.8, 0.1], [0.1, 0.6, 0.75], [0.8, 0.15, 0.35]])


def _face_coordinates(pos: np.ndarray, side: int) -> tuple[np.ndarray, np.ndarray]:
    """(u, v) on a box side in meters: right and up as seen from outside the box, so prints
    read unmirrored on every side."""
    name = BOX_SIDES[side]
    axis = "xyz".index(name[1])
    ia, ib = PLANE_AXES[axis]
    sign = 1.0 if name[0] == "+" else -1.0
    return sign * pos[:, ia], pos[:, ib]


def _box_print(size, side: int):
    """One side of the colour box: its base colour, diagonal stripes along part of its lower
    edge, a dozen ink blobs at fixed random places and a large letter off-centre. Nothing on it
    maps onto itself by a turn or a mirror, and the sides differ in colour and letter, so each
    side and its turn can be identified (and feature matchers find corners at several scales)."""
    name = BOX_SIDES[side]
    axis = "xyz".index(name[1])
    ia, ib = PLANE_AXES[axis]
    hu, hv = size[ia] / 2, size[ib] / 2
    base, letter = _BOX_FACES[side]
    layout = np.random.default_rng(1009 + side)  # the print is the object's, not the scene seed's
    blobs = [
        (
            layout.uniform(-0.85, 0.85) * hu,
            layout.uniform(-0.85, 0.85) * hv,
            layout.uniform(0.06, 0.2) * min(hu, hv),
            _INKS[layout.integers(len(_INKS))],
        )
        for _ in range(12)
    ]
    glyph = np.array([[c == "#" for c in row] for row in _GLYPHS[letter]])
    cell = 0.55 * min(hu, hv) / 2.5  # the letter is 5 cells tall, a bit over half the short edge
    gu0, gv0 = -0.75 * hu, 0.8 * hv  # its top-left corner, in the upper left quadrant
    ink = _INKS[1] if np.mean(base) > 0.35 else _INKS[0]

    def shader(pos, nrm):
        u, v = _face_coordinates(pos, side)
        out = np.broadcast_to(np.asarray(base, np.float64), (len(pos), 3)).copy()
        stripes = (v < -0.55 * hv) & (u > -0.2 * hu) & (np.floor((u + v) / (0.12 * hv)).astype(np.int64) % 2 == 0)
        out[stripes] = _INKS[0]
        for bu, bv, r, colour in blobs:
            out[(u - bu) ** 2 + (v - bv) ** 2 < r * r] = colour
        col = np.floor((u - gu0) / cell).astype(np.int64)
        row = np.floor((gv0 - v) / cell).astype(np.int64)
        inside = (col >= 0) & (col < glyph.shape[1]) & (row >= 0) & (row < glyph.shape[0])
        on = np.zeros(len(pos), bool)
        on[inside] = glyph[row[inside], col[inside]]
        out[on] = ink
        return out

    return shader


def _object_materials(cfg) -> list[Material]:
    """The object's materials in its part order (``_part_names``)."""
    ocfg = cfg["object"]
    if ocfg["kind"] == "box":
        size = np.asarray(ocfg["size"], np.float64)
        return [Material(kd=_box_print(size, k), ks=cfg["ks"], ka=cfg["ka"]) for k in range(len(BOX_SIDES))]
    return [
        Material(kd=_label(ocfg["radius"], ocfg["height"]), ks=cfg["ks"], ka=cfg["ka"]),
        Material(kd=_cap(ocfg["radius"], tab=True), ks=cfg["cap_ks"], ka=cfg["cap_ka"]),
        Material(kd=_cap(ocfg["radius"], tab=False), ks=cfg["cap_ks"], ka=cfg["cap_ka"]),
    ]


def _tiles(tile: float, rng: np.random.Generator):
    """Square tiles with per-tile tint in two colours and dark grout lines."""
    tint = rng.random((64, 64))
    a, b = np.array([0.75, 0.7, 0.6]), np.array([0.45, 0.47, 0.5])

    def shader(pos, nrm):
        i = np.floor(pos[:, 0] / tile).astype(np.int64)
        k = np.floor(pos[:, 2] / tile).astype(np.int64)
        base = np.where(((i + k) % 2 == 0)[:, None], a, b)
        out = base * (0.85 + 0.3 * tint[i % 64, k % 64])[:, None]
        fx, fz = pos[:, 0] / tile - i, pos[:, 2] / tile - k
        grout = np.minimum(np.minimum(fx, 1 - fx), np.minimum(fz, 1 - fz)) < 0.04
        out[grout] = 0.2
        return np.clip(out, 0, 1)

    return shader


def _random_rotation(rng: np.random.Generator) -> np.ndarray:
    """Uniform on SO(3): a normalised Gaussian quaternion."""
    w, x, y, z = (q := rng.normal(size=4)) / np.linalg.norm(q)
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
            [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
            [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
        ]
    )


def _rotation(axis: int, angle: float) -> np.ndarray:
    """The rotation by ``angle`` radians about coordinate axis ``axis`` (right hand)."""
    c, s = np.cos(angle), np.sin(angle)
    i, j = PLANE_AXES[axis]
    R = np.eye(3)
    R[i, i], R[i, j], R[j, i], R[j, j] = c, -s, s, c
    return R


def _rest_rotation(kind: str, orientation: str, rng: np.random.Generator) -> np.ndarray:
    """How a copy lies before its yaw: upright (+Y up), upside down, or lying on its side (a
    can rolled by a uniform angle about its axis; a box on one of its four x or z sides)."""
    if orientation == "upright":
        return np.eye(3)
    if orientation == "upside_down":
        return _rotation(0, np.pi)
    if kind == "box":
        axis, sign = [(2, 1), (2, -1), (0, 1), (0, -1)][rng.integers(4)]
        return _rotation(axis, sign * np.pi / 2)
    return _rotation(2, np.pi / 2) @ _rotation(1, rng.uniform(0, 2 * np.pi))


def _draw_rotation(kind: str, orientation: str, rng: np.random.Generator, max_yaw_deg: float = 180.0) -> np.ndarray:
    """A copy's rotation: uniform on SO(3) ("random"), else its rest rotation turned about the
    floor normal by a uniform yaw (a turn in the image plane under a camera looking down), within
    +-max_yaw_deg (180: any; a smaller range makes copies that show the same faces)."""
    if orientation == "random":
        return _random_rotation(rng)
    rest = _rest_rotation(kind, orientation, rng)
    if max_yaw_deg >= 180.0:
        return _rotation(1, rng.uniform(0, 2 * np.pi)) @ rest
    return _rotation(1, np.radians(rng.uniform(-max_yaw_deg, max_yaw_deg))) @ rest


def _unique_directions(vectors: np.ndarray) -> np.ndarray:
    """Unit vectors of ``vectors`` without the zero ones, one per direction up to sign."""
    n = np.linalg.norm(vectors, axis=1)
    v = vectors[n > 1e-12] / n[n > 1e-12, None]
    lead = np.take_along_axis(v, np.argmax(np.abs(v) > 1e-9, axis=1)[:, None], axis=1)
    v = v * np.sign(lead)
    return np.unique(np.round(v, 9), axis=0)


class ConvexShape:
    """A convex mesh as the separating-axis test needs it: its vertices, its face normals and
    its edge directions (each once, up to sign)."""

    def __init__(self, positions, faces):
        self.points = np.asarray(positions, np.float64)
        tri = self.points[np.asarray(faces)]
        self.normals = _unique_directions(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]))
        self.edges = _unique_directions(
            np.concatenate([tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 1], tri[:, 0] - tri[:, 2]])
        )

    def axes(self, Ra: np.ndarray, Rb: np.ndarray) -> np.ndarray:
        """The candidate separating axes of this shape turned by Ra against it turned by Rb:
        both sets of face normals and every cross product of an edge of one with one of the
        other. For convex polyhedra the set is complete: no separation along any of them means
        the two intersect."""
        ea, eb = self.edges @ Ra.T, self.edges @ Rb.T
        cross = np.cross(ea[:, None, :], eb[None, :, :]).reshape(-1, 3)
        return np.concatenate([self.normals @ Ra.T, self.normals @ Rb.T, _unique_directions(cross)])


def _separations(shape: ConvexShape, Ta: np.ndarray, Tb: np.ndarray, direction=None):
    """Per candidate axis: the gap c between copy a and copy b along it (negative: overlap),
    and how fast it grows as b moves along ``direction`` (k, zero without one)."""
    axes = shape.axes(Ta[:3, :3], Tb[:3, :3])
    pa = (shape.points @ Ta[:3, :3].T + Ta[:3, 3]) @ axes.T
    pb = (shape.points @ Tb[:3, :3].T + Tb[:3, 3]) @ axes.T
    ahead = pb.min(0) - pa.max(0)  # b beyond a along +axis
    behind = pa.min(0) - pb.max(0)  # b before a
    k = np.zeros(len(axes)) if direction is None else axes @ np.asarray(direction, np.float64)
    return np.concatenate([ahead, behind]), np.concatenate([k, -k])


def convex_gap(shape: ConvexShape, Ta: np.ndarray, Tb: np.ndarray) -> float:
    """The largest separation of two copies of a convex ``shape`` at poses Ta and Tb along any
    candidate axis: > 0 they are apart (by at least that), <= 0 they touch or intersect."""
    gaps, _ = _separations(shape, Ta, Tb)
    return float(gaps.max())


def _contact_distance(shape: ConvexShape, Ta: np.ndarray, Tb: np.ndarray, direction: np.ndarray) -> float | None:
    """How far b (at Tb, overlapping a) must move along ``direction`` to just touch a. Every
    axis's gap grows linearly, c + s k; the copies are apart once any gap is >= 0, so the
    contact is the least root -c / k over the axes whose gap grows. None if they do not
    overlap to begin with."""
    c, k = _separations(shape, Ta, Tb, direction)
    if c.max() >= 0:
        return None
    grows = k > 1e-12
    return float(np.min(-c[grows] / k[grows]))


def _in_view(points: np.ndarray, camera, margin: float) -> bool:
    uv = project_points(camera, points)
    if not np.all(np.isfinite(uv)):
        return False
    return bool(uv.min() >= margin and np.all(uv.max(axis=0) <= [camera.width - margin, camera.height - margin]))


def _check_placement(cfg) -> tuple[list[str], int]:
    p, count = cfg["placement"], int(cfg["count"])
    orientations = list(p["orientations"])
    if not orientations or any(o not in ORIENTATIONS for o in orientations):
        raise ValueError(
            f"config.placement.orientations: {orientations!r}; expected a list drawn from {list(ORIENTATIONS)}"
        )
    touching = int(p["touching"])
    if not 0 <= touching < max(count, 1):
        raise ValueError(f"config.placement.touching: {touching}; expected 0 .. count - 1 = {count - 1}")
    return orientations, touching


def _place(obj_positions, shape: ConvexShape, camera, cfg, rng):
    """Poses of the copies and the touching pairs (earlier id, later id).

    Copy i lies as ``orientations[i mod len]``, its lowest point 0 .. max_lift above the floor
    and every vertex inside the image. A free copy keeps its bounding sphere ``gap`` away from
    every other; one of the last ``touching`` copies starts at an earlier copy's centre and is
    pushed out along a random floor direction until the two meshes just touch."""
    p, kind, count = cfg["placement"], cfg["object"]["kind"], int(cfg["count"])
    orientations, touching = _check_placement(cfg)
    radius = np.linalg.norm(obj_positions, axis=1).max()
    ex, ez = np.asarray(p["extent"], np.float64) / 2
    margin = float(p["margin_px"])
    poses, pairs = [], []
    for _ in range(int(p["attempts"])):
        if len(poses) == count:
            break
        i = len(poses)
        toucher = i >= count - touching
        partner = int(rng.integers(i)) if toucher else None
        R = _draw_rotation(kind, orientations[i % len(orientations)], rng, float(p.get("max_yaw_deg", 180.0)))
        rotated = obj_positions @ R.T
        if toucher:
            angle = rng.uniform(0, 2 * np.pi)
            t = poses[partner][:3, 3].copy()
        else:
            t = np.array([rng.uniform(-ex, ex), 0.0, rng.uniform(-ez, ez)])
        t[1] = -rotated[:, 1].min() + rng.uniform(0, p["max_lift"])
        if toucher:
            T = np.eye(4)
            T[:3, :3], T[:3, 3] = R, t
            direction = np.array([np.cos(angle), 0.0, np.sin(angle)])
            s = _contact_distance(shape, poses[partner], T, direction)
            if s is None:
                continue
            t = t + s * direction
        others = [q for j, q in enumerate(poses) if j != partner]
        if any(np.linalg.norm((t - q[:3, 3])[[0, 2]]) < 2 * radius + p["gap"] for q in others):
            continue
        if not _in_view(rotated + t, camera, margin):
            continue
        T = np.eye(4)
        T[:3, :3], T[:3, 3] = R, t
        poses.append(T)
        if toucher:
            pairs.append((partner + 1, i + 1))
    if len(poses) < count:
        raise ValueError(
            f"config.placement: could place only {len(poses)} of {count} objects apart and in view; "
            "expected a larger extent, a wider camera view, fewer objects or fewer touching"
        )
    return poses, pairs


def make_duplicates(config: dict | None = None) -> tuple[Scene, dict]:
    """Build the duplicates scene and its JSON-serialisable metadata (with ``poses`` in the
    poses.json form of scene/poses.py). ``config`` overrides ``DUPLICATES_DEFAULTS`` (or the preset it
    names) key by key."""
    cfg = resolve_config(config)
    _check_placement(cfg)  # before the atlas is baked
    rng = np.random.default_rng(cfg["seed"])
    ocfg, fcfg = cfg["object"], cfg["floor"]
    obj = build_object(cfg)
    kind = ocfg["kind"]

    # The template: floor (world frame) + one object (object frame), faces grouped by part.
    fx, fz = (s / 2 for s in fcfg["size"])
    floor = axis_grid(1, 0.0, +1, subdivide_breaks(-fz, fz, fcfg["cell"]), subdivide_breaks(-fx, fx, fcfg["cell"]))
    positions = np.concatenate([floor.positions, obj.positions])
    faces = np.concatenate([floor.faces, obj.faces + len(floor.positions)])
    part = np.concatenate([np.full(len(floor.faces), FLOOR), obj.part + OBJECT]).astype(np.int32)
    is_obj_vertex = np.arange(len(positions)) >= len(floor.positions)
    # Scale the object for the unwrap so it gets object_texel_share of the texels.
    share = float(cfg["object_texel_share"])
    area_floor = triangle_areas(floor.positions, floor.faces).sum()
    area_obj = triangle_areas(obj.positions, obj.faces).sum()
    scale = np.sqrt(share / (1 - share) * area_floor / area_obj)
    unwrap_positions = np.where(is_obj_vertex[:, None], positions * scale, positions)
    atlas = unwrap(
        unwrap_positions, faces, resolution=int(cfg["atlas_resolution"]), padding=int(cfg["atlas_padding"]), groups=part
    )
    template = Mesh(positions=positions[atlas.vertex_map].astype(np.float32), faces=atlas.faces, uvs=atlas.uvs)

    materials = {FLOOR: Material(kd=_tiles(fcfg["tile"], rng), ks=cfg["ks"], ka=cfg["ka"])}
    materials.update({OBJECT + k: m for k, m in enumerate(_object_materials(cfg))})
    texels = rasterize_atlas(template, atlas.height, atlas.width)
    maps = bake_materials(texels, part, materials, dilation=max(1, int(cfg["atlas_padding"])))
    maps = Maps(**maps, kg=sky_cube_map(cfg["environment"]))

    # Split the template into the floor and the object (own vertex lists, shared UVs).
    def submesh(face_sel):
        f = template.faces[face_sel]
        used, inverse = np.unique(f, return_inverse=True)
        return template.positions[used].astype(np.float64), inverse.reshape(-1, 3).astype(np.int32), template.uvs[used]

    floor_pos, floor_faces, floor_uvs = submesh(part == FLOOR)
    obj_pos, obj_faces, obj_uvs = submesh(part != FLOOR)

    c = cfg["camera"]
    el, az = np.radians(c["elevation_deg"]), np.radians(c["azimuth_deg"])
    eye = c["distance"] * np.array([np.cos(el) * np.sin(az), np.sin(el), np.cos(el) * np.cos(az)])
    camera = pinhole_camera("view_000.exr", eye, [0.0, 0.0, 0.0], c["width"], c["height"], c["fov_deg"])
    poses, pairs = _place(obj_pos, ConvexShape(obj.positions, obj.faces), camera, cfg, rng)
    orientations = cfg["placement"]["orientations"]

    # The combined mesh: floor, then copy 1 .. N (object faces in template order).
    pos_list, face_list, uv_list, inst = [floor_pos], [floor_faces], [floor_uvs], [np.zeros(len(floor_faces), np.int32)]
    offset = len(floor_pos)
    ranges = []
    for i, T in enumerate(poses, 1):
        pos_list.append(obj_pos @ T[:3, :3].T + T[:3, 3])
        face_list.append(obj_faces + offset)
        uv_list.append(obj_uvs)
        inst.append(np.full(len(obj_faces), i, np.int32))
        start_face = sum(len(f) for f in face_list[:-1])
        ranges.append(
            {
                "instance_id": i,
                "faces": [start_face, start_face + len(obj_faces)],
                "vertices": [offset, offset + len(obj_pos)],
                "orientation": orientations[(i - 1) % len(orientations)],
                "touches": sorted({a for a, b in pairs if b == i} | {b for a, b in pairs if a == i}),
            }
        )
        offset += len(obj_pos)
    mesh = Mesh(
        positions=np.concatenate(pos_list).astype(np.float32),
        faces=np.concatenate(face_list).astype(np.int32),
        uvs=np.concatenate(uv_list).astype(np.float32),
        instance_ids=np.concatenate(inst),
    )
    scene = Scene(mesh=mesh, maps=maps, cameras=[camera])

    names = _part_names(kind)
    obj_part = part[part != FLOOR] - OBJECT
    obj_bounds = np.searchsorted(obj_part, np.arange(len(names) + 1))
    metadata = {
        "generator": "invrender.synthesize.duplicates",
        "kind": "duplicates",
        "seed": int(cfg["seed"]),
        "config": cfg,
        "triangle_count": int(len(mesh.faces)),
        "atlas": {
            "height": atlas.height,
            "width": atlas.width,
            "padding": int(cfg["atlas_padding"]),
            "coverage": float(texels.mask.mean()),
            "object_unwrap_scale": float(scale),
        },
        "floor": {"faces": [0, len(floor_faces)], "vertices": [0, len(floor_pos)]},
        "object": {
            "vertex_count": int(len(obj_pos)),
            "face_count": int(len(obj_faces)),
            "parts": [
                {"name": name, "faces": [int(obj_bounds[k]), int(obj_bounds[k + 1])]} for k, name in enumerate(names)
            ],
            "kind": kind,
            "symmetry": _SYMMETRY[kind],
        },
        "touching": [list(pair) for pair in pairs],
        "copies": ranges,
        "poses": {
            "convention": _poses_convention(kind),
            "symmetry": _SYMMETRY[kind],
            "scale": "metric: the ground truth of a synthetic scene, in meters",
            "instances": [
                {"instance_id": i, "mask_value": i, "registered": True, "T_obj2world": T.tolist()}
                for i, T in enumerate(poses, 1)
            ],
        },
    }
    return scene, metadata


def object_mesh(scene: Scene, metadata: dict, instance_id: int = 1) -> Mesh:
    """The shared object in its own frame (with its atlas UVs), taken from one copy of a
    duplicates scene and moved back by that copy's true pose."""
    copy = next(c for c in metadata["copies"] if c["instance_id"] == instance_id)
    pose = next(p for p in metadata["poses"]["instances"] if p["instance_id"] == instance_id)
    T = np.asarray(pose["T_obj2world"], np.float64)
    v0, v1 = copy["vertices"]
    f0, f1 = copy["faces"]
    world = scene.mesh.positions[v0:v1].astype(np.float64)
    local = (world - T[:3, 3]) @ T[:3, :3]  # R^T (p - t), row-vector form
    return Mesh(
        positions=local.astype(np.float32),
        faces=(scene.mesh.faces[f0:f1] - v0).astype(np.int32),
        uvs=scene.mesh.uvs[v0:v1].copy(),
        instance_ids=None,
    )
