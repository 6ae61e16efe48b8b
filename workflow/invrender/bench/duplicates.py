"""`invrender bench duplicates`: Structure from Duplicates' poses and shape on the synthetic fixtures,
beside the paper's Table 2 (docs/benchmarks.md, "Structure from Duplicates: poses and shape").

Per scene (a preset of invrender.synthesize.duplicates, docs/duplicates-fixtures.md) and variant
(the stage's Settings overridden, VARIANTS), the pipeline as the workflow runs it, each step a
stage's Python entry point timed with its peak memory:

    capture   synthesize duplicates at RENDER_SPP (or an earlier render, $INVRENDER_DUPLICATES_CAPTURES)
    cameras   the capture's COLMAP model -> WORK/SCENE/cameras        (shared by the variants)
    segment   the opencv backend -> WORK/SCENE/segmentation            (shared by the variants)
    crop      per instance: crop + features -> WORK/SCENE/VARIANT/crops
    solve     match, map, carve, refine -> WORK/SCENE/VARIANT/duplicates
    evaluate  against the truth -> WORK/SCENE/VARIANT/report/metrics.json

A step whose output exists is skipped (resume); its time is then the one recorded when it ran
(steps.json beside it), or none if another run made it (a folder laid out by hand-run stages,
copied in). A step that stops with a SceneError ends its row with the message; the others go on.
"""

from __future__ import annotations

import json
import logging
import os
import time
from dataclasses import dataclass, field
from pathlib import Path

from ..scene.types import SceneError
from . import duplicates_independent as independent
from .harness import Ledger, Stopped, format_table, quiet_pyopencl, run_scenes

log = logging.getLogger("invrender.bench")

