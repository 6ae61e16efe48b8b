"""Stage inputs written by hand, so that a test can write any fault into them: meshes (OBJ, PLY
text and binary), COLMAP models (text and binary), transforms.json, and the directories the
gradients and render stages read (from testscenes.box_room)."""

from __future__ import annotations

import json
import struct
from pathlib import Path

import numpy as np
from testscenes import box_room

from invrender.scene.cameras import write_colmap
from invrender.scene.format import write_scene
from invrender.scene.images import write_exr
from invrender.scene.mesh_io import write_ply as write_mesh_ply

COLMAP_MODEL_IDS = {"SIMPLE_PINHOLE": 0, "PINHOLE": 1, "OPENCV": 4}


def grid_mesh(n: int = 12, scale: float = 1.0) -> tuple[np.ndarray, np.ndarray]:
    """A gently curved n x n vertex sheet `scale` meters across: (positions (V, 3), faces (F, 3))."""
    u, v = np.meshgrid(np.linspace(0, 1, n), np.linspace(0, 1, n), indexing="ij")
    positions = np.stack([u, 0.2 * np.sin(3 * u) * np.cos(2 * v), v], -1).reshape(-1, 3) * scale
    i = (np.arange(n - 1)[:, None] * n + np.arange(n - 1)[None, :]).ravel()
    faces = np.concatenate([np.stack([i, i + 1, i + n + 1], 1), np.stack([i, i + n + 1, i + n], 1)])
    return positions, faces


def write_obj(path: Path, positions, faces) -> None:
    lines = [f"v {x!r} {y!r} {z!r}" for x, y, z in np.asarray(positions, np.float64).tolist()]
    lines += ["f " + " ".join(str(int(i) + 1) for i in face) for face in faces]
    Path(path).write_text("\n".join(lines) + "\n")


def write_ply(path: Path, positions, faces, binary: bool) -> None:
    """x, y, z (float32) and vertex_indices, written by hand (indices as given, even if wrong)."""
    positions, faces = np.asarray(positions, np.float32), np.asarray(faces, np.int64)
    header = [
        "ply",
        f"format {'binary_little_endian' if binary else 'ascii'} 1.0",
        f"element vertex {len(positions)}",
        "property float x",
        "property float y",
        "property float z",
        f"element face {len(faces)}",
        "property list uchar int vertex_indices",
        "end_header",
    ]
    if binary:
        body = positions.astype("<f4").tobytes()
        body += b"".join(struct.pack("<B3i", 3, *(int(np.clip(i, -(2**31), 2**31 - 1)) for i in f)) for f in faces)
        Path(path).write_bytes(("\n".join(header) + "\n").encode() + body)
    else:
        lines = [" ".join(repr(float(c)) for c in p) for p in positions.tolist()]
        lines += ["3 " + " ".join(str(int(i)) for i in f) for f in faces]
        Path(path).write_text("\n".join(header + lines) + "\n")


def write_colmap_text(directory: Path, cameras: list[tuple], images: list[tuple]) -> None:
    """cameras: (id, model, width, height, params); images: (id, qvec wxyz, tvec, camera id, name)."""
    directory.mkdir(parents=True, exist_ok=True)
    (directory / "cameras.txt").write_text(
        "".join(
            f"{i} {model} {w} {h} {' '.join(repr(float(p)) for p in params)}\n" for i, model, w, h, params in cameras
        )
    )
    (directory / "images.txt").write_text(
        "".join(
            f"{i} {' '.join(repr(float(q)) for q in qvec)} {' '.join(repr(float(t)) for t in tvec)} {cam} {name}\n\n"
            for i, qvec, tvec, cam, name in images
        )
    )
    (directory / "points3D.txt").write_text("")


def write_colmap_binary(directory: Path, cameras: list[tuple], images: list[tuple]) -> None:
    """The same as write_colmap_text, in COLMAP's binary format (cameras.bin, images.bin, points3D.bin)."""
    directory.mkdir(parents=True, exist_ok=True)
    data = struct.pack("<Q", len(cameras))
    for i, model, w, h, params in cameras:
        data += struct.pack("<iiQQ", i, COLMAP_MODEL_IDS[model], w, h) + struct.pack(f"<{len(params)}d", *params)
    (directory / "cameras.bin").write_bytes(data)
    data = struct.pack("<Q", len(images))
    for i, qvec, tvec, cam, name in images:
        data += struct.pack("<i4d3di", i, *qvec, *tvec, cam) + name.encode() + b"\0" + struct.pack("<Q", 0)
    (directory / "images.bin").write_bytes(data)
    (directory / "points3D.bin").write_bytes(struct.pack("<Q", 0))


def good_camera(width: int = 32, height: int = 24) -> tuple:
    return (1, "PINHOLE", width, height, [30.0, 30.0, width / 2, height / 2])


def good_image(name: str = "view.png") -> tuple:
    return (1, [1.0, 0.0, 0.0, 0.0], [0.0, 0.0, 2.0], 1, name)


def transforms_doc(fl_x=30.0, cx=16.0, matrix=None, w=32, h=24) -> dict:
    matrix = np.eye(4).tolist() if matrix is None else matrix
    return {
        "fl_x": fl_x,
        "fl_y": fl_x,
        "cx": cx,
        "cy": h / 2,
        "w": w,
        "h": h,
        "frames": [{"file_path": "view.png", "transform_matrix": matrix}],
    }


def write_json(path: Path, doc) -> None:
    Path(path).write_text(json.dumps(doc))  # NaN / Infinity tokens allowed: bad input on purpose


def gradient_inputs(root: Path, image: str = "view.exr") -> tuple[Path, Path, Path]:
    """(geometry dir, COLMAP model, images dir) of testscenes.box_room, as the geometry, cameras
    and synthesize stages write them; the camera's image (named ``image``) is a uniform grey EXR."""
    scene = box_room()
    scene.cameras[0].name = image
    geometry, sparse, images = root / "geometry", root / "sparse", root / "images"
    geometry.mkdir(parents=True)
    write_mesh_ply(geometry / "mesh.ply", scene.mesh)
    np.savez(geometry / "atlas.npz", mask=np.ones(scene.maps.atlas_shape, bool))
    write_colmap(sparse, scene.cameras)
    images.mkdir()
    write_exr(images / image, np.full((24, 32, 3), 0.5, np.float32))
    return geometry, sparse, images


def render_inputs(root: Path, **box) -> Path:
    """A scene directory of testscenes.box_room (its keywords: kd, ks, ...)."""
    scene = box_room(**box)
    scene.cameras[0].name = "view.exr"
    write_scene(root / "scene", scene)
    return root / "scene"
