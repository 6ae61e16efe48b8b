"""A tiny synthetic room for the material stage's tests: a box (walls, floor, ceiling) with two
one-sided ceiling panels, each quad in its own block of one small atlas, homogeneous materials
and known radiances; its photo is the renderer's, so the truth is exact."""

from __future__ import annotations

import numpy as np

from invrender.room_materials.model import Light, Part, RoomModel
from invrender.scene.cameras import pinhole_camera
from invrender.scene.types import Maps, Mesh, Scene

SIZE = (3.0, 2.5, 3.5)  # x, y, z; floor at y = 0, centred in x and z
BLOCK = 16  # texels per quad's block
ALBEDO = {"walls": (0.70, 0.60, 0.50), "floor": (0.30, 0.35, 0.55), "ceiling": (0.80, 0.80, 0.78)}
RADIANCE = {"panel_front": 6.0, "panel_back": 9.0}
SEGMENTS = {"walls": 1, "floor": 2, "ceiling": 3, "panel_front": 4, "panel_back": 5}
LABELS = {
    1: ("wall", "walls"),
    2: ("floor", "floor"),
    3: ("ceiling", "ceiling"),
    4: ("lamp", "panel_front"),
    5: ("lamp", "panel_back"),
}


def _quads():
    """(name, corners (4, 3) counter-clockwise seen from inside the room)."""
    sx, sy, sz = SIZE
    x0, x1, z0, z1 = -sx / 2, sx / 2, -sz / 2, sz / 2
    q = []
    q.append(("walls", [[x0, 0, z0], [x1, 0, z0], [x1, sy, z0], [x0, sy, z0]]))  # -z, normal +z
    q.append(("walls", [[x1, 0, z1], [x0, 0, z1], [x0, sy, z1], [x1, sy, z1]]))  # +z
    q.append(("walls", [[x0, 0, z1], [x0, 0, z0], [x0, sy, z0], [x0, sy, z1]]))  # -x
    q.append(("walls", [[x1, 0, z0], [x1, 0, z1], [x1, sy, z1], [x1, sy, z0]]))  # +x
    q.append(("floor", [[x0, 0, z1], [x1, 0, z1], [x1, 0, z0], [x0, 0, z0]]))  # normal +y
    q.append(("ceiling", [[x0, sy, z0], [x1, sy, z0], [x1, sy, z1], [x0, sy, z1]]))  # normal -y
    y = sy - 0.01
    for name, (xc, zc) in (("panel_front", (-0.5, -1.1)), ("panel_back", (0.7, -0.4))):
        a, b = 0.35, 0.3
        q.append((name, [[xc - a, y, zc - b], [xc + a, y, zc - b], [xc + a, y, zc + b], [xc - a, y, zc + b]]))
    return q


def room_scene(width=64, height=48, albedo=ALBEDO, radiance=RADIANCE):
    """(Scene, parts, lights): the truth room with its photo camera."""
    quads = _quads()
    grid = int(np.ceil(np.sqrt(len(quads))))
    size = grid * BLOCK
    positions, faces, uvs, ids, one_sided = [], [], [], [], []
    maps = Maps.uniform((size, size), kd=0.0, ks=0.0, ka=0.25, ke=0.0, kg=0.0)  # ks, ka: the plain defaults
    by_name: dict[str, list[int]] = {}
    for k, (name, corners) in enumerate(quads):
        r, c = divmod(k, grid)
        u0, u1 = (c * BLOCK + 2) / size, ((c + 1) * BLOCK - 2) / size
        v1, v0 = 1 - (r * BLOCK + 2) / size, 1 - ((r + 1) * BLOCK - 2) / size
        positions.append(np.asarray(corners, np.float32))
        uvs.append(np.array([[u0, v0], [u1, v0], [u1, v1], [u0, v1]], np.float32))
        faces.append(np.array([[0, 1, 2], [0, 2, 3]]) + 4 * k)
        ids += [SEGMENTS[name]] * 2
        one_sided += [name.startswith("panel")] * 2
        by_name.setdefault(name, []).extend([2 * k, 2 * k + 1])
        block = (slice(r * BLOCK, (r + 1) * BLOCK), slice(c * BLOCK, (c + 1) * BLOCK))
        if name in albedo:
            maps.kd[block], maps.ks[block] = albedo[name], 0.04
        else:
            maps.ke[block] = radiance[name]
    mesh = Mesh(
        positions=np.concatenate(positions),
        faces=np.concatenate(faces).astype(np.int32),
        uvs=np.concatenate(uvs),
        instance_ids=np.array(ids, np.int32),
        one_sided=np.array(one_sided, bool),
    )
    camera = pinhole_camera("photo", [0.4, 1.1, 1.6], [-0.3, 1.55, -1.75], width, height, 90.0)
    scene = Scene(mesh=mesh, maps=maps, cameras=[camera])
    parts = [Part(name, np.array(by_name[name]), (SEGMENTS[name],)) for name in ("walls", "floor", "ceiling")]
    lights = [Light(name, np.array(by_name[name]), np.full(3, 1.0)) for name in ("panel_front", "panel_back")]
    return scene, parts, lights


def render(scene, spp, seed=0):
    from invrender.render.analysis import analyse
    from invrender.render.renderer import Renderer

    return Renderer(scene, analyse(scene)).render(scene.cameras[0], spp=spp, seed=seed)


def model(scene, parts, lights):
    return RoomModel(scene, parts, lights)