DEFAULT_WORK = "results/bench/duplicates"
RENDER_SPP = 64
# Earlier renders to reuse (the folder `invrender synthesize duplicates --out DIR/<preset>` wrote
# beside DIR/<preset>.json): $INVRENDER_DUPLICATES_CAPTURES, else none.
REUSE_VARIABLE = "INVRENDER_DUPLICATES_CAPTURES"
# The order they run in: the acceptance's scenes first (box, 10 and 20 copies), cans beside them.
SCENES = ("box-10-hd", "can-10-hd", "box-20-hd", "can-20-hd", "box-6-hd")
QUICK_SCENES = ("box-6-ci", "can-6-ci")  # 15 pairs each: matching, not the renders, costs the time
# ASIFT on the capture's own instance masks (the renderer's instance AOV, given to the segment
# stage's provided backend), 512-pixel crops, sub-pixel tracks: what the provided-asift-* share
PROVIDED_ASIFT = {"masks": "provided", "matcher": "asift", "crop_size": 512, "subpixel_rounds": 3}
# and the hull carved by the floor, snapped onto COLMAP's and photo-consistent points
PHOTO = {**PROVIDED_ASIFT, "hull_outliers": 0, "hull_floor": True, "hull_snap": True, "hull_photo": True}
VARIANTS = {
    # xfeat with the rotation search; refinement on, so that one run gives COLMAP's poses
    # (poses_colmap.json, "before") and the refined ones ("after"): the workflow's default is off
    "default": {"refine": True},
    "no-rotation-search": {"rotation_search": False, "refine": True},  # the ablation (section 3.1)
    "sift": {"matcher": "sift", "refine": True},
    # one keypoint set per copy (tracks.py), the planar flip turned back, sub-pixel tracks and a
    # joint bundle adjustment (adjust.py); refinement off: it is worse with a hull from rough poses
    "tracks-subpixel": {"track_size": 512, "subpixel_rounds": 3},
    # the same from the capture's own instance masks (the renderer's instance AOV, given to the
    # segment stage's provided backend as a user gives masks from any tool), with refinement on,
    # so that one run gives the poses before and after render-and-compare
    "provided-tracks-subpixel": {"masks": "provided", "track_size": 512, "subpixel_rounds": 3, "refine": True},
    # and with every pair's angle searched again on the fixed keypoints, pairs that disagree dropped
    "provided-track-search": {
        "masks": "provided",
        "track_size": 512,
        "subpixel_rounds": 3,
        "track_search": True,
        "pair_support": 0.5,
        "refine": True,
    },  # fmt: skip
    # ASIFT (matching.py): every crop described under simulated tilts, no rotation search; its
    # keypoints are one fixed set per copy already, so long tracks need no track_size
    "asift": {"matcher": "asift", "crop_size": 512, "subpixel_rounds": 3, "refine": True},
    # from the capture's masks: with refinement (the poses before and after it) and without (the
    # workflow's default, refine off: the poses and hull bench duplicates-material recovers with)
    "provided-asift-refine": {**PROVIDED_ASIFT, "refine": True},
    "provided-asift": PROVIDED_ASIFT,
    # the same with the strict hull (no copy may disagree): with 0.15-degree poses a tenth of the
    # copies' tolerance only loosens it (box-10-hd's Chamfer 0.041 -> 0.017 of the diagonal)
    "provided-asift-strict": {**PROVIDED_ASIFT, "hull_outliers": 0},
    # and that hull moved onto COLMAP's triangulated points (snap.py): the shape the copies' pixels
    # agree on, where no silhouette reaches (box-20-hd's Chamfer 0.0098 -> 0.0039 of the diagonal)
    "provided-asift-snap": {**PROVIDED_ASIFT, "hull_outliers": 0, "hull_snap": True},
    # and first carved with the floor the copies rest on (floor.py): no silhouette carves under
    # the face a copy stands on (box-10-hd's hull kept a 12 mm skirt there)
    "provided-asift-floor": {**PROVIDED_ASIFT, "hull_outliers": 0, "hull_floor": True, "hull_snap": True},
    # and snapped onto points where the copies' pixels agree too (photo.py), for the faces
    # COLMAP's matches left without points
    "provided-asift-photo": PHOTO,
    # and those points made tracks in every copy that sees them, the copies adjusted again
    # (extend.py): a copy that COLMAP's matches saw on one face only is held by the others' print
    "provided-asift-tracks": {**PHOTO, "photo_tracks": True},
    # the same settings from the segment stage's masks of the photograph (the opencv backend)
    "asift-tracks": {**{k: v for k, v in PHOTO.items() if k != "masks"}, "photo_tracks": True},
    # and COLMAP's reprojection error bound halved (mapping.py): with six copies a few loose tracks
    # tilt a copy (box-6-hd: 1.02 -> 0.48 degrees mean), but box-10-hd's go 0.15 -> 0.34 degrees and
    # box-20-hd's copies are lost: a per-photograph setting, not the headline (docs/benchmarks.md)
    "provided-asift-photo-tight": {**PHOTO, "max_error_px": 1.0},
}
# Where a variant's instance masks come from: the opencv backend on the photo (the default), or
# the capture's instance-id image through the provided backend. Not a setting of the stage.
MASK_SOURCES = {"opencv": "segmentation", "provided": "segmentation-provided"}
# What runs unless --variants names others: on every scene the headline (ASIFT from the capture's
# instance masks, as the fixtures give them); on the ablation scene (turned in the image
# plane, lying any way up) also the matchers and the rotation search from the segmentation's masks.
HEADLINE_VARIANTS = ("provided-asift-refine",)
ABLATION_SCENES = ("box-10-hd",)
ABLATION_VARIANTS = ("default", "no-rotation-search", "sift", "asift", "provided-asift-refine")
# On the captures Mitsuba rendered (duplicates_independent.py): the best settings of the HD
# fixtures, from the capture's masks and from the photograph's
INDEPENDENT_VARIANTS = ("provided-asift-tracks", "asift-tracks")
STEPS = ("cameras", "segment", "crop", "solve", "evaluate")


@dataclass
class Settings:
    mode: str
    scenes: list
    variants: dict = field(default_factory=dict)  # scene -> [variant]
    work: str = DEFAULT_WORK
    render_spp: int = RENDER_SPP


