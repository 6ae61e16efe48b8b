"""Small scenes with known answers, built in code (no fixture files)."""

from __future__ import annotations

import numpy as np

from invrender.scene.types import Maps, Mesh, Scene
from invrender.synthesize.room import pinhole_camera


def icosphere(radius=1.0, center=(0, 0, 0), subdivisions=3):
    t = (1 + 5**0.5) / 2
    verts = [
        (-1, t, 0),
        (1, t, 0),
        (-1, -t, 0),
        (1, -t, 0),
        (0, -1, t),
        (0, 1, t),
        (0, -1, -t),
        (0, 1, -t),
        (t, 0, -1),
        (t, 0, 1),
        (-t, 0, -1),
        (-t, 0, 1),
    ]
    faces = [
        (0, 11, 5),
        (0, 5, 1),
        (0, 1, 7),
        (0, 7, 10),
        (0, 10, 11),
        (1, 5, 9),
        (5, 11, 4),
        (11, 10, 2),
        (10, 7, 6),
        (7, 1, 8),
        (3, 9, 4),
        (3, 4, 2),
        (3, 2, 6),
        (3, 6, 8),
        (3, 8, 9),
        (4, 9, 5),
        (2, 4, 11),
        (6, 2, 10),
        (8, 6, 7),
        (9, 8, 1),
    ]
    v = np.array(verts, np.float64)
    v /= np.linalg.norm(v, axis=1, keepdims=True)
    f = np.array(faces)
    for _ in range(subdivisions):
        cache, verts_list, new_faces = {}, list(v), []

        def midpoint(a, b):
            key = (min(a, b), max(a, b))
            if key not in cache:
                m = verts_list[a] + verts_list[b]
                verts_list.append(m / np.linalg.norm(m))
                cache[key] = len(verts_list) - 1
            return cache[key]

        for a, b, c in f:
            ab, bc, ca = midpoint(a, b), midpoint(b, c), midpoint(c, a)
            new_faces += [(a, ab, ca), (b, bc, ab), (c, ca, bc), (ab, bc, ca)]
        v, f = np.array(verts_list), np.array(new_faces)
    return (v * radius + np.asarray(center)).astype(np.float32), f.astype(np.int32)


def quad(center, u_axis, v_axis):
    """Two triangles spanning center +- u_axis +- v_axis, front face towards u x v, UVs 0..1."""
    c, u, v = (np.asarray(a, np.float64) for a in (center, u_axis, v_axis))
    positions = np.array([c - u - v, c + u - v, c + u + v, c - u + v], np.float32)
    faces = np.array([[0, 1, 2], [0, 2, 3]], np.int32)
    uvs = np.array([[0, 0], [1, 0], [1, 1], [0, 1]], np.float32)
    return positions, faces, uvs


def merge(*parts):
    """Concatenate (positions, faces, uvs) parts into one Mesh; instance id = part index + 1."""
    positions, faces, uvs, ids, offset = [], [], [], [], 0
    for index, (p, f, uv) in enumerate(parts):
        positions.append(p)
        faces.append(f + offset)
        uvs.append(uv)
        ids.append(np.full(len(f), index + 1, np.int32))
        offset += len(p)
    return Mesh(
        np.concatenate(positions), np.concatenate(faces).astype(np.int32), np.concatenate(uvs), np.concatenate(ids)
    )


def look_at_camera(eye, target, width=48, height=36, fov_x_deg=50.0, name="cam", cx=None, cy=None):
    """A PINHOLE camera at eye looking at target, principal point (cx, cy) (default centred)."""
    camera = pinhole_camera(name, eye, target, width, height, fov_x_deg)
    camera.params[2:] = [width / 2 if cx is None else cx, height / 2 if cy is None else cy]
    return camera


def sphere_in_sky(kd=0.5, sky=1.0, subdivisions=3, atlas=(4, 4)):
    """A diffuse unit sphere under a uniform sky: a convex object never sees itself, so with one
    or more bounces every sphere pixel is kd * sky exactly (white furnace when kd = 1)."""
    p, f = icosphere(1.0, subdivisions=subdivisions)
    mesh = Mesh(p, f, np.full((len(p), 2), 0.5, np.float32), np.ones(len(f), np.int32))
    maps = Maps.uniform(size=atlas, kd=kd, ks=0.0, ka=0.1, kg=sky, cube=4)
    camera = look_at_camera((0, 0, 4), (0, 0, 0), width=32, height=32, fov_x_deg=40)
    return Scene(mesh, maps, [camera])


