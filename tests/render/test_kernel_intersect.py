"""Ray casting in the kernels: closest hits against brute force, watertightness through shared
edges and vertices, and no self-intersection at scene scales from 1 cm to 1 km."""

import numpy as np
import pytest
from probe import KernelProbe
from testscenes import icosphere

from invrender.render.features import Features
from invrender.scene.types import Maps, Mesh, Scene


def scene_of(positions, faces):
    positions = np.asarray(positions, np.float32)
    mesh = Mesh(positions, np.asarray(faces, np.int32), np.zeros((len(positions), 2), np.float32))
    return Scene(mesh, Maps.uniform(size=(2, 2)))


def probe_for(positions, faces):
    return KernelProbe(Features.everything(), scene_of(positions, faces))


def unit(v):
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def brute_force(v0, v1, v2, o, d):
    """Closest hit (t, triangle) by Moeller-Trumbore in float64 over every triangle."""
    t = hit_distances(v0, v1, v2, o, d)
    return t.min(1), np.where(np.isfinite(t.min(1)), t.argmin(1), -1)


def hit_distances(v0, v1, v2, o, d):
    """(rays, triangles): t of every hit by Moeller-Trumbore in float64, inf where missed."""
    e1, e2 = v1 - v0, v2 - v0
    p = np.cross(d[:, None], e2[None])
    det = np.einsum("tc,rtc->rt", e1, p)
    inv = 1.0 / np.where(det == 0, np.inf, det)
    s = o[:, None] - v0[None]
    u = np.einsum("rtc,rtc->rt", s, p) * inv
    q = np.cross(s, e1[None])
    v = np.einsum("rc,rtc->rt", d, q) * inv
    t = np.einsum("tc,rtc->rt", e2, q) * inv
    return np.where((u >= 0) & (v >= 0) & (u + v <= 1) & (t > 0), t, np.inf)


def test_closest_hits_match_brute_force():
    rng = np.random.default_rng(0)
    centers = rng.uniform(-1, 1, (300, 3))
    tris = centers[:, None] + rng.normal(scale=0.15, size=(300, 3, 3))
    positions, faces = tris.reshape(-1, 3), np.arange(900).reshape(-1, 3)
    probe = probe_for(positions, faces)
    o = rng.uniform(-2, 2, (3000, 3))
    d = unit(rng.normal(size=(3000, 3)))
    got = probe.intersect(o, d)
    p32 = positions.astype(np.float32).astype(np.float64)
    t, tri = brute_force(
        p32[0::3],
        p32[1::3],
        p32[2::3],
        o.astype(np.float32).astype(np.float64),
        d.astype(np.float32).astype(np.float64),
    )
    hit = tri >= 0
    agree = got[:, 3].astype(int) == tri
    assert agree.mean() > 0.999, f"{(~agree).sum()} of 3000 rays disagree"  # ties at shared t are allowed
    assert np.allclose(got[hit & agree, 0], t[hit & agree], rtol=1e-5)
    assert np.all(got[~hit, 3] == -1)


def grid(n=12, jitter=0.0, seed=0):
    rng = np.random.default_rng(seed)
    xs, ys = np.meshgrid(np.linspace(-1, 1, n + 1), np.linspace(-1, 1, n + 1))
    z = jitter * rng.normal(size=xs.shape)
    positions = np.stack([xs, ys, z], -1).reshape(-1, 3)
    idx = np.arange((n + 1) ** 2).reshape(n + 1, n + 1)
    a, b, c, d = idx[:-1, :-1], idx[:-1, 1:], idx[1:, 1:], idx[1:, :-1]
    faces = np.concatenate([np.stack([a, b, c], -1).reshape(-1, 3), np.stack([a, c, d], -1).reshape(-1, 3)])
    return positions.astype(np.float32), faces


@pytest.mark.parametrize("jitter", [0.0, 0.05])
def test_watertight_through_shared_vertices_and_edges(jitter):
    """Rays aimed exactly at interior vertices and at points on shared edges never leak."""
    positions, faces = grid(jitter=jitter)
    probe = probe_for(positions, faces)
    rng = np.random.default_rng(1)
    inner = np.flatnonzero((np.abs(positions[:, 0]) < 0.99) & (np.abs(positions[:, 1]) < 0.99))
    e = faces[:, [0, 1]]
    edge_points = positions[e[:, 0]] + rng.uniform(0, 1, (len(e), 1)) * (positions[e[:, 1]] - positions[e[:, 0]])
    edge_points = edge_points[(np.abs(edge_points[:, :2]) < 0.99).all(1)]
    targets = np.concatenate([positions[inner], edge_points]).astype(np.float64)
    for height in (1.0, 1e3):
        origins = targets + np.column_stack(
            [rng.normal(scale=0.3, size=(len(targets), 2)), np.full(len(targets), height)]
        )
        out = probe.intersect(origins, unit(targets - origins))
        leaks = np.count_nonzero(out[:, 3] < 0)
        assert leaks == 0, f"{leaks} of {len(targets)} rays through vertices/edges leaked (height {height})"


