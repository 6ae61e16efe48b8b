"""Geometric gradients (render/silhouette.py, kernels/silhouette.cl): the forward against
analytic coverage and depth, and the backward (interior + edge-sampling boundary terms) against
central finite differences of the forward, with both estimators' noise measured over seeds.

The loss is <w_m, masks> + <w_d, depth> with smooth adjoint images w (low-frequency cosines): a
finite difference of a pixel-discrete image then sees no kinks where an edge crosses from one
pixel into the next, so a step of a fraction of a pixel has only its O(h^2) bias."""

import numpy as np
import pytest
import torch

from invrender.render.silhouette import (
    MeshPart,
    PosedScene,
    edge_candidates,
    pose_vertices,
    render_masks_depth,
    rotation_matrix,
)
from invrender.scene.cameras import pinhole_camera, project_points
from test_gpu_compile import NO_FP64, TARGETS, clang

W, H = 40, 30
SIGMAS = 4.0  # the assertion: |gradient - finite difference| within this many standard errors


def box_part(label=0, labels_by_axis=None) -> MeshPart:
    """A unit cube centred at the origin, 12 triangles, outward winding; per-face labels by the
    axis of the face's normal and its sign when given ((-x, +x, -y, +y, -z, +z) -> label)."""
    v = np.array([[x, y, z] for x in (-0.5, 0.5) for y in (-0.5, 0.5) for z in (-0.5, 0.5)])
    f = np.array(
        [[0, 1, 3], [0, 3, 2], [4, 6, 7], [4, 7, 5], [0, 4, 5], [0, 5, 1],
         [2, 3, 7], [2, 7, 6], [0, 2, 6], [0, 6, 4], [1, 5, 7], [1, 7, 3]]
    )  # fmt: skip
    labels = np.full(12, label) if labels_by_axis is None else np.repeat(labels_by_axis, 2)
    return MeshPart(v, f, labels)


def room_part(wall=0, floor=1, ceiling=2) -> MeshPart:
    """The room box as the room stage builds it: a unit cube with split vertices per face (each
    face its own 4 corners, as meshes with per-face normals come) seen from inside."""
    cube = box_part()
    faces = np.arange(36).reshape(12, 3)
    labels = np.array([wall, wall, wall, wall, floor, floor, ceiling, ceiling, wall, wall, wall, wall])
    return MeshPart(cube.vertices[cube.faces].reshape(-1, 3), faces, labels)


def smooth_weights(labels: int, seed: int):
    """Adjoint images: a constant plus two random low-frequency cosines per image."""
    rng = np.random.default_rng(seed)
    ys, xs = np.mgrid[0:H, 0:W] + 0.5

    def image():
        k = rng.uniform(-0.75, 0.75, (2, 2)) * 2 * np.pi / np.array([W, H])
        phase = rng.uniform(0, 2 * np.pi, 2)
        return rng.normal() + sum(np.cos(k[i, 0] * xs + k[i, 1] * ys + phase[i]) for i in range(2))

    return torch.tensor(np.stack([image() for _ in range(labels)])), torch.tensor(image())


def loss(parts, params, camera, labels, weights, spp, seed, grad, edge_samples=None):
    p = torch.tensor(params, requires_grad=grad)
    masks, depth = render_masks_depth(parts, p, camera, labels=labels, spp=spp, seed=seed, edge_samples=edge_samples)
    value = (weights[0] * masks).sum() + (weights[1] * depth).sum()
    if not grad:
        return value.item()
    value.backward()
    return p.grad.numpy()


