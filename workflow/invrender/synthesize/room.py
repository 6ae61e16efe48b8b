"""A parametric room with known parameter maps: the ground truth for the multiview (MILO) mode.

A box room seen from inside (+Y up, floor at y = 0, centred on x and z): wood-plank floor,
striped walls with a wainscot, a window opening (a separate coplanar quad in a hole of one
wall: kd = ks = 0, kw = 1), textured emitting ceiling panels (separate coplanar quads in holes
of the ceiling: kd = ks = 0, ke brighter in the centre), a couple of boxes and a glossy table.
Outside is a kg cube map: sky gradient, ground, a small bright sun.

Geometry is unwrapped with xatlas (one group per part, so charts never straddle two
materials), rasterised into the atlas, and the procedural materials are evaluated at each
texel's 3D point and dilated (``scene.atlas``). Everything follows from the config and its
seed.

This module also holds what the other synthetic scene (``duplicates.py``) shares with it:
``Material`` / ``bake_materials``, ``sky_cube_map``, and (from ``scene/cameras.py``) ``look_at`` and
``pinhole_camera``.
"""

from __future__ import annotations

import copy
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from ..scene.atlas import bake, rasterize_atlas, unwrap
from ..scene.cameras import look_at, pinhole_camera
from ..scene.cubemap import texel_directions
from ..scene.types import Camera, Maps, Mesh, Scene
from ..assets.primitives import Primitive, axis_grid, box, concatenate, subdivide_breaks

__all__ = [
    "ROOM_DEFAULTS",
    "ENVIRONMENT_DEFAULTS",
    "make_room",
    "Material",
    "bake_materials",
    "sky_cube_map",
    "look_at",
    "pinhole_camera",
    "merge_config",
]

ENVIRONMENT_DEFAULTS = {
    "size": 16,  # N of the 6 x N x N kg cube map
    "sky_zenith": [0.35, 0.55, 1.0],  # radiance straight up
    "sky_horizon": [1.1, 1.1, 1.15],  # radiance at the horizon
    "ground": [0.25, 0.21, 0.16],  # radiance below the horizon
    "sun_elevation_deg": 35.0,
    "sun_azimuth_deg": 20.0,  # from -Z towards +X: the default sun shines in through a -Z window
    "sun_radius_deg": 4.0,  # the texel nearest the sun is always lit, whatever the radius
    "sun_radiance": [150.0, 142.0, 128.0],
}

ROOM_DEFAULTS = {
    "seed": 0,
    "size": [4.0, 2.6, 3.0],  # x, y (height), z extents in meters
    "cell": 0.25,  # largest triangle-pair cell of the shell and furniture, meters
    # The window: which wall (the name of the axis its inward normal points against:
    # "-z" is the wall at z = -size_z / 2), its centre (along the wall, height) and size.
    "window": {"wall": "-z", "center": [0.0, 1.45], "size": [1.6, 1.1]},
    # Ceiling lights: centre (x, z) and size (x, z) of each emitting panel.
    "lights": [
        {"center": [-0.9, 0.0], "size": [0.6, 0.6]},
        {"center": [0.9, 0.0], "size": [0.6, 0.6]},
    ],
    "light_radiance": 12.0,  # ke at a panel's centre (times light_color)
    "light_falloff": 0.5,  # ke at its edge = centre * (1 - falloff)
    "light_color": [1.0, 0.93, 0.82],
    # Furniture: footprint centre (x, z), size (x, y, z); kind "box" or "table".
    "furniture": [
        {"name": "cabinet", "kind": "box", "center": [-1.2, 1.2], "size": [0.9, 0.8, 0.45]},
        {"name": "crate", "kind": "box", "center": [1.35, -0.85], "size": [0.5, 0.45, 0.5]},
        {"name": "table", "kind": "table", "center": [0.2, 0.15], "size": [1.2, 0.74, 0.7]},
    ],
    "furniture_jitter": 0.08,  # seeded shift of each piece's footprint, meters
    "ks": 0.04,  # specular albedo of every ordinary surface
    "ka": 0.3,  # its roughness (Beckmann alpha^2)
    "table_ks": 0.45,
    "table_ka": 0.02,
    "emitter_ka": 0.05,  # MILO's template value for light-emitting materials
    "atlas_resolution": 256,
    "atlas_padding": 2,
    "environment": ENVIRONMENT_DEFAULTS,
    "cameras": {
        "count": 6,
        "width": 96,
        "height": 72,
        "fov_deg": 65.0,  # horizontal
        "eye_height": 1.6,
        "wall_margin": 0.5,  # distance of the camera ellipse from the walls
        # Views aim at the room centre, then alternate views tilt up (ceiling lights, window)
        # and down (floor, furniture) by this fraction of half the vertical field of view.
        "tilt": 0.6,
        "jitter": 0.1,  # seeded perturbation of eyes and targets, meters
    },
}


