"""Triangle meshes with UVs: PLY (via plyfile) and OBJ (own reader) in, binary PLY out.

PLY vertex UVs are read from the first present pair of vertex properties
(s, t), (u, v), (texture_u, texture_v), (texture_s, texture_t); failing those, from a
per-face ``texcoord`` list of 6 floats (MeshLab's wedge UVs), splitting vertices into
unique (vertex, uv) pairs. An optional per-face int property ``instance_id`` is kept.
Polygons are fan-triangulated.

OBJ: ``v``, ``vt`` and ``f`` (v, v/vt, v/vt/vn, v//vn, negative indices). Each distinct
(v, vt) pair of the faces becomes one vertex, so seams where one position has several
UVs are split; positions that no face uses are dropped.

Every problem is a ``SceneError`` naming the file and the field.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import plyfile

from .atomic import atomic_path
from .types import Mesh, SceneError

__all__ = ["read_mesh", "read_ply", "read_obj", "read_triangles", "write_ply", "validate_mesh", "check_extent"]

# Extents a capture can have: a bounding-box diagonal from a small object (1 mm) to a large site
# (10 km). Beyond them the input is in the wrong unit or broken, and xatlas and pymeshlab misbehave
# (an atlas of 3 covered texels, a hang) instead of failing.
MIN_DIAGONAL_M, MAX_DIAGONAL_M = 1e-3, 1e4
# A vertex farther from the bulk of the mesh (the box of the 1st-99th percentiles of each axis)
# than this many bulk diagonals is a stray (one vertex at 1e30), not part of the scene. Tested only
# with enough vertices for the percentiles to describe a bulk.
OUTLIER_DIAGONALS, OUTLIER_MIN_VERTICES = 10.0, 100

UV_PROPERTY_PAIRS = (("s", "t"), ("u", "v"), ("texture_u", "texture_v"), ("texture_s", "texture_t"))
MISSING_UVS = "vertex s,t (texture coordinates)"


def read_mesh(path, require_uvs: bool = True) -> Mesh:
    """Read a PLY or OBJ mesh and validate it.

    With ``require_uvs=False`` a mesh without texture coordinates is accepted and
    returned with ``uvs=None``.
    """
    path = Path(path)
    if not path.is_file():
        raise SceneError(path, "(file)", "an existing PLY or OBJ mesh file")
    suffix = path.suffix.lower()
    if suffix == ".ply":
        mesh = read_ply(path, require_uvs)
    elif suffix == ".obj":
        mesh = read_obj(path, require_uvs)
    else:
        raise SceneError(path, "(file name)", f"a .ply or .obj mesh, got '{path.suffix}'")
    validate_mesh(mesh, path, require_uvs)
    return mesh


def validate_mesh(mesh: Mesh, path, require_uvs: bool = True) -> None:
    """Check a mesh in memory; ``path`` is the file named in the errors."""
    positions = np.asarray(mesh.positions)
    if positions.ndim != 2 or positions.shape[1] != 3:
        raise SceneError(path, "vertex x,y,z", f"(V, 3) positions, got shape {positions.shape}")
    if len(positions) == 0:
        raise SceneError(path, "vertex", "at least one vertex, got none")
    bad = ~np.isfinite(positions).all(axis=1)
    if bad.any():
        i = int(np.flatnonzero(bad)[0])
        raise SceneError(
            path,
            f"vertex {i} x,y,z",
            f"finite coordinates, got {positions[i].tolist()} ({int(bad.sum())} non-finite vertices)",
        )
    check_extent(positions, path)
    faces = np.asarray(mesh.faces)
    if faces.ndim != 2 or faces.shape[1] != 3:
        raise SceneError(path, "face vertex_indices", f"(F, 3) triangles, got shape {faces.shape}")
    if len(faces) == 0:
        raise SceneError(path, "face", "at least one face, got none")
    out = (faces < 0) | (faces >= len(positions))
    if out.any():
        i = int(np.flatnonzero(out.any(axis=1))[0])
        raise SceneError(
            path,
            f"face {i} vertex_indices",
            f"indices in [0, {len(positions)}) (the vertex count), got {faces[i].tolist()}",
        )
    if mesh.uvs is None:
        if require_uvs:
            raise SceneError(path, MISSING_UVS, "per-vertex texture coordinates")
    else:
        uvs = np.asarray(mesh.uvs)
        if uvs.shape != (len(positions), 2):
            raise SceneError(path, MISSING_UVS, f"shape ({len(positions)}, 2), got {uvs.shape}")
        bad = ~np.isfinite(uvs).all(axis=1)
        if bad.any():
            i = int(np.flatnonzero(bad)[0])
            raise SceneError(path, f"vertex {i} s,t", f"finite texture coordinates, got {uvs[i].tolist()}")
    if mesh.instance_ids is not None and np.asarray(mesh.instance_ids).shape != (len(faces),):
        raise SceneError(path, "face instance_id", f"one id per face ({len(faces)})")


def check_extent(positions, path) -> None:
    """Refuse finite positions whose extent no capture has: a bounding-box diagonal outside
    [MIN_DIAGONAL_M, MAX_DIAGONAL_M], or a vertex more than OUTLIER_DIAGONALS bulk diagonals
    outside the bulk of the vertices. The error names the file, the vertex and the extent."""
    p = np.asarray(positions, np.float64)
    lo, hi = p.min(axis=0), p.max(axis=0)
    diagonal = float(np.linalg.norm(hi - lo))
    if len(p) >= OUTLIER_MIN_VERTICES:
        b_lo, b_hi = np.percentile(p, [1, 99], axis=0)
        bulk = max(float(np.linalg.norm(b_hi - b_lo)), MIN_DIAGONAL_M)
        outside = np.linalg.norm(np.maximum(b_lo - p, 0) + np.maximum(p - b_hi, 0), axis=1)
        i = int(np.argmax(outside))
        if outside[i] > OUTLIER_DIAGONALS * bulk:
            raise SceneError(
                path,
                f"vertex {i} x,y,z",
                f"a vertex near the others, got {p[i].tolist()}, "
                f"{outside[i]:.3g} m outside the box of 98% of the vertices (diagonal {bulk:.3g} m)",
            )
    if not MIN_DIAGONAL_M <= diagonal <= MAX_DIAGONAL_M:
        far = int(np.argmax(np.linalg.norm(p - np.median(p, axis=0), axis=1)))
        raise SceneError(
            path,
            "vertex x,y,z (extent)",
            f"a bounding-box diagonal between {MIN_DIAGONAL_M:g} m "
            f"and {MAX_DIAGONAL_M:g} m (meters), got {diagonal:.3g} m; farthest vertex {far} at "
            f"{p[far].tolist()}",
        )


def read_triangles(path) -> Mesh:
    """A PLY or OBJ mesh's positions and triangles only (``uvs=None``, vertices not split at UV
    seams), validated: what a stage that makes its own UVs reads, and what it hands a native
    library instead of the file."""
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix == ".ply":
        mesh = read_ply(path, require_uvs=False, with_uvs=False)
    elif suffix == ".obj":
        parsed = _parse_obj(path)
        parsed["texcoords"] = np.zeros((0, 2))
        mesh = _obj_mesh(parsed, path, require_uvs=False)
    else:
        raise SceneError(path, "(file name)", f"a .ply or .obj mesh, got '{path.suffix}'")
    validate_mesh(mesh, path, require_uvs=False)
    return mesh


# ---------------------------------------------------------------------------- PLY


def _fan(polygons: list[np.ndarray], path) -> tuple[np.ndarray, np.ndarray]:
    """Fan-triangulate variable-length polygons; return (triangles, source polygon per triangle)."""
    tris, src = [], []
    for k, poly in enumerate(polygons):
        n = len(poly)
        if n < 3:
            raise SceneError(path, f"face {k} vertex_indices", f"at least 3 vertices, got {n}")
        for j in range(1, n - 1):
            tris.append((poly[0], poly[j], poly[j + 1]))
            src.append(k)
    return np.asarray(tris, np.int64).reshape(-1, 3), np.asarray(src, np.int64)


def _read_plydata(path: Path) -> plyfile.PlyData:
    # Fast path: triangle-only binary files are memory-mapped as fixed-size records
    # (plyfile otherwise parses variable-length lists row by row in Python).
    known = {"face": {"vertex_indices": 3, "vertex_index": 3, "texcoord": 6}}
    try:
        try:
            data = plyfile.PlyData.read(str(path), known_list_len=known)
        except plyfile.PlyElementParseError as exc:
            if "unexpected list length" not in str(exc):
                raise
            data = plyfile.PlyData.read(str(path), mmap=False)
    except (plyfile.PlyParseError, ValueError, OSError, IndexError, EOFError) as exc:
        raise SceneError(path, "(file)", f"a readable PLY file ({exc})") from None
    return data


def read_ply_vertices(path):
    """(PlyData, positions (V, 3) float64, names of the vertex properties) of a PLY file, with
    one SceneError for an unreadable file, no vertex element or no x, y, z."""
    path = Path(path)
    data = _read_plydata(path)
    if "vertex" not in [el.name for el in data.elements]:
        raise SceneError(path, "element vertex", "a vertex element")
    vertex = data["vertex"]
    vprops = {p.name for p in vertex.properties}
    missing = [c for c in "xyz" if c not in vprops]
    if missing:
        raise SceneError(path, "vertex x,y,z", f"vertex properties x, y, z; missing {','.join(missing)}")
    return data, np.stack([np.asarray(vertex[c], np.float64) for c in "xyz"], axis=1), vprops


def read_ply(path, require_uvs: bool = True, with_uvs: bool = True) -> Mesh:
    path = Path(path)
    data, positions, vprops = read_ply_vertices(path)
    names = [el.name for el in data.elements]
    vertex = data["vertex"]
    uvs = None
    for a, b in UV_PROPERTY_PAIRS if with_uvs else ():
        if a in vprops and b in vprops:
            uvs = np.stack([np.asarray(vertex[a], np.float64), np.asarray(vertex[b], np.float64)], axis=1)
            break

    if "face" not in names:
        raise SceneError(path, "face", "a face element with vertex_indices (a mesh, not a point cloud)")
    face = data["face"]
    fprops = {p.name for p in face.properties}
    key = "vertex_indices" if "vertex_indices" in fprops else "vertex_index" if "vertex_index" in fprops else None
    if key is None:
        raise SceneError(path, "face vertex_indices", "a face list property vertex_indices")
    raw = face[key]
    instance = np.asarray(face["instance_id"], np.int64) if "instance_id" in fprops else None
    wedge = None
    if uvs is None and with_uvs and "texcoord" in fprops:
        wedge = face["texcoord"]

    if len(face.data) == 0:
        raise SceneError(path, "face", "at least one face, got none")
    if raw.dtype != object and raw.ndim == 2:  # fixed-size (memory-mapped) triangles
        faces, src = np.asarray(raw, np.int64), np.arange(len(raw))
    else:
        lengths = np.fromiter((len(p) for p in raw), np.int64, len(raw))
        if (lengths == 3).all():
            faces, src = np.stack([np.asarray(p, np.int64) for p in raw]), np.arange(len(raw))
        else:
            faces, src = _fan([np.asarray(p, np.int64) for p in raw], path)
    if instance is not None:
        instance = instance[src]

    if wedge is not None:
        # Per-corner UVs: corner j of triangle t came from polygon corner (0, j, j+1).
        if wedge.dtype != object and len(src) == len(wedge):  # triangles, fixed-size lists
            corner_uv = np.asarray(wedge, np.float64).reshape(-1, 2)
        else:
            polys = [np.asarray(p, np.float64).reshape(-1, 2) for p in wedge]
            corner_uv, counts = [], {}
            for k in src.tolist():
                j = counts.get(k, 0)
                counts[k] = j + 1
                poly = polys[k]
                if len(poly) < j + 3:
                    raise SceneError(path, f"face {k} texcoord", "two floats (s, t) per face corner")
                corner_uv.append((poly[0], poly[j + 1], poly[j + 2]))
            corner_uv = np.asarray(corner_uv, np.float64).reshape(-1, 2)
        if len(corner_uv) != 3 * len(faces):
            raise SceneError(path, "face texcoord", "two floats (s, t) per face corner")
        v_idx = faces.reshape(-1)
        if ((v_idx < 0) | (v_idx >= len(positions))).any():
            pass  # reported by validate_mesh below, on the original indices
        else:
            positions, uvs, faces = _split_pairs(positions, v_idx, corner_uv)

    return Mesh(
        positions=positions.astype(np.float32),
        faces=faces.astype(np.int32),
        uvs=None if uvs is None else uvs.astype(np.float32),
        instance_ids=None if instance is None else instance.astype(np.int32),
    )


def _split_pairs(positions: np.ndarray, v_idx: np.ndarray, corner_uv: np.ndarray):
    """One vertex per distinct (position index, uv) pair over the face corners."""
    keys = np.concatenate([v_idx[:, None].astype(np.float64), corner_uv], axis=1)
    unique, inverse = np.unique(keys, axis=0, return_inverse=True)
    return positions[unique[:, 0].astype(np.int64)], unique[:, 1:], inverse.reshape(-1, 3)


def write_ply(path, mesh: Mesh) -> None:
    """Binary little-endian PLY: vertex x,y,z,s,t (float32); face vertex_indices, instance_id.

    ``instance_ids=None`` is written as zeros (0 = no instance). A mesh without UVs is
    written without s,t.
    """
    positions = np.asarray(mesh.positions, np.float32)
    fields = [("x", "f4"), ("y", "f4"), ("z", "f4")]
    if mesh.uvs is not None:
        fields += [("s", "f4"), ("t", "f4")]
    vertex = np.empty(len(positions), dtype=fields)
    vertex["x"], vertex["y"], vertex["z"] = positions.T
    if mesh.uvs is not None:
        uvs = np.asarray(mesh.uvs, np.float32)
        vertex["s"], vertex["t"] = uvs.T
    faces = np.asarray(mesh.faces, np.int32)
    face = np.empty(len(faces), dtype=[("vertex_indices", "i4", (3,)), ("instance_id", "i4")])
    face["vertex_indices"] = faces
    face["instance_id"] = 0 if mesh.instance_ids is None else np.asarray(mesh.instance_ids, np.int32)
    ply = plyfile.PlyData(
        [
            plyfile.PlyElement.describe(vertex, "vertex"),
            plyfile.PlyElement.describe(face, "face", len_types={"vertex_indices": "u1"}),
        ],
        text=False,
        byte_order="<",
        comments=["invrender mesh: meters, +Y up, UVs v up"],
    )
    with atomic_path(path) as tmp:
        ply.write(str(tmp))


# ---------------------------------------------------------------------------- OBJ


def _obj_index(token: str, count: int, path, line_no: int, what: str) -> int:
    try:
        i = int(token)
    except ValueError:
        raise SceneError(path, f"line {line_no} f", f"integer {what} indices, got '{token}'") from None
    if i == 0:
        raise SceneError(path, f"line {line_no} f", f"1-based {what} indices, got 0")
    if abs(i) >= 2**31:  # no file has that many; int64 arrays would overflow
        raise SceneError(path, f"line {line_no} f", f"{what} indices below 2^31, got {i}")
    return i - 1 if i > 0 else count + i


def _check_obj_indices(path, corners, count: int, starts, kind: str) -> None:
    """Every face corner's `kind` (v or vt) index within the file's count of them."""
    bad = (corners < 0) | (corners >= count)
    if bad.any():
        k = int(np.flatnonzero(bad)[0])
        face = int(np.searchsorted(starts, k, side="right") - 1)
        raise SceneError(
            path, f"face {face} {kind}", f"indices in [1, {count}] (the {kind} count), got {corners[k] + 1}"
        )


def obj_statements(path):
    """(line number, words) of every non-empty, non-comment line of an OBJ file."""
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8", errors="replace")
    except OSError as exc:
        raise SceneError(path, "(file)", f"a readable OBJ file ({exc})") from None
    for line_no, line in enumerate(text.splitlines(), 1):
        parts = line.split("#", 1)[0].split()
        if parts:
            yield line_no, parts


def read_obj(path, require_uvs: bool = True) -> Mesh:
    return _obj_mesh(_parse_obj(path), path, require_uvs)


def read_obj_parts(path, require_uvs: bool = False) -> tuple[list[tuple[str, Mesh]], list[str]]:
    """An OBJ split by ``usemtl``: [(material name, Mesh of its faces)] in order of first use
    (faces before any ``usemtl`` get the name ""), and the ``mtllib`` files it names. Each part
    keeps only the vertices its faces use."""
    parsed = _parse_obj(path)
    parts = []
    for index, name in enumerate(parsed["materials"]):
        keep = parsed["polygon_material"] == index
        if keep.any():
            mesh = _obj_mesh(parsed, path, require_uvs, keep)
            validate_mesh(mesh, path, require_uvs)  # here, where the file can still be named
            parts.append((name, mesh))
    return parts, parsed["mtllibs"]


def _parse_obj(path) -> dict:
    """The raw statements of an OBJ: positions, texcoords, face corners, polygon sizes, the
    ``usemtl`` in force for each polygon and the ``mtllib`` names."""
    path = Path(path)
    positions, texcoords = [], []
    corners_v, corners_vt, polygon_sizes, polygon_material = [], [], [], []
    materials, mtllibs, current = [""], [], 0
    for line_no, parts in obj_statements(path):
        tag = parts[0]
        try:
            if tag == "v":
                if len(parts) < 4:
                    raise ValueError
                positions.append([float(x) for x in parts[1:4]])
            elif tag == "vt":
                if len(parts) < 3:
                    raise ValueError
                texcoords.append([float(parts[1]), float(parts[2])])
        except ValueError:
            raise SceneError(path, f"line {line_no} {tag}", "numbers: v x y z / vt u v") from None
        if tag == "usemtl":
            name = " ".join(parts[1:])
            if name not in materials:
                materials.append(name)
            current = materials.index(name)
        elif tag == "mtllib":
            mtllibs += parts[1:]
        elif tag == "f":
            if len(parts) < 4:
                raise SceneError(path, f"line {line_no} f", f"at least 3 vertices, got {len(parts) - 1}")
            for token in parts[1:]:
                fields = token.split("/")
                corners_v.append(_obj_index(fields[0], len(positions), path, line_no, "v"))
                has_vt = len(fields) > 1 and fields[1]
                corners_vt.append(_obj_index(fields[1], len(texcoords), path, line_no, "vt") if has_vt else -1)
            polygon_sizes.append(len(parts) - 1)
            polygon_material.append(current)
    if not polygon_sizes:
        raise SceneError(path, "f", "at least one face, got none")
    return {
        "positions": np.asarray(positions, np.float64).reshape(-1, 3),
        "texcoords": np.asarray(texcoords, np.float64).reshape(-1, 2),
        "corners_v": np.asarray(corners_v, np.int64),
        "corners_vt": np.asarray(corners_vt, np.int64),
        "polygon_sizes": np.asarray(polygon_sizes, np.int64),
        "polygon_material": np.asarray(polygon_material, np.int64),
        "materials": materials,
        "mtllibs": mtllibs,
    }


def _obj_mesh(parsed: dict, path, require_uvs: bool, keep: np.ndarray | None = None) -> Mesh:
    """The triangle mesh of the polygons ``keep`` selects (all by default), fan-triangulated."""
    path = Path(path)
    positions, texcoords = parsed["positions"], parsed["texcoords"]
    corners_v, corners_vt, sizes = parsed["corners_v"], parsed["corners_vt"], parsed["polygon_sizes"]
    starts = np.concatenate([[0], np.cumsum(sizes)[:-1]])
    _check_obj_indices(path, corners_v, len(positions), starts, "v")
    keep = np.ones(len(sizes), bool) if keep is None else keep
    tri = [(s, s + j, s + j + 1) for s, n in zip(starts[keep].tolist(), sizes[keep].tolist()) for j in range(1, n - 1)]
    tri = np.asarray(tri, np.int64).reshape(-1, 3)
    used_corners = np.unique(tri)
    has_uvs = len(texcoords) > 0 and bool(np.all(corners_vt[used_corners] >= 0))
    if not has_uvs:
        if require_uvs:
            raise SceneError(path, MISSING_UVS, "vt lines and f v/vt (every face corner with a vt index)")
        used, inverse = np.unique(corners_v[tri], return_inverse=True)
        return Mesh(
            positions=positions[used].astype(np.float32), faces=inverse.reshape(-1, 3).astype(np.int32), uvs=None
        )
    in_part = np.zeros(len(corners_vt), bool)
    in_part[used_corners] = True
    _check_obj_indices(path, np.where(in_part, corners_vt, 0), len(texcoords), starts, "vt")
    pairs, inverse = np.unique(
        np.stack([corners_v[tri].ravel(), corners_vt[tri].ravel()], axis=1), axis=0, return_inverse=True
    )
    return Mesh(
        positions=positions[pairs[:, 0]].astype(np.float32),
        faces=inverse.reshape(-1, 3).astype(np.int32),
        uvs=texcoords[pairs[:, 1]].astype(np.float32),
    )
