"""A small textured room as another tool would export it: per-object OBJ files with their MTL
and PNG textures, a lat-long sky and a COLMAP camera. The room is open at +z (the sky comes in
there), its walls share one checker texture with UVs in [0, 1], its floor's UVs tile (0..4), a
box has a constant colour, and a lamp panel just under the ceiling emits downwards."""

from pathlib import Path

import cv2
import numpy as np

from invrender.scene.cameras import write_colmap
from invrender.scene.types import Camera

WIDTH, HEIGHT = 48, 36


def quad(corners, uv_scale=1.0):
    """v and vt lines of a quad (counter-clockwise seen from its front) and its face."""
    uvs = np.array([[0, 0], [1, 0], [1, 1], [0, 1]], float) * uv_scale
    return [tuple(c) for c in corners], [tuple(t) for t in uvs]


def write_obj(path: Path, mtllib: str, groups) -> None:
    """groups: [(material, [(corners, uvs), ...])]; one face per quad."""
    lines, v, vt = [f"mtllib {mtllib}"], 0, 0
    for material, quads in groups:
        lines.append(f"usemtl {material}")
        for corners, uvs in quads:
            lines += [f"v {x} {y} {z}" for x, y, z in corners] + [f"vt {s} {t}" for s, t in uvs]
            lines.append("f " + " ".join(f"{v + i + 1}/{vt + i + 1}" for i in range(4)))
            v, vt = v + 4, vt + 4
    path.write_text("\n".join(lines) + "\n")


def checker(size: int, a: int, b: int, tint=(1.0, 1.0, 1.0)) -> np.ndarray:
    rows, cols = np.indices((size, size))
    grey = np.where((rows // 2 + cols // 2) % 2 == 0, a, b)
    return np.stack([grey * t for t in tint[::-1]], -1).astype(np.uint8)  # BGR for OpenCV


def box_quads(lo, hi):
    (x0, y0, z0), (x1, y1, z1) = lo, hi
    return [
        quad([(x0, y1, z0), (x0, y1, z1), (x1, y1, z1), (x1, y1, z0)]),  # top, +y
        quad([(x0, y0, z1), (x1, y0, z1), (x1, y1, z1), (x0, y1, z1)]),  # front, +z
        quad([(x1, y0, z1), (x1, y0, z0), (x1, y1, z0), (x1, y1, z1)]),  # +x
        quad([(x1, y0, z0), (x0, y0, z0), (x0, y1, z0), (x1, y1, z0)]),  # back, -z
        quad([(x0, y0, z0), (x0, y0, z1), (x0, y1, z1), (x0, y1, z0)]),  # -x
    ]


def sky_radiance(directions: np.ndarray) -> np.ndarray:
    """A smooth sky: blue above, warm at the horizon, dark below (radiance per direction)."""
    y = directions[..., 1:2]
    up = np.clip(y, 0, 1)
    return (np.array([0.6, 0.8, 1.2]) * (0.3 + up) + np.array([1.0, 0.7, 0.4]) * np.exp(-8 * y**2) * (y > -0.2)).astype(
        np.float32
    )


def camera() -> Camera:
    """Inside the room near its open side, looking at the box and the back wall."""
    f = 0.9 * WIDTH
    eye, target = np.array([0.3, 1.2, 1.6]), np.array([-0.1, 0.6, -1.0])
    z = (target - eye) / np.linalg.norm(target - eye)
    x = np.cross([0.0, -1.0, 0.0], z)  # OpenCV: x right, y down, z forward (x = y cross z)
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    R = np.stack([x, y, z])
    return Camera("view.png", "PINHOLE", WIDTH, HEIGHT, np.array([f, f, WIDTH / 2, HEIGHT / 2]), R, -R @ eye)


def write_room(folder: Path, latlong_writer) -> Path:
    """Write the room into `folder`; `latlong_writer(path, sky_radiance)` writes the sky in the
    importer's lat-long convention. Returns the folder."""
    folder.mkdir(parents=True, exist_ok=True)
    cv2.imwrite(str(folder / "walls.png"), checker(16, 210, 120, (1.0, 0.9, 0.8)))
    cv2.imwrite(str(folder / "floor.png"), checker(8, 160, 60, (0.8, 0.6, 0.4)))
    (folder / "room.mtl").write_text(
        "newmtl walls\nKd 1 1 1\nmap_Kd walls.png\n\nnewmtl floor\nKd 1 1 1\nmap_Kd floor.png\n"
        "\nnewmtl box\nKd 0.7 0.3 0.2\n\nnewmtl lamp\nKd 0 0 0\nKe 6 6 5\n"
    )
    w, h, d = 2.0, 2.5, 2.0
    walls = [
        quad([(-w, 0, -d), (w, 0, -d), (w, h, -d), (-w, h, -d)]),  # back wall, facing +z
        quad([(-w, 0, d), (-w, 0, -d), (-w, h, -d), (-w, h, d)]),  # left wall, facing +x
        quad([(w, 0, -d), (w, 0, d), (w, h, d), (w, h, -d)]),  # right wall, facing -x
        quad([(-w, h, -d), (w, h, -d), (w, h, d), (-w, h, d)]),  # ceiling, facing -y
    ]
    floor = [quad([(-w, 0, d), (w, 0, d), (w, 0, -d), (-w, 0, -d)], uv_scale=4.0)]  # facing +y, tiled
    write_obj(folder / "room.obj", "room.mtl", [("walls", walls), ("floor", floor)])
    write_obj(folder / "box.obj", "room.mtl", [("box", box_quads((-0.6, 0.0, -0.9), (0.2, 0.7, -0.1)))])
    lamp = [quad([(-0.5, 2.45, -1.0), (0.5, 2.45, -1.0), (0.5, 2.45, 0.0), (-0.5, 2.45, 0.0)])]  # facing -y
    write_obj(folder / "lamp.obj", "room.mtl", [("lamp", lamp)])
    latlong_writer(folder / "sky.exr", sky_radiance)
    write_colmap(folder / "sparse", [camera()])
    return folder