def check_against_fd(parts, params, camera, labels, entries, h=0.005, fd_spp=256, seeds=8, spp=64, edge_samples=200_000):
    """Mean and standard error over seeds of the gradient (spp, edge_samples) and of the central
    finite difference (fd_spp, common random numbers for +h and -h) of the entries (part, param).
    h moves the edges by a fraction of a pixel: the derivative of a pixel-discrete image varies
    over a pixel's width as the edges cross rows and columns of pixels of different weights."""
    params = np.asarray(params, np.float64)
    weights = smooth_weights(labels, 7)
    grads = [loss(parts, params, camera, labels, weights, spp, s, True, edge_samples) for s in range(seeds)]
    grads = np.array([[g[i, j] for i, j in entries] for g in grads])
    fds = np.zeros((seeds, len(entries)))
    for s in range(seeds):
        for k, (i, j) in enumerate(entries):
            step = np.zeros_like(params)
            step[i, j] = h
            plus = loss(parts, params + step, camera, labels, weights, fd_spp, 1000 + s, False)
            minus = loss(parts, params - step, camera, labels, weights, fd_spp, 1000 + s, False)
            fds[s, k] = (plus - minus) / (2 * h)
    g, fd = grads.mean(0), fds.mean(0)
    se = np.hypot(grads.std(0, ddof=1), fds.std(0, ddof=1)) / np.sqrt(seeds)
    return g, fd, se


def assert_agrees(g, fd, se):
    report = "\n".join(f"  gradient {a:12.3f}  fd {b:12.3f}  se {c:8.3f}" for a, b, c in zip(g, fd, se))
    assert np.all(np.abs(g - fd) <= SIGMAS * se), f"gradient vs finite differences:\n{report}"
    # the test has power: a zero derivative would fail it, with a margin
    assert np.all(np.abs(fd) > 1.5 * SIGMAS * se), f"derivatives lost in noise:\n{report}"


def camera(eye=(0.3, 0.8, -3.0), target=(0.0, 0.0, 0.0)):
    return pinhole_camera("c", eye, target, W, H, 40.0)


# --- forward: analytic cases -----------------------------------------------------------------


def rectangle_coverage(x0, x1, y0, y1):
    """Exact fraction of each pixel [x, x+1) x [y, y+1) inside the rectangle [x0, x1] x [y0, y1]."""
    cover = lambda lo, hi, n: np.clip(np.minimum(np.arange(n) + 1, hi) - np.maximum(np.arange(n), lo), 0, 1)
    return np.outer(cover(y0, y1, H), cover(x0, x1, W))


def test_square_coverage_is_its_area_per_pixel():
    """A square facing the camera: each pixel's coverage is the area of the square in it."""
    square = MeshPart([[-0.5, -0.5, 0], [0.5, -0.5, 0], [0.5, 0.5, 0], [-0.5, 0.5, 0]], [[0, 1, 2], [0, 2, 3]], [1, 1])
    cam = camera(eye=(0.0, 0.0, -2.5))
    params = torch.tensor([[0.05, 0.1, 0, 0, 0, 0, 0, 0, 0]], dtype=torch.float64)
    masks, depth = render_masks_depth([square], params, cam, labels=2, spp=256, seed=3)
    f, (cx, cy) = cam.focal[0], cam.principal_point
    # camera x is world -x (looking along +z with y up), camera y is world -y
    x0, x1 = cx - f * (0.55) / 2.5, cx - f * (-0.45) / 2.5
    y0, y1 = cy - f * (0.6) / 2.5, cy - f * (-0.4) / 2.5
    truth = rectangle_coverage(x0, x1, y0, y1)
    assert masks[0].abs().max().item() == 0.0
    # stratified 16 x 16: a straight edge through a pixel misses by at most 1/16 of it
    assert np.abs(masks[1].numpy() - truth).max() < 1 / 16
    assert abs(masks[1].sum().item() - truth.sum()) < 0.02 * np.sqrt(truth.sum())
    np.testing.assert_allclose(depth.numpy(), 2.5 * masks[1].numpy(), rtol=1e-5, atol=1e-6)


