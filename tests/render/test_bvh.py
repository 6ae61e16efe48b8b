"""Tests of the host-side 8-wide BVH builder (invrender.render.bvh)."""

import time

import numpy as np
import pytest

from invrender.render.bvh import (
    WideBVH,
    _closest_hit_reference,
    _intersect_mt,
    build_bvh,
    leaf_blocks,
    triangle_vertices,
    valid_triangle_mask,
)

W = 8


# ---------------------------------------------------------------------------------------------
# Scenes
# ---------------------------------------------------------------------------------------------


def soup(n, seed=0, size=10.0, tri=0.3, dtype=np.float32):
    rng = np.random.default_rng(seed)
    c = rng.random((n, 3)) * size
    return tuple((c + rng.normal(size=(n, 3)) * tri).astype(dtype) for _ in range(3))


def grid(k, z_wave=0.0):
    """(k x k quads -> 2 k^2 triangles) on the unit-spaced grid, optionally wavy in z."""
    x, y = np.meshgrid(np.arange(k + 1), np.arange(k + 1), indexing="ij")
    z = z_wave * np.sin(0.7 * x) * np.cos(0.5 * y)
    p = np.stack([x.ravel(), y.ravel(), z.ravel()], 1).astype(np.float32)
    i = (np.arange(k)[:, None] * (k + 1) + np.arange(k)[None, :]).ravel()
    f = np.concatenate([np.stack([i, i + k + 1, i + 1], 1), np.stack([i + 1, i + k + 1, i + k + 2], 1)])
    return triangle_vertices(p, f)


# ---------------------------------------------------------------------------------------------
# Invariants
# ---------------------------------------------------------------------------------------------


def check_structure(bvh: WideBVH, v0, v1, v2, expected_valid=None):
    """Assert every documented invariant of the layout; returns the number of leaves."""
    a, b, c = (np.asarray(x, dtype=np.float64) for x in (v0, v1, v2))
    N = bvh.bounds.shape[0]
    assert N >= 1
    assert bvh.bounds.shape == (N, 6, W) and bvh.bounds.dtype == np.float32
    assert bvh.children.shape == (N, 2, W) and bvh.children.dtype == np.int32
    assert bvh.tri_order.ndim == 1 and bvh.tri_order.dtype == np.int32
    assert not np.isnan(bvh.bounds).any()
    assert bvh.nbytes == bvh.bounds.nbytes + bvh.children.nbytes + bvh.tri_order.nbytes

    first, count = bvh.children[:, 0, :], bvh.children[:, 1, :]
    assert ((count >= -1) & (count <= 8)).all(), "leaf counts must be 1..8"
    occupied = count >= 0
    # Occupied lanes form a prefix of every node.
    n_occ = occupied.sum(1)
    assert (occupied == (np.arange(W)[None, :] < n_occ[:, None])).all()
    # Empty lanes: min = +inf, max = -inf, index 0.
    empty = ~occupied
    assert (bvh.bounds[:, :3, :][np.broadcast_to(empty[:, None, :], (N, 3, W))] == np.inf).all()
    assert (bvh.bounds[:, 3:, :][np.broadcast_to(empty[:, None, :], (N, 3, W))] == -np.inf).all()
    assert (first[empty] == 0).all()
    # Occupied lanes have finite, non-inverted boxes.
    lo = bvh.bounds[:, :3, :]
    hi = bvh.bounds[:, 3:, :]
    occ3 = np.broadcast_to(occupied[:, None, :], (N, 3, W))
    assert np.isfinite(lo[occ3]).all() and np.isfinite(hi[occ3]).all()
    assert (lo[occ3] <= hi[occ3]).all()

    # Tree: every node but the root is referenced by exactly one internal lane, children come
    # after their parent (breadth-first numbering), the root is never referenced.
    internal = count == 0
    parent_of = np.nonzero(internal)[0]
    kids = first[internal]
    assert ((kids >= 1) & (kids < N)).all()
    assert (kids > parent_of).all()
    assert np.array_equal(np.sort(kids), np.arange(1, N))
    # Every non-root node has at least one occupied lane.
    assert (n_occ[1:] >= 1).all()

    # Leaves: ranges of tri_order that partition it.
    T = bvh.tri_order.size
    leaf = count > 0
    f_l, c_l = first[leaf].astype(np.int64), count[leaf].astype(np.int64)
    assert ((f_l >= 0) & (f_l + c_l <= T)).all()
    slots = np.concatenate([np.arange(f, f + n) for f, n in zip(f_l, c_l)]) if f_l.size else []
    assert np.array_equal(np.sort(slots), np.arange(T)), "every slot in exactly one leaf"
    # tri_order: each valid triangle exactly once, nothing else.
    if expected_valid is None:
        expected_valid = valid_triangle_mask(v0, v1, v2)
    assert np.array_equal(np.sort(bvh.tri_order), np.flatnonzero(expected_valid))

    # Containment: each lane's box contains (exactly, in float64) all vertices below it.
    tlo = np.minimum(np.minimum(a, b), c)
    thi = np.maximum(np.maximum(a, b), c)
    sub_lo = np.full((N, 3), np.inf)
    sub_hi = np.full((N, 3), -np.inf)
    for n in range(N - 1, -1, -1):  # children after parents: reverse order is bottom-up
        for lane in range(int(n_occ[n])):
            if count[n, lane] > 0:
                tris = bvh.tri_order[first[n, lane] : first[n, lane] + count[n, lane]]
                l_lo, l_hi = tlo[tris].min(0), thi[tris].max(0)
            else:
                l_lo, l_hi = sub_lo[first[n, lane]], sub_hi[first[n, lane]]
            assert (lo[n, :, lane].astype(np.float64) <= l_lo).all(), (n, lane)
            assert (hi[n, :, lane].astype(np.float64) >= l_hi).all(), (n, lane)
            sub_lo[n] = np.minimum(sub_lo[n], l_lo)
            sub_hi[n] = np.maximum(sub_hi[n], l_hi)
    return int(leaf.sum())