def inside_sphere(kd=0.5, ke=1.0, subdivisions=2):
    """A closed sphere that emits ke and reflects kd everywhere, seen from inside: by the
    rendering equation L = ke + kd L at every point, so with B bounces
    L = ke (1 - kd^(B+1)) / (1 - kd) exactly (the furnace of multi-bounce light)."""
    p, f = icosphere(1.0, subdivisions=subdivisions)
    mesh = Mesh(p, f, np.full((len(p), 2), 0.5, np.float32), np.ones(len(f), np.int32))
    maps = Maps.uniform(size=(2, 2), kd=kd, ks=0.0, ka=0.1, ke=ke, kg=0.0, cube=2)
    camera = look_at_camera((0.1, -0.2, 0.3), (0.0, 0.0, -1.0), width=24, height=18, fov_x_deg=70)
    return Scene(mesh, maps, [camera])


def box_room(kd=(0.6, 0.5, 0.4), light=8.0, ks=0.0, ka=0.1, size=(32, 24), window=False, sky=2.0):
    """A closed 4 x 2.6 x 3 m box seen from inside, a ceiling light (texel 1) and a diffuse box
    on the floor; with window=True a window quad in the +X wall (kw = 1, texel 2) shows a sky.
    Atlas: 2 x 2 texels, texel 0 = walls/floor/box, 1 = light, 2 = window."""
    W, H, D = 2.0, 2.6, 1.5
    parts = [
        quad((0, 0, 0), (0, 0, D), (W, 0, 0)),  # floor, front +Y
        quad((0, H, 0), (W, 0, 0), (0, 0, D)),  # ceiling, front -Y
        quad((0, H / 2, -D), (W, 0, 0), (0, H / 2, 0)),  # back wall, front +Z
        quad((0, H / 2, D), (0, H / 2, 0), (W, 0, 0)),  # front wall, front -Z
        quad((-W, H / 2, 0), (0, H / 2, 0), (0, 0, D)),  # left wall, front +X
        quad((W, H / 2, 0), (0, 0, D), (0, H / 2, 0)),  # right wall, front -X
        quad((0.3, H - 0.01, 0.2), (0.5, 0, 0), (0, 0, 0.4)),  # light, facing down
        quad((-0.8, 0.4, -0.3), (0.3, 0, 0), (0, 0, 0.3)),  # top of a little table
    ]
    texel_uv = {0: (0.25, 0.75), 1: (0.75, 0.75), 2: (0.25, 0.25)}
    uv_of = [0, 0, 0, 0, 0, 0, 1, 0]
    if window:
        parts.append(quad((W - 0.005, 1.4, 0.0), (0, 0.5, 0), (0, 0, 0.6)))  # in front of +X wall
        uv_of.append(2)
    positions = np.concatenate([p for p, _, _ in parts]).astype(np.float32)
    faces = np.concatenate([f + 4 * i for i, (_, f, _) in enumerate(parts)]).astype(np.int32)
    uvs = np.concatenate([np.full((4, 2), texel_uv[t]) for t in uv_of]).astype(np.float32)
    maps = Maps.uniform(size=(2, 2), kd=0.0, ks=0.0, ka=ka, kg=sky if window else 0.0, cube=4)
    maps.kd[0, 0], maps.ks[0, 0] = kd, ks
    maps.ke[0, 1] = light
    maps.kw[1, 0] = 1.0 if window else 0.0
    camera = look_at_camera((-1.2, 1.4, 1.2), (0.5, 0.8, -0.8), width=size[0], height=size[1], fov_x_deg=75)
    ids = np.repeat(np.arange(len(parts)) + 1, 2).astype(np.int32)
    return Scene(Mesh(positions, faces, uvs, ids), maps, [camera])


TILE, TILES = 4, 4  # textured_room: each part owns a TILE x TILE texel tile of a 16 x 16 atlas