def _names(text, known, what: str) -> list[str]:
    if text is None:
        return None
    names = [n.strip() for n in (text.split(",") if isinstance(text, str) else text) if n.strip()]
    unknown = [n for n in names if n not in known]
    if not names or unknown:
        raise SceneError(f"bench duplicates --{what}", what, f"a comma-separated list of {', '.join(known)}")
    return names


def settings_from(quick: bool, scenes, variants, work) -> Settings:
    from ..synthesize.duplicates import DUPLICATES_PRESETS

    known = [*sorted(DUPLICATES_PRESETS), *independent.INDEPENDENT_SCENES, "independent"]
    scenes = _names(scenes, known, "scenes") or list(QUICK_SCENES if quick else SCENES)
    if "independent" in scenes:  # every capture Mitsuba renders, both splits
        at = scenes.index("independent")
        chosen_captures = independent.QUICK_INDEPENDENT if quick else independent.INDEPENDENT_SCENES
        scenes = [*scenes[:at], *chosen_captures, *scenes[at + 1 :]]
    chosen = _names(variants, list(VARIANTS), "variants")
    per_scene = {}
    for scene in scenes:
        if chosen is not None:
            per_scene[scene] = chosen
        elif independent.is_independent(scene):
            per_scene[scene] = list(INDEPENDENT_VARIANTS)
        elif quick:
            per_scene[scene] = ["default"]
        else:
            per_scene[scene] = list(ABLATION_VARIANTS if scene in ABLATION_SCENES else HEADLINE_VARIANTS)
    mode = "quick" if quick else "full"
    return Settings(mode=mode, scenes=scenes, variants=per_scene, work=str(work or DEFAULT_WORK))


# ---------------------------------------------------------------------------------------------
# Steps
# ---------------------------------------------------------------------------------------------


def _render(preset: str, out: Path, spp: int):
    from ..synthesize import stage as synthesize

    synthesize.run("duplicates", out, {"preset": preset}, spp=spp)


def capture_roots() -> dict[str, str]:
    """$INVRENDER_DUPLICATES_CAPTURES as the reports' placeholder CAPTURES (harness.portable)."""
    folder = os.environ.get(REUSE_VARIABLE)
    return {str(Path(folder).resolve()): "CAPTURES", folder: "CAPTURES"} if folder else {}


def capture_of(preset: str, work: Path, spp: int) -> tuple[Path, dict | None, str]:
    """The capture of `preset`: an earlier render in $INVRENDER_DUPLICATES_CAPTURES if its config
    is exactly the preset's, else WORK/captures/<preset> (rendered now unless there). (folder,
    measurements, source)."""
    if independent.is_independent(preset):
        out = work / "captures" / preset
        measured = Ledger(work / "captures").run(f"render {preset}", out, independent.render, preset, out)
        spp = independent.independent_config(preset)[1]
        return out, measured, f"rendered by Mitsuba 3 at {spp} spp, the photo its 8-bit sRGB image"
    reuse = Path(os.environ.get(REUSE_VARIABLE) or work / "captures")
    earlier = reuse / preset
    config = reuse / f"{preset}.json"
    if (earlier / "ground_truth").is_dir() and config.exists():
        if json.loads(config.read_text()) == {"preset": preset}:
            return earlier, None, f"reused {earlier} ({config.name}: the preset alone)"
    out = work / "captures" / preset
    measured = Ledger(work / "captures").run(f"render {preset}", out, _render, preset, out, spp)
    return out, measured, f"rendered at {spp} spp"


def mask_source(variant: str) -> str:
    return VARIANTS[variant].get("masks", "opencv")


def segmentation_of(scene_dir: Path, variant: str) -> Path:
    return scene_dir / MASK_SOURCES[mask_source(variant)]