def brute_force(v0, v1, v2, origins, directions, chunk=64):
    a, b, c = (np.asarray(x, dtype=np.float64) for x in (v0, v1, v2))
    ids, ts = [], []
    for s in range(0, len(origins), chunk):
        o = origins[s : s + chunk, None, :]
        d = directions[s : s + chunk, None, :]
        t = _intersect_mt(o, d, a[None], b[None], c[None])  # (R, F)
        i = np.argmin(t, axis=1)  # first minimum: ties go to the lower triangle index
        tt = t[np.arange(len(i)), i]
        ids.append(np.where(np.isfinite(tt), i, -1))
        ts.append(tt)
    return np.concatenate(ids), np.concatenate(ts)


# ---------------------------------------------------------------------------------------------
# Tests
# ---------------------------------------------------------------------------------------------


@pytest.mark.parametrize("n", [2, 5, 9, 17, 100, 3000])
def test_structure_random_soup(n):
    v = soup(n, seed=n)
    bvh = build_bvh(*v)
    n_leaves = check_structure(bvh, *v, expected_valid=np.ones(n, bool))
    assert n_leaves >= 1
    if n >= 100:
        assert bvh.n_nodes > 1


def test_structure_grid_and_leaf_sizes():
    v = grid(40, z_wave=1.0)
    bvh = build_bvh(*v)
    check_structure(bvh, *v, expected_valid=np.ones(len(v[0]), bool))
    counts = bvh.children[:, 1][bvh.children[:, 1] > 0]
    assert counts.max() <= 8 and counts.min() >= 1
    assert counts.mean() <= 6  # SAH leaves on a well-behaved mesh are small


def test_no_triangles():
    z = np.zeros((0, 3), np.float32)
    bvh = build_bvh(z, z, z)
    assert bvh.n_nodes == 1 and bvh.tri_order.size == 0
    check_structure(bvh, z, z, z)