def test_box_depth_is_the_plane_depth():
    """Pixels wholly inside a rotated box's face: depth is the mean over the pixel of the face
    plane's camera depth (the ray-plane distance times forward . d), integrated here on a fine
    grid in float64."""
    cam = camera()
    pose = np.array([0.1, 0.0, 0.2, 0.2, 0.5, 0.1, 0.1, -0.2, 0.1])
    part = box_part(labels_by_axis=[0, 1, 2, 3, 4, 5])
    masks, depth = render_masks_depth([part], torch.tensor(pose[None]), cam, labels=6, spp=256, seed=0)
    R = rotation_matrix(pose[3:6])
    C, fwd = cam.center, cam.R[2]
    n_sub = 8
    sub = (np.arange(n_sub) + 0.5) / n_sub
    checked = 0
    for label in range(6):
        axis, sign = divmod(label, 2)
        normal = R[:, axis] * (1 if sign else -1)
        point = pose[:3] + normal * 0.5 * np.exp(pose[6 + axis])
        inside = masks[label].numpy() == 1.0
        ys, xs = np.nonzero(inside)
        for x, y in zip(xs, ys):
            px = (x + sub[None, :] - cam.principal_point[0]) / cam.focal[0]
            py = (y + sub[:, None] - cam.principal_point[1]) / cam.focal[1]
            d_cam = np.stack(np.broadcast_arrays(px, py, np.ones_like(px)), -1)  # z = 1: depth = t
            d = d_cam @ cam.R  # to world, unnormalised
            z = (normal @ (point - C)) / (d @ normal)
            assert depth[y, x].item() == pytest.approx(z.mean(), rel=2e-4)
            checked += 1
    assert checked > 100


def test_edges_silhouette_of_a_box_seen_from_a_corner():
    """A box seen from a general direction has a hexagonal silhouette: 6 of its 18 edges (the
    face diagonals are never candidates, split vertices or not)."""
    cam = camera()
    for part in (box_part(), room_part(0, 0, 0)):
        posed = PosedScene([part], np.zeros((1, 9)), cam)
        assert edge_candidates(posed)["count"] == 6


def convex_hull(points: np.ndarray) -> np.ndarray:
    """Andrew's monotone chain, counter-clockwise in (x, y)."""
    pts = sorted(map(tuple, points))

    def chain(seq):
        out = []
        for q in seq:
            while len(out) >= 2 and (out[-1][0] - out[-2][0]) * (q[1] - out[-2][1]) - (out[-1][1] - out[-2][1]) * (
                q[0] - out[-2][0]
            ) <= 0:
                out.pop()
            out.append(q)
        return out[:-1]

    return np.array(chain(pts) + chain(pts[::-1]))


def clip_polygon(poly, axis: int, value: float, keep_above: bool) -> list:
    """Sutherland-Hodgman against the line coordinate[axis] = value."""
    out = []
    for a, b in zip(poly, poly[1:] + poly[:1]):
        a_in, b_in = (a[axis] >= value) == keep_above, (b[axis] >= value) == keep_above
        if a_in:
            out.append(a)
        if a_in != b_in:
            out.append(a + (value - a[axis]) / (b[axis] - a[axis]) * (b - a))
    return out


def polygon_area(poly) -> float:
    if len(poly) < 3:
        return 0.0
    p = np.array(poly)
    return 0.5 * abs(np.sum(p[:, 0] * np.roll(p[:, 1], -1) - np.roll(p[:, 0], -1) * p[:, 1]))


def exact_box_coverage(part: MeshPart, pose, cam) -> np.ndarray:
    """(H, W) exact coverage of a convex part: its silhouette is the convex hull of its
    projected vertices, clipped to each pixel square (float64)."""
    poly = list(convex_hull(project_points(cam, pose_vertices(part, pose))))
    cover = np.zeros((H, W))
    for y in range(H):
        row = clip_polygon(clip_polygon(poly, 1, y, True), 1, y + 1, False)
        for x in range(W) if len(row) >= 3 else ():
            cover[y, x] = polygon_area(clip_polygon(clip_polygon(row, 0, x, True), 0, x + 1, False))
    return cover


