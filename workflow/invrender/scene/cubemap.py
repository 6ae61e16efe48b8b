"""The kg cube map: its layout, its texel <-> direction convention, and lat-long <-> cube resampling.

docs/renderer.md ("Textures") is the contract; the kernels (kernels/textures.h) and the float64
reference of the sampling strategies (render/sampling.py) follow this file.

kg is (6, N, N, C) in memory and stacked (6 N, N, C) on disk, faces in the order
+X, -X, +Y, -Y, +Z, -Z, each with the OpenGL orientation (OpenGL 2.1 specification,
section 3.8.6, table 3.21; section 8.13 "Cube Map Texture Selection" in OpenGL 4.x):

    face  major  sc    tc          s = (sc / |ma| + 1) / 2,  column = floor(s N)
    +X    +rx    -rz   -ry         t = (tc / |ma| + 1) / 2,  row    = floor(t N)
    -X    -rx    +rz   -ry
    +Y    +ry    +rx   +rz         Row 0 is the first (top) row of the face in the stored
    -Y    -ry    +rx   -rz         array, as OpenGL's first row of texel data.
    +Z    +rz    +rx   -ry
    -Z    -rz    -rx   -ry

The major axis is the component with the largest magnitude; ties (a set of measure zero)
go to x before y before z, and a zero component's sign counts as +.

Lat-long images follow the UsdLux DomeLight (OpenEXR) convention (docs/export.md): pixel
(column j, row i) of a W x H image holds the radiance arriving from
d = (sin(lon) cos(lat), sin(lat), cos(lon) cos(lat)), lon = pi - 2 pi j / (W - 1),
lat = pi / 2 - pi i / (H - 1). As an area, pixel (i, j) is the cell of the directions nearest
its centre in lon and in lat: lon within pi / (W - 1) and lat within pi / (2 (H - 1)) of it,
clipped to the sphere (the first and last columns and rows are half cells).

Resampling either way is area-weighted: an output cell's value is the solid-angle-weighted mean
of the input cells overlapping it, so the integral of radiance over the sphere is kept (`_sweep`).
"""

from __future__ import annotations

import numpy as np

__all__ = [
    "FACES",
    "direction_to_cube",
    "cube_to_direction",
    "cube_texel",
    "cube_texel_solid_angles",
    "texel_directions",
    "as_cube",
    "lookup_cube",
    "kg_to_stacked",
    "kg_from_stacked",
    "latlong_directions",
    "latlong_solid_angles",
    "latlong_to_cube",
    "cube_to_latlong",
]

FACES = ("+X", "-X", "+Y", "-Y", "+Z", "-Z")


def _normalize(v):
    """v / |v| along the last axis, for v of length >= 1e-150 (the cube's directions have a
    largest component of 1, so this is render/bsdf.normalize's result to the bit)."""
    return v / np.sqrt(np.sum(v * v, axis=-1, keepdims=True))


# --------------------------------------------------------------------------------------------
# texel <-> direction


def direction_to_cube(d):
    """d (..., 3), any nonzero length -> (face int (...), s (...), t (...)), s, t in [0, 1]."""
    d = np.asarray(d, dtype=np.float64)
    rx, ry, rz = d[..., 0], d[..., 1], d[..., 2]
    ax, ay, az = np.abs(rx), np.abs(ry), np.abs(rz)
    x_major = (ax >= ay) & (ax >= az)
    y_major = ~x_major & (ay >= az)
    face = np.where(
        x_major, np.where(rx >= 0, 0, 1), np.where(y_major, np.where(ry >= 0, 2, 3), np.where(rz >= 0, 4, 5))
    )
    # table 3.21: (sc, tc, ma) per face
    conds = [face == k for k in range(6)]
    sc = np.select(conds, [-rz, rz, rx, rx, rx, -rx])
    tc = np.select(conds, [-ry, -ry, rz, -rz, -ry, -ry])
    ma = np.where(x_major, ax, np.where(y_major, ay, az))
    ma = np.where(ma > 0, ma, 1.0)  # d = 0: face +X, centre (no direction to honour)
    s = 0.5 * (sc / ma + 1.0)
    t = 0.5 * (tc / ma + 1.0)
    return face.astype(np.int64), s, t