def test_all_degenerate():
    rng = np.random.default_rng(1)
    p = rng.integers(-5, 5, (30, 3)).astype(np.float32)
    q = rng.integers(-5, 5, (30, 3)).astype(np.float32)
    v0 = p.copy()
    v1 = np.concatenate([p[:10], q[10:20], np.full((10, 3), np.nan, np.float32)])
    v2 = np.concatenate([p[:10], 2 * q[10:20] - p[10:20], p[20:]])  # points, collinear, NaN
    v2[25] = np.inf
    bvh = build_bvh(v0, v1, v2)
    assert bvh.n_nodes == 1 and bvh.tri_order.size == 0
    assert (bvh.children[0, 1] == -1).all()
    assert (bvh.bounds[0, :3] == np.inf).all() and (bvh.bounds[0, 3:] == -np.inf).all()
    check_structure(bvh, v0, v1, v2, expected_valid=np.zeros(30, bool))


def test_one_triangle():
    v = [np.array([x], np.float32) for x in ([0, 0, 0], [1, 0, 0], [0, 1, 0])]
    bvh = build_bvh(*v)
    assert bvh.n_nodes == 1
    assert list(bvh.children[0, 1]) == [1] + [-1] * 7
    assert list(bvh.tri_order) == [0]
    np.testing.assert_array_equal(bvh.bounds[0, :, 0], [0, 0, 0, 1, 1, 0])
    check_structure(bvh, *v)
    assert bvh.sah_cost() == pytest.approx(2.0)  # root visit + one triangle


def test_mixed_valid_and_invalid():
    v0, v1, v2 = (x.copy() for x in soup(500, seed=3))
    bad = np.array([0, 7, 100, 250, 499])
    v1[bad[:2]] = v0[bad[:2]]  # zero area
    v2[bad[2]] = np.nan
    v0[bad[3], 1] = -np.inf
    v1[bad[4]] = v2[bad[4]]  # zero area
    # A sliver: nonzero area but below 1e-12 * extent^2 (extent ~ 17 here).
    v0[300] = [0, 0, 0]
    v1[300] = [1, 0, 0]
    v2[300] = [0.5, 1e-11, 0]
    valid = np.ones(500, bool)
    valid[bad] = False
    valid[300] = False
    bvh = build_bvh(v0, v1, v2)
    check_structure(bvh, v0, v1, v2, expected_valid=valid)


def test_beyond_float32_range_is_dropped():
    v = [x.astype(np.float64) for x in soup(50, seed=13)]
    v[2][[4, 9]] = 1e39  # finite in float64, inf in the kernel's float32 vertex buffer
    valid = np.ones(50, bool)
    valid[[4, 9]] = False
    bvh = build_bvh(*v)
    check_structure(bvh, *v, expected_valid=valid)


def test_identical_triangles():
    n = 5000
    v = [np.tile(np.array([x], np.float32), (n, 1)) for x in ([0, 0, 0], [1, 0, 0], [0, 1, 0])]
    t0 = time.perf_counter()
    bvh = build_bvh(*v)
    assert time.perf_counter() - t0 < 5
    check_structure(bvh, *v, expected_valid=np.ones(n, bool))
    # Coincident centroids: median splits down to leaves of at most 8.
    assert bvh.children[:, 1].max() <= 8


def test_identical_triangles_plus_others():
    same = [np.tile(np.array([x], np.float32), (300, 1)) for x in ([5, 5, 5], [6, 5, 5], [5, 6, 5])]
    other = soup(300, seed=4)
    v = [np.concatenate([s, o]) for s, o in zip(same, other)]
    bvh = build_bvh(*v)
    check_structure(bvh, *v, expected_valid=np.ones(600, bool))


@pytest.mark.parametrize("scale", [1e-2, 1.0, 1e3])
def test_scales(scale):
    v = soup(2000, seed=5, size=scale, tri=0.03 * scale)
    bvh = build_bvh(*v)
    check_structure(bvh, *v, expected_valid=np.ones(2000, bool))


