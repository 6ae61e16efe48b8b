"""Input geometry for the geometry stage: load, clean, reconstruct, simplify (all pymeshlab).

- ``load_geometry``: a PLY/OBJ triangle mesh, or a point cloud with normals (PLY with nx, ny, nz
  and no faces; OBJ with one ``vn`` per ``v``), into a ``pymeshlab.MeshSet``. The file is read
  with our own parsers only and handed to pymeshlab as arrays: pymeshlab silently drops vertices
  with NaN positions (and the faces using them), ignores the normals of an OBJ point cloud, and
  its loaders crash on bad face indices.
- ``clean_mesh``: merge duplicate vertices, drop duplicate and zero-area faces, faces on
  non-manifold edges, small islands and unreferenced vertices; returns what each step removed.
- ``reconstruct``: screened Poisson from the point cloud, then trims the faces far from every input
  point (Poisson closes any gap in the cloud with a smooth surface: small holes become plausible
  patches, but a large missing region becomes a blob far from all data), then ``clean_mesh``.
- ``simplify``: quadric edge collapse to a face count (MILO simplifies to about 20K faces).
"""

from __future__ import annotations

import logging
import os
from pathlib import Path

import numpy as np
import pymeshlab

from ..scene.mesh_io import check_extent, obj_statements, read_ply_vertices, read_triangles
from ..scene.types import SceneError

__all__ = [
    "DEFAULT_TARGET_FACES",
    "load_geometry",
    "input_kind",
    "clean_mesh",
    "reconstruct",
    "simplify",
    "mean_point_spacing",
]

log = logging.getLogger(__name__)

DEFAULT_TARGET_FACES = 20_000  # MILO: "simplify the triangular meshes to about 20K triangular faces"
SIMPLIFY_TOLERANCE = 0.05  # the face count lands within 5% of the target
NO_FACES = "a mesh with faces, or a point cloud with normals"


# ---------------------------------------------------------------------------- loading


def _read_ply_header(path: Path):
    """(positions (V, 3) float64, normals (V, 3) or None, face count) of a PLY file."""
    data, positions, props = read_ply_vertices(path)
    vertex = data["vertex"]
    normals = None
    if all(c in props for c in ("nx", "ny", "nz")):
        normals = np.stack([np.asarray(vertex[c], np.float64) for c in ("nx", "ny", "nz")], axis=1)
    faces = data["face"].count if "face" in [el.name for el in data.elements] else 0
    return positions, normals, faces


def _read_obj_header(path: Path):
    """(positions, normals or None, face count) of an OBJ file; normals only when one per v."""
    positions, normals, faces = [], [], 0
    for line_no, parts in obj_statements(path):
        if parts[0] in ("v", "vn"):
            try:
                values = [float(x) for x in parts[1:4]]
                if len(values) != 3:
                    raise ValueError
            except ValueError:
                raise SceneError(path, f"line {line_no} {parts[0]}", "three numbers") from None
            (positions if parts[0] == "v" else normals).append(values)
        elif parts[0] == "f":
            faces += 1
    positions = np.asarray(positions, np.float64).reshape(-1, 3)
    normals = np.asarray(normals, np.float64).reshape(-1, 3) if len(normals) == len(positions) else None
    return positions, normals, faces


