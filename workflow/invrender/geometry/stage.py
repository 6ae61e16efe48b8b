"""The `geometry` stage: a mesh or point cloud in, a clean simplified mesh with an atlas out.

    out_dir/mesh.ply       triangles with xatlas UVs (s, t), meters, +Y up, instance_id 0 per face
    out_dir/atlas.npz      per texel: triangle, barycentric, position, normal, mask (AtlasTexels)
    out_dir/geometry.json  the report: input kind, what cleaning removed, face counts before and
                           after simplification, atlas size, utilisation and texel density

The input is taken as it is (meters, +Y up: docs/scene-format.md, "Conventions"); nothing is moved
or scaled. The directory appears whole or not at all (``atomic_dir``); bad input is refused by
``load_geometry`` before any work starts.
"""

from __future__ import annotations

import json
import logging
import time
from pathlib import Path

import numpy as np
from tqdm import tqdm

from ..scene.atlas import rasterize_atlas, triangle_areas, unwrap
from ..scene.atomic import atomic_dir, check_output
from ..scene.mesh_io import write_ply
from ..scene.types import Mesh, SceneError, require_positive
from .clean import DEFAULT_TARGET_FACES, clean_mesh, input_kind, load_geometry, reconstruct, simplify

__all__ = ["run", "texel_density", "REPORT_VERSION"]

logger = logging.getLogger(__name__)

REPORT_VERSION = 1


def texel_density(positions, faces, uvs, height: int, width: int) -> np.ndarray:
    """Per triangle: sqrt(UV area in texels / 3D area in m^2), in texels per meter (NaN where
    the 3D area is zero)."""
    uv = np.asarray(uvs, np.float64)[np.asarray(faces)] * np.array([width, height], np.float64)
    e1, e2 = uv[:, 1] - uv[:, 0], uv[:, 2] - uv[:, 0]
    uv_area = 0.5 * np.abs(e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0])
    area = triangle_areas(positions, faces)
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(area > 0, np.sqrt(uv_area / area), np.nan)