def test_mixed_scales_and_float64_rounding():
    """Sizes from 1e-2 to 1e3 in one scene, far from the origin, given as float64 values that
    float32 cannot represent: lane boxes must still contain the exact triangles."""
    rng = np.random.default_rng(6)
    n = 3000
    size = 10.0 ** rng.uniform(-2, 3, n)
    c = 1000.0 + rng.random((n, 3)) * 2000.0
    v = tuple(c + rng.normal(size=(n, 3)) * size[:, None] for _ in range(3))
    # Expected validity, computed independently: area > 1e-12 * (scene diagonal)^2.
    pts = np.concatenate(v)
    diag2 = np.sum((pts.max(0) - pts.min(0)) ** 2)
    area = 0.5 * np.linalg.norm(np.cross(v[1] - v[0], v[2] - v[0]), axis=1)
    valid = area > 1e-12 * diag2
    assert 0.9 * n < valid.sum() < n  # some 1e-2 slivers fall under the threshold
    bvh = build_bvh(*v)
    check_structure(bvh, *v, expected_valid=valid)


def test_thin_slabs_and_axis_aligned():
    """Every triangle in the plane z = 0.1 (not exact in float32) plus a stack of parallel
    planes: flat boxes, zero-extent centroid axes."""
    a, b, c = grid(20)
    a, b, c = a.copy(), b.copy(), c.copy()
    for x in (a, b, c):
        x[:, 2] = np.float32(0.1)
    stack = [np.concatenate([x + np.float32([0, 0, k]) for k in range(5)]) for x in (a, b, c)]
    bvh = build_bvh(*stack)
    check_structure(bvh, *stack, expected_valid=np.ones(len(stack[0]), bool))


def _random_rays(v, n, seed):
    rng = np.random.default_rng(seed)
    pts = np.concatenate(v).astype(np.float64)
    lo, hi = pts.min(0), pts.max(0)
    o = lo - 0.1 * (hi - lo) + rng.random((n, 3)) * 1.2 * (hi - lo)
    d = rng.normal(size=(n, 3))
    return o, d


def test_traversal_matches_brute_force_soup():
    v = soup(1500, seed=7, size=10.0, tri=0.6)
    bvh = build_bvh(*v)
    o, d = _random_rays(v, 300, seed=8)
    o = o * 0.6 + 2.0  # start inside the soup
    ids, ts = _closest_hit_reference(bvh, *v, o, d)
    ids_bf, ts_bf = brute_force(*v, o, d)
    assert (ids_bf >= 0).sum() > 150  # the test is meaningful only if most rays hit
    np.testing.assert_array_equal(ids, ids_bf)
    np.testing.assert_array_equal(ts, ts_bf)


def test_traversal_matches_brute_force_grid():
    """Wavy grid, rays aimed at vertices and edges (shared by several triangles: ties go to the
    lower index in both) and random rays."""
    v = grid(24, z_wave=2.0)
    bvh = build_bvh(*v)
    rng = np.random.default_rng(9)
    tri = rng.integers(0, len(v[0]), 200)
    corner = rng.integers(0, 3, 200)
    target = np.stack([v[k][t] for k, t in zip(corner, tri)]).astype(np.float64)
    target[100:150] = 0.5 * (v[0][tri[100:150]] + v[1][tri[100:150]])  # edge midpoints
    o1 = target + np.array([0.3, -0.2, 10.0]) * rng.uniform(0.5, 2.0, (200, 1))
    d1 = target - o1
    o2, d2 = _random_rays(v, 150, seed=10)
    o, d = np.concatenate([o1, o2]), np.concatenate([d1, d2])
    ids, ts = _closest_hit_reference(bvh, *v, o, d)
    ids_bf, ts_bf = brute_force(*v, o, d)
    assert (ids_bf[:200] >= 0).mean() > 0.9
    np.testing.assert_array_equal(ids, ids_bf)
    np.testing.assert_array_equal(ts, ts_bf)


def test_traversal_skips_invalid_triangles():
    v0, v1, v2 = (x.copy() for x in grid(6))
    v2[3] = np.nan
    v1[10] = v0[10]
    bvh = build_bvh(v0, v1, v2)
    valid = valid_triangle_mask(v0, v1, v2)
    assert valid.sum() == len(v0) - 2
    o, d = _random_rays((v0[valid], v1[valid], v2[valid]), 100, seed=11)
    d[:, 2] = -np.abs(d[:, 2]) - 0.5
    o[:, 2] = 3.0
    ids, ts = _closest_hit_reference(bvh, v0, v1, v2, o, d)
    ids_bf, ts_bf = brute_force(v0[valid], v1[valid], v2[valid], o, d)
    np.testing.assert_array_equal(ids, np.where(ids_bf >= 0, np.flatnonzero(valid)[ids_bf], -1))
    np.testing.assert_array_equal(ts, ts_bf)