# ---------------------------------------------------------------------------- config


def merge_config(defaults: dict, config: dict | None, where: str = "config") -> dict:
    """Defaults overridden by ``config``, recursively for dicts; lists are replaced whole.
    An unknown key stops with a message naming it."""
    out = copy.deepcopy(defaults)
    for key, value in (config or {}).items():
        if key not in defaults:
            raise ValueError(f"{where}: unknown key {key!r}; expected one of {sorted(defaults)}")
        if isinstance(defaults[key], dict) and isinstance(value, dict):
            out[key] = merge_config(defaults[key], value, f"{where}.{key}")
        else:
            out[key] = copy.deepcopy(value)
    return out


# ---------------------------------------------------------------------------- materials


Shader = Callable[[np.ndarray, np.ndarray], np.ndarray]  # (positions (n, 3), normals (n, 3)) -> values


@dataclass
class Material:
    """One part's parameter maps: each a constant or a shader of the texel's point and normal."""

    kd: object = 0.5
    ks: object = 0.04
    ka: object = 0.3
    ke: object = 0.0
    kw: object = 0.0


MAP_SPECS = (("kd", 3), ("ks", 3), ("ka", 1), ("ke", 3), ("kw", 1))
# Where no chart reaches (never looked up): black, and a valid roughness.
BACKGROUND = {"kd": 0.0, "ks": 0.0, "ka": 0.3, "ke": 0.0, "kw": 0.0}


def bake_materials(texels, face_part: np.ndarray, materials: dict[int, Material], dilation: int):
    """The five atlas maps (kd, ks, ka, ke, kw) of ``materials`` (by part label) over ``texels``."""
    face_part = np.asarray(face_part)
    maps = {}
    for name, channels in MAP_SPECS:

        def shade(tri, pos, nrm, name=name, channels=channels):
            out = np.zeros((len(tri), channels), np.float32)
            part = face_part[tri]
            for p, mat in materials.items():
                sel = part == p
                if not sel.any():
                    continue
                value = getattr(mat, name)
                if callable(value):
                    value = value(pos[sel].astype(np.float64), nrm[sel].astype(np.float64))
                value = np.asarray(value, np.float32)
                if value.ndim == 1 and channels == 1 and len(value) == sel.sum():
                    value = value[:, None]  # one value per texel of a one-channel map
                out[sel] = np.broadcast_to(value, (sel.sum(), channels))
            return out

        maps[name] = bake(texels, shade, channels, dilation, BACKGROUND[name])
    return maps


def _hash_table(rng: np.random.Generator, size: int = 256) -> Callable[..., np.ndarray]:
    """A seeded value in [0, 1) per integer lattice cell (procedural texture noise)."""
    table = rng.random(size)

    def lookup(*cells):
        h = np.zeros(np.shape(cells[0]), np.int64)
        for k, c in zip((73856093, 19349663, 83492791), cells):
            h ^= np.asarray(c, np.int64) * k
        return table[h % size]

    return lookup