def run(
    source,
    out_dir,
    target_faces: int = DEFAULT_TARGET_FACES,
    texels_per_meter: float | None = None,
    atlas_resolution: int | None = 1024,
    padding: int = 2,
    poisson_depth: int = 8,
    min_island_fraction: float = 0.01,
    min_island_faces: int = 0,
    trim_spacings: float = 10.0,
    threads: int | None = None,
    log: logging.Logger = logger,
    progress: bool = True,
) -> dict:
    """Load, clean (or reconstruct), simplify, unwrap and rasterise; write ``out_dir``; return the
    report that is also written as ``geometry.json``.

    Atlas size: ``texels_per_meter`` fixes the density (the atlas grows to fit); otherwise the
    charts are packed as densely as fits an ``atlas_resolution`` square. ``padding`` empty texels
    separate the charts. A point cloud is reconstructed with screened Poisson at
    ``poisson_depth`` and trimmed ``trim_spacings`` mean point spacings from the points (see
    ``clean.reconstruct``). Islands below ``min_island_fraction`` of the diagonal (and, if
    ``min_island_faces`` > 0, with fewer faces than that) are removed: size relative to the scene
    decides, so a lamp of two triangles survives (``clean.clean_mesh``).
    """
    source, out_dir = Path(source), Path(out_dir)
    if texels_per_meter is not None:
        if not (np.isfinite(texels_per_meter) and texels_per_meter > 0):
            raise SceneError(
                "geometry --texels-per-meter", "texel density", f"a positive number, got {texels_per_meter}"
            )
        atlas_resolution = None
    else:
        require_positive("geometry --atlas-resolution", "atlas size", atlas_resolution, minimum=8)
    require_positive("geometry --target-faces", "face count", target_faces, minimum=4)
    require_positive("geometry --padding", "texels", padding, minimum=0)
    require_positive("geometry --min-island-faces", "face count", min_island_faces, minimum=0)
    if not 0 <= min_island_fraction < 1:
        raise SceneError(
            "geometry --min-island-fraction",
            "fraction of the diagonal",
            f"a number in [0, 1), got {min_island_fraction}",
        )
    require_positive("geometry --poisson-depth", "octree depth", poisson_depth, minimum=1)
    timings: dict[str, float] = {}
    started = time.perf_counter()

    check_output(out_dir, "geometry")  # before the work, not after it
    ms = load_geometry(source)  # refuses bad input before any work and before out_dir exists
    kind = input_kind(ms)
    loaded = ms.current_mesh()
    report: dict = {
        "version": REPORT_VERSION,
        "source": str(source),
        "input_kind": kind,
        "input": {"vertices": int(loaded.vertex_number()), "faces": int(loaded.face_number())},
        "units": "meters, +Y up (as given)",
    }
    log.info(
        "geometry: %s is a %s with %d vertices and %d faces",
        source,
        kind.replace("_", " "),
        loaded.vertex_number(),
        loaded.face_number(),
    )

    steps = ["reconstruct" if kind == "point_cloud" else "clean", "simplify", "unwrap", "rasterize", "write"]
    with tqdm(total=len(steps), desc="geometry", unit="step", disable=not progress, leave=False) as bar:

        def done(step: str, t0: float) -> float:
            timings[step] = round(time.perf_counter() - t0, 3)
            bar.update(1)
            return time.perf_counter()

        t0 = time.perf_counter()
        bar.set_postfix_str(steps[0])
        if kind == "point_cloud":
            recon = reconstruct(
                ms,
                depth=poisson_depth,
                trim_spacings=trim_spacings,
                min_island_fraction=min_island_fraction,
                min_island_faces=min_island_faces,
                threads=threads,
                log=log,
            )
            report["cleaning"] = recon.pop("removed")
            report["reconstruction"] = recon
        else:
            report["cleaning"] = clean_mesh(ms, min_island_fraction, min_island_faces, log=log)
            report["reconstruction"] = None
        if ms.current_mesh().face_number() == 0:
            removed = {k: v["faces"] for k, v in report["cleaning"].items() if v["faces"]}
            raise SceneError(
                source, "faces", f"a surface with area that survives cleaning; every face was removed ({removed})"
            )
        t0 = done(steps[0], t0)

        bar.set_postfix_str("simplify")
        report["simplification"] = simplify(ms, target_faces, log=log)
        t0 = done("simplify", t0)

        mesh = ms.current_mesh()
        positions = np.asarray(mesh.vertex_matrix(), np.float64)
        faces = np.asarray(mesh.face_matrix(), np.int64)
        bar.set_postfix_str("unwrap")
        uv = unwrap(positions, faces, texels_per_meter=texels_per_meter, resolution=atlas_resolution, padding=padding)
        t0 = done("unwrap", t0)

        bar.set_postfix_str("rasterize")
        out_mesh = Mesh(
            positions=uv.positions, faces=uv.faces, uvs=uv.uvs, instance_ids=np.zeros(len(uv.faces), np.int32)
        )
        texels = rasterize_atlas(out_mesh, uv.height, uv.width)
        t0 = done("rasterize", t0)

        density = texel_density(uv.positions, uv.faces, uv.uvs, uv.height, uv.width)
        median_density = float(np.nanmedian(density))
        utilisation = float(texels.mask.mean())
        area = float(triangle_areas(uv.positions, uv.faces).sum())
        report["mesh"] = {
            "vertices": int(len(uv.positions)),
            "faces": int(len(uv.faces)),
            "area_m2": area,
            "bbox_min": np.asarray(uv.positions).min(0).tolist(),
            "bbox_max": np.asarray(uv.positions).max(0).tolist(),
        }
        report["atlas"] = {
            "width": int(uv.width),
            "height": int(uv.height),
            "padding": int(padding),
            "requested": (
                {"texels_per_meter": float(texels_per_meter)}
                if texels_per_meter is not None
                else {"resolution": int(atlas_resolution)}
            ),
            "covered_texels": int(texels.mask.sum()),
            "utilisation": utilisation,
            "texel_density_per_m": median_density,
            "texel_density_per_m_p5_p95": np.nanpercentile(density, [5, 95]).tolist(),
            "texel_size_m": 1.0 / median_density,
        }
        log.info(
            "atlas %dx%d: utilisation %.1f%% (covered texels / all texels), texel density %.1f "
            "texels/m (median over triangles; texel size %.4g m)",
            uv.width,
            uv.height,
            100 * utilisation,
            median_density,
            1.0 / median_density,
        )

        bar.set_postfix_str("write")
        with atomic_dir(out_dir, kind="geometry") as tmp:
            tmp = Path(tmp)
            write_ply(tmp / "mesh.ply", out_mesh)
            texels.save(tmp / "atlas.npz")
            t0 = done("write", t0)
            report["timings_s"] = timings | {"total": round(time.perf_counter() - started, 3)}
            (tmp / "geometry.json").write_text(json.dumps(report, indent=2, allow_nan=False) + "\n")
    log.info(
        "geometry: wrote %s (%d faces, %dx%d atlas) in %.1f s",
        out_dir,
        len(uv.faces),
        uv.width,
        uv.height,
        report["timings_s"]["total"],
    )
    return report