def tile_texels(tile: int) -> tuple[slice, slice]:
    """Atlas rows and columns of a textured_room tile."""
    row, col = divmod(tile, TILES)
    return slice(TILE * row, TILE * row + TILE), slice(TILE * col, TILE * col + TILE)


def _tile_uvs(uvs: np.ndarray, tile: int) -> np.ndarray:
    """A quad's 0..1 UVs squeezed into its tile (inset 1e-3 texel: no lookup lands on a border)."""
    row, col = divmod(tile, TILES)
    size, inset = TILE * TILES, 1e-3
    u = (TILE * col + inset + uvs[:, 0] * (TILE - 2 * inset)) / size
    v = 1 - (TILE * row + inset + (1 - uvs[:, 1]) * (TILE - 2 * inset)) / size
    return np.stack([u, v], 1).astype(np.float32)


ROOM_TILES = {
    "floor": 0,
    "ceiling": 1,
    "back": 2,
    "front": 3,
    "left": 4,
    "right": 5,
    "light": 6,
    "table": 7,
    "window": 8,
}


def textured_room(size=(32, 24), seed=0):
    """The box room with a texture on every part: 4 x 4 texels of random kd per part, a glossy
    floor and table (ks, ka), a textured ceiling light (ke), a window (kw = 0.9) onto a random
    sky (kg). Every texel kind the gradients must handle, in one small closed-but-for-the-window
    scene; `ROOM_TILES` and `tile_texels` say which texels belong to which part."""
    rng = np.random.default_rng(seed)
    W, H, D = 2.0, 2.6, 1.5
    parts = {
        "floor": quad((0, 0, 0), (0, 0, D), (W, 0, 0)),
        "ceiling": quad((0, H, 0), (W, 0, 0), (0, 0, D)),
        "back": quad((0, H / 2, -D), (W, 0, 0), (0, H / 2, 0)),
        "front": quad((0, H / 2, D), (0, H / 2, 0), (W, 0, 0)),
        "left": quad((-W, H / 2, 0), (0, H / 2, 0), (0, 0, D)),
        "right": quad((W, H / 2, 0), (0, 0, D), (0, H / 2, 0)),
        "light": quad((0.3, H - 0.01, 0.2), (0.5, 0, 0), (0, 0, 0.4)),
        "table": quad((-0.8, 0.4, -0.3), (0.3, 0, 0), (0, 0, 0.3)),
        "window": quad((W - 0.005, 1.4, 0.0), (0, 0.5, 0), (0, 0, 0.6)),
    }
    mesh = merge(*[(p, f, _tile_uvs(uv, ROOM_TILES[name])) for name, (p, f, uv) in parts.items()])
    side = TILE * TILES
    maps = Maps.uniform(size=(side, side), kd=0.0, ks=0.0, ka=0.1, kg=0.0, cube=4)
    maps.kg[:] = rng.uniform(1.0, 3.0, maps.kg.shape)
    for name in ("floor", "ceiling", "back", "front", "left", "right", "table"):
        maps.kd[tile_texels(ROOM_TILES[name])] = rng.uniform(0.3, 0.7, (TILE, TILE, 3))
    for name, ks, ka in (("floor", 0.3, 0.08), ("table", 0.5, 0.03)):
        maps.ks[tile_texels(ROOM_TILES[name])] = rng.uniform(0.8, 1.2, (TILE, TILE, 1)) * ks
        maps.ka[tile_texels(ROOM_TILES[name])] = rng.uniform(0.8, 1.2, (TILE, TILE)) * ka
    maps.ke[tile_texels(ROOM_TILES["light"])] = rng.uniform(4.0, 12.0, (TILE, TILE, 3))
    maps.kw[tile_texels(ROOM_TILES["window"])] = 0.9
    camera = look_at_camera((-1.2, 1.4, 1.2), (0.5, 0.8, -0.8), width=size[0], height=size[1], fov_x_deg=75)
    return Scene(mesh, maps, [camera])