def cube_to_direction(face, s, t):
    """Inverse of `direction_to_cube`: (face, s, t) -> unit direction (..., 3)."""
    face = np.asarray(face)
    s, t = np.asarray(s, dtype=np.float64), np.asarray(t, dtype=np.float64)
    face, s, t = np.broadcast_arrays(face, s, t)
    sc, tc = 2.0 * s - 1.0, 2.0 * t - 1.0
    one = np.ones_like(sc)
    # invert table 3.21 with |ma| = 1
    conds = [face == k for k in range(6)]
    rx = np.select(conds, [one, -one, sc, sc, sc, -sc])
    ry = np.select(conds, [-tc, -tc, one, -one, -tc, -tc])
    rz = np.select(conds, [-sc, sc, tc, -tc, one, -one])
    return _normalize(np.stack([rx, ry, rz], axis=-1))


def cube_texel(s, t, n: int):
    """(row, column) of face coordinates: row = floor(t N), column = floor(s N), clamped."""
    s, t = np.asarray(s, dtype=np.float64), np.asarray(t, dtype=np.float64)
    col = np.clip(np.floor(s * n), 0, n - 1).astype(np.int64)
    row = np.clip(np.floor(t * n), 0, n - 1).astype(np.int64)
    return row, col


def texel_index(d, n: int) -> np.ndarray:
    """Flat index into the 6 x N x N cube (texel_directions' order, face-major) of the texel each
    direction d (..., 3) falls in."""
    face, s, t = direction_to_cube(d)
    row, col = cube_texel(s, t, n)
    return (face * n + row) * n + col


def texel_directions(n: int) -> np.ndarray:
    """(6, N, N, 3) unit direction of each texel's centre."""
    face = np.arange(6)[:, None, None]
    row, col = np.meshgrid(np.arange(n), np.arange(n), indexing="ij")
    return cube_to_direction(face, (col[None] + 0.5) / n, (row[None] + 0.5) / n)


def _area_element(x, y):
    """Solid angle of the face rectangle [0, x] x [0, y] at unit distance (signed):
    atan2(x y, sqrt(x^2 + y^2 + 1)). The integral of (1 + u^2 + v^2)^(-3/2) du dv, as in
    Driscoll, "Cubemap Texel Solid Angle" (2012) and AMD CubeMapGen's AreaElement."""
    return np.arctan2(x * y, np.sqrt(x * x + y * y + 1.0))


def cube_texel_solid_angles(n: int):
    """Exact solid angle of each texel of one face, (N, N) indexed [row, column]; the same for
    all six faces (sum over the cube = 4 pi)."""
    e = np.linspace(-1.0, 1.0, n + 1)  # texel edges in u = 2 s - 1 (columns), v = 2 t - 1 (rows)
    v0, v1 = e[:-1, None], e[1:, None]
    u0, u1 = e[None, :-1], e[None, 1:]
    return _area_element(u1, v1) - _area_element(u0, v1) - _area_element(u1, v0) + _area_element(u0, v0)


# --------------------------------------------------------------------------------------------
# layout


def kg_to_stacked(kg: np.ndarray) -> np.ndarray:
    """(6, N, N, C) cube map -> (6 N, N, C), faces +X, -X, +Y, -Y, +Z, -Z top to bottom."""
    kg = np.asarray(kg)
    return kg.reshape(6 * kg.shape[1], kg.shape[2], kg.shape[3])


def kg_from_stacked(stacked: np.ndarray) -> np.ndarray:
    """(6 N, N, C) -> (6, N, N, C)."""
    n = stacked.shape[1]
    return np.ascontiguousarray(stacked).reshape(6, n, n, stacked.shape[2])


def as_cube(kg):
    """kg as (6, N, N, C): accepts that or the stacked layout (6 N, N, C)."""
    kg = np.asarray(kg)
    if kg.ndim == 4 and kg.shape[0] == 6 and kg.shape[1] == kg.shape[2]:
        return kg
    if kg.ndim == 3 and kg.shape[0] == 6 * kg.shape[1]:
        return kg_from_stacked(kg)
    raise ValueError(f"kg: expected shape (6, N, N, C) or (6 N, N, C), got {kg.shape}")


def lookup_cube(kg, d):
    """Nearest-texel value of the cube map kg in direction d: (..., 3) -> (..., C)."""
    kg = as_cube(kg)
    face, s, t = direction_to_cube(d)
    row, col = cube_texel(s, t, kg.shape[1])
    return kg[face, row, col]


# --------------------------------------------------------------------------------------------
# lat-long images


