"""Copies of the generator's object posed in one 640 x 480 photograph, and their id image drawn
with a z-buffer: the hull's and the duplicates stage's fixtures (no renderer, no OpenCL)."""

import numpy as np

from invrender.scene.types import Mesh
from invrender.synthesize.duplicates import make_duplicates, object_mesh

WIDTH, HEIGHT = 640, 480


def rasterize_ids(objects, K, height, width) -> np.ndarray:
    """[(id, positions in the camera frame, faces)] -> uint16 id image with a z-buffer; a pixel
    belongs to a triangle when its centre (x + 0.5, y + 0.5) is inside it."""
    ids = np.zeros((height, width), np.uint16)
    depth = np.full((height, width), np.inf)
    for instance, cam, faces in objects:
        uv = (cam @ K.T)[:, :2] / cam[:, 2:3]
        for f in faces:
            (a, b, c), z = uv[f], cam[f, 2]
            x0, y0 = np.maximum(np.floor(uv[f].min(0) - 0.5).astype(int), 0)
            x1, y1 = np.minimum(np.ceil(uv[f].max(0) - 0.5).astype(int), [width - 1, height - 1])
            area = (b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0])
            if x1 < x0 or y1 < y0 or abs(area) < 1e-12:
                continue
            xs, ys = np.meshgrid(np.arange(x0, x1 + 1) + 0.5, np.arange(y0, y1 + 1) + 0.5)
            w0 = ((b[0] - xs) * (c[1] - ys) - (b[1] - ys) * (c[0] - xs)) / area
            w1 = ((c[0] - xs) * (a[1] - ys) - (c[1] - ys) * (a[0] - xs)) / area
            w2 = 1 - w0 - w1
            inside = (w0 >= 0) & (w1 >= 0) & (w2 >= 0)
            zz = 1.0 / (w0 / z[0] + w1 / z[1] + w2 / z[2])  # 1/z is linear in the image
            sub_depth, sub_ids = depth[y0 : y1 + 1, x0 : x1 + 1], ids[y0 : y1 + 1, x0 : x1 + 1]
            near = inside & (zz < sub_depth)
            sub_depth[near], sub_ids[near] = zz[near], instance
    return ids


def ids_for(mesh: Mesh, poses: dict, K, extra=()) -> np.ndarray:
    P = mesh.positions.astype(np.float64)
    objects = [(i, P @ T[:3, :3].T + T[:3, 3], mesh.faces) for i, T in poses.items()]
    return rasterize_ids(objects + list(extra), K, HEIGHT, WIDTH)


def generated(config: dict):
    """The generator's scene at 640 x 480 from ``config``: (object mesh, {id: T_cam_from_obj}, K,
    the world's up in the camera frame)."""
    scene, metadata = make_duplicates({**config, "camera": {"width": WIDTH, "height": HEIGHT}})
    camera = scene.cameras[0]
    world_to_cam = np.eye(4)
    world_to_cam[:3, :3], world_to_cam[:3, 3] = camera.R, camera.t
    poses = {
        p["instance_id"]: world_to_cam @ np.asarray(p["T_obj2world"], np.float64)
        for p in metadata["poses"]["instances"]
    }
    (fx, fy), (cx, cy) = camera.focal, camera.principal_point
    K = np.array([[fx, 0.0, cx], [0.0, fy, cy], [0.0, 0.0, 1.0]])
    return object_mesh(scene, metadata), poses, K, np.asarray(camera.R, np.float64) @ [0.0, 1.0, 0.0]


def can_scene(count: int, seed: int = 0):
    """The generator's cans: (object mesh, {id: T_cam_from_obj}, K)."""
    config = {"seed": seed, "count": count, "placement": {"extent": [0.6, 0.4]}, "floor": {"size": [1.2, 1.0]}}
    return generated(config)[:3]


def box_scene(count: int = 9, seed: int = 0):
    """The generator's boxes, upright, upside down and lying in turn, resting on the floor (0-2 mm
    above it): ``generated``'s four."""
    placement = {"extent": [0.6, 0.4], "max_lift": 0.002, "orientations": ["upright", "upside_down", "lying"]}
    return generated(
        {"seed": seed, "count": count, "object": {"kind": "box"}, "placement": placement, "floor": {"size": [1.2, 1.0]}}
    )
