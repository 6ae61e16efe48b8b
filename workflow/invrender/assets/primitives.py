"""Triangle mesh builders for synthetic scenes.

Every builder returns a ``Primitive``: positions (V, 3) float64, faces (F, 3) int32 wound
counter-clockwise seen from the front (the front is where the normal points), and a per-face
integer ``part`` label so materials can be assigned. Meters, +Y up.

Grids built by ``axis_grid`` take their vertex coordinates straight from the given break lists
(no arithmetic), so two grids that share an edge and the breaks along it share bit-identical
vertices there: meshes stitched from them have no cracks and no T-junctions.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import NamedTuple

import numpy as np

__all__ = [
    "Primitive",
    "BOX_SIDES",
    "CYLINDER_PARTS",
    "PLANE_AXES",
    "axis_grid",
    "grid_quad",
    "quad",
    "box",
    "cylinder",
    "concatenate",
    "face_normals",
    "signed_volume",
    "subdivide_breaks",
]

# Box sides in part-label order: the axis and the direction its outward normal points.
BOX_SIDES = ("+x", "-x", "+y", "-y", "+z", "-z")
CYLINDER_PARTS = ("side", "top", "bottom")


class Primitive(NamedTuple):
    positions: np.ndarray  # (V, 3) float64
    faces: np.ndarray  # (F, 3) int32
    part: np.ndarray  # (F,) int32

    def flipped(self) -> Primitive:
        """The same surface seen from the other side (winding reversed)."""
        return Primitive(self.positions, self.faces[:, ::-1].copy(), self.part)

    def transformed(self, matrix) -> Primitive:
        """Apply a 4 x 4 affine transform (p' = M [p, 1]); winding flips if it mirrors."""
        m = np.asarray(matrix, np.float64)
        pos = self.positions @ m[:3, :3].T + m[:3, 3]
        faces = self.faces if np.linalg.det(m[:3, :3]) > 0 else self.faces[:, ::-1].copy()
        return Primitive(pos, faces, self.part)


def _grid_faces(nu: int, nv: int) -> np.ndarray:
    """Two triangles per cell of an (nu + 1) x (nv + 1) vertex grid indexed i * (nv + 1) + j,
    counter-clockwise in the (u, v) plane, cells in row-major (i, j) order."""
    i, j = np.meshgrid(np.arange(nu), np.arange(nv), indexing="ij")
    i, j = i.ravel(), j.ravel()
    v00 = i * (nv + 1) + j
    v10, v01, v11 = v00 + nv + 1, v00 + 1, v00 + nv + 2
    quads = np.stack([v00, v10, v11, v01], axis=1)
    # Interleave the cell's two triangles so cell c owns faces 2c and 2c + 1.
    return np.stack([quads[:, [0, 1, 2]], quads[:, [0, 2, 3]]], axis=1).reshape(-1, 3).astype(np.int32)


def _drop_unused(positions: np.ndarray, faces: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    used, inverse = np.unique(faces, return_inverse=True)
    return positions[used], inverse.reshape(faces.shape).astype(np.int32)


# In-plane axes (a, b) of a grid normal to each axis, with e_a x e_b = +e_axis.
PLANE_AXES = {0: (1, 2), 1: (2, 0), 2: (0, 1)}


def axis_grid(
    axis: int,
    value: float,
    facing: int,
    breaks_a,
    breaks_b,
    label: Callable[[np.ndarray, np.ndarray], np.ndarray] | None = None,
) -> Primitive:
    """A rectangle in the plane ``x[axis] = value``, front facing ``facing`` (+1 or -1) along that
    axis, split into cells at ``breaks_a`` / ``breaks_b`` (increasing coordinates along the plane's
    axes a, b: for axis x they are (y, z), for y (z, x), for z (x, y)).

    ``label(a_centre, b_centre) -> int array`` gives each cell's part label; cells labelled < 0
    are left out (holes). Without it every face gets part 0.
    """
    a, b = np.asarray(breaks_a, np.float64), np.asarray(breaks_b, np.float64)
    if np.any(np.diff(a) <= 0) or np.any(np.diff(b) <= 0):
        raise ValueError("axis_grid: breaks must be strictly increasing")
    ia, ib = PLANE_AXES[axis]
    A, B = np.meshgrid(a, b, indexing="ij")
    pos = np.empty((A.size, 3))
    pos[:, axis], pos[:, ia], pos[:, ib] = value, A.ravel(), B.ravel()
    faces = _grid_faces(len(a) - 1, len(b) - 1)
    ca, cb = np.meshgrid(0.5 * (a[1:] + a[:-1]), 0.5 * (b[1:] + b[:-1]), indexing="ij")
    cell_part = np.zeros(ca.size, np.int32) if label is None else np.asarray(label(ca.ravel(), cb.ravel()), np.int32)
    part = np.repeat(cell_part, 2)
    keep = part >= 0
    faces, part = faces[keep], part[keep]
    if facing < 0:
        faces = faces[:, ::-1]
    pos, faces = _drop_unused(pos, faces)
    return Primitive(pos, np.ascontiguousarray(faces, np.int32), part)


def grid_quad(origin, edge_u, edge_v, nu: int = 1, nv: int = 1, part: int = 0) -> Primitive:
    """The parallelogram origin + s edge_u + t edge_v, s, t in [0, 1], in nu x nv cells,
    front on the side of edge_u x edge_v."""
    o, eu, ev = (np.asarray(x, np.float64) for x in (origin, edge_u, edge_v))
    s, t = np.meshgrid(np.linspace(0, 1, nu + 1), np.linspace(0, 1, nv + 1), indexing="ij")
    pos = o + s.reshape(-1, 1) * eu + t.reshape(-1, 1) * ev
    faces = _grid_faces(nu, nv)
    return Primitive(pos, faces, np.full(len(faces), part, np.int32))


def quad(corners, part: int = 0) -> Primitive:
    """Two triangles over four corners given counter-clockwise seen from the front."""
    pos = np.asarray(corners, np.float64).reshape(4, 3)
    faces = np.array([[0, 1, 2], [0, 2, 3]], np.int32)
    return Primitive(pos, faces, np.full(2, part, np.int32))


def subdivide_breaks(lo: float, hi: float, cell: float, extra=()) -> np.ndarray:
    """Breaks from lo to hi about ``cell`` apart, plus the ``extra`` coordinates inside (hole
    edges). A regular break closer than 0.3 cells to an extra one is dropped (no slivers)."""
    n = max(1, int(np.ceil((hi - lo) / cell - 1e-9))) if np.isfinite(cell) else 1
    extra = np.array([e for e in extra if lo < e < hi], np.float64)
    regular = np.linspace(lo, hi, n + 1)[1:-1]
    tol = 0.3 * (hi - lo) / n
    if len(extra):
        regular = regular[np.abs(regular[:, None] - extra[None, :]).min(axis=1) >= tol]
    return np.unique(np.concatenate([[lo, hi], regular, extra]))


def box(lo, hi, cell: float | None = None, omit=(), extra_breaks=((), (), ())) -> Primitive:
    """Axis-aligned box [lo, hi], outward normals, sides labelled by ``BOX_SIDES`` index.

    ``cell``: largest cell size when subdividing each side (None: one cell per side).
    ``omit``: side names (``"+x"`` ... ``"-z"``) to leave out, e.g. ``("-y",)`` for a box
    standing on the floor. Sides share breaks along each axis, so the box is watertight.
    """
    lo, hi = np.asarray(lo, np.float64), np.asarray(hi, np.float64)
    if np.any(hi <= lo):
        raise ValueError(f"box: hi {hi} must exceed lo {lo} on every axis")
    breaks = [subdivide_breaks(lo[k], hi[k], cell if cell else np.inf, extra_breaks[k]) for k in range(3)]
    pieces = []
    for side, name in enumerate(BOX_SIDES):
        if name in omit:
            continue
        axis, facing = "xyz".index(name[1]), (1 if name[0] == "+" else -1)
        ia, ib = PLANE_AXES[axis]
        value = hi[axis] if facing > 0 else lo[axis]
        g = axis_grid(axis, value, facing, breaks[ia], breaks[ib])
        pieces.append(Primitive(g.positions, g.faces, np.full(len(g.faces), side, np.int32)))
    return concatenate(pieces, weld=True)


def cylinder(radius: float, height: float, segments: int = 32, rings: int = 1, caps: bool = True) -> Primitive:
    """A capped cylinder ("can") around +Y, centred at the origin, outward normals.

    Parts: 0 side, 1 top cap (y = +height/2), 2 bottom cap. The side's seam is at angle 0
    (+X); angle phi runs from +X towards -Z (counter-clockwise seen from above, +Y).
    Caps are triangle fans around a centre vertex, sharing the rim vertices with the side.
    """
    phi = 2 * np.pi * np.arange(segments) / segments
    ring = np.stack([radius * np.cos(phi), np.zeros(segments), -radius * np.sin(phi)], axis=1)
    ys = np.linspace(-height / 2, height / 2, rings + 1)
    pos = np.concatenate([ring + [0, y, 0] for y in ys])
    faces = []
    for r in range(rings):
        k = np.arange(segments)
        a, b = r * segments + k, r * segments + (k + 1) % segments
        c, d = a + segments, b + segments
        # Seen from outside phi increases to the right and y upwards: a, b, d and a, d, c are
        # counter-clockwise.
        faces += [np.stack([a, b, d], 1), np.stack([a, d, c], 1)]
    side = np.concatenate(faces)
    parts = [np.zeros(len(side), np.int32)]
    all_faces = [side]
    if caps:
        top_c, bot_c = len(pos), len(pos) + 1
        pos = np.concatenate([pos, [[0, height / 2, 0], [0, -height / 2, 0]]])
        k = np.arange(segments)
        top_ring = rings * segments + k
        top = np.stack([np.full(segments, top_c), top_ring, rings * segments + (k + 1) % segments], 1)
        bottom = np.stack([np.full(segments, bot_c), (k + 1) % segments, k], 1)
        all_faces += [top, bottom]
        parts += [np.full(segments, 1, np.int32), np.full(segments, 2, np.int32)]
    return Primitive(pos, np.concatenate(all_faces).astype(np.int32), np.concatenate(parts))


def concatenate(pieces, weld: bool = False) -> Primitive:
    """One mesh from several; ``weld`` merges vertices with bit-identical coordinates."""
    pos, faces, part, offset = [], [], [], 0
    for p in pieces:
        pos.append(p.positions)
        faces.append(p.faces + offset)
        part.append(p.part)
        offset += len(p.positions)
    pos, faces, part = np.concatenate(pos), np.concatenate(faces), np.concatenate(part)
    if weld:
        pos, inverse = np.unique(pos, axis=0, return_inverse=True)
        faces = inverse.reshape(-1)[faces]
    return Primitive(pos, faces.astype(np.int32), part.astype(np.int32))


def face_normals(positions, faces) -> np.ndarray:
    """Unit normals of the counter-clockwise fronts."""
    p = np.asarray(positions, np.float64)[np.asarray(faces)]
    n = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])
    return n / np.linalg.norm(n, axis=1, keepdims=True)


def signed_volume(positions, faces) -> float:
    """Volume enclosed by a closed mesh: positive if its fronts face outwards."""
    p = np.asarray(positions, np.float64)[np.asarray(faces)]
    return float(np.einsum("ij,ij->i", p[:, 0], np.cross(p[:, 1], p[:, 2])).sum() / 6.0)