def shared_steps(capture: Path, scene_dir: Path, ledger: Ledger, sources=("opencv",)):
    """cameras and segment (once per mask source): what every variant of a scene starts from."""
    from ..cameras import stage as cameras
    from ..segment import stage as segment

    image = capture / "images" / "view_000.exr"
    ledger.run(
        "cameras", scene_dir / "cameras", cameras.run, capture / "sparse", scene_dir / "cameras",
        images_dir=capture / "images", progress=False,
    )  # fmt: skip
    if "opencv" in sources:
        out = scene_dir / MASK_SOURCES["opencv"]
        ledger.run("segment", out, segment.run, image, out)
    if "provided" in sources:
        masks, out = capture / "ground_truth" / "masks" / "view_000.png", scene_dir / MASK_SOURCES["provided"]
        ledger.run("segment provided", out, segment.run, image, out, backend="provided", masks=masks)


def _crops(seg: Path, crops: Path, ids: list[int], settings):
    from ..duplicates import stage

    scene_dir, masks = seg.parent, seg / "masks" / "view_000.png"
    for i in ids:
        crop, features = crops / f"instance_{i:03d}.npz", crops / f"instance_{i:03d}.features.npz"
        if not (crop.exists() and features.exists()):
            stage.run_crop(scene_dir / "cameras", masks, i, crop, features, settings)


def variant_steps(capture: Path, scene_dir: Path, variant: str, ledger: Ledger):
    """crop, solve and evaluate of one variant."""
    from ..duplicates import stage
    from ..evaluate import stage as evaluate

    settings = stage.settings_from({k: v for k, v in VARIANTS[variant].items() if k != "masks"})
    folder = scene_dir / variant
    seg = segmentation_of(scene_dir, variant)
    ids = [int(e["id"]) for e in json.loads((seg / "instances.json").read_text())["instances"]]
    crops = folder / "crops"
    crops.mkdir(parents=True, exist_ok=True)
    done = folder / "crops.done"  # the crops folder fills one instance at a time
    made = [crops / f"instance_{i:03d}.features.npz" for i in ids]
    if not done.exists():
        if not all(path.exists() for path in made):  # all there: another run made them, untimed
            ledger.run("crop", done, _crops, seg, crops, ids, settings)
        done.write_text("\n".join(map(str, ids)) + "\n")
    ledger.run(
        "solve", folder / "duplicates", stage.run, scene_dir / "cameras", seg / "masks" / "view_000.png",
        seg / "instances.json", crops, crops, folder / "duplicates", settings, progress=False,
    )  # fmt: skip
    ledger.run(
        "evaluate", folder / "report", evaluate.run_duplicates, seg, folder / "duplicates",
        capture / "ground_truth", capture / "images", folder / "report",
    )  # fmt: skip


def run_scene(preset: str, variants: list[str], work: Path, spp: int) -> list[dict]:
    """Every variant of one scene: its rows (metrics, measurements, or the error that stopped it)."""
    capture, render, source = capture_of(preset, work, spp)
    scene_dir = work / preset
    rows, error, shared = [], None, Ledger(scene_dir)
    try:
        shared_steps(capture, scene_dir, shared, {mask_source(v) for v in variants})
    except Stopped as stop:
        error = str(stop)
    for variant in variants:
        instances = segmentation_of(scene_dir, variant) / "instances.json"
        segmented = len(json.loads(instances.read_text())["instances"]) if instances.exists() else None
        row = {"scene": preset, "variant": variant, "capture": str(capture), "capture_source": source}
        own = Ledger(scene_dir / variant)
        if error is None:
            try:
                variant_steps(capture, scene_dir, variant, own)
            except Stopped as stop:
                row["error"] = str(stop)
                log.error("bench duplicates: %s %s stopped: %s", preset, variant, stop)
        else:
            row["error"] = error
        row["render"] = render
        row["segmented"] = segmented
        row["steps"] = {**shared.steps, **own.steps}
        metrics = scene_dir / variant / "report" / "metrics.json"
        row["metrics"] = json.loads(metrics.read_text()) if metrics.exists() else None
        solved = scene_dir / variant / "duplicates" / "duplicates.json"
        row["duplicates"] = json.loads(solved.read_text()) if solved.exists() else None
        rows.append(row)
    return rows