def test_closed_sphere_holds_every_ray_from_inside():
    positions, faces = icosphere(1.0, subdivisions=3)
    probe = probe_for(positions, faces)
    a, b = faces[:, 0], faces[:, 1]
    targets = np.concatenate([positions, 0.5 * (positions[a] + positions[b])]).astype(np.float64)
    for origin in (np.zeros(3), np.array([0.3, -0.2, 0.1])):
        out = probe.intersect(np.broadcast_to(origin, targets.shape), unit(targets - origin))
        assert np.all(out[:, 3] >= 0), "a ray from inside escaped the closed sphere"


@pytest.mark.parametrize("scale", [0.01, 1.0, 1000.0])
@pytest.mark.parametrize("offset", [0.0, 1000.0])
def test_no_self_intersection_from_cm_to_km(scale, offset):
    """Leaving a convex sphere outwards must miss it; going inwards must hit the far side."""
    positions, faces = icosphere(1.0, subdivisions=2)
    center = np.array([offset, 0.5 * offset, -offset])
    positions = (positions * scale + center).astype(np.float32)
    probe = probe_for(positions, faces)
    rng = np.random.default_rng(2)
    tri = rng.integers(0, len(faces), 4000)
    b = rng.dirichlet([1, 1, 1], 4000)
    v = positions[faces[tri]].astype(np.float64)
    p = np.einsum("rk,rkc->rc", b, v)
    n = unit(np.cross(v[:, 1] - v[:, 0], v[:, 2] - v[:, 0]))
    n *= np.sign(np.einsum("rc,rc->r", n, p - center))[:, None]  # outward
    d = unit(rng.normal(size=(4000, 3)))
    d *= np.sign(np.einsum("rc,rc->r", d, n))[:, None]
    out = probe.intersect(probe.offset(p, n), d)
    assert np.all(out[:, 3] < 0), f"{np.count_nonzero(out[:, 3] >= 0)} outward rays re-hit the sphere"
    inside = probe.intersect(probe.offset(p, -n), -d)
    assert np.all(inside[:, 3] >= 0)
    # the far side, never the surface just left: at least a grazing chord's length away
    assert np.all(inside[:, 0] > 1e-4 * scale), inside[:, 0].min()


def test_the_triangle_a_ray_leaves_is_skipped_and_no_other():
    """bvh_closest_hit(..., skip): rays from a point inside triangle k, skipping k's leaf slot (as
    the integrator does), find the closest of the other triangles (the leaf test of 8 triangles
    at once must drop exactly that lane). Through kernels/traversal.cl, which takes the skip."""
    import pyopencl as cl

    from invrender.render.device import context_and_queue
    from invrender.render.program import build_program
    from invrender.render.scene_buffers import HostScene

    rng = np.random.default_rng(5)
    centers = rng.uniform(-1, 1, (400, 3))
    p32 = (centers[:, None] + rng.normal(scale=0.2, size=(400, 3, 3))).astype(np.float32)
    scene = scene_of(p32.reshape(-1, 3), np.arange(1200).reshape(-1, 3))
    host = HostScene.pack(scene.mesh, scene.maps)
    context, queue = context_and_queue(None)
    args = host.upload(context, 0.25, 0.25)
    tri = rng.integers(0, 400, 4000)
    slot = np.argsort(host.tri_id)[tri]  # leaf slot of each ray's own triangle
    v = p32.astype(np.float64)
    o = np.einsum("rk,rkc->rc", rng.dirichlet([1, 1, 1], 4000), v[tri]).astype(np.float32)
    d = unit(rng.normal(size=(4000, 3))).astype(np.float32)
    origin = np.zeros((4000, 4), np.float32)
    origin[:, :3], origin[:, 3] = o, slot.astype(np.int32).view(np.float32)
    direction = np.zeros((4000, 4), np.float32)
    direction[:, :3] = d
    out = np.zeros((4000, 4), np.float32)
    mf = cl.mem_flags
    bufs = [cl.Buffer(context, mf.READ_WRITE | mf.COPY_HOST_PTR, hostbuf=a) for a in (origin, direction, out)]
    build_program(context, "traversal.cl").closest_hits(queue, (4000,), None, *args, *bufs)
    cl.enqueue_copy(queue, out, bufs[2])
    got = np.where(out[:, 3].view(np.int32) < 0, -1, host.tri_id[np.maximum(out[:, 3].view(np.int32), 0)])
    assert not np.any(got == tri), "a ray hit the triangle it leaves"
    t = hit_distances(v[:, 0], v[:, 1], v[:, 2], o.astype(np.float64), d.astype(np.float64))
    t[np.arange(4000), tri] = np.inf
    expected = np.where(np.isfinite(t.min(1)), t.argmin(1), -1)
    agree = got == expected
    assert agree.mean() > 0.999, f"{(~agree).sum()} of 4000 rays disagree"
    assert (expected >= 0).mean() > 0.3  # the rays do hit other triangles