def _check_latlong(width: int, height: int) -> None:
    if width < 2 or height < 2:
        raise ValueError(f"lat-long image: need at least 2 x 2 pixels, got {width} x {height}")


def latlong_directions(width: int, height: int) -> np.ndarray:
    """World direction of each pixel's centre of a lat-long image: (height, width, 3)."""
    _check_latlong(width, height)
    lon = np.pi - 2.0 * np.pi * np.arange(width) / (width - 1)
    lat = 0.5 * np.pi - np.pi * np.arange(height) / (height - 1)
    lat, lon = np.meshgrid(lat, lon, indexing="ij")
    return np.stack([np.sin(lon) * np.cos(lat), np.sin(lat), np.cos(lon) * np.cos(lat)], -1)


def _column_edges(width: int, split: int = 1) -> np.ndarray:
    """Longitudes bounding the pixel columns, each cut into `split` equal parts, from +pi down
    to -pi: column j spans pi - 2 pi (j -+ 1/2) / (W - 1), the first and last clipped."""
    edges = np.pi - 2.0 * np.pi * (np.arange(width * split + 1) / split - 0.5) / (width - 1)
    return np.clip(edges, -np.pi, np.pi)


def _row_edges_z(height: int) -> np.ndarray:
    """z = sin(lat) bounding the pixel rows, ascending from -1 (the last row's bottom) to +1."""
    lat = 0.5 * np.pi - np.pi * (np.arange(height + 1) - 0.5) / (height - 1)
    return np.sin(np.clip(lat, -0.5 * np.pi, 0.5 * np.pi))[::-1]


def latlong_solid_angles(width: int, height: int) -> np.ndarray:
    """Exact solid angle of each pixel's cell, (H, W): (lon width) x (sin lat_top - sin lat_bottom)."""
    _check_latlong(width, height)
    dlon = -np.diff(_column_edges(width))
    dz = np.diff(_row_edges_z(height))[::-1]
    return dz[:, None] * dlon[None, :]


# --------------------------------------------------------------------------------------------
# area-weighted resampling: a sweep over meridians
#
# Parametrise the sphere by (lon, z = sin lat): the area element is dlon dz (Lambert's
# cylindrical equal-area map), so a lat-long pixel is the rectangle (its columns) x (its rows)
# and solid angles are areas. Every cube texel edge is an arc of a great circle; along the
# meridian at longitude x it is crossed at most once, at a z that is a smooth function of x. So
# along each meridian the texels are segments [b_m, b_m+1] of z, and the overlap of texel T with
# pixel (i, j) is the integral over x in column j of the length of T's segment within row i.
# Between breakpoints (pixel column edges, the longitudes of every texel corner) the set and order
# of the crossed edges stays the same and each b_m(x) is smooth; Gauss-Legendre nodes integrate x.
#
# Radiance is kept exactly where the sum over one meridian telescopes: lat-long -> cube sends each
# meridian's integral over z of the pixel column to the texels, whole; cube -> lat-long divides by
# the pixels' exact solid angles, and a constant cube comes out constant. The other direction's
# constant (the texel areas) rests on the quadrature: measured in tests/scene/test_scene_cubemap.py.

GAUSS_NODES = 2  # per interval between breakpoints
COLUMN_SPLIT = 2  # each pixel column cut in parts, so that a row edge crossing b_m(x) costs little
MIN_INTERVALS = 1024  # at least as many intervals over 2 pi, for coarse images: b_m(x) curves near the poles


def _dome(rotation) -> np.ndarray:
    return np.eye(3) if rotation is None else np.asarray(rotation, np.float64)


def _grid_lines(n: int, rotation) -> tuple[np.ndarray, ...]:
    """The great-circle arcs of all texel edges in the lat-long's frame: unit plane normals, the
    two bounds m0, m1 (a point d of the circle is on the arc iff d.m0 >= 0 and d.m1 >= 0), and
    the longitude range [start, start + span] the arc covers (less than pi: an arc shorter than a
    half circle whose circle misses the poles turns monotonically in longitude). Arcs in a plane
    through the poles are never crossed between breakpoints and are left out."""
    e = np.arange(n + 1) / n
    face = np.repeat(np.arange(6), n + 1)
    edge = np.tile(e, 6)
    zero, one = np.zeros_like(edge), np.ones_like(edge)
    starts = np.concatenate([cube_to_direction(face, edge, zero), cube_to_direction(face, zero, edge)])
    ends = np.concatenate([cube_to_direction(face, edge, one), cube_to_direction(face, one, edge)])
    starts, ends = starts @ _dome(rotation), ends @ _dome(rotation)  # world -> dome: R^T d
    normal = _normalize(np.cross(starts, ends))
    crossed = np.abs(normal[:, 1]) > 1e-12
    starts, ends, normal = starts[crossed], ends[crossed], normal[crossed]
    lon0, lon1 = (np.arctan2(p[:, 0], p[:, 2]) for p in (starts, ends))
    first = np.where(np.mod(lon1 - lon0, 2 * np.pi) <= np.pi, lon0, lon1)
    span = np.minimum(np.mod(lon1 - lon0, 2 * np.pi), np.mod(lon0 - lon1, 2 * np.pi))
    return normal, np.cross(normal, starts), np.cross(ends, normal), first, span