def hard_room(ks=1.0, ka=1e-6, light=1e6, kd=(0.6, 0.5, 0.4), open_top=False):
    """The path tracer's hard cases in one scene: the box room with a window (and by default a
    mirror-sharp ks = 1 lobe and emission 1e6), a sphere, a zero-area and a sliver triangle;
    without its floor when open_top, so rays escape to the sky."""
    room = box_room(kd=kd, ks=ks, ka=ka, light=light, window=True)
    p, f = icosphere(0.3, center=(0.5, 0.6, 0.0), subdivisions=1)
    degenerate = np.array([[0, 1, 0], [0, 1, 0], [0, 1, 0], [0, 0, 0], [1, 1e-9, 0], [2, 2e-9, 0]], np.float32)
    n0, n1 = len(room.mesh.positions), len(room.mesh.positions) + len(p)
    faces = np.concatenate([room.mesh.faces, f + n0, [[n1, n1 + 1, n1 + 2], [n1 + 3, n1 + 4, n1 + 5]]])
    uvs = np.concatenate([room.mesh.uvs, np.full((len(p) + 6, 2), [0.25, 0.75], np.float32)])
    mesh = Mesh(
        np.concatenate([room.mesh.positions, p, degenerate]), faces[2 if open_top else 0 :].astype(np.int32), uvs
    )
    return Scene(mesh, room.maps, room.cameras)


# ---------------------------------------------------------------------------- v2: objects


def rigid(angle_deg=0.0, translation=(0, 0, 0)) -> np.ndarray:
    """4x4 object-to-world: a rotation about +Y, then a translation."""
    a = np.radians(angle_deg)
    T = np.eye(4)
    T[:3, :3] = [[np.cos(a), 0, np.sin(a)], [0, 1, 0], [-np.sin(a), 0, np.cos(a)]]
    T[:3, 3] = translation
    return T


def _in_rect(uvs, u0, v0, u1, v1, inset=1e-3):
    """0..1 UVs squeezed into [u0, u1] x [v0, v1], inset a little: no lookup lands on a texel border."""
    u = u0 + inset + uvs[:, 0] * (u1 - u0 - 2 * inset)
    v = v0 + inset + uvs[:, 1] * (v1 - v0 - 2 * inset)
    return np.stack([u, v], 1).astype(np.float32)


def cube_mesh(half=0.25):
    """A cube standing on y = 0, fronts outwards, every face over its whole (inset) atlas."""
    h = half
    faces = [
        ((0, h, h), (h, 0, 0), (0, h, 0)),
        ((0, h, -h), (-h, 0, 0), (0, h, 0)),
        ((h, h, 0), (0, 0, -h), (0, h, 0)),
        ((-h, h, 0), (0, 0, h), (0, h, 0)),
        ((0, 2 * h, 0), (h, 0, 0), (0, 0, -h)),
        ((0, 0, 0), (h, 0, 0), (0, 0, h)),
    ]
    parts = [quad(*f) for f in faces]
    mesh = merge(*[(p, f, _in_rect(uv, 0, 0, 1, 1)) for p, f, uv in parts])
    mesh.instance_ids = None
    return mesh