def _wood_planks(rng, origin_x, origin_z, plank_width=0.18, plank_length=1.3, base=(0.50, 0.32, 0.17)) -> Shader:
    """Planks along x: per-plank tint, staggered joints, grain, dark gaps (on the y = const floor)."""
    tint, stagger, grain_phase = _hash_table(rng), _hash_table(rng), _hash_table(rng)

    def shader(pos, nrm):
        x, z = pos[:, 0] - origin_x, pos[:, 2] - origin_z
        row = np.floor(z / plank_width).astype(np.int64)
        xs = x + stagger(row) * plank_length
        seg = np.floor(xs / plank_length).astype(np.int64)
        f = 0.75 + 0.5 * tint(row, seg)
        grain = 1.0 + 0.08 * np.sin(2 * np.pi * (xs / 0.31 + 7.0 * grain_phase(row, seg)))
        dz = np.minimum(z - row * plank_width, (row + 1) * plank_width - z)
        dx = np.minimum(xs - seg * plank_length, (seg + 1) * plank_length - xs)
        gap = np.where(np.minimum(dz, dx) < 0.012, 0.4, 1.0)
        return np.clip(np.asarray(base)[None] * (f * grain * gap)[:, None], 0, 1)

    return shader


def _striped_wall(stripe=0.15, wainscot=0.9) -> Shader:
    """Vertical two-tone stripes above a blue-grey wainscot, on walls facing x or z."""
    light, dark, panel = np.array([0.80, 0.76, 0.67]), np.array([0.68, 0.64, 0.57]), np.array([0.42, 0.50, 0.56])

    def shader(pos, nrm):
        along = pos[:, 0] * np.abs(nrm[:, 2]) + pos[:, 2] * np.abs(nrm[:, 0])
        stripes = np.where((np.floor(along / stripe).astype(np.int64) % 2 == 0)[:, None], light, dark)
        return np.where((pos[:, 1] < wainscot)[:, None], panel, stripes)

    return shader


def _checker(color, cell=0.15, contrast=0.7) -> Shader:
    color = np.asarray(color, np.float64)

    def shader(pos, nrm):
        # Offset by half a cell so faces on cell boundaries do not sit on the checker edges.
        k = np.floor(pos / cell + 0.5).astype(np.int64).sum(axis=1) % 2
        return color[None] * np.where(k == 0, 1.0, contrast)[:, None]

    return shader


def _wood_grain(base=(0.30, 0.18, 0.10)) -> Shader:
    def shader(pos, nrm):
        g = 1.0 + 0.15 * np.sin(2 * np.pi * (pos[:, 0] / 0.07 + 3.0 * np.sin(pos[:, 2] / 0.11)))
        return np.clip(np.asarray(base)[None] * g[:, None], 0, 1)

    return shader


def _panel_emission(center, half, radiance, falloff, color) -> Shader:
    """ke of a ceiling panel: brightest at the centre, (1 - falloff) of that at the rim."""
    c, h, col = np.asarray(center, np.float64), np.asarray(half, np.float64), np.asarray(color, np.float64)

    def shader(pos, nrm):
        r2 = ((pos[:, 0] - c[0]) / h[0]) ** 2 + ((pos[:, 2] - c[1]) / h[1]) ** 2
        return radiance * col[None] * (1.0 - falloff * np.minimum(r2, 1.0))[:, None]

    return shader


# ---------------------------------------------------------------------------- environment


def sky_cube_map(env: dict) -> np.ndarray:
    """kg (6, N, N, 3): a sky gradient above the horizon, flat ground below, a small sun.
    Texel directions follow ``scene.cubemap`` (docs/renderer.md)."""
    n = int(env["size"])
    d = texel_directions(n)  # (6, N, N, 3)
    up = d[..., 1:2]
    t = np.sqrt(np.clip(up, 0, 1))
    sky = (1 - t) * np.asarray(env["sky_horizon"]) + t * np.asarray(env["sky_zenith"])
    ground = np.asarray(env["ground"]) * (1.0 - 0.3 * np.clip(-up, 0, 1))
    kg = np.where(up >= 0, sky, ground)
    el, az = np.radians(env["sun_elevation_deg"]), np.radians(env["sun_azimuth_deg"])
    sun = np.array([np.cos(el) * np.sin(az), np.sin(el), -np.cos(el) * np.cos(az)])
    cos_angle = d @ sun
    in_sun = cos_angle >= np.cos(np.radians(env["sun_radius_deg"]))
    in_sun.reshape(-1)[np.argmax(cos_angle)] = True
    kg[in_sun] = np.asarray(env["sun_radiance"])
    return kg.astype(np.float32)