def load_geometry(path) -> pymeshlab.MeshSet:
    """A MeshSet whose current mesh is the file's triangle mesh or point cloud with normals.

    Refuses, with a ``SceneError`` naming the file and the field: a missing, empty or unreadable
    file, a file that is neither .ply nor .obj, non-finite vertex positions, no vertices, and
    vertices with neither faces nor normals. ``input_kind(ms)`` says which of the two it is.
    """
    path = Path(path)
    if not path.is_file():
        raise SceneError(path, "(file)", "an existing PLY or OBJ mesh or point cloud")
    suffix = path.suffix.lower()
    if suffix not in (".ply", ".obj"):
        raise SceneError(path, "(file name)", f"a .ply or .obj mesh or point cloud, got '{path.suffix}'")
    if path.stat().st_size == 0:
        raise SceneError(path, "(file)", "a non-empty PLY or OBJ file, got an empty file")
    positions, normals, face_count = (_read_ply_header if suffix == ".ply" else _read_obj_header)(path)
    if len(positions) == 0:
        raise SceneError(path, "vertex", "at least one vertex, got none")
    bad = ~np.isfinite(positions).all(axis=1)
    if bad.any():
        i = int(np.flatnonzero(bad)[0])
        raise SceneError(
            path,
            "vertex positions",
            f"finite numbers; vertex {i} is {positions[i].tolist()} "
            f"({int(bad.sum())} of {len(positions)} vertices non-finite)",
        )

    ms = pymeshlab.MeshSet()
    if face_count > 0:
        # pymeshlab's own loaders crash (signal 11) on faults such as an OBJ face index past the
        # vertex count: it only ever sees arrays our readers have checked, never the file.
        mesh = read_triangles(path)
        ms.add_mesh(
            pymeshlab.Mesh(
                vertex_matrix=np.asarray(mesh.positions, np.float64), face_matrix=np.asarray(mesh.faces, np.int32)
            ),
            "mesh",
        )
        return ms

    if normals is None:
        raise SceneError(path, "faces", f"{NO_FACES}; got {len(positions)} vertices with neither")
    check_extent(positions, path)
    length = np.linalg.norm(normals, axis=1)
    bad = ~np.isfinite(length) | (length < 1e-6)
    if bad.any():
        i = int(np.flatnonzero(bad)[0])
        raise SceneError(
            path,
            "vertex normals",
            f"finite non-zero normals on every point; point {i} has "
            f"{normals[i].tolist()} ({int(bad.sum())} of {len(normals)} points)",
        )
    cloud = pymeshlab.Mesh(vertex_matrix=positions, v_normals_matrix=normals / length[:, None])
    ms.add_mesh(cloud, "point cloud")
    return ms


def input_kind(ms: pymeshlab.MeshSet) -> str:
    """'point_cloud' or 'mesh': what ``load_geometry`` read."""
    return "point_cloud" if ms.current_mesh().face_number() == 0 else "mesh"


# ---------------------------------------------------------------------------- cleaning


def _counts(ms: pymeshlab.MeshSet) -> tuple[int, int]:
    mesh = ms.current_mesh()
    return mesh.vertex_number(), mesh.face_number()


def _step(ms: pymeshlab.MeshSet, report: dict, name: str, filter_name: str, **params) -> None:
    """Apply one pymeshlab filter and record how many vertices and faces it removed."""
    v0, f0 = _counts(ms)
    getattr(ms, filter_name)(**params)
    v1, f1 = _counts(ms)
    report[name] = {"vertices": v0 - v1, "faces": f0 - f1}


