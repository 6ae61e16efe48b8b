"""Several copies of one textured object at known 6-DoF poses: the ground truth for the
duplicates (Structure from Duplicates) mode.

The object is a can: a capped cylinder with a printed label on its side (stripes, a disc and
an L-shaped mark, deliberately not rotationally symmetric so a pose can be recovered from
its appearance) and metallic-ish caps with an off-centre tab. Copies rest on or float just
above a tiled floor quad; there are no walls, so every ray that misses escapes to kg.

Shared atlas. All copies read the same texels: the object is unwrapped once, packed in one
xatlas atlas beside the floor, and every copy gets the object's UVs. This is the SfD model
(one shared mesh and one shared material), so an optimiser updates one material from all
copies at once, and the export can instance one mesh. The object's positions are scaled up
for the unwrap so it gets ``object_texel_share`` of the atlas area instead of its tiny
fraction of the surface area.

Poses: ``T_obj2world`` row-major 4 x 4, p_world = T [p_obj, 1]; the object frame is the can's
(centred at its centroid, axis +Y, label seam at +X), as written to
``ground_truth/object.ply``.
"""

from __future__ import annotations

import numpy as np

from ..scene.atlas import rasterize_atlas, triangle_areas, unwrap
from ..scene.cameras import project_points
from ..scene.types import Maps, Mesh, Scene
from .primitives import CYLINDER_PARTS, axis_grid, cylinder, subdivide_breaks
from .room import ENVIRONMENT_DEFAULTS, Material, bake_materials, merge_config, pinhole_camera, sky_cube_map

__all__ = ["DUPLICATES_DEFAULTS", "make_duplicates", "build_object", "object_mesh", "POSES_CONVENTION"]

DUPLICATES_DEFAULTS = {
    "seed": 0,
    "count": 6,
    "object": {"radius": 0.033, "height": 0.122, "segments": 32, "rings": 3},
    "floor": {"size": [1.0, 0.8], "cell": 0.1, "tile": 0.1},  # x, z extents; centred at the origin
    "placement": {
        "extent": [0.5, 0.36],  # centres are drawn in this x, z rectangle around the origin
        "max_lift": 0.03,  # lowest point of a copy is 0 .. max_lift above the floor
        "gap": 0.01,  # least clearance between two copies' bounding spheres
        "margin_px": 2,  # every vertex of every copy projects this far inside the image
        "attempts": 2000,
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

POSES_CONVENTION = (
    "p_world = T_obj2world @ [p_obj, 1]; T_obj2world row-major 4x4; world = the capture's COLMAP world "
    "(meters, +Y up, floor at y = 0); object frame = ground_truth/object.ply (the can centred at its "
    "centroid, axis +Y, label seam at +X)"
)

FLOOR, LABEL, TOP, BOTTOM = 0, 1, 2, 3  # part labels of the template (floor + one object)


def build_object(config: dict | None = None):
    """The can in its object frame: (positions (V, 3) float64, faces (F, 3) int32, part (F,)
    with 0 side/label, 1 top, 2 bottom: ``primitives.CYLINDER_PARTS``)."""
    cfg = merge_config(DUPLICATES_DEFAULTS, config)["object"]
    return cylinder(cfg["radius"], cfg["height"], int(cfg["segments"]), int(cfg["rings"]))


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


def _place(obj_positions, camera, cfg, rng) -> list[np.ndarray]:
    """Random poses: uniform rotation, lowest point 0 .. max_lift above the floor, centres apart
    by their bounding spheres, every vertex inside the image."""
    p = cfg["placement"]
    radius = np.linalg.norm(obj_positions, axis=1).max()
    ex, ez = np.asarray(p["extent"], np.float64) / 2
    margin = float(p["margin_px"])
    poses = []
    for _ in range(int(p["attempts"])):
        if len(poses) == int(cfg["count"]):
            break
        R = _random_rotation(rng)
        rotated = obj_positions @ R.T
        t = np.array([rng.uniform(-ex, ex), 0.0, rng.uniform(-ez, ez)])
        t[1] = -rotated[:, 1].min() + rng.uniform(0, p["max_lift"])
        if any(np.linalg.norm((t - q[:3, 3])[[0, 2]]) < 2 * radius + p["gap"] for q in poses):
            continue
        uv = project_points(camera, rotated + t)
        if not np.all(np.isfinite(uv)):
            continue
        if uv.min() < margin or np.any(uv.max(axis=0) > [camera.width - margin, camera.height - margin]):
            continue
        T = np.eye(4)
        T[:3, :3], T[:3, 3] = R, t
        poses.append(T)
    if len(poses) < int(cfg["count"]):
        raise ValueError(
            f"config.placement: could place only {len(poses)} of {cfg['count']} objects apart and in view; "
            "expected a larger extent, a wider camera view or fewer objects"
        )
    return poses


def make_duplicates(config: dict | None = None) -> tuple[Scene, dict]:
    """Build the duplicates scene and its JSON-serialisable metadata (with ``poses`` in the
    DESIGN.md poses.json form). ``config`` overrides ``DUPLICATES_DEFAULTS`` key by key."""
    cfg = merge_config(DUPLICATES_DEFAULTS, config)
    rng = np.random.default_rng(cfg["seed"])
    ocfg, fcfg = cfg["object"], cfg["floor"]
    obj = build_object(cfg)

    # The template: floor (world frame) + one object (object frame), faces grouped by part.
    fx, fz = (s / 2 for s in fcfg["size"])
    floor = axis_grid(1, 0.0, +1, subdivide_breaks(-fz, fz, fcfg["cell"]), subdivide_breaks(-fx, fx, fcfg["cell"]))
    positions = np.concatenate([floor.positions, obj.positions])
    faces = np.concatenate([floor.faces, obj.faces + len(floor.positions)])
    part = np.concatenate([np.full(len(floor.faces), FLOOR), obj.part + LABEL]).astype(np.int32)
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

    materials = {
        FLOOR: Material(kd=_tiles(fcfg["tile"], rng), ks=cfg["ks"], ka=cfg["ka"]),
        LABEL: Material(kd=_label(ocfg["radius"], ocfg["height"]), ks=cfg["ks"], ka=cfg["ka"]),
        TOP: Material(kd=_cap(ocfg["radius"], tab=True), ks=cfg["cap_ks"], ka=cfg["cap_ka"]),
        BOTTOM: Material(kd=_cap(ocfg["radius"], tab=False), ks=cfg["cap_ks"], ka=cfg["cap_ka"]),
    }
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
    poses = _place(obj_pos, camera, cfg, rng)

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

    obj_part = part[part != FLOOR] - LABEL
    obj_bounds = np.searchsorted(obj_part, np.arange(len(CYLINDER_PARTS) + 1))
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
                {"name": name, "faces": [int(obj_bounds[k]), int(obj_bounds[k + 1])]}
                for k, name in enumerate(CYLINDER_PARTS)
            ],
        },
        "copies": ranges,
        "poses": {
            "convention": POSES_CONVENTION,
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
