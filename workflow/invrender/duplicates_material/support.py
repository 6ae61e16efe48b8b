"""The support surface (the table or floor the copies stand on) as its own mesh and material.

Its plane comes from the poses alone: copies that rest on one plane each touch it at their lowest
points along its normal. Starting from the camera's up direction (a photograph of objects on a
table is taken above it, upright), the normal is refitted to the copies' lowest vertices along
the current normal (a total least-squares plane through one contact point per copy) until it
settles; the offset is that of the lowest placed vertex, so no copy sinks into it. With fewer
than three copies the contact points do not fix a plane and the camera's up direction is kept.

The mesh is one quad in that plane covering what the cameras see (each image corner's ray meets
the plane, or is cut at `reach` times the copies' spread where it runs above the horizon), with
UVs spanning it, so its atlas is a plain grid of `resolution` texels on its longer side.
"""

from __future__ import annotations

import numpy as np

from ..scene.atlas import AtlasTexels, rasterize_atlas
from ..scene.cubemap import cube_texel_solid_angles, texel_directions
from ..scene.resting import resting_normal
from ..scene.types import Camera, Mesh, SceneObject

CONTACT_TOLERANCE = 1e-3  # fraction of the object's size: vertices this close to the lowest count as contact


def camera_up(cameras: list[Camera]) -> np.ndarray:
    """The world direction of the cameras' "up" (OpenCV's -y), averaged."""
    up = sum(-np.asarray(c.R, np.float64)[1] for c in cameras)
    return up / np.linalg.norm(up)


def support_plane(copies: list[np.ndarray], up: np.ndarray) -> tuple[np.ndarray, float]:
    """(normal, offset) of the plane n.x = offset the copies (world vertices, one array each)
    rest on, the normal on the side of `up` (scene/resting.py); the offset that of the lowest
    vertex, so no copy sinks into it."""
    size = float(np.linalg.norm(np.ptp(copies[0], axis=0)))
    normal = resting_normal(copies, up, CONTACT_TOLERANCE * size)
    offset = min(float((world @ normal).min()) for world in copies)
    return normal, offset


def _basis(normal: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    helper = np.eye(3)[np.argmin(np.abs(normal))]
    u = np.cross(normal, helper)
    u /= np.linalg.norm(u)
    return u, np.cross(normal, u)  # (u, v, normal) right-handed: the quad faces +normal


def _corner_hits(camera: Camera, normal, offset, limit: float) -> np.ndarray:
    """Where the rays through the image's corners and edge midpoints meet the plane; a ray that
    misses it (above the horizon) is cut at distance `limit` and dropped onto the plane."""
    (fx, fy), (cx, cy) = camera.focal, camera.principal_point
    w, h = camera.width, camera.height
    xs, ys = np.meshgrid([0, w / 2, w], [0, h / 2, h])
    d_cam = np.stack([(xs.ravel() - cx) / fx, (ys.ravel() - cy) / fy, np.ones(xs.size)], -1)
    d = d_cam @ np.asarray(camera.R, np.float64)
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    o = camera.center
    denom = d @ normal
    with np.errstate(divide="ignore", invalid="ignore"):
        t = (offset - o @ normal) / denom
    t = np.where((t > 0) & np.isfinite(t), np.minimum(t, limit), limit)
    points = o + t[:, None] * d
    return points - ((points @ normal) - offset)[:, None] * normal


def support_mesh(copies: list[np.ndarray], cameras: list[Camera], margin: float = 0.05, reach: float = 20.0) -> Mesh:
    """The quad (two triangles, world coordinates, UVs over [0, 1]^2) of the support plane under
    everything the cameras see, grown by `margin` of its size."""
    normal, offset = support_plane(copies, camera_up(cameras))
    spread = float(np.linalg.norm(np.ptp(np.concatenate(copies), axis=0)))
    u, v = _basis(normal)
    hits = np.concatenate([_corner_hits(c, normal, offset, reach * max(spread, 1e-6)) for c in cameras])
    hits = np.concatenate([hits, *copies])
    a, b = hits @ u, hits @ v
    (a0, a1), (b0, b1) = (a.min(), a.max()), (b.min(), b.max())
    pad = margin * max(a1 - a0, b1 - b0)
    a0, a1, b0, b1 = a0 - pad, a1 + pad, b0 - pad, b1 + pad
    corners2d = np.array([[a0, b0], [a1, b0], [a1, b1], [a0, b1]])
    positions = corners2d[:, :1] * u + corners2d[:, 1:] * v + offset * normal
    uvs = np.array([[0, 0], [1, 0], [1, 1], [0, 1]], np.float32)
    faces = np.array([[0, 1, 2], [0, 2, 3]], np.int32)  # counter-clockwise seen from +normal
    return Mesh(positions=positions.astype(np.float32), faces=faces, uvs=uvs)


def support_shape(mesh: Mesh, resolution: int) -> tuple[int, int]:
    """(rows, cols) of the support's atlas: square texels, `resolution` along the longer side."""
    p = np.asarray(mesh.positions, np.float64)
    width, height = np.linalg.norm(p[1] - p[0]), np.linalg.norm(p[3] - p[0])
    long = max(width, height)
    return max(2, round(resolution * height / long)), max(2, round(resolution * width / long))


def support_texels(mesh: Mesh, resolution: int) -> AtlasTexels:
    return rasterize_atlas(mesh, *support_shape(mesh, resolution))


def support_object(mesh: Mesh) -> SceneObject:
    """The support in a v2 scene: its own material set "support", instance id 0 (the masks'
    background)."""
    return SceneObject("support", mesh, "support", np.eye(4), instance_id=0)


def _facing(n: int, support: Mesh) -> np.ndarray:
    """(6, n, n): the cosine between each sky texel's direction and the support's normal."""
    a, b, c = support.positions[support.faces[0]].astype(np.float64)
    normal = np.cross(b - a, c - a)  # the quad faces +normal (_basis)
    return texel_directions(n) @ (normal / np.linalg.norm(normal))


def below_horizon(n: int, support: Mesh | None) -> np.ndarray | None:
    """(6, n, n) bool: the sky texels whose directions point below the support's plane, which the
    support hides from every copy (None without a support)."""
    if support is None:
        return None
    return _facing(n, support) < 0


def irradiance_weights(n: int, support: Mesh) -> np.ndarray:
    """(6, n, n): each sky texel's share of the irradiance on the support's plane, cos x solid
    angle (0 below the horizon), so that E = sum(w kg) is what the sky pours onto the ground."""
    return np.clip(_facing(n, support), 0.0, None) * cube_texel_solid_angles(n)[None]


def first_sky(n: int, below: np.ndarray | None, support_radiance) -> np.ndarray:
    """The sky training starts from, (6, n, n, 3): white (the first guess' sky) above the support's
    horizon; below it (`below`), where no gradient ever arrives, the support's median radiance in
    the photograph (the ground beyond the table looks like the table). Left white, that half of
    the sphere was most of the env MSE: box-10-hd 0.154, 0.024 with the truth's ground there."""
    kg = np.ones((6, n, n, 3), np.float32)
    if below is not None:
        kg[below] = np.asarray(support_radiance, np.float32)
    return kg