def clean_mesh(
    ms: pymeshlab.MeshSet,
    min_island_fraction: float = 0.01,
    min_island_faces: int = 0,
    log: logging.Logger = log,
) -> dict:
    """Clean the current mesh in place; returns {step: {"vertices": removed, "faces": removed}}.
    The mesh may be left with no faces (all degenerate): the caller decides what that means.

    Islands (connected components) are removed when their bounding-box diagonal is below
    ``min_island_fraction`` of the whole mesh's diagonal, or, if ``min_island_faces`` > 0, when
    they have fewer faces than that. Size relative to the scene decides by default, not face
    count: a captured lamp is often a separate piece of two triangles (a 0.6 m ceiling panel is 7 %
    of a 4 x 3 x 5 m room's diagonal), and light-emitting objects are what MILO recovers. The
    default keeps furniture and lamps and removes the crumbs that reconstruction and trimming
    leave (millimetres to centimetres in a room).
    """
    report: dict = {}
    _step(ms, report, "duplicate_vertices", "meshing_remove_duplicate_vertices")
    _step(ms, report, "duplicate_faces", "meshing_remove_duplicate_faces")
    _step(ms, report, "zero_area_faces", "meshing_remove_null_faces")
    # On an edge shared by more than two faces pymeshlab removes the smallest of them (crumbs and
    # fins, measured), not the surface they hang on.
    _step(ms, report, "non_manifold_edges", "meshing_repair_non_manifold_edges", method="Remove Faces")
    if min_island_fraction > 0:
        _step(
            ms,
            report,
            "small_islands_by_size",
            "meshing_remove_connected_component_by_diameter",
            mincomponentdiag=pymeshlab.PercentageValue(100.0 * min_island_fraction),
            removeunref=False,
        )
    if min_island_faces > 0:
        _step(
            ms,
            report,
            "small_islands_by_faces",
            "meshing_remove_connected_component_by_face_number",
            mincomponentsize=int(min_island_faces),
            removeunref=False,
        )
    _step(ms, report, "unreferenced_vertices", "meshing_remove_unreferenced_vertices")
    removed = {k: v for k, v in report.items() if v["vertices"] or v["faces"]}
    vertices, faces = _counts(ms)
    log.info("cleaned: %d vertices, %d faces left; removed %s", vertices, faces, removed or "nothing")
    return report


# ---------------------------------------------------------------------------- reconstruction


def mean_point_spacing(points, samples: int = 512, seed: int = 0, chunk: int = 8192) -> float:
    """Mean distance from a point to its nearest other point, over a random subset of the points.

    For points spread over a surface this is also about the mean distance from a surface point
    to the nearest sample (both are 1 / (2 sqrt(density)) for uniform random samples), which is
    what the trimming threshold is measured against.
    """
    points = np.asarray(points, np.float64)
    if len(points) < 2:
        raise ValueError("mean_point_spacing: need at least two points")
    rng = np.random.default_rng(seed)
    pick = rng.choice(len(points), size=min(samples, len(points)), replace=False)
    query = points[pick]
    best = np.full(len(query), np.inf)
    q2 = (query**2).sum(1)
    for start in range(0, len(points), chunk):
        block = points[start : start + chunk]
        d2 = q2[:, None] + (block**2).sum(1)[None, :] - 2.0 * query @ block.T
        own = (pick >= start) & (pick < start + len(block))  # a query point is not its own neighbour
        d2[np.flatnonzero(own), pick[own] - start] = np.inf
        np.minimum(best, d2.min(axis=1), out=best)
    return float(np.sqrt(np.maximum(best, 0.0)).mean())


def _default_threads() -> int:
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # not on Linux
        return os.cpu_count() or 1