# ---------------------------------------------------------------------------------------------
# The tables
# ---------------------------------------------------------------------------------------------


def _get(document, *path):
    for key in path:
        if document is None:
            return None
        document = document.get(key) if isinstance(document, dict) else None
    return document


def copies(preset: str) -> str:
    return preset.split("-")[1]


def table_row(row: dict) -> dict:
    """One line of the table from a row's metrics.json, duplicates.json and measurements."""
    from ..evaluate.duplicates import PAPER_TABLE2

    m = row["metrics"]
    steps = row["steps"] or {}
    out = {"scene": row["scene"], "variant": row["variant"], "error": row.get("error")}
    out["iou"] = _get(m, "masks", "mean_iou")
    counts = _get(m, "counts") or {}
    out["truth"] = counts.get("truth")
    out["segmented"] = counts.get("segmented", row.get("segmented"))
    registered = _get(row["duplicates"], "registered_by_colmap")
    placed = _get(row["duplicates"], "placed")
    out["registered"] = None if registered is None else len(registered)
    out["placed"] = None if placed is None else len(placed)
    out["instances"] = "/".join(
        "-" if out[k] is None else str(out[k]) for k in ("truth", "segmented", "registered", "placed")
    )
    for stage in ("before", "after"):
        rotation = _get(m, "poses", stage, "rotation")
        out[f"rot_{stage}_mean"] = _get(rotation, "error_deg", "mean")
        out[f"rot_{stage}_median"] = _get(rotation, "error_deg", "median")
        out[f"swing_{stage}_mean"] = _get(rotation, "symmetry", "swing_deg", "mean")
        out[f"twist_{stage}_mean"] = _get(rotation, "symmetry", "twist_deg", "mean")
        out[f"trans_{stage}_mean"] = _get(m, "poses", stage, "translation", "error_fraction_of_diagonal", "mean")
        out[f"evaluated_{stage}"] = _get(m, "poses", stage, "evaluated")
    out["chamfer"] = _get(m, "mesh", "chamfer_fraction_of_diagonal")
    out["chamfer_icp"] = _get(m, "mesh", "icp", "chamfer_fraction_of_diagonal")
    paper = PAPER_TABLE2.get(copies(row["scene"]), {})
    out["paper_rot"], out["paper_trans"], out["paper_chamfer"] = (
        paper.get(k) for k in ("rotation_deg", "translation", "chamfer")
    )
    for step in STEPS:
        out[f"{step}_s"] = _get(steps, step, "wall_s")
    peaks = [s["peak_rss_mb"] for s in steps.values() if s]
    out["peak_rss_mb"] = max(peaks) if peaks else None
    timings = _get(row["duplicates"], "timings") or {}
    out["match_and_map_s"] = timings.get("match_and_map_s")
    pairs = _get(row["duplicates"], "pairs")
    out["pairs"] = None if pairs is None else len(pairs)
    return out