def test_box_mask_gradients_match_the_exact_coverage_derivative():
    """Masks of a rotated, scaled box (silhouette edges only): the gradient of <w, mask> against
    the derivative of the exact pixel coverage (central differences, h = 1e-6, of a function
    smooth at that scale), all nine parameters, within the gradient's noise over seeds."""
    part, pose, cam = box_part(), np.array(BOX_POSE), camera()
    w = smooth_weights(1, 3)[0]
    truth = np.zeros(9)
    for j in range(9):
        step = np.zeros(9)
        step[j] = 1e-6
        diff = exact_box_coverage(part, pose + step, cam) - exact_box_coverage(part, pose - step, cam)
        truth[j] = (w[0].numpy() * diff).sum() / 2e-6
    masks, _ = render_masks_depth([part], torch.tensor(pose[None]), cam, labels=1, spp=1024, seed=1)
    assert np.abs(masks[0].numpy() - exact_box_coverage(part, pose, cam)).max() < 1 / 32  # 32 x 32 strata
    weights = (w, torch.zeros(H, W, dtype=torch.float64))
    grads = np.array([loss([part], pose[None], cam, 1, weights, 16, s, True)[0] for s in range(6)])
    se = grads.std(0, ddof=1) / np.sqrt(len(grads))
    assert_agrees(grads.mean(0), truth, se)


# --- backward: against finite differences ----------------------------------------------------

BOX_POSE = [0.1, 0.0, 0.0, 0.2, 0.5, 0.1, 0.0, -0.2, 0.1]


@pytest.mark.parametrize(
    "entries",
    [[(0, 0), (0, 1), (0, 2)], [(0, 3), (0, 4)], [(0, 6), (0, 7), (0, 8)]],
    ids=["translated", "rotated", "scaled"],
)
def test_box_gradients_match_finite_differences(entries):
    """A box with label edges inside its silhouette too (top and bottom faces another label).
    (rz is left out: its derivative under these weights, -38, is within the noise of zero.)"""
    part = box_part(labels_by_axis=[0, 0, 1, 1, 0, 0])
    g, fd, se = check_against_fd([part], [BOX_POSE], camera(), 2, entries)
    assert_agrees(g, fd, se)


def test_occlusion_and_depth_discontinuity_match_finite_differences():
    """A box in front of another: the front box's silhouette over the back box is an occlusion
    edge with the same label on both sides, so only the depth jump drives it; the back box's
    parameters move edges that are partly hidden."""
    parts = [box_part(0), box_part(0)]
    params = [[0.25, 0.1, -0.6, 0.0, 0.4, 0.0, -0.4, -0.4, -0.4], [-0.1, 0.0, 0.8, 0.0, -0.3, 0.0, 0.2, 0.2, 0.2]]
    entries = [(0, 0), (0, 2), (0, 4), (1, 0), (1, 1)]
    g, fd, se = check_against_fd(parts, params, camera(), 1, entries)
    assert_agrees(g, fd, se)


def test_room_box_from_inside_matches_finite_differences():
    """The room stage's case: a room box (split vertices, inward view) around the camera, wall,
    floor and ceiling labels; its edges cross the near plane and leave the image."""
    room = room_part()
    cam = pinhole_camera("c", (0.3, 1.4, 0.5), (1.0, 1.2, 3.0), W, H, 70.0)
    params = [[0.5, 1.5, 1.5, 0.0, 0.2, 0.0, np.log(4.0), np.log(3.0), np.log(5.0)]]
    entries = [(0, 0), (0, 1), (0, 4), (0, 7)]
    g, fd, se = check_against_fd([room], params, cam, 3, entries)
    assert_agrees(g, fd, se)


@pytest.mark.parametrize("target", list(TARGETS))
@pytest.mark.parametrize("extra", [(), NO_FP64], ids=["fp64", "no fp64"])
def test_silhouette_kernels_compile_for_gpu_targets(target, extra):
    """Portable OpenCL C 1.2, as tests/render/test_gpu_compile.py checks the renderer's builds."""
    result = clang("silhouette.cl", (), target, extra)
    assert result.returncode == 0, result.stderr[-2000:]
    assert "unsupported OpenCL extension" not in result.stderr