def reconstruct(
    ms: pymeshlab.MeshSet,
    depth: int = 8,
    trim_spacings: float = 10.0,
    min_island_fraction: float = 0.01,
    min_island_faces: int = 10,
    threads: int | None = None,
    log: logging.Logger = log,
) -> dict:
    """Screened Poisson surface of the current point cloud, trimmed, cleaned; in place.

    Faces with a vertex farther than ``trim_spacings`` x the mean point spacing from every input
    point are removed: holes in the cloud narrower than about twice that stay closed, larger
    missing regions (where Poisson would put a blob) are cut away. The cloud is dropped from the
    MeshSet; the surface becomes its current (and only) mesh, possibly with no faces left.
    Returns the report.

    ``threads``: Poisson's OpenMP threads (default: the CPUs this process may use). More threads
    than free cores makes it several times slower (busy waiting), so a Snakemake rule passes its
    ``threads``.
    """
    cloud_id = ms.current_mesh_id()
    cloud = ms.current_mesh()
    if cloud.face_number() != 0:
        raise ValueError("reconstruct: the current mesh has faces; expected a point cloud")
    points = cloud.vertex_matrix()
    spacing = mean_point_spacing(points)
    threads = int(threads or _default_threads())
    log.info(
        "screened Poisson: %d points, mean spacing %.4g m, depth %d, %d threads", len(points), spacing, depth, threads
    )
    ms.generate_surface_reconstruction_screened_poisson(depth=int(depth), preclean=True, threads=threads)
    surface_id = ms.current_mesh_id()
    poisson_faces = ms.current_mesh().face_number()

    # Distance from each surface vertex to the nearest input point (the cloud has no faces, so
    # pymeshlab measures to its vertices), into the vertex quality; then cut the far vertices.
    threshold = trim_spacings * spacing
    ms.compute_scalar_by_distance_from_another_mesh_per_vertex(
        measuremesh=surface_id,
        refmesh=cloud_id,
        signeddist=False,
        maxdist=pymeshlab.PureValue(max(10.0 * threshold, ms.current_mesh().bounding_box().diagonal())),
    )
    distance = ms.current_mesh().vertex_scalar_array()
    report: dict = {}
    ms.compute_selection_by_condition_per_vertex(condselect=f"(q > {threshold:.12f})")
    _step(ms, report, "trimmed_far_from_points", "meshing_remove_selected_vertices")
    ms.set_current_mesh(cloud_id)
    ms.delete_current_mesh()
    ms.set_current_mesh(surface_id)
    trimmed = report["trimmed_far_from_points"]["faces"]
    log.info(
        "Poisson surface: %d faces; trimmed %d (%.1f%%) with a vertex farther than %.4g m "
        "(%g spacings) from the points; vertex-to-point distance median %.4g m, max %.4g m",
        poisson_faces,
        trimmed,
        100.0 * trimmed / max(poisson_faces, 1),
        threshold,
        trim_spacings,
        float(np.median(distance)),
        float(distance.max()),
    )
    report.update(clean_mesh(ms, min_island_fraction, min_island_faces, log=log))
    return {
        "points": int(len(points)),
        "mean_point_spacing_m": spacing,
        "poisson_depth": int(depth),
        "poisson_faces": int(poisson_faces),
        "trim_distance_m": threshold,
        "removed": report,
    }


# ---------------------------------------------------------------------------- simplification


def simplify(ms: pymeshlab.MeshSet, target_faces: int = DEFAULT_TARGET_FACES, log: logging.Logger = log) -> dict:
    """Quadric edge collapse of the current mesh to ``target_faces`` (within 5%), in place.

    Keeps boundaries, normals (no flipped faces) and topology, and uses the planar quadric term
    that keeps flat walls from turning into slivers. If those constraints stop the collapse
    short of the target, it is run again without them. A mesh already at or below the target is
    kept as it is. Returns {"faces_before", "faces_after", "target_faces", "passes"}.
    """
    target = int(target_faces)
    if target < 4:
        raise ValueError(f"simplify: target_faces must be at least 4, got {target}")
    before = ms.current_mesh().face_number()
    report = {"target_faces": target, "faces_before": before, "faces_after": before, "passes": 0}
    if before <= target:
        log.info("simplify: %d faces, already at most the target %d; kept as is", before, target)
        return report
    constrained = dict(preserveboundary=True, boundaryweight=1.0, preservenormal=True, preservetopology=True)
    for constraints in (constrained, {}):
        ms.meshing_decimation_quadric_edge_collapse(
            targetfacenum=target,
            qualitythr=0.3,
            optimalplacement=True,
            planarquadric=True,
            autoclean=True,
            **constraints,
        )
        report["passes"] += 1
        faces = ms.current_mesh().face_number()
        if faces <= target * (1 + SIMPLIFY_TOLERANCE):
            break
        log.info("simplify: the constrained collapse stopped at %d faces; again without constraints", faces)
    faces = ms.current_mesh().face_number()
    report["faces_after"] = faces
    log.info("simplify: %d -> %d faces (target %d)", before, faces, target)
    if abs(faces - target) > SIMPLIFY_TOLERANCE * target:
        log.warning(
            "simplify: %d faces is more than %.0f%% from the target %d", faces, 100 * SIMPLIFY_TOLERANCE, target
        )
    return report
