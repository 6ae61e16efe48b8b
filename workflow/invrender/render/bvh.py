"""Host-side BVH builder: binned-SAH binary BVH collapsed into an 8-wide BVH.

Everything is vectorised numpy: the binary build processes all nodes of one tree level at once
(bins are filled with ``np.bincount`` / ``np.minimum.at`` over (node, axis, bin) keys), and the
collapse into the 8-wide tree processes all wide nodes of one level at once.

Layout for the OpenCL kernel (one ray against the 8 lanes of a node with ``float8``):

``bounds[n]``   (6, 8) float32, rows min x, min y, min z, max x, max y, max z; column = lane.
``children[n]`` (2, 8) int32, row 0 = child node index (internal lane) or first leaf slot (leaf
                lane), row 1 = 0 (internal), > 0 (leaf with that many triangles), -1 (empty).
``tri_order``   (T,) int32, leaf slot -> original triangle index.

The kernel reads the main BVH with its leaves as blocks (``leaf_blocks``): a leaf lane's row 0 is
then its block, and block k is (10, 8) float32, rows v0 x y z, v1 x y z, v2 x y z and the leaf
slots (int32 bits; -1 past the leaf's count), column = triangle of the leaf, so that one ray
tests a whole leaf with ``float8`` as it tests a node's boxes.

Guarantees: node 0 is the root and is internal; occupied lanes come first in every node (empty
lanes are a suffix, so a node's lane count is the number of lanes with count != -1); empty lanes
have min = +inf, max = -inf and row 0 = 0; a lane's box contains (in exact arithmetic) every
triangle below it; leaf counts are 1..8; wide nodes are numbered breadth-first, so a child index
is always larger than its parent's.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["WideBVH", "build_bvh", "leaf_blocks", "triangle_vertices", "valid_triangle_mask"]

WIDTH = 8
N_BINS = 12
MIN_LEAF = 8  # nodes with at most this many triangles are always leaves (the kernel tests 8 at once)
MAX_LEAF = 8  # nodes with more than this many triangles are always split
C_NODE = 1.0  # SAH cost of visiting an internal node, relative to one triangle test
C_TRI = 1.0
DEGENERATE_AREA = 1e-12  # triangles with area <= this * scene extent^2 are dropped


@dataclass
class WideBVH:
    bounds: np.ndarray  # (N, 6, 8) float32
    children: np.ndarray  # (N, 2, 8) int32
    tri_order: np.ndarray  # (T,) int32

    @property
    def n_nodes(self) -> int:
        return int(self.bounds.shape[0])

    @property
    def nbytes(self) -> int:
        """Bytes of the three arrays (what the kernel uploads)."""
        return int(self.bounds.nbytes + self.children.nbytes + self.tri_order.nbytes)

    def sah_cost(self, c_node: float = C_NODE, c_tri: float = C_TRI) -> float:
        """SAH cost of the wide tree, normalised by the area of the root's box.

        ``c_node`` per internal node visited (the root counts once) plus ``c_tri`` per triangle
        tested, each weighted by the probability (area ratio) that a random ray reaches it.
        """
        return sah_cost(self, c_node, c_tri)


def sah_cost(bvh: WideBVH, c_node: float = C_NODE, c_tri: float = C_TRI) -> float:
    """See :meth:`WideBVH.sah_cost`. Returns 0 for a tree without triangles."""
    counts = bvh.children[:, 1, :]
    b = bvh.bounds.astype(np.float64)
    occupied = counts >= 0
    if not occupied.any():
        return 0.0
    ext = np.where(occupied[:, None, :], b[:, 3:, :] - b[:, :3, :], 0.0)  # (N, 3, 8)
    area = 2.0 * (ext[:, 0] * ext[:, 1] + ext[:, 1] * ext[:, 2] + ext[:, 2] * ext[:, 0])
    lo = np.where(occupied[0], b[0, :3, :], np.inf).min(axis=1)
    hi = np.where(occupied[0], b[0, 3:, :], -np.inf).max(axis=1)
    e = hi - lo
    root_area = 2.0 * (e[0] * e[1] + e[1] * e[2] + e[2] * e[0])
    if not root_area > 0.0:
        return float(c_node + c_tri * counts[counts > 0].sum())
    cost = c_node * (root_area + area[counts == 0].sum())
    cost += c_tri * (area * np.maximum(counts, 0))[counts > 0].sum()
    return float(cost / root_area)


def triangle_vertices(positions, faces):
    """(P, 3) positions and (F, 3) vertex indices -> v0, v1, v2, each (F, 3) float32."""
    p = np.asarray(positions, dtype=np.float32).reshape(-1, 3)
    f = np.asarray(faces, dtype=np.int64).reshape(-1, 3)
    return p[f[:, 0]], p[f[:, 1]], p[f[:, 2]]


def valid_triangle_mask(v0, v1, v2) -> np.ndarray:
    """True for triangles the BVH keeps: finite vertices (within float32 range) and
    area > 1e-12 * scene extent^2.

    The scene extent is the diagonal of the bounding box of all triangles with finite vertices.
    """
    a = np.asarray(v0, dtype=np.float64).reshape(-1, 3)
    b = np.asarray(v1, dtype=np.float64).reshape(-1, 3)
    c = np.asarray(v2, dtype=np.float64).reshape(-1, 3)
    with np.errstate(all="ignore"):
        big = float(np.finfo(np.float32).max)
        finite = (np.abs(a) <= big).all(1) & (np.abs(b) <= big).all(1) & (np.abs(c) <= big).all(1)
        if not finite.any():
            return finite
        pts = np.concatenate([a[finite], b[finite], c[finite]])
        ext2 = float(np.sum((pts.max(0) - pts.min(0)) ** 2))
        e1 = b - a
        e2 = c - a
        cr = _cross(e1, e2)
        area = 0.5 * np.sqrt(np.sum(cr * cr, axis=1))
        return finite & (area > 0.0) & (area > DEGENERATE_AREA * ext2) & np.isfinite(area)


def _cross(a, b):
    return np.stack(
        [
            a[..., 1] * b[..., 2] - a[..., 2] * b[..., 1],
            a[..., 2] * b[..., 0] - a[..., 0] * b[..., 2],
            a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0],
        ],
        axis=-1,
    )


def _area(lo, hi):
    """Surface area of boxes (..., 3); empty boxes (lo > hi) have area 0."""
    e = np.maximum(hi - lo, 0.0)
    return 2.0 * (e[..., 0] * e[..., 1] + e[..., 1] * e[..., 2] + e[..., 2] * e[..., 0])


def _round_out(lo, hi):
    """float64 boxes -> float32 boxes that contain them (min rounded down, max rounded up)."""
    lo32 = lo.astype(np.float32)
    hi32 = hi.astype(np.float32)
    with np.errstate(invalid="ignore"):
        down = lo32.astype(np.float64) > lo
        up = hi32.astype(np.float64) < hi
    lo32[down] = np.nextafter(lo32[down], np.float32(-np.inf))
    hi32[up] = np.nextafter(hi32[up], np.float32(np.inf))
    return lo32, hi32


# --------------------------------------------------------------------------------------------
# Binary build
# --------------------------------------------------------------------------------------------


class _BinaryTree:
    """Flat binary tree: ``left`` = first child id (right = left + 1) or -1 for a leaf; a node
    covers ``order[start:start + count]``; ``lo``/``hi`` are exact float64 boxes."""

    def __init__(self, lo, hi, start, count, left):
        self.lo = lo
        self.hi = hi
        self.start = start
        self.count = count
        self.left = left


def _choose_splits(b_lo, b_hi, b_c, bcount, b_off, node_of, axis_tol, nb):
    """Binned SAH for a batch of nodes whose triangles are contiguous ranges of the arrays.

    ``b_lo``, ``b_hi``, ``b_c``: (3, M) float32 (component-major, so every step below is a
    contiguous 1-D operation). Returns ``split`` (per node) and ``right`` (per triangle: goes to
    the right child).
    """
    Kb = bcount.size
    Mb = b_c.shape[1]
    n_split = nb - 1
    c_min = np.minimum.reduceat(b_c, b_off, axis=1)  # (3, Kb)
    c_max = np.maximum.reduceat(b_c, b_off, axis=1)
    c_ext = (c_max - c_min).astype(np.float64)
    ok_axis = (c_ext > axis_tol) & (c_ext > 1e-30)
    scale = (nb / np.where(ok_axis, c_ext, 1.0)).astype(np.float32)
    scale[~ok_axis] = 0.0
    fb = b_c - c_min[:, node_of]
    fb *= scale[:, node_of]
    np.clip(fb, 0, nb - 1, out=fb)
    bins = fb.astype(np.int32)  # (3 axes, Mb)
    del fb
    # Bin key (bin, node, axis), bin-major so that prefix sums over bins are whole-row ops.
    n_keys = nb * Kb * 3
    key = bins * np.int32(Kb * 3)
    key += (node_of * 3).astype(np.int32)
    key += np.arange(3, dtype=np.int32)[:, None]
    cnt = np.bincount(key.ravel(), minlength=n_keys).reshape(nb, Kb, 3)
    blo = np.full((3, n_keys), np.inf, dtype=np.float32)  # (component, key)
    bhi = np.full((3, n_keys), -np.inf, dtype=np.float32)
    for comp in range(3):
        for axis in range(3):
            np.minimum.at(blo[comp], key[axis], b_lo[comp])
            np.maximum.at(bhi[comp], key[axis], b_hi[comp])
    del key
    blo = blo.reshape(3, nb, Kb, 3)
    bhi = bhi.reshape(3, nb, Kb, 3)

    # SAH over the nb - 1 planes per axis; plane p puts bins 0..p left.
    with np.errstate(invalid="ignore", over="ignore"):
        acc_lo = _scan(blo.copy(), np.minimum)
        acc_hi = _scan(bhi.copy(), np.maximum)
        p_area = _box_area_cm(acc_lo[:, -1, :, 0], acc_hi[:, -1, :, 0])  # (Kb,) node's box
        l_area = _box_area_cm(acc_lo[:, :n_split], acc_hi[:, :n_split])  # (n_split, Kb, 3)
        del acc_lo, acc_hi
        r_area = _box_area_cm(
            _scan(blo, np.minimum, reverse=True)[:, 1:],
            _scan(bhi, np.maximum, reverse=True)[:, 1:],
        )
        l_cnt = np.cumsum(cnt, axis=0)[:n_split]
        r_cnt = bcount[None, :, None] - l_cnt
        cost = l_area * l_cnt + r_area * r_cnt  # nan/inf where a side is empty: masked next
        cost[(l_cnt == 0) | (r_cnt == 0)] = np.inf
        cost = cost.transpose(1, 2, 0).reshape(Kb, 3 * n_split)  # (node, axis * plane)
        best = np.argmin(cost, axis=1)
        best_cost = cost[np.arange(Kb), best].astype(np.float64)
        split_cost = C_NODE + C_TRI * best_cost / np.maximum(p_area, 1e-30)
    best_axis = best // n_split
    best_plane = best % n_split
    has_split = np.isfinite(best_cost)
    sah_split = has_split & ((bcount > MAX_LEAF) | (split_cost < C_TRI * bcount))
    median = ~has_split & (bcount > MAX_LEAF)
    split = sah_split | median
    rank = np.arange(Mb, dtype=np.int64) - b_off[node_of]
    right = np.where(
        sah_split[node_of],
        bins[best_axis[node_of], np.arange(Mb)] > best_plane[node_of],
        rank >= (bcount // 2)[node_of],
    )
    right &= split[node_of]
    return split, right


def _scan(a, op, reverse=False):
    """In-place inclusive prefix (or suffix) ``op`` along axis 1 of ``a``, one whole-slice op
    per bin (several times faster than ``op.accumulate`` along a non-last axis)."""
    n = a.shape[1]
    steps = range(n - 2, -1, -1) if reverse else range(1, n)
    d = 1 if reverse else -1
    for i in steps:
        op(a[:, i + d], a[:, i], out=a[:, i])
    return a


def _box_area_cm(lo, hi):
    """Surface area of boxes stored component-major: lo, hi (3, ...)."""
    e = hi - lo
    return 2 * (e[0] * e[1] + e[1] * e[2] + e[2] * e[0])


def _build_binary(tlo, thi, n_bins=N_BINS, min_leaf=MIN_LEAF):
    """Level-by-level binned SAH over the triangle boxes ``tlo``/``thi`` (float64).

    Returns the tree and ``order`` (positions into the input arrays, leaves contiguous).
    """
    T = tlo.shape[0]
    scene_ext = float(np.sqrt(np.sum((thi.max(0) - tlo.min(0)) ** 2)))
    axis_tol = 1e-12 * scene_ext
    lo32 = np.ascontiguousarray(tlo.T, dtype=np.float32)  # (3, T), component-major
    hi32 = np.ascontiguousarray(thi.T, dtype=np.float32)
    cen32 = np.ascontiguousarray((0.5 * (tlo + thi)).T, dtype=np.float32)
    order = np.arange(T, dtype=np.int64)

    start_parts, count_parts, left_parts = [], [], []
    n_nodes = 1
    cur_start = np.zeros(1, dtype=np.int64)
    cur_count = np.array([T], dtype=np.int64)
    empty = np.zeros(0, dtype=np.int64)

    while cur_start.size:
        left = np.full(cur_start.size, -1, dtype=np.int64)
        start_parts.append(cur_start)
        count_parts.append(cur_count)
        left_parts.append(left)
        nxt_start, nxt_count = empty, empty

        big = cur_count > min_leaf
        if big.any():
            bidx = np.flatnonzero(big)
            Kb = bidx.size
            bcount = cur_count[bidx]
            bstart = cur_start[bidx]
            b_off = np.zeros(Kb, dtype=np.int64)
            np.cumsum(bcount[:-1], out=b_off[1:])
            Mb = int(bcount.sum())
            node_of = np.repeat(np.arange(Kb, dtype=np.int64), bcount)
            b_pos = np.repeat(bstart - b_off, bcount) + np.arange(Mb, dtype=np.int64)
            b_tris = order[b_pos]
            split, right = _choose_splits(
                lo32[:, b_tris],
                hi32[:, b_tris],
                cen32[:, b_tris],
                bcount,
                b_off,
                node_of,
                axis_tol,
                n_bins,
            )
            if split.any():
                # Stable in-place partition of every splitting node's range of `order`.
                n_right = np.bincount(node_of, weights=right, minlength=Kb).astype(np.int64)
                n_left = bcount - n_right
                is_left = ~right
                cl = np.cumsum(is_left) - is_left
                cr = np.cumsum(right) - right
                cl -= cl[b_off][node_of]
                cr -= cr[b_off][node_of]
                new_pos = bstart[node_of] + np.where(right, n_left[node_of] + cr, cl)
                sel = split[node_of]
                order[new_pos[sel]] = b_tris[sel]

                sidx = np.flatnonzero(split)
                if (n_left[sidx] == 0).any() or (n_right[sidx] == 0).any():
                    raise RuntimeError("BVH build produced an empty child")  # would not terminate
                n_s = sidx.size
                left[bidx[sidx]] = n_nodes + 2 * np.arange(n_s, dtype=np.int64)
                n_nodes += 2 * n_s
                s_start = bstart[sidx]
                nxt_start = np.stack([s_start, s_start + n_left[sidx]], axis=1).ravel()
                nxt_count = np.stack([n_left[sidx], n_right[sidx]], axis=1).ravel()
        cur_start, cur_count = nxt_start, nxt_count

    start = np.concatenate(start_parts)
    count = np.concatenate(count_parts)
    left = np.concatenate(left_parts)

    # Exact float64 boxes, bottom-up: leaves partition `order`, parents are unions of children.
    lo = np.empty((start.size, 3))
    hi = np.empty((start.size, 3))
    leaves = np.flatnonzero(left < 0)
    leaves = leaves[np.argsort(start[leaves])]
    lo[leaves] = np.minimum.reduceat(tlo[order], start[leaves], axis=0)
    hi[leaves] = np.maximum.reduceat(thi[order], start[leaves], axis=0)
    level_first = np.concatenate([[0], np.cumsum([p.size for p in start_parts])])
    for L in range(len(start_parts) - 1, -1, -1):
        ids = np.arange(level_first[L], level_first[L + 1])
        ids = ids[left[ids] >= 0]
        if ids.size:
            c0 = left[ids]
            lo[ids] = np.minimum(lo[c0], lo[c0 + 1])
            hi[ids] = np.maximum(hi[c0], hi[c0 + 1])
    return _BinaryTree(lo, hi, start, count, left), order


# --------------------------------------------------------------------------------------------
# Collapse into the 8-wide tree
# --------------------------------------------------------------------------------------------


def _collapse(tree: _BinaryTree):
    """Greedy collapse: a wide node starts with the two children of a binary node and repeatedly
    opens its internal child with the largest surface area until it has 8 children or only
    leaves. Processes all wide nodes of one level at once. Returns per wide node the (W, 8)
    binary node ids of its lanes (-1 = empty)."""
    left = tree.left
    area = _area(tree.lo, tree.hi)
    levels = []
    if left[0] < 0:
        lanes = np.full((1, WIDTH), -1, dtype=np.int64)
        lanes[0, 0] = 0
        return lanes
    cur = np.zeros(1, dtype=np.int64)  # binary ids of the wide nodes of this level
    while cur.size:
        W = cur.size
        rows = np.arange(W)
        lanes = np.full((W, WIDTH), -1, dtype=np.int64)
        lanes[:, 0] = left[cur]
        lanes[:, 1] = left[cur] + 1
        n_lanes = np.full(W, 2, dtype=np.int64)
        for _ in range(WIDTH - 2):
            occ = lanes >= 0
            internal = occ & (left[np.maximum(lanes, 0)] >= 0)
            key = np.where(internal, area[np.maximum(lanes, 0)], -1.0)
            j = np.argmax(key, axis=1)
            can = internal[rows, j] & (n_lanes < WIDTH)
            if not can.any():
                break
            r = rows[can]
            opened = lanes[r, j[can]]
            lanes[r, j[can]] = left[opened]
            lanes[r, n_lanes[can]] = left[opened] + 1
            n_lanes[can] += 1
        levels.append(lanes)
        internal = (lanes >= 0) & (left[np.maximum(lanes, 0)] >= 0)
        cur = lanes[internal]  # row-major: breadth-first numbering of the next level
    return np.concatenate(levels)


def build_bvh(v0, v1, v2, n_bins: int = N_BINS, min_leaf: int = MIN_LEAF) -> WideBVH:
    """Build the 8-wide BVH of triangles ``v0``, ``v1``, ``v2`` ((F, 3) each, original order).

    Triangles with non-finite vertices or (near-)zero area are left out of ``tri_order``.
    Subtrees of at most ``min_leaf`` (1..8) triangles are leaves.
    """
    a = np.asarray(v0, dtype=np.float64).reshape(-1, 3)
    b = np.asarray(v1, dtype=np.float64).reshape(-1, 3)
    c = np.asarray(v2, dtype=np.float64).reshape(-1, 3)
    if not (a.shape == b.shape == c.shape):
        raise ValueError(f"vertex arrays differ in shape: {a.shape}, {b.shape}, {c.shape}")
    if n_bins < 2:
        raise ValueError("n_bins must be at least 2")
    if not 1 <= min_leaf <= MAX_LEAF:
        raise ValueError(f"min_leaf must be 1..{MAX_LEAF}")
    valid = valid_triangle_mask(a, b, c)
    ids = np.flatnonzero(valid)
    if ids.size == 0:
        bounds = np.empty((1, 6, WIDTH), dtype=np.float32)
        bounds[:, :3] = np.inf
        bounds[:, 3:] = -np.inf
        children = np.zeros((1, 2, WIDTH), dtype=np.int32)
        children[:, 1] = -1
        return WideBVH(bounds, children, np.zeros(0, dtype=np.int32))
    a, b, c = a[ids], b[ids], c[ids]
    tlo = np.minimum(np.minimum(a, b), c)
    thi = np.maximum(np.maximum(a, b), c)
    del a, b, c

    tree, order = _build_binary(tlo, thi, n_bins, min_leaf)
    lanes = _collapse(tree)

    # ---- flatten ------------------------------------------------------------------------
    N = lanes.shape[0]
    occ = lanes >= 0
    li = np.maximum(lanes, 0)
    internal = occ & (tree.left[li] >= 0)
    leaf = occ & ~internal
    child_row0 = np.zeros((N, WIDTH), dtype=np.int64)
    # Wide nodes are numbered in the order their internal lanes appear (row-major), after root.
    child_row0[internal] = 1 + np.arange(int(internal.sum()))
    child_row0[leaf] = tree.start[li[leaf]]
    child_row1 = np.where(internal, 0, np.where(leaf, tree.count[li], -1))
    lo32, hi32 = _round_out(tree.lo[li], tree.hi[li])  # (N, 8, 3)
    lo32[~occ] = np.inf
    hi32[~occ] = -np.inf
    bounds = np.concatenate([lo32, hi32], axis=2).transpose(0, 2, 1)
    children = np.stack([child_row0, child_row1], axis=1)
    return WideBVH(
        np.ascontiguousarray(bounds, dtype=np.float32),
        np.ascontiguousarray(children, dtype=np.int32),
        ids[order].astype(np.int32),
    )


def leaf_blocks(bvh: WideBVH, v0, v1, v2) -> tuple[np.ndarray, np.ndarray]:
    """The kernel's layout of ``bvh`` built over ``v0``, ``v1``, ``v2`` (float32, original
    order): (children, blocks). Each leaf lane's row 0 becomes its block's index, blocks are
    numbered in slot order (as the triangles lie in memory); unused columns are 0 with slot -1."""
    children = bvh.children.copy()
    leaf = children[:, 1, :] > 0
    first, count = children[:, 0, :][leaf], children[:, 1, :][leaf]
    by_slot = np.argsort(first, kind="stable")
    block = np.empty(first.size, np.int32)
    block[by_slot] = np.arange(first.size, dtype=np.int32)
    row0 = children[:, 0, :]
    row0[leaf] = block
    first, count = first[by_slot], count[by_slot]
    slots = first[:, None] + np.arange(WIDTH)[None, :]  # (L, 8)
    live = np.arange(WIDTH)[None, :] < count[:, None]
    tri = bvh.tri_order[np.where(live, slots, 0)] if bvh.tri_order.size else np.zeros(slots.shape, np.int64)
    blocks = np.zeros((first.size, 10, WIDTH), np.float32)
    for k, v in enumerate((v0, v1, v2)):
        coords = np.asarray(v, np.float32).reshape(-1, 3)[tri]  # (L, 8, 3)
        blocks[:, 3 * k : 3 * k + 3, :] = np.where(live[:, :, None], coords, 0.0).transpose(0, 2, 1)
    blocks[:, 9, :] = np.where(live, slots, -1).astype(np.int32).view(np.float32)
    return children, blocks


# --------------------------------------------------------------------------------------------
# Reference traversal (testing only)
# --------------------------------------------------------------------------------------------


def _intersect_mt(o, d, a, b, c):
    """Möller-Trumbore in float64 with broadcasting. Returns t (inf where missed)."""
    with np.errstate(all="ignore"):
        e1 = b - a
        e2 = c - a
        p = _cross(d, e2)
        det = np.sum(e1 * p, axis=-1)
        inv = 1.0 / det
        s = o - a
        u = np.sum(s * p, axis=-1) * inv
        q = _cross(s, e1)
        v = np.sum(d * q, axis=-1) * inv
        t = np.sum(e2 * q, axis=-1) * inv
        hit = (det != 0.0) & (u >= 0.0) & (v >= 0.0) & (u + v <= 1.0) & (t > 0.0)
        hit &= np.isfinite(t)
    return np.where(hit, t, np.inf)


def _closest_hit_reference(bvh: WideBVH, v0, v1, v2, origins, directions):
    """Closest hit of each ray by traversing the wide BVH (slow, for tests).

    Returns (triangle index (-1 = miss), t (inf = miss)); ties in t go to the lower index.
    """
    a = np.asarray(v0, dtype=np.float64).reshape(-1, 3)
    b = np.asarray(v1, dtype=np.float64).reshape(-1, 3)
    c = np.asarray(v2, dtype=np.float64).reshape(-1, 3)
    ray_origins = np.asarray(origins, dtype=np.float64).reshape(-1, 3)
    ray_directions = np.asarray(directions, dtype=np.float64).reshape(-1, 3)
    bmin = bvh.bounds[:, :3, :].astype(np.float64)
    bmax = bvh.bounds[:, 3:, :].astype(np.float64)
    kids = bvh.children
    ids = np.full(ray_origins.shape[0], -1, dtype=np.int64)
    ts = np.full(ray_origins.shape[0], np.inf)
    for r in range(ray_origins.shape[0]):
        o, d = ray_origins[r], ray_directions[r]
        with np.errstate(all="ignore"):
            inv = 1.0 / d
        best_t, best_id = np.inf, -1
        stack = [0]
        while stack:
            n = stack.pop()
            with np.errstate(all="ignore"):
                t0 = (bmin[n] - o[:, None]) * inv[:, None]
                t1 = (bmax[n] - o[:, None]) * inv[:, None]
                tn = np.nanmax(np.minimum(t0, t1), axis=0)
                tf = np.nanmin(np.maximum(t0, t1), axis=0)
            slack = 1e-9 * np.maximum(1.0, np.abs(tf))
            lane_hit = (kids[n, 1] >= 0) & (tn <= tf + slack) & (tf >= 0) & (tn <= best_t + slack)
            for lane in np.flatnonzero(lane_hit):
                cnt = kids[n, 1, lane]
                if cnt == 0:
                    stack.append(int(kids[n, 0, lane]))
                else:
                    first = kids[n, 0, lane]
                    tri = bvh.tri_order[first : first + cnt].astype(np.int64)
                    t = _intersect_mt(o, d, a[tri], b[tri], c[tri])
                    for k in np.flatnonzero(np.isfinite(t)):
                        if t[k] < best_t or (t[k] == best_t and tri[k] < best_id):
                            best_t, best_id = float(t[k]), int(tri[k])
        ids[r], ts[r] = best_id, best_t
    return ids, ts
