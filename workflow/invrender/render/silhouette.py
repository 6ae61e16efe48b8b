"""Anti-aliased label-coverage and depth images of posed meshes, differentiable w.r.t. each
mesh's pose and scale through primary visibility (Li et al. 2018, "Differentiable Monte Carlo
Ray Tracing through Edge Sampling"). Kernels: kernels/silhouette.cl (entries), edges.h (the
edge samples), pose.h (velocity fields), projection.h; docs/renderer.md, "Geometric gradients".

    parts = [MeshPart(vertices (V, 3), faces (F, 3), face_labels (F,)), ...]
    params: (P, 9) tensor, per part [tx, ty, tz, rx, ry, rz (axis-angle), log sx, log sy, log sz]
            world = R(r) @ (diag(exp(log s)) @ v) + t
    masks, depth = render_masks_depth(parts, params, camera, labels=L, spp=16, seed=0)

masks (L, H, W): the fraction of each pixel's area whose first hit has that label; depth (H, W):
the pixel's mean camera-space depth, a miss counting 0. The backward adds the interior term (a
hit's depth moves with its triangle) and the boundary term (the jump of the integrand across the
silhouette, occlusion and label edges times their normal velocity on the screen).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import cached_property

import numpy as np
import pyopencl as cl
import torch

from ..scene.types import Camera
from .bvh import build_bvh, leaf_blocks
from .device import context_and_queue
from .program import build_program
from .scene_buffers import pack_cameras

POSE_PARAMS = 9  # kernels/pose.h
RAYS_PER_LAUNCH = 1 << 20  # interior rays / edge samples per launch: bounds the per-sample output
EDGE_EPS = 1e-3  # pixels: the offset of the two side rays of an edge sample
NEAR = 1e-6  # near clipping plane of the edges, relative to the parts' extent in camera space

__all__ = ["MeshPart", "render_masks_depth", "rotation_matrix", "pose_vertices", "PosedScene"]


@dataclass(eq=False)
class MeshPart:
    """A mesh in its own frame with a label per face (an index into the masks; others ignored)."""

    vertices: np.ndarray
    faces: np.ndarray
    face_labels: np.ndarray

    def __post_init__(self):
        self.vertices = np.asarray(self.vertices, np.float64).reshape(-1, 3)
        self.faces = np.asarray(self.faces, np.int64).reshape(-1, 3)
        self.face_labels = np.asarray(self.face_labels, np.int64).reshape(-1)
        if len(self.face_labels) != len(self.faces):
            raise ValueError(f"MeshPart: {len(self.face_labels)} face_labels for {len(self.faces)} faces")
        if self.faces.size and (self.faces.min() < 0 or self.faces.max() >= len(self.vertices)):
            raise ValueError(f"MeshPart: face indices outside 0..{len(self.vertices) - 1}")
        if not np.isfinite(self.vertices).all():
            raise ValueError("MeshPart: non-finite vertices")

    @cached_property
    def edges(self) -> tuple[np.ndarray, np.ndarray]:
        """(E, 2) vertex indices of each edge and (E, 2) its two faces (-1, -1 for a boundary or
        non-manifold edge: always a candidate). Vertices at the same position are one vertex
        here: meshes split at creases (per-face normals or UVs) would otherwise list every
        crease twice as a boundary, and count its jump twice."""
        _, first, weld = np.unique(self.vertices, axis=0, return_index=True, return_inverse=True)
        weld = weld.reshape(-1)
        corners = first[weld][self.faces]  # each vertex replaced by the first at its position
        pairs = np.concatenate([corners[:, [0, 1]], corners[:, [1, 2]], corners[:, [2, 0]]])
        face_of = np.tile(np.arange(len(self.faces)), 3)
        keys = np.sort(pairs, axis=1)
        keep = keys[:, 0] != keys[:, 1]  # collapsed by the weld
        keys, face_of = keys[keep], face_of[keep]
        unique, inverse, counts = np.unique(keys, axis=0, return_inverse=True, return_counts=True)
        inverse = inverse.reshape(-1)
        order = np.argsort(inverse, kind="stable")
        start = np.concatenate([[0], np.cumsum(counts)[:-1]])
        faces = np.full((len(unique), 2), -1, np.int64)
        two = counts == 2
        faces[two, 0] = face_of[order][start[two]]
        faces[two, 1] = face_of[order][start[two] + 1]
        return unique, faces


def rotation_matrix(r) -> np.ndarray:
    """Rodrigues: the rotation by |r| about r / |r| (float64)."""
    r = np.asarray(r, np.float64)
    theta = np.linalg.norm(r)
    K = _cross_matrix(r)
    if theta < 1e-8:
        return np.eye(3) + K + 0.5 * K @ K
    return np.eye(3) + np.sin(theta) / theta * K + (1.0 - np.cos(theta)) / theta**2 * K @ K


def _cross_matrix(v) -> np.ndarray:
    return np.array([[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]])


def _rotation_derivatives(r) -> list[np.ndarray]:
    """dR/dr_k (Gallego and Yezzi 2015, "A compact formula for the derivative of a 3-D rotation
    in exponential coordinates"): (r_k [r]x + [r x (I - R) e_k]x) R / |r|^2; [e_k]x at r = 0."""
    r = np.asarray(r, np.float64)
    R, theta2 = rotation_matrix(r), float(r @ r)
    eye = np.eye(3)
    if theta2 < 1e-16:
        return [_cross_matrix(eye[k]) for k in range(3)]
    return [(r[k] * _cross_matrix(r) + _cross_matrix(np.cross(r, (eye - R) @ eye[k]))) @ R / theta2 for k in range(3)]


def pose_vertices(part: MeshPart, pose) -> np.ndarray:
    """World vertices of a part at pose (9,): R(r) diag(exp(log s)) v + t."""
    pose = np.asarray(pose, np.float64)
    return (part.vertices * np.exp(pose[6:9])) @ rotation_matrix(pose[3:6]).T + pose[:3]


def velocity_fields(pose) -> np.ndarray:
    """(9, 3, 4) float64: V_j(x) = A_j x + b_j, the velocity of the part's material point at
    world x w.r.t. parameter j (kernels/pose.h). With u = S^-1 R^T (x - t): d/dt_k = e_k;
    d/dr_k = dR/dr_k S u = dR/dr_k R^T (x - t); d/dlog s_k = R E_kk S u = R E_kk R^T (x - t)."""
    pose = np.asarray(pose, np.float64)
    t, R = pose[:3], rotation_matrix(pose[3:6])
    fields = np.zeros((POSE_PARAMS, 3, 4))
    fields[0:3, :, 3] = np.eye(3)
    linear = [dR @ R.T for dR in _rotation_derivatives(pose[3:6])]
    linear += [np.outer(R[:, k], R[:, k]) for k in range(3)]
    for j, A in enumerate(linear, start=3):
        fields[j, :, :3], fields[j, :, 3] = A, -A @ t
    return fields


@dataclass
class PosedScene:
    """The parts at one pose, packed for the kernels: world triangles in BVH order, each slot's
    label and part, the velocity fields and the edge candidates."""

    parts: list[MeshPart]
    params: np.ndarray  # (P, 9) float64
    camera: Camera
    world: list[np.ndarray] = field(default_factory=list)  # per part (V, 3) world vertices

    def __post_init__(self):
        self.world = [pose_vertices(p, q) for p, q in zip(self.parts, self.params)]
        tris = [w[p.faces] for p, w in zip(self.parts, self.world)]
        all_tris = np.concatenate(tris) if tris else np.zeros((0, 3, 3))
        self.labels = np.concatenate([p.face_labels for p in self.parts]).astype(np.int32)
        self.part_of = np.repeat(np.arange(len(self.parts)), [len(p.faces) for p in self.parts]).astype(np.int32)
        v0, v1, v2 = (all_tris[:, k].astype(np.float32) for k in range(3))
        self.bvh = build_bvh(v0, v1, v2)
        self.children, self.leaves = leaf_blocks(self.bvh, v0, v1, v2)
        order = self.bvh.tri_order
        self.tri_v = np.zeros((len(order) * 3, 4), np.float32)
        self.tri_v[:, :3] = all_tris[order].reshape(-1, 3)
        self.slot_label = self.labels[order] if len(order) else np.full(1, -1, np.int32)
        self.slot_part = self.part_of[order] if len(order) else np.full(1, -1, np.int32)
        self.velocity = np.stack([velocity_fields(q) for q in self.params]).astype(np.float32).reshape(-1, 4)


def edge_candidates(posed: PosedScene) -> dict:
    """The edges where the integrand may jump, as seen from the camera: mesh boundaries,
    silhouettes (the two faces on opposite sides of the camera) and edges between two labels;
    clipped to the near plane and then to the image, in float64. Returns the kernel's edge
    buffers (end points with their camera z, their pixels, part, cdf) and the total length."""
    cam = posed.camera
    R, t, C = np.asarray(cam.R, np.float64), np.asarray(cam.t, np.float64), cam.center
    ends, part_ids = [], []
    for index, (part, world) in enumerate(zip(posed.parts, posed.world)):
        edges, faces = part.edges
        if not len(edges):
            continue
        manifold = faces[:, 0] >= 0
        f0, f1 = np.maximum(faces[:, 0], 0), np.maximum(faces[:, 1], 0)
        jump = ~manifold | _folded(world, part.faces, edges, f0, f1, C) | (part.face_labels[f0] != part.face_labels[f1])
        ends.append(world[edges[jump]])
        part_ids.append(np.full(int(jump.sum()), index))
    if not ends:
        return {"count": 0}
    ends, part_ids = np.concatenate(ends), np.concatenate(part_ids)
    X = ends @ R.T + t  # (E, 2, 3) camera space
    near = NEAR * max(float(np.abs(X).max()), 1e-30)
    X, part_ids = _clip_near(X, part_ids, near)
    fx, fy = cam.focal
    cx, cy = cam.principal_point
    y = np.stack([fx * X[..., 0] / X[..., 2] + cx, fy * X[..., 1] / X[..., 2] + cy], -1)
    a, b, inside = _clip_segments(y, cam.width, cam.height)
    X, y, part_ids, a, b = X[inside], y[inside], part_ids[inside], a[inside], b[inside]
    z0, z1 = X[:, 0, 2], X[:, 1, 2]
    # 3D fraction of the screen fractions a, b: 1/z is linear on the screen
    sa, sb = (f * z0 / ((1 - f) * z1 + f * z0) for f in (a, b))
    XA = X[:, 0] + sa[:, None] * (X[:, 1] - X[:, 0])
    XB = X[:, 0] + sb[:, None] * (X[:, 1] - X[:, 0])
    ya = y[:, 0] + a[:, None] * (y[:, 1] - y[:, 0])
    yb = y[:, 0] + b[:, None] * (y[:, 1] - y[:, 0])
    length = np.linalg.norm(yb - ya, axis=1)
    keep = length > 1e-6
    XA, XB, ya, yb, length, part_ids = XA[keep], XB[keep], ya[keep], yb[keep], length[keep], part_ids[keep]
    if not len(length):
        return {"count": 0}
    to_world = lambda Xc: (Xc - t) @ R  # R^T (Xc - t)
    pack = lambda Xc: np.concatenate([to_world(Xc), Xc[:, 2:3]], 1).astype(np.float32)
    cdf = np.cumsum(length) / length.sum()
    cdf[-1] = 1.0
    return {
        "count": len(length),
        "edge_a": pack(XA),
        "edge_b": pack(XB),
        "edge_pixels": np.concatenate([ya, yb], 1).astype(np.float32),
        "edge_part": part_ids.astype(np.int32),
        "edge_cdf": cdf.astype(np.float32),
        "total_length": float(length.sum()),
    }


def _folded(world, faces, edges, f0, f1, C) -> np.ndarray:
    """Silhouette edges: both faces on the same side of the plane through the camera centre and
    the edge (one seen from the front, one from the back), whatever the faces' winding."""
    a, b = world[edges[:, 0]] - C, world[edges[:, 1]] - C
    m = np.cross(a, b)
    far = lambda f: world[faces[f]].sum(1) - world[edges].sum(1)  # each face's third vertex
    side0 = np.sign(np.einsum("ij,ij->i", m, far(f0) - C))
    side1 = np.sign(np.einsum("ij,ij->i", m, far(f1) - C))
    return side0 == side1


def _clip_near(X: np.ndarray, part_ids: np.ndarray, near: float):
    """Segments (E, 2, 3) cut to camera z >= near; wholly behind it, dropped."""
    z = X[..., 2]
    keep = (z >= near).any(1)
    X, part_ids, z = X[keep].copy(), part_ids[keep], z[keep]
    for k in range(2):
        behind = z[:, k] < near
        s = (near - z[behind, k]) / (z[behind, 1 - k] - z[behind, k])
        X[behind, k] = X[behind, k] + s[:, None] * (X[behind, 1 - k] - X[behind, k])
        X[behind, k, 2] = near
    return X, part_ids


def _clip_segments(y: np.ndarray, width: int, height: int):
    """Liang-Barsky: the fractions [a, b] of each screen segment (E, 2, 2) inside the image,
    and which segments have any part inside."""
    p0, d = y[:, 0], y[:, 1] - y[:, 0]
    a, b = np.zeros(len(y)), np.ones(len(y))
    for axis, size in ((0, width), (1, height)):
        for q, p in ((p0[:, axis], -d[:, axis]), (size - p0[:, axis], d[:, axis])):
            # the constraint p s <= q
            with np.errstate(divide="ignore", invalid="ignore"):
                s = q / p
            parallel = p == 0
            a = np.where(~parallel & (p < 0), np.maximum(a, s), a)
            b = np.where(~parallel & (p > 0), np.minimum(b, s), b)
            b = np.where(parallel & (q < 0), -1.0, b)
    return a, b, a < b


class SilhouetteKernels:
    """The program of kernels/silhouette.cl on one device, and its launches."""

    def __init__(self, device: str | None = None):
        self.context, self.queue = context_and_queue(device)
        program = build_program(self.context, "silhouette.cl")
        self.forward_kernel = cl.Kernel(program, "silhouette_forward")
        self.interior_kernel = cl.Kernel(program, "silhouette_interior")
        self.boundary_kernel = cl.Kernel(program, "silhouette_boundary")

    def buffer(self, array, writable: bool = False) -> cl.Buffer:
        array = np.ascontiguousarray(array)
        array = array if array.size else np.zeros(4, array.dtype)  # OpenCL has no empty buffers
        flags = (cl.mem_flags.READ_WRITE if writable else cl.mem_flags.READ_ONLY) | cl.mem_flags.COPY_HOST_PTR
        return cl.Buffer(self.context, flags, hostbuf=array)

    def upload(self, posed: PosedScene) -> dict:
        b = self.buffer
        return {
            "bvh": (b(posed.bvh.bounds), b(posed.children), b(posed.leaves)),
            "slot_label": b(posed.slot_label),
            "slot_part": b(posed.slot_part),
            "tri_v": b(posed.tri_v),
            "camera": b(pack_cameras([posed.camera])),
            "velocity": b(posed.velocity),
        }

    def forward(self, posed: PosedScene, dev: dict, labels: int, spp: int, seed: int):
        h, w = posed.camera.height, posed.camera.width
        masks = np.zeros((labels, h, w), np.float32)
        depth = np.zeros((h, w), np.float32)
        masks_buf, depth_buf = self.buffer(masks, True), self.buffer(depth, True)
        self.forward_kernel(
            self.queue, (h * w,), None, *dev["bvh"], dev["slot_label"], dev["camera"],
            np.int32(spp), np.uint64(seed), np.int32(labels), masks_buf, depth_buf,
        )  # fmt: skip
        cl.enqueue_copy(self.queue, masks, masks_buf)
        cl.enqueue_copy(self.queue, depth, depth_buf)
        return masks, depth

    def _reduce(self, launch, total: int, parts: int) -> np.ndarray:
        """Sum the per-sample (part, 9 derivatives) records of `launch(first, count, part_buf,
        grad_buf)` over batches of RAYS_PER_LAUNCH into (P, 9), in float64."""
        grad = np.zeros((parts, POSE_PARAMS))
        batch = min(total, RAYS_PER_LAUNCH)
        if batch == 0:
            return grad
        part_buf = cl.Buffer(self.context, cl.mem_flags.WRITE_ONLY, 4 * batch)
        grad_buf = cl.Buffer(self.context, cl.mem_flags.WRITE_ONLY, 4 * POSE_PARAMS * batch)
        part, records = np.empty(batch, np.int32), np.empty((batch, POSE_PARAMS), np.float32)
        for first in range(0, total, batch):
            count = min(batch, total - first)
            launch(first, count, part_buf, grad_buf)
            cl.enqueue_copy(self.queue, part, part_buf)
            cl.enqueue_copy(self.queue, records, grad_buf)
            hit = part[:count] >= 0
            for j in range(POSE_PARAMS):
                grad[:, j] += np.bincount(part[:count][hit], records[:count, j][hit].astype(np.float64), parts)
        return grad

    def interior(self, posed: PosedScene, dev: dict, spp: int, seed: int, adj_depth: np.ndarray) -> np.ndarray:
        adj = self.buffer(adj_depth.astype(np.float32))
        num_rays = adj_depth.size * spp

        def launch(first, count, part_buf, grad_buf):
            self.interior_kernel(
                self.queue, (count,), None, *dev["bvh"], dev["slot_label"], dev["slot_part"], dev["tri_v"],
                dev["camera"], dev["velocity"], np.int32(spp), np.uint64(seed), adj, np.int32(first),
                np.int32(count), part_buf, grad_buf,
            )  # fmt: skip

        return self._reduce(launch, num_rays, len(posed.parts))

    def boundary(self, posed, dev, samples: int, seed: int, adj_masks: np.ndarray, adj_depth: np.ndarray):
        edges = edge_candidates(posed)
        if edges["count"] == 0 or samples == 0:
            return np.zeros((len(posed.parts), POSE_PARAMS))
        e = {name: self.buffer(edges[name]) for name in ("edge_a", "edge_b", "edge_pixels", "edge_part", "edge_cdf")}
        adj_m, adj_d = self.buffer(adj_masks.astype(np.float32)), self.buffer(adj_depth.astype(np.float32))

        def launch(first, count, part_buf, grad_buf):
            self.boundary_kernel(
                self.queue, (count,), None, *dev["bvh"], dev["slot_label"], dev["camera"], dev["velocity"],
                e["edge_a"], e["edge_b"], e["edge_pixels"], e["edge_part"], e["edge_cdf"],
                np.int32(edges["count"]), np.float32(edges["total_length"]), np.int32(samples),
                np.float32(EDGE_EPS), np.uint64(seed), np.int32(adj_masks.shape[0]), adj_m, adj_d,
                np.int32(first), np.int32(count), part_buf, grad_buf,
            )  # fmt: skip

        return self._reduce(launch, samples, len(posed.parts))


_KERNELS: dict = {}


def kernels(device: str | None = None) -> SilhouetteKernels:
    if device not in _KERNELS:
        _KERNELS[device] = SilhouetteKernels(device)
    return _KERNELS[device]


def _check_camera(camera: Camera) -> None:
    if np.any(camera.distortion != 0):
        raise ValueError(f"render_masks_depth: camera {camera.name!r} is distorted; expected a pinhole camera")


def _edge_seed(seed: int) -> int:
    """The boundary term's stream: another key than the camera rays'."""
    return (int(seed) * 0x9E3779B97F4A7C15 + 0x632BE59BD9B4E019) % (1 << 64)


class MasksDepth(torch.autograd.Function):
    """MasksDepth.apply(params, parts, camera, labels, spp, seed, edge_samples, device)."""

    @staticmethod
    def forward(ctx, params, parts, camera, labels, spp, seed, edge_samples, device):
        k = kernels(device)
        posed = PosedScene(list(parts), params.detach().cpu().numpy().astype(np.float64), camera)
        dev = k.upload(posed)
        masks, depth = k.forward(posed, dev, labels, spp, seed)
        ctx.state = (k, posed, dev, labels, spp, seed, edge_samples)
        ctx.dtype = params.dtype
        return torch.from_numpy(masks).to(params.dtype), torch.from_numpy(depth).to(params.dtype)

    @staticmethod
    def backward(ctx, grad_masks, grad_depth):
        k, posed, dev, labels, spp, seed, edge_samples = ctx.state
        h, w = posed.camera.height, posed.camera.width
        adj_m = np.zeros((labels, h, w)) if grad_masks is None else grad_masks.detach().cpu().numpy()
        adj_d = np.zeros((h, w)) if grad_depth is None else grad_depth.detach().cpu().numpy()
        grad = k.interior(posed, dev, spp, seed, adj_d)
        grad += k.boundary(posed, dev, edge_samples, _edge_seed(seed), adj_m, adj_d)
        return (torch.from_numpy(grad).to(ctx.dtype),) + (None,) * 7


def render_masks_depth(
    parts,
    params: torch.Tensor,
    camera: Camera,
    labels: int,
    spp: int = 16,
    seed: int = 0,
    edge_samples: int | None = None,
    device: str | None = None,
):
    """masks (labels, H, W) and depth (H, W), differentiable w.r.t. params (P, 9) (module
    docstring). `edge_samples`: points drawn on the edges by the backward's boundary term
    (default spp per pixel of the image's width plus height, times 64)."""
    parts = list(parts)
    if not isinstance(params, torch.Tensor) or params.shape != (len(parts), POSE_PARAMS):
        got = tuple(params.shape) if isinstance(params, torch.Tensor) else type(params).__name__
        raise ValueError(f"render_masks_depth: params: expected a ({len(parts)}, 9) tensor, got {got}")
    _check_camera(camera)
    if edge_samples is None:
        edge_samples = 64 * spp * (camera.width + camera.height)
    return MasksDepth.apply(params, parts, camera, int(labels), int(spp), int(seed), int(edge_samples), device)