# ---------------------------------------------------------------------------- cameras


# look_at and pinhole_camera live in scene/cameras.py (the edit stage places novel cameras too).


# ---------------------------------------------------------------------------- the room


WALL_CLEARANCE = 0.02  # least gap between furniture and walls, meters

WALLS = {  # name -> (axis, which end of the room, inward facing)
    "-x": (0, 0, +1),
    "+x": (0, 1, -1),
    "-z": (2, 0, +1),
    "+z": (2, 1, -1),
}


def _inside(a, b, rect) -> np.ndarray:
    (a0, a1), (b0, b1) = rect
    return (a > a0) & (a < a1) & (b > b0) & (b < b1)


def _room_geometry(cfg: dict, rng: np.random.Generator):
    """The room as labelled pieces: returns (mesh Primitive, part names, part instance ids,
    materials by part) with the Primitive's part labels indexing the names."""
    sx, sy, sz = map(float, cfg["size"])
    lo, hi = np.array([-sx / 2, 0.0, -sz / 2]), np.array([sx / 2, sy, sz / 2])
    cell = float(cfg["cell"])

    win = cfg["window"]
    if win["wall"] not in WALLS:
        raise ValueError(f"config.window.wall: expected one of {sorted(WALLS)}, got {win['wall']!r}")
    w_axis, w_end, w_facing = WALLS[win["wall"]]
    along_axis = 2 if w_axis == 0 else 0  # the wall's horizontal axis
    (wc, wy), (ww, wh) = win["center"], win["size"]
    win_along = (wc - ww / 2, wc + ww / 2)
    win_up = (wy - wh / 2, wy + wh / 2)
    if not (lo[along_axis] < win_along[0] and win_along[1] < hi[along_axis] and 0 < win_up[0] and win_up[1] < sy):
        raise ValueError("config.window: expected the window inside its wall")

    lights = []
    for i, light in enumerate(cfg["lights"]):
        (cx, cz), (lx, lz) = light["center"], light["size"]
        rect = ((cx - lx / 2, cx + lx / 2), (cz - lz / 2, cz + lz / 2))
        if not (lo[0] < rect[0][0] and rect[0][1] < hi[0] and lo[2] < rect[1][0] and rect[1][1] < hi[2]):
            raise ValueError(f"config.lights[{i}]: expected the panel inside the ceiling")
        lights.append(rect)

    # Every hole edge becomes a break line across the whole shell, so walls, floor and ceiling
    # share identical vertices along their common edges (watertight, no T-junctions).
    extra = [[], [*win_up], []]
    extra[along_axis] += list(win_along)
    for rect in lights:
        extra[0] += list(rect[0])
        extra[2] += list(rect[1])
    bx, by, bz = (subdivide_breaks(lo[k], hi[k], cell, extra[k]) for k in range(3))
    breaks = (bx, by, bz)

    names = ["floor", "wall", "ceiling", "window"] + [f"light_{i}" for i in range(len(lights))]
    FLOOR, WALL, CEILING, WINDOW = 0, 1, 2, 3
    pieces = [axis_grid(1, lo[1], +1, bz, bx, label=lambda z, x: np.full(z.shape, FLOOR))]

    def ceiling_label(z, x):
        label = np.full(z.shape, CEILING)
        for i, rect in enumerate(lights):
            label[_inside(x, z, rect)] = 4 + i
        return label

    pieces.append(axis_grid(1, hi[1], -1, bz, bx, label=ceiling_label))
    for name, (axis, end, facing) in WALLS.items():
        a_axis, b_axis = {0: (1, 2), 2: (0, 1)}[axis]  # axis_grid's in-plane axes

        def wall_label(a, b, name=name, a_axis=a_axis):
            label = np.full(a.shape, WALL)
            if name == win["wall"]:
                along, up = (b, a) if a_axis == 1 else (a, b)
                label[_inside(along, up, (win_along, win_up))] = WINDOW
            return label

        value = (lo, hi)[end][axis]
        pieces.append(axis_grid(axis, value, facing, breaks[a_axis], breaks[b_axis], label=wall_label))
    instance_of = [0] * len(names)

    # Materials of the shell.
    materials = {
        FLOOR: Material(kd=_wood_planks(rng, lo[0], lo[2]), ks=cfg["ks"], ka=cfg["ka"]),
        WALL: Material(kd=_striped_wall(), ks=cfg["ks"], ka=cfg["ka"]),
        CEILING: Material(kd=[0.85, 0.85, 0.83], ks=cfg["ks"], ka=cfg["ka"]),
        WINDOW: Material(kd=0.0, ks=0.0, ka=cfg["emitter_ka"], kw=1.0),
    }
    for i, rect in enumerate(lights):
        center = (0.5 * sum(rect[0]), 0.5 * sum(rect[1]))
        half = (0.5 * (rect[0][1] - rect[0][0]), 0.5 * (rect[1][1] - rect[1][0]))
        ke = _panel_emission(center, half, cfg["light_radiance"], cfg["light_falloff"], cfg["light_color"])
        materials[4 + i] = Material(kd=0.0, ks=0.0, ka=cfg["emitter_ka"], ke=ke)

    # Furniture: one part and one instance id per piece.
    palette = np.array(
        [[0.55, 0.22, 0.15], [0.20, 0.35, 0.55], [0.30, 0.50, 0.25], [0.65, 0.55, 0.25], [0.45, 0.45, 0.48]]
    )
    colors = palette[rng.permutation(len(palette))]
    jitter = float(cfg["furniture_jitter"])
    for k, piece in enumerate(cfg["furniture"]):
        part = len(names)
        names.append(piece["name"])
        instance_of.append(k + 1)
        centre = np.asarray(piece["center"], np.float64)
        half = np.array([piece["size"][0], piece["size"][2]], np.float64) / 2
        room_lo, room_hi = lo[[0, 2]] + half + WALL_CLEARANCE, hi[[0, 2]] - half - WALL_CLEARANCE
        if np.any(centre < room_lo) or np.any(centre > room_hi) or not 0 < piece["size"][1] < hi[1]:
            raise ValueError(
                f"config.furniture[{k}] ({piece['name']}): expected it inside the room, "
                f"{WALL_CLEARANCE} m from the walls"
            )
        # The seeded shift never pushes a piece into a wall.
        cx, cz = np.clip(centre + rng.uniform(-jitter, jitter, 2), room_lo, room_hi)
        fx, fy, fz = map(float, piece["size"])
        foot_lo, foot_hi = np.array([cx - fx / 2, 0.0, cz - fz / 2]), np.array([cx + fx / 2, fy, cz + fz / 2])
        if piece.get("kind", "box") == "table":
            mesh = _table(foot_lo, foot_hi, cell)
            materials[part] = Material(kd=_wood_grain(), ks=cfg["table_ks"], ka=cfg["table_ka"])
        elif piece.get("kind", "box") == "box":
            mesh = box(foot_lo, foot_hi, cell=cell, omit=("-y",))  # its bottom rests on the floor
            materials[part] = Material(kd=_checker(colors[k % len(colors)]), ks=cfg["ks"], ka=cfg["ka"])
        else:
            raise ValueError(f"config.furniture[{k}].kind: expected 'box' or 'table', got {piece['kind']!r}")
        pieces.append(Primitive(mesh.positions, mesh.faces, np.full(len(mesh.faces), part, np.int32)))

    return concatenate(pieces), names, instance_of, materials