def _arcs_over(first, span, lo: float, hi: float) -> np.ndarray:
    """Indices of the arcs whose longitude range meets [lo, hi] (-pi <= lo <= hi <= pi)."""
    slack = 1e-9
    start = np.mod(lo - first + slack, 2 * np.pi) - slack  # where lo falls after the arc's start
    return np.flatnonzero((start <= span + slack) | (np.mod(first - lo, 2 * np.pi) <= hi - lo + slack))


def _nodes(n: int, width: int, rotation) -> tuple[np.ndarray, np.ndarray]:
    """Longitudes and weights of the quadrature over x in [-pi, pi]."""
    e = np.arange(n + 1) / n
    face, s, t = np.meshgrid(np.arange(6), e, e, indexing="ij")
    corners = cube_to_direction(face, s, t).reshape(-1, 3) @ _dome(rotation)
    breaks = np.unique(
        np.concatenate(
            [
                np.arctan2(corners[:, 0], corners[:, 2]),
                _column_edges(width, COLUMN_SPLIT),
                np.linspace(-np.pi, np.pi, MIN_INTERVALS + 1),
            ]
        )
    )
    breaks = breaks[(breaks >= -np.pi) & (breaks <= np.pi)]
    lo, hi = breaks[:-1], breaks[1:]
    keep = hi > lo
    lo, hi = lo[keep], hi[keep]
    xi, wi = np.polynomial.legendre.leggauss(GAUSS_NODES)
    half, mid = 0.5 * (hi - lo), 0.5 * (hi + lo)
    return (mid[:, None] + half[:, None] * xi).ravel(), (half[:, None] * wi).ravel()