ACCURACY_COLUMNS = [
    ("scene", "scene", "s"),
    ("variant", "variant", "s"),
    ("iou", "mask IoU", ".3f"),
    ("instances", "instances truth/seg/COLMAP/placed", "s"),
    ("rot_before_mean", "rot. before mean [deg]", ".3f"),
    ("rot_before_median", "median", ".3f"),
    ("rot_after_mean", "rot. after mean [deg]", ".3f"),
    ("rot_after_median", "median", ".3f"),
    ("paper_rot", "paper rot. [deg]", ".3f"),
    ("trans_before_mean", "transl. before [diag]", ".4f"),
    ("trans_after_mean", "transl. after [diag]", ".4f"),
    ("paper_trans", "paper transl.", ".3f"),
    ("chamfer", "Chamfer [diag]", ".4f"),
    ("chamfer_icp", "after ICP", ".4f"),
    ("paper_chamfer", "paper Chamfer", ".3f"),
]
SYMMETRY_COLUMNS = [
    ("scene", "scene", "s"),
    ("variant", "variant", "s"),
    ("swing_before_mean", "swing before mean [deg]", ".3f"),
    ("twist_before_mean", "twist before mean [deg]", ".3f"),
    ("swing_after_mean", "swing after mean [deg]", ".3f"),
    ("twist_after_mean", "twist after mean [deg]", ".3f"),
    ("rot_after_mean", "rot. after mean [deg]", ".3f"),
]
COST_COLUMNS = [
    ("scene", "scene", "s"),
    ("variant", "variant", "s"),
    ("cameras_s", "cameras [s]", ".1f"),
    ("segment_s", "segment [s]", ".1f"),
    ("crop_s", "crop + features [s]", ".1f"),
    ("pairs", "pairs", "d"),
    ("match_and_map_s", "match + map [s]", ".1f"),
    ("solve_s", "solve [s]", ".1f"),
    ("evaluate_s", "evaluate [s]", ".1f"),
    ("peak_rss_mb", "peak RSS [MB]", ".0f"),
]


def write_markdown(out: Path, report: dict) -> str:
    lines = report["table"]
    text = [
        f"# invrender bench duplicates ({report['mode']}; {report['seconds']:.0f} s)",
        "",
        "Rotation error: degrees, after the rotation that best aligns the recovered object frame to the "
        "true one; translation: the centres' error after a robust similarity, as a fraction of the object's "
        "diagonal; Chamfer: the shared mesh against the true object, fraction of the diagonal. Before: "
        "COLMAP's poses; after: render-and-compare. The paper's Table 2 (a colour box) beside each row of "
        "the same number of copies.",
        "",
        format_table("Poses and shape, beside the paper's Table 2", ACCURACY_COLUMNS, lines),
    ]
    cans = [line for line in lines if line["swing_after_mean"] is not None or line["swing_before_mean"] is not None]
    if cans:
        text.append(
            format_table("Cans: the rotation error split into swing (axis tilt) and twist", SYMMETRY_COLUMNS, cans)
        )
    text.append(format_table("Wall time of each step and peak memory", COST_COLUMNS, lines))
    text.append(
        "Times: wall clock of each stage's Python entry point in this process ('-': not reached, the row "
        "stopped before it, or made by another run and reused); peak RSS: this process's resident set "
        "while the steps ran (psutil, every 2 ms), the largest over the row's steps."
    )
    text.append("")
    errors = [f"{line['scene']} {line['variant']}: {line['error']}" for line in lines if line["error"]]
    text += [f"STOPPED: {e}" for e in errors]
    text.append("Machine: " + ", ".join(f"{k}={v}" for k, v in report["machine"].items()))
    text += [f"NOTE: {n}" for n in report["notes"]]
    markdown = "\n".join(text) + "\n"
    (out / "duplicates.md").write_text(markdown)
    return markdown


# ---------------------------------------------------------------------------------------------
# The benchmark
# ---------------------------------------------------------------------------------------------


def run(
    quick: bool = False, out="docs/benchmarks", device: str | None = None, scenes=None, variants=None, work=None
) -> dict:
    """Every scene x variant through the pipeline (resuming in `work`), the tables under `out`."""
    quiet_pyopencl()
    started, load_start = time.time(), os.getloadavg()
    settings = settings_from(quick, scenes, variants, work)
    work, out = Path(settings.work), Path(out)
    out.mkdir(parents=True, exist_ok=True)
    work.mkdir(parents=True, exist_ok=True)

    def run_one(scene):
        log.info("bench duplicates: %s, variants %s", scene, settings.variants[scene])
        return run_scene(scene, settings.variants[scene], work, settings.render_spp)

    note = "the -ci fixtures (320 x 240), the default variant: checks the plumbing, not accuracy"
    return run_scenes(
        "duplicates", settings, out, run_one, table_row, write_markdown, note, device, (started, load_start),
        capture_roots(),
    )  # fmt: skip