def _table(lo, hi, cell, top=0.05, leg=0.06, inset=0.05) -> Primitive:
    """A table top slab on four legs (legs stand on the floor, their tops under the slab)."""
    top_lo = np.array([lo[0], hi[1] - top, lo[2]])
    pieces = [box(top_lo, hi, cell=cell)]
    for sx in (0, 1):
        for sz in (0, 1):
            x0 = lo[0] + inset if sx == 0 else hi[0] - inset - leg
            z0 = lo[2] + inset if sz == 0 else hi[2] - inset - leg
            pieces.append(box([x0, 0.0, z0], [x0 + leg, hi[1] - top, z0 + leg], cell=cell, omit=("-y", "+y")))
    return concatenate(pieces)


def _room_cameras(cfg: dict, rng: np.random.Generator) -> list[Camera]:
    """Eyes on an ellipse inside the walls, each looking across the room at its centre, tilted
    alternately up (ceiling lights, window) and down (floor, furniture) with the centre kept
    in view."""
    c = cfg["cameras"]
    sx, sy, sz = map(float, cfg["size"])
    a, b = sx / 2 - c["wall_margin"], sz / 2 - c["wall_margin"]
    if a <= 0 or b <= 0:
        raise ValueError("config.cameras.wall_margin: expected less than half the room's width and depth")
    n, jitter = int(c["count"]), float(c["jitter"])
    half_vfov = np.arctan(np.tan(np.radians(c["fov_deg"]) / 2) * c["height"] / c["width"])
    cams = []
    for i in range(n):
        angle = 2 * np.pi * (i + 0.5 * rng.uniform(-0.5, 0.5)) / n
        eye = np.array([a * np.cos(angle), c["eye_height"], b * np.sin(angle)]) + rng.uniform(-jitter, jitter, 3)
        aim = np.array([0.0, sy / 2, 0.0]) + rng.uniform(-jitter, jitter, 3) - eye
        elevation = np.arcsin(aim[1] / np.linalg.norm(aim)) + (1 if i % 2 else -1) * c["tilt"] * half_vfov
        heading = aim[[0, 2]] / np.linalg.norm(aim[[0, 2]])
        forward = np.array([np.cos(elevation) * heading[0], np.sin(elevation), np.cos(elevation) * heading[1]])
        cams.append(pinhole_camera(f"view_{i:03d}.exr", eye, eye + forward, c["width"], c["height"], c["fov_deg"]))
    return cams