def _sweep(n: int, width: int, rotation, chunk_cells: int):
    """Per chunk of meridians: (column j (K,), weight w (K,), boundaries b (K, M + 1) ascending
    from -1 to 1, texel (K, M) the flat index face N^2 + row N + column of each segment)."""
    normal_all, m0_all, m1_all, first, span = _grid_lines(n, rotation)
    xs, ws = _nodes(n, width, rotation)
    columns = np.clip(np.rint((np.pi - xs) * (width - 1) / (2.0 * np.pi)), 0, width - 1).astype(np.int64)
    step = max(16, min(256, chunk_cells // (4 * n + 4)))  # few meridians: a narrow longitude range, few arcs
    for a in range(0, len(xs), step):
        x, w, j = xs[a : a + step, None], ws[a : a + step], columns[a : a + step]
        arcs = _arcs_over(first, span, x[0, 0], x[-1, 0])
        normal, m0, m1 = normal_all[arcs], m0_all[arcs], m1_all[arcs]
        sx, cx = np.sin(x), np.cos(x)
        along = normal[:, 0] * sx + normal[:, 2] * cx  # (K, P); the plane: c along + ny z = 0
        ny = normal[:, 1]
        z = -along * np.sign(ny) / np.sqrt(ny * ny + along * along)
        c = np.sqrt(np.clip(1.0 - z * z, 0.0, None))
        on_arc = (c * (m0[:, 0] * sx + m0[:, 2] * cx) + z * m0[:, 1] >= -1e-9) & (
            c * (m1[:, 0] * sx + m1[:, 2] * cx) + z * m1[:, 1] >= -1e-9
        )
        z = np.sort(np.where(on_arc, np.clip(z, -1.0, 1.0), 1.0), axis=1)[:, : max(1, on_arc.sum(1).max())]
        b = np.concatenate([np.full((len(x), 1), -1.0), z, np.ones((len(x), 1))], axis=1)
        zm = 0.5 * (b[:, :-1] + b[:, 1:])
        cm = np.sqrt(1.0 - zm * zm)
        d = np.stack([cm * sx, zm, cm * cx], axis=-1) @ _dome(rotation).T  # dome -> world
        f, s, t = direction_to_cube(d)
        row, col = cube_texel(s, t, n)
        yield j, w, b, (f * n + row) * n + col


def latlong_to_cube(image, n: int, rotation=None) -> np.ndarray:
    """A lat-long image (H, W, C) to a (6, N, N, C) cube map, float32, area-weighted: each texel
    the solid-angle-weighted mean of the pixels over it. `rotation` (3 x 3) turns the image's
    frame into the cube's (dome-to-world): the texel in world direction d reads R^T d."""
    image = np.asarray(image, np.float64)
    height, width, channels = image.shape
    _check_latlong(width, height)
    columns = np.ascontiguousarray(image[::-1].transpose(1, 0, 2))  # (W, H, C), rows by ascending z
    z_edges = _row_edges_z(height)
    cumulative = np.concatenate(
        [np.zeros((width, 1, channels)), np.cumsum(columns * np.diff(z_edges)[:, None], axis=1)], axis=1
    )
    total = np.zeros((6 * n * n, channels))
    for j, w, b, texel in _sweep(n, width, rotation, 1 << 21):
        e = np.clip(np.searchsorted(z_edges, b, side="right") - 1, 0, height - 1)
        # the column's integral over z up to b: exact, as the image is constant per pixel
        r = cumulative[j[:, None], e] + columns[j[:, None], e] * (b - z_edges[e])[..., None]
        part = w[:, None, None] * np.diff(r, axis=1)
        for k in range(channels):
            total[:, k] += np.bincount(texel.ravel(), part[..., k].ravel(), minlength=len(total))
    area = np.broadcast_to(cube_texel_solid_angles(n), (6, n, n)).reshape(-1, 1)
    return (total / area).reshape(6, n, n, channels).astype(np.float32)


def cube_to_latlong(kg, width: int, height: int | None = None, rotation=None) -> np.ndarray:
    """A cube map to a lat-long image (H, W, C) (H = W / 2 unless given), float32, area-weighted:
    each pixel the solid-angle-weighted mean of the texels under its cell. `rotation` as in
    `latlong_to_cube`."""
    kg = as_cube(kg).astype(np.float64)
    n, channels = kg.shape[1], kg.shape[3]
    height = height or width // 2
    _check_latlong(width, height)
    flat = kg.reshape(-1, channels)
    z_edges = _row_edges_z(height)
    # Along a meridian the radiance is v_m on (b_m, b_m+1), so its integral up to z is
    # sum_m delta_m min(z, b_m) with delta = (-v_0, v_0 - v_1, ..., v_M-2 - v_M-1, v_M-1). Summed
    # over a column's meridians: a histogram of the knots b_m by row gives every row edge at once.
    weight = np.zeros((width, height, channels))  # sum of w delta over the knots in each pixel
    moment = np.zeros((width, height, channels))  # sum of w delta b
    for j, w, b, texel in _sweep(n, width, rotation, 1 << 21):
        v = flat[texel]
        delta = w[:, None, None] * np.concatenate([-v[:, :1], v[:, :-1] - v[:, 1:], v[:, -1:]], axis=1)
        row = np.clip(np.searchsorted(z_edges, b, side="right") - 1, 0, height - 1)
        low = j.min()  # the chunk's meridians cover a few neighbouring columns
        bins = ((j[:, None] - low) * height + row).ravel()
        size = (j.max() - low + 1) * height
        for k in range(channels):
            d = delta[..., k].ravel()
            weight[low : low + size // height, :, k] += np.bincount(bins, d, size).reshape(-1, height)
            moment[low : low + size // height, :, k] += np.bincount(bins, d * b.ravel(), size).reshape(-1, height)
    below = lambda a: np.concatenate([np.zeros((width, 1, channels)), np.cumsum(a, axis=1)], axis=1)
    weight_below, moment_below = below(weight), below(moment)
    integral = z_edges[:, None] * (weight_below[:, -1:] - weight_below) + moment_below  # (W, H + 1, C)
    image = np.diff(integral, axis=1).transpose(1, 0, 2)[::-1] / latlong_solid_angles(width, height)[..., None]
    return np.ascontiguousarray(image, np.float32)
