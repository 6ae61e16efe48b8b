"""Small closed rooms for the paper's ambiguity cases (MILO sections 3.3 and 4.4), written as the
milo stage's inputs, with the truth of every atlas texel known.

A room is an axis-aligned box seen from inside, its walls black (kd = ks = 0: they neither emit
nor reflect, so every photon the cameras see came from the patches), closed so that no ray
reaches the sky. Patches are rectangles of other materials cut into the walls (coplanar cells of
the same grid, as synthesize/room.py cuts its ceiling lights), each its own part, so that each
patch's texels are known from atlas.npz's triangle ids.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from invrender.render.analysis import analyse
from invrender.render.renderer import Renderer
from invrender.scene.atlas import AtlasTexels, rasterize_atlas, unwrap
from invrender.scene.cameras import pinhole_camera, write_colmap
from invrender.scene.images import write_exr
from invrender.scene.mesh_io import write_ply
from invrender.scene.types import Camera, Maps, Mesh, Scene
from invrender.assets.primitives import axis_grid, concatenate, subdivide_breaks
from invrender.synthesize.room import Material, bake_materials

BLACK = Material(kd=0.0, ks=0.0, ka=0.3)
# (axis, which end) of each wall by the name of the axis its inward normal points against,
# as synthesize/room.py names its window wall; the plane axes (a, b) are axis_grid's.
WALLS = {"-x": (0, 0), "+x": (0, 1), "-y": (1, 0), "+y": (1, 1), "-z": (2, 0), "+z": (2, 1)}
PLANE_AXES = {0: (1, 2), 1: (2, 0), 2: (0, 1)}


@dataclass
class Patch:
    """A rectangle of `material` on a wall: its centre and size along the wall's plane axes
    (a, b) = (y, z) on an x wall, (z, x) on a y wall, (x, y) on a z wall."""

    wall: str
    center: tuple[float, float]
    size: tuple[float, float]
    material: Material


@dataclass
class Fixture:
    scene: Scene  # the truth: mesh with UVs, maps, cameras
    texels: AtlasTexels
    face_part: np.ndarray  # (F,) index into `parts`
    parts: list[str]  # "room", then the patches' names

    def part_texels(self, name: str) -> np.ndarray:
        """(H, W) bool: the covered texels of one part."""
        part = self.parts.index(name)
        return self.texels.mask & (self.face_part[np.maximum(self.texels.triangle, 0)] == part)


def _breaks(lo, hi, patches: dict[str, Patch], cell: float) -> list[np.ndarray]:
    """Cell breaks along each world axis with every patch edge among them, shared by all walls
    (as primitives.box shares them), so walls meet edge to edge: no cracks, no T-junctions."""
    edges = [[], [], []]
    for p in patches.values():
        axes = PLANE_AXES[WALLS[p.wall][0]]
        for k, axis in enumerate(axes):
            edges[axis] += [p.center[k] - p.size[k] / 2, p.center[k] + p.size[k] / 2]
    return [subdivide_breaks(lo[k], hi[k], cell, edges[k]) for k in range(3)]


def _wall(lo, hi, name: str, breaks, patches: dict[str, Patch], parts: list[str]):
    axis, end = WALLS[name]
    ia, ib = PLANE_AXES[axis]
    mine = [(parts.index(key), p) for key, p in patches.items() if p.wall == name]

    def label(ca, cb):
        out = np.zeros(len(ca), np.int32)
        for part, p in mine:
            inside = (np.abs(ca - p.center[0]) < p.size[0] / 2) & (np.abs(cb - p.center[1]) < p.size[1] / 2)
            out[inside] = part
        return out

    value, facing = (lo[axis], 1) if end == 0 else (hi[axis], -1)  # fronts face into the room
    return axis_grid(axis, value, facing, breaks[ia], breaks[ib], label)


def closed_room(
    size,
    patches: dict[str, Patch],
    cameras: list[Camera],
    atlas_resolution: int = 48,
    cell: float = 0.25,
    sky_resolution: int = 4,
) -> Fixture:
    """A box [-x/2, x/2] x [0, y] x [-z/2, z/2] with black walls and `patches`, unwrapped into an
    `atlas_resolution` square atlas (one chart group per part, so no chart straddles two)."""
    lo = np.array([-size[0] / 2, 0.0, -size[2] / 2])
    hi = np.array([size[0] / 2, size[1], size[2] / 2])
    parts = ["room", *patches]
    breaks = _breaks(lo, hi, patches, cell)
    prim = concatenate([_wall(lo, hi, name, breaks, patches, parts) for name in WALLS], weld=True)
    order = np.argsort(prim.part, kind="stable")
    faces, part = prim.faces[order], prim.part[order]
    atlas = unwrap(prim.positions, faces, resolution=atlas_resolution, padding=2, groups=part)
    mesh = Mesh(positions=atlas.positions.astype(np.float32), faces=atlas.faces, uvs=atlas.uvs)
    texels = rasterize_atlas(mesh, atlas.height, atlas.width)
    materials = {0: BLACK, **{parts.index(key): p.material for key, p in patches.items()}}
    maps = bake_materials(texels, part, materials, dilation=2)
    kg = np.zeros((6, sky_resolution, sky_resolution, 3), np.float32)  # closed: never seen
    scene = Scene(mesh=mesh, maps=Maps(**maps, kg=kg), cameras=cameras)
    return Fixture(scene, texels, part, parts)


def ring_cameras(center, target, radius: float, count: int, width: int = 32, height: int = 24, fov=100.0):
    """`count` cameras on a horizontal circle around `center`, all looking at `target`; named as
    the images the stage reads (view_000.exr, ...)."""
    angles = 2 * np.pi * (np.arange(count) + 0.5) / count
    eyes = np.asarray(center, np.float64) + radius * np.stack([np.cos(angles), 0 * angles, np.sin(angles)], 1)
    return [pinhole_camera(f"view_{k:03d}.exr", eye, target, width, height, fov) for k, eye in enumerate(eyes)]


def write_inputs(fixture: Fixture, root, spp: int = 1024, seed: int = 7) -> dict[str, Path]:
    """The milo stage's inputs under `root`: geometry/ (mesh.ply with the truth's UVs, atlas.npz),
    cameras/ (COLMAP text model), images/ (EXR rendered from the truth with every effect it calls
    for, at `spp`)."""
    root = Path(root)
    scene = fixture.scene
    paths = {"geometry": root / "geometry", "cameras": root / "cameras", "images": root / "images"}
    paths["geometry"].mkdir(parents=True)
    paths["images"].mkdir()
    write_ply(paths["geometry"] / "mesh.ply", scene.mesh)
    fixture.texels.save(paths["geometry"] / "atlas.npz")
    write_colmap(paths["cameras"], scene.cameras)
    renderer = Renderer(scene, analyse(scene))
    for camera in scene.cameras:
        write_exr(paths["images"] / camera.name, renderer.render(camera, spp=spp, seed=seed, aovs=False)["radiance"])
    return paths