def make_room(config: dict | None = None) -> tuple[Scene, dict]:
    """Build the room scene (mesh with UVs and instance ids, the six maps, cameras) and its
    JSON-serialisable metadata. ``config`` overrides ``ROOM_DEFAULTS`` key by key."""
    cfg = merge_config(ROOM_DEFAULTS, config)
    rng = np.random.default_rng(cfg["seed"])
    prim, names, instance_of, materials = _room_geometry(cfg, rng)

    # Faces grouped by part, so each part is one contiguous face range.
    order = np.argsort(prim.part, kind="stable")
    faces, part = prim.faces[order], prim.part[order]
    atlas = unwrap(
        prim.positions, faces, resolution=int(cfg["atlas_resolution"]), padding=int(cfg["atlas_padding"]), groups=part
    )
    mesh = Mesh(
        positions=atlas.positions.astype(np.float32),
        faces=atlas.faces,
        uvs=atlas.uvs,
        instance_ids=np.asarray(instance_of, np.int32)[part],
    )
    texels = rasterize_atlas(mesh, atlas.height, atlas.width)
    maps = bake_materials(texels, part, materials, dilation=max(1, int(cfg["atlas_padding"])))
    maps = Maps(**maps, kg=sky_cube_map(cfg["environment"]))
    cameras = _room_cameras(cfg, rng)
    scene = Scene(mesh=mesh, maps=maps, cameras=cameras)

    bounds = np.searchsorted(part, np.arange(len(names) + 1))
    metadata = {
        "generator": "invrender.synthesize.room",
        "kind": "room",
        "seed": int(cfg["seed"]),
        "config": cfg,
        "triangle_count": int(len(faces)),
        "atlas": {
            "height": atlas.height,
            "width": atlas.width,
            "padding": int(cfg["atlas_padding"]),
            "coverage": float(texels.mask.mean()),
        },
        "parts": [
            {
                "name": name,
                "faces": [int(bounds[p]), int(bounds[p + 1])],
                "instance_id": int(instance_of[p]),
                "emitter": name.startswith("light_"),
                "window": name == "window",
            }
            for p, name in enumerate(names)
        ],
        "instances": [{"instance_id": 0, "name": "room"}]
        + [{"instance_id": k + 1, "name": f["name"]} for k, f in enumerate(cfg["furniture"])],
        "room_bounds": [
            [-cfg["size"][0] / 2, 0.0, -cfg["size"][2] / 2],
            [cfg["size"][0] / 2, cfg["size"][1], cfg["size"][2] / 2],
        ],
    }
    return scene, metadata