def three_objects(size=(32, 24), seed=0):
    """The v2 acceptance scene: a closed box room with a ceiling light (material 'walls', 4 x 4
    texels, the only emitter), a table top ('wood', 2 x 2, glossy) and one cube instanced twice
    ('paint', 2 x 3), each placed by its own transform inside a room that is itself moved.
    Returns (objects, materials, kg, cameras) for scene.packing.pack_scene."""
    from invrender.scene.types import Atlas, SceneObject

    rng = np.random.default_rng(seed)
    W, H, D = 2.0, 2.6, 1.5
    room_parts = [  # (quad, UV rect in the walls atlas)
        (quad((0, 0, 0), (0, 0, D), (W, 0, 0)), (0, 0.5, 0.5, 1)),  # floor
        (quad((0, H, 0), (W, 0, 0), (0, 0, D)), (0.5, 0.5, 1, 1)),  # ceiling
        (quad((0, H / 2, -D), (W, 0, 0), (0, H / 2, 0)), (0, 0, 0.5, 0.5)),  # back
        (quad((0, H / 2, D), (0, H / 2, 0), (W, 0, 0)), (0, 0, 0.5, 0.5)),  # front
        (quad((-W, H / 2, 0), (0, H / 2, 0), (0, 0, D)), (0, 0, 0.5, 0.5)),  # left
        (quad((W, H / 2, 0), (0, 0, D), (0, H / 2, 0)), (0, 0, 0.5, 0.5)),  # right
        (quad((0.3, H - 0.01, 0.2), (0.5, 0, 0), (0, 0, 0.4)), (0.5, 0, 1, 0.5)),  # light, facing down
    ]
    room = merge(*[(p, f, _in_rect(uv, *rect)) for (p, f, uv), rect in room_parts])
    room.instance_ids = None
    p, f, uv = quad((0, 0, 0), (0.3, 0, 0), (0, 0, -0.3))
    table = Mesh(p, f, _in_rect(uv, 0, 0, 1, 1))
    cube = cube_mesh()

    walls = Atlas.uniform((4, 4), kd=0.0, ks=0.0, ka=0.1)
    walls.kd[:] = rng.uniform(0.3, 0.7, (4, 4, 3))
    walls.ke[2:, 2:] = rng.uniform(6.0, 10.0, (2, 2, 3))  # under the light's UVs: rows 2-3, cols 2-3
    walls.kd[2:, 2:] = 0.0
    wood = Atlas.uniform((2, 2), kd=0.0, ks=0.0, ka=0.05)
    wood.kd[:] = rng.uniform(0.4, 0.8, (2, 2, 3))
    wood.ks[:] = rng.uniform(0.2, 0.4, (2, 2, 3))
    paint = Atlas.uniform((2, 3), kd=0.0, ks=0.1, ka=0.2)
    paint.kd[:] = rng.uniform(0.2, 0.9, (2, 3, 3))
    materials = {"walls": walls, "wood": wood, "paint": paint}

    placed = rigid(20, (0.3, 0.0, 0.1))  # the room itself is moved
    objects = [
        SceneObject("room", room, "walls", placed, instance_id=1),
        SceneObject("table", table, "wood", placed @ rigid(30, (-0.8, 0.4, -0.3)), instance_id=2),
        SceneObject("cube_a", cube, "paint", placed @ rigid(15, (-0.2, 0.0, -0.5)), instance_id=3),
        SceneObject("cube_b", cube, "paint", placed @ rigid(60, (0.6, 0.0, -0.2)), instance_id=4),
    ]
    to_world = lambda x: (placed @ np.append(x, 1.0))[:3]
    camera = look_at_camera(
        to_world((-1.2, 1.4, 1.2)), to_world((0.5, 0.6, -0.6)), width=size[0], height=size[1], fov_x_deg=75
    )
    kg = np.zeros((6, 2, 2, 3), np.float32)
    return objects, materials, kg, [camera]


def flattened_by_hand(objects, materials, kg, cameras):
    """The same geometry as one v1 scene, built without scene/packing.py: the material sets side by
    side left to right (no padding), each object's positions through its transform, its UVs into
    its set's columns."""
    width = sum(a.atlas_shape[1] for a in materials.values())
    height = max(a.atlas_shape[0] for a in materials.values())
    maps = Maps.uniform(size=(height, width), kd=0.0, ks=0.0, ka=0.1, kg=0.0, cube=kg.shape[1])
    maps.kg[:] = kg
    column, c = {}, 0
    for name, atlas in materials.items():
        h, w = atlas.atlas_shape
        column[name] = c
        for m in ("kd", "ks", "ka", "ke", "kw"):
            getattr(maps, m)[:h, c : c + w] = getattr(atlas, m)
        c += w
    positions, faces, uvs, ids, offset = [], [], [], [], 0
    for obj in objects:
        T, mesh = obj.transform, obj.mesh
        positions.append((mesh.positions.astype(np.float64) @ T[:3, :3].T + T[:3, 3]).astype(np.float32))
        faces.append(mesh.faces + offset)
        h, w = materials[obj.material].atlas_shape
        u = (column[obj.material] + mesh.uvs[:, 0].astype(np.float64) * w) / width
        v = 1 - (1 - mesh.uvs[:, 1].astype(np.float64)) * h / height  # rows from the top
        uvs.append(np.stack([u, v], 1).astype(np.float32))
        ids.append(np.full(len(mesh.faces), obj.instance_id, np.int32))
        offset += len(mesh.positions)
    mesh = Mesh(
        np.concatenate(positions), np.concatenate(faces).astype(np.int32), np.concatenate(uvs), np.concatenate(ids)
    )
    return Scene(mesh, maps, cameras), column
