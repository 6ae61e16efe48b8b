"""The lights' radiance scale (PSDR-Room section 4.4): "as light transport is linear in light
intensity, a single rendering with unit radiance is needed". The room box (grey diffuse walls,
floor and ceiling) lit by the initial lights at unit radiance is rendered once; the scale s is
then the closed-form least-squares fit of s * I_unit to the photo over the room's pixels.

The render scene is built here from quads, not from the room stage's mesh (a stage imports only
the libraries): one mesh of two triangles per quad, on a tiny atlas with one grey texel block and
one emissive block, every triangle's UVs on its block's centre (constant maps, no bleeding).
"""

from __future__ import annotations

import numpy as np

from ..scene.types import Camera, Maps, Mesh, Scene
from .lights import Quad, _center, _frame, _size, wall_quads

__all__ = ["box_quads", "light_scene", "unit_render", "radiance_scale"]

ATLAS = 8  # texels per block side; the atlas is ATLAS x 2 ATLAS: grey block left, emitter right
GREY_UV, EMIT_UV = (0.25, 0.5), (0.75, 0.5)


def box_quads(box) -> list[Quad]:
    """The box's six faces (walls, floor, ceiling) as quads, normals into the room."""
    R, size, center = _frame(box), _size(box), _center(box)
    floor = Quad(center - R[:, 1] * size[1] / 2, R[:, 0] * size[0], R[:, 2] * size[2], R[:, 1], "floor", "floor")
    ceiling = Quad(center + R[:, 1] * size[1] / 2, R[:, 0] * size[0], R[:, 2] * size[2], -R[:, 1], "ceiling", "ceiling")
    return wall_quads(box) + [floor, ceiling]


def _triangles(quad: Quad) -> tuple[np.ndarray, np.ndarray]:
    """(4, 3) corners and (2, 3) faces wound counter-clockwise seen from the quad's normal side
    (the side a one-sided emitter lights)."""
    corners = quad.corners()
    if np.cross(quad.e1, quad.e2) @ quad.normal < 0:
        corners = corners[::-1]
    return corners, np.array([[0, 1, 2], [0, 2, 3]])


def light_scene(box, lights: list[Quad], camera: Camera, albedo: float = 0.5, inset: float = 1e-3) -> Scene:
    """The box, grey (kd ``albedo``, no specular), and the lights at unit radiance, each moved
    ``inset`` times the box's height along its normal (off the ceiling or wall it lies on), one
    sided. Instance ids: 1 for the box, 2 + i for light i. No sky."""
    offset = inset * _size(box)[1]
    shifted = [Quad(q.center + q.normal * offset, q.e1, q.e2, q.normal, q.kind, q.name) for q in lights]
    positions, faces, uvs, ids, one_sided = [], [], [], [], []
    for k, quad in enumerate(box_quads(box) + shifted):
        corners, tri = _triangles(quad)
        faces.append(tri + 4 * k)
        positions.append(corners)
        uvs.append(np.tile(GREY_UV if k < 6 else EMIT_UV, (4, 1)))
        ids += [1 if k < 6 else k - 4] * 2
        one_sided += [k >= 6] * 2
    mesh = Mesh(
        positions=np.concatenate(positions).astype(np.float32),
        faces=np.concatenate(faces).astype(np.int32),
        uvs=np.concatenate(uvs).astype(np.float32),
        instance_ids=np.array(ids, np.int32),
        one_sided=np.array(one_sided, bool),
    )
    maps = Maps.uniform((ATLAS, 2 * ATLAS), kd=albedo, ks=0.0, ka=0.25, ke=0.0, kg=0.0)
    maps.kd[:, ATLAS:] = 0.0
    maps.ke[:, ATLAS:] = 1.0
    return Scene(mesh=mesh, maps=maps, cameras=[camera])


def unit_render(scene: Scene, camera: Camera, spp: int = 64, seed: int = 0, device: str | None = None) -> dict:
    """One render of the unit-radiance scene with the effects it calls for (render/analysis)."""
    from ..render.analysis import analyse
    from ..render.renderer import Renderer

    return Renderer(scene, analyse(scene, device=device), device=device).render(camera, spp=spp, seed=seed)


def radiance_scale(
    unit: np.ndarray, photo: np.ndarray, mask: np.ndarray | None = None, variance: np.ndarray | None = None
) -> float:
    """argmin_s sum over the masked pixels and channels of (s I_unit - photo)^2, in closed form
    <I, P> / <I, I>. Both (H, W, 3) linear; ``mask`` (H, W) bool, the room's pixels.

    I_unit is a Monte Carlo estimate: E[I^2] = mu^2 + var, so <I, I> overestimates <mu, mu> and
    the plain fit shrinks s by 1 / (1 + var / mu^2) (errors in the regressor). With the render's
    ``variance`` (of each pixel's mean, the renderer's 'variance') that excess is subtracted."""
    unit, photo = np.asarray(unit, np.float64), np.asarray(photo, np.float64)
    var = np.zeros_like(unit) if variance is None else np.asarray(variance, np.float64)
    if mask is not None:
        unit, photo, var = unit[mask], photo[mask], var[mask]
    energy = float(np.sum(unit * unit) - np.sum(var))
    if energy <= 0:
        raise ValueError("radiance_scale: the unit-radiance render is black (or all noise) over the room's pixels")
    return float(np.sum(unit * photo)) / energy