def test_sah_cost_prefers_a_real_tree():
    v = grid(30, z_wave=1.0)
    bvh = build_bvh(*v)
    cost = bvh.sah_cost()
    assert np.isfinite(cost) and cost > 1.0
    # A tree that tests every triangle would cost ~ the number of triangles.
    assert cost < 0.05 * len(v[0])


def test_leaf_blocks_hold_each_leafs_triangles_in_slot_order():
    """The kernel's layout: a leaf lane's row 0 names its block, the block's columns are the
    leaf's triangles (vertex coordinates, slot) in slot order, unused columns 0 with slot -1."""
    v = soup(500, seed=4)
    bvh = build_bvh(*v)
    children, blocks = leaf_blocks(bvh, *v)
    count = bvh.children[:, 1]
    leaf = count > 0
    assert np.array_equal(children[:, 1], count)
    assert np.array_equal(children[:, 0][~leaf], bvh.children[:, 0][~leaf])
    block, first, n = children[:, 0][leaf], bvh.children[:, 0][leaf], count[leaf]
    assert blocks.shape == (leaf.sum(), 10, W) and np.array_equal(np.sort(block), np.arange(len(blocks)))
    assert (np.diff(first[np.argsort(block)]) > 0).all()  # blocks lie in slot order
    slots = blocks[:, 9].view(np.int32)
    for b, f, k in zip(block, first, n):
        assert list(slots[b]) == list(range(f, f + k)) + [-1] * (W - k)
        for j, vertex in enumerate(v):
            np.testing.assert_array_equal(blocks[b, 3 * j : 3 * j + 3, :k], vertex[bvh.tri_order[f : f + k]].T)
            assert (blocks[b, 3 * j : 3 * j + 3, k:] == 0).all()


def test_min_leaf():
    """Every subtree of at most min_leaf triangles is one leaf: an inner lane holds more."""
    v = grid(20, z_wave=1.0)
    for min_leaf in (1, 4, 8):
        bvh = build_bvh(*v, min_leaf=min_leaf)
        check_structure(bvh, *v)
        first, count = bvh.children[:, 0], bvh.children[:, 1]
        below = np.zeros(bvh.n_nodes, np.int64)
        for node in range(bvh.n_nodes - 1, -1, -1):  # children come after their parents
            below[node] = count[node][count[node] > 0].sum() + below[first[node][count[node] == 0]].sum()
        assert (below[first[count == 0]] > min_leaf).all(), min_leaf
    with pytest.raises(ValueError):
        build_bvh(*v, min_leaf=9)


def test_triangle_vertices():
    p = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0]], np.float64)
    f = np.array([[0, 1, 2], [1, 3, 2]])
    v0, v1, v2 = triangle_vertices(p, f)
    assert v0.dtype == np.float32 and v0.shape == (2, 3)
    np.testing.assert_array_equal(v1[1], [1, 1, 0])
    np.testing.assert_array_equal(v2[0], [0, 1, 0])


def test_build_time_200k():
    v = soup(200_000, seed=12, size=50.0, tri=0.2)
    t0 = time.perf_counter()
    bvh = build_bvh(*v)
    dt = time.perf_counter() - t0
    print(
        f"\nbuild_bvh(200k triangles): {dt:.2f} s, {bvh.n_nodes} nodes, "
        f"{bvh.nbytes / 200_000:.1f} bytes/triangle, SAH {bvh.sah_cost():.1f}"
    )
    assert dt < 10.0
    assert bvh.tri_order.size == 200_000
    assert np.array_equal(np.sort(bvh.tri_order), np.arange(200_000))
    assert bvh.children[:, 1].max() <= 8
