"""`invrender bench duplicates-material`: Structure from Duplicates' appearance half on
the synthetic fixtures, beside the paper's Table 1 (single view) and Table 2 (albedo against the
number of copies) (docs/benchmarks.md, "Structure from Duplicates: material and light").

Per scene (a preset of invrender.synthesize.duplicates) and pose source (POSES), each step a
stage's Python entry point timed with its peak memory (harness.Ledger, steps.json in the row's
folder WORK/SCENE/appearance/POSES):

    inputs     truth: the true object mesh with an atlas, the true poses and masks
               recovered: the geometry stage on bench duplicates' `default` variant's shared mesh
               (that variant run first, in the same WORK, if its poses are missing)
    material   duplicates-material (MATERIAL_PRESET; resumed from its checkpoints if killed)
    bake       bake --material -> scene/
    evaluate   evaluate --duplicates ... --scene scene --training material/training.json -> report/
    first guess: bake without --material -> first_guess/scene, evaluated -> first_guess/report
               (what the material stage starts from, so that what it gains is visible)

The cameras and the segmentation are bench duplicates' shared steps (WORK/SCENE/cameras,
WORK/SCENE/segmentation), the capture bench duplicates' (capture_of: $INVRENDER_DUPLICATES_CAPTURES
reused). A step whose output exists is skipped; a step stopped by a SceneError ends its row with
the message, the other rows go on.
"""

from __future__ import annotations

import json
import logging
import os
import shutil
import time
from dataclasses import dataclass, field
from pathlib import Path

from ..scene.types import SceneError
from . import duplicates as poses_bench
from .harness import Ledger, Stopped, format_table, quiet_pyopencl, run_scenes

log = logging.getLogger("invrender.bench")

DEFAULT_WORK = poses_bench.DEFAULT_WORK  # the same folder: the recovered rows start from bench duplicates' runs
SCENES = ("box-6-hd", "box-10-hd", "box-20-hd")  # the acceptance's copies: 6, 10, 20
QUICK_SCENES = ("box-6-ci", "box-10-ci", "box-20-ci")
POSES = ("truth", "recovered")
QUICK_POSES = ("truth",)  # recovered poses need bench duplicates' matching: minutes even at 320 x 240
MATERIAL_PRESET, QUICK_MATERIAL_PRESET = "default", "ci"
EVALUATE_SPP = 16  # relighting renders: 4 per side at the photograph's size (its noise floor is reported)
TARGET_FACES = 20_000  # the geometry stage's default (MILO's 20 K faces)
VARIANT = "default"  # bench duplicates' variant whose poses are "recovered", unless --variants names another


def atlas_resolution(preset: str) -> int:
    """Texels per atlas side: 512 for the 1600 x 1200 fixtures, 256 for the 320 x 240 ones (the
    resolutions docs/duplicates-material.md measured with)."""
    return 512 if preset.endswith("-hd") else 256


@dataclass
class Settings:
    mode: str
    scenes: list
    poses: list
    work: str = DEFAULT_WORK
    material_preset: str = MATERIAL_PRESET
    evaluate_spp: int = EVALUATE_SPP
    render_spp: int = poses_bench.RENDER_SPP
    atlas_resolution: dict = field(default_factory=dict)
    pose_variant: str = VARIANT


def settings_from(quick: bool, scenes, poses, work, variants=None) -> Settings:
    from ..synthesize.duplicates import DUPLICATES_PRESETS

    scenes = poses_bench._names(scenes, sorted(DUPLICATES_PRESETS), "scenes") or list(QUICK_SCENES if quick else SCENES)
    poses = poses_bench._names(poses, list(POSES), "poses") or list(QUICK_POSES if quick else POSES)
    chosen = poses_bench._names(variants, list(poses_bench.VARIANTS), "variants") or [VARIANT]
    if len(chosen) != 1:
        raise SceneError("bench duplicates-material --variants", "variants", "one bench duplicates variant")
    return Settings(
        pose_variant=chosen[0],
        mode="quick" if quick else "full",
        scenes=scenes,
        poses=poses,
        work=str(work or DEFAULT_WORK),
        material_preset=QUICK_MATERIAL_PRESET if quick else MATERIAL_PRESET,
        atlas_resolution={scene: atlas_resolution(scene) for scene in scenes},
    )


# ---------------------------------------------------------------------------------------------
# Inputs
# ---------------------------------------------------------------------------------------------


@dataclass
class Inputs:
    """What the material stage, bake and evaluate read for one row."""

    geometry: Path  # mesh.ply + atlas.npz
    poses: Path  # poses.json
    masks: Path  # the photograph's instance-id PNG
    duplicates: Path  # poses.json + object.ply, as evaluate --duplicates reads them
    segmentation: Path  # masks/ + instances.json, as evaluate --segmentation reads them


def truth_inputs(capture: Path, row: Path) -> Inputs:
    folder, truth = row / "inputs", capture / "ground_truth"
    return Inputs(
        folder / "geometry", truth / "poses.json", truth / "masks" / "view_000.png",
        folder / "duplicates", folder / "segmentation",
    )  # fmt: skip


def recovered_inputs(scene_dir: Path, row: Path, variant: str) -> Inputs:
    solved = scene_dir / variant / "duplicates"
    segmentation = poses_bench.segmentation_of(scene_dir, variant)
    return Inputs(
        row / "geometry", solved / "poses.json", segmentation / "masks" / "view_000.png", solved, segmentation
    )


def make_truth_inputs(capture: Path, out: Path, resolution: int):
    """out/geometry (the true object mesh, its atlas rasterised from its own UVs: a recovered and
    a true texel at the same UV are the same surface point), out/duplicates (the true poses and
    mesh) and out/segmentation (the true masks, `write_truth_segmentation`)."""
    from ..scene.atlas import rasterize_atlas
    from ..scene.atomic import atomic_dir
    from ..scene.mesh_io import read_mesh, write_ply

    truth = capture / "ground_truth"
    with atomic_dir(out, kind="bench-truth-inputs") as tmp:
        tmp = Path(tmp)
        mesh = read_mesh(truth / "object.ply")
        (tmp / "geometry").mkdir()
        write_ply(tmp / "geometry" / "mesh.ply", mesh)
        rasterize_atlas(mesh, resolution, resolution).save(tmp / "geometry" / "atlas.npz")
        (tmp / "duplicates").mkdir()
        for name in ("poses.json", "object.ply"):
            shutil.copy(truth / name, tmp / "duplicates" / name)
        write_truth_segmentation(truth / "masks" / "view_000.png", tmp / "segmentation")


def write_truth_segmentation(mask: Path, out: Path) -> None:
    """The true instance-id PNG as the segment stage lays it out (masks/, instances.json), its ids
    kept: they name the true poses (segment's provided backend renumbers them in reading order,
    which would pair each copy's mask with another copy's pose)."""
    from ..scene.images import read_mask
    from ..segment.stage import instance_table

    ids = read_mask(mask)
    (out / "masks").mkdir(parents=True)
    shutil.copy(mask, out / "masks" / mask.name)
    document = {
        "image": mask.with_suffix(".exr").name,
        "width": int(ids.shape[1]),
        "height": int(ids.shape[0]),
        "backend": "truth",
        "instances": instance_table(ids, {i: 1.0 for i in range(1, int(ids.max()) + 1)}),
    }
    (out / "instances.json").write_text(json.dumps(document, indent=2) + "\n")


def recovered_poses(preset: str, work: Path, spp: int, variant: str) -> None:
    """bench duplicates' `variant` of `preset` in `work`, run now if its poses are missing."""
    if (work / preset / variant / "duplicates" / "poses.json").exists():
        return
    log.info("bench duplicates-material: %s has no %s poses yet: bench duplicates runs it", preset, variant)
    row = poses_bench.run_scene(preset, [variant], work, spp)[0]
    if row.get("error"):
        raise Stopped(f"bench duplicates {preset} {variant}: {row['error']}")


# ---------------------------------------------------------------------------------------------
# Steps
# ---------------------------------------------------------------------------------------------


def inputs_step(source: str, capture: Path, scene_dir: Path, row: Path, settings: Settings, ledger: Ledger):
    from ..geometry import stage as geometry

    resolution = settings.atlas_resolution.get(scene_dir.name, atlas_resolution(scene_dir.name))
    if source == "truth":
        ledger.run("inputs", row / "inputs", make_truth_inputs, capture, row / "inputs", resolution)
        return truth_inputs(capture, row)
    recovered_poses(scene_dir.name, scene_dir.parent, settings.render_spp, settings.pose_variant)
    inputs = recovered_inputs(scene_dir, row, settings.pose_variant)
    ledger.run(
        "inputs", inputs.geometry, geometry.run, inputs.duplicates / "object.ply", inputs.geometry,
        target_faces=TARGET_FACES, atlas_resolution=resolution,
    )  # fmt: skip
    return inputs


def row_steps(source: str, capture: Path, scene_dir: Path, settings: Settings, ledger: Ledger) -> None:
    """One row: its inputs, the material stage, bake, evaluate, and the first guess beside."""
    from ..bake import duplicates as bake
    from ..duplicates_material import stage as material
    from ..evaluate import stage as evaluate

    row = ledger.path.parent
    inputs = inputs_step(source, capture, scene_dir, row, settings, ledger)
    cameras, truth, images = scene_dir / "cameras", capture / "ground_truth", capture / "images"
    recovered = row / "material"
    # training.json is the stage's last file: the folder alone may be a killed run's, resumed
    ledger.run(
        "material", recovered / "training.json", material.run, inputs.geometry, inputs.poses, cameras,
        inputs.masks, recovered, preset=settings.material_preset, resume="auto", progress=False,
    )  # fmt: skip
    for name, material_dir, folder in (("", recovered, row), (" first guess", None, row / "first_guess")):
        ledger.run(
            "bake" + name, folder / "scene", bake.run, inputs.geometry, inputs.poses, cameras, inputs.masks,
            folder / "scene", material_dir=material_dir,
        )  # fmt: skip
        ledger.run(
            "evaluate" + name, folder / "report", evaluate.run_duplicates, inputs.segmentation,
            inputs.duplicates, truth, images, folder / "report", scene_dir=folder / "scene",
            training=None if material_dir is None else material_dir / "training.json", spp=settings.evaluate_spp,
        )  # fmt: skip


def _read(path: Path):
    return json.loads(path.read_text()) if path.exists() else None


def row_folder(poses: str, variant: str) -> str:
    """appearance/<this>: `recovered` from bench duplicates' default variant, `recovered-<variant>`
    from another (so rows from different poses never share a folder)."""
    return poses if poses == "truth" or variant == VARIANT else f"{poses}-{variant}"


def run_scene(preset: str, settings: Settings) -> list[dict]:
    """Every pose source of one scene: its rows (metrics, measurements, or the error that stopped it)."""
    work = Path(settings.work)
    capture, _, source = poses_bench.capture_of(preset, work, settings.render_spp)
    scene_dir = work / preset
    shared, error = Ledger(scene_dir), None
    recovering = "recovered" in settings.poses
    try:
        sources = {poses_bench.mask_source(settings.pose_variant)} if recovering else set()
        poses_bench.shared_steps(capture, scene_dir, shared, sources)
    except Stopped as stop:
        error = str(stop)
    rows = []
    for poses in settings.poses:
        folder = scene_dir / "appearance" / row_folder(poses, settings.pose_variant)
        own = Ledger(folder)
        row = {"scene": preset, "poses": poses, "capture": str(capture), "capture_source": source, "error": error}
        row["pose_variant"] = settings.pose_variant if poses == "recovered" else None
        if error is None:
            try:
                row_steps(poses, capture, scene_dir, settings, own)
            except Stopped as stop:
                row["error"] = str(stop)
                log.error("bench duplicates-material: %s %s stopped: %s", preset, poses, stop)
        row["steps"] = {**shared.steps, **own.steps}
        row["metrics"] = _read(folder / "report" / "metrics.json")
        row["first_guess"] = _read(folder / "first_guess" / "report" / "metrics.json")
        row["training"] = _read(folder / "material" / "training.json")
        rows.append(row)
    return rows


# ---------------------------------------------------------------------------------------------
# The tables
# ---------------------------------------------------------------------------------------------

_get = poses_bench._get
METRICS = ("albedo_psnr_db", "roughness_mse", "relighting_psnr_db", "env_mse")


def table_row(row: dict) -> dict:
    """One line of the table from a row's two metrics.json (recovered, first guess), its
    training.json and its measurements; the paper's Table 1 single-view column and Table 2's
    colour box of the same number of copies beside."""
    from ..evaluate.appearance import PAPER_TABLE1_SINGLE_VIEW, PAPER_TABLE2_COLOR_BOX

    steps, training = row.get("steps") or {}, row.get("training") or {}
    copies = poses_bench.copies(row["scene"])
    out = {"scene": row["scene"], "poses": pose_label(row), "copies": int(copies), "error": row.get("error")}
    ours = _get(row["metrics"], "appearance", "table1", "ours") or {}
    start = _get(row["first_guess"], "appearance", "table1", "ours") or {}
    table2 = PAPER_TABLE2_COLOR_BOX.get(copies, {})
    for key in METRICS:
        out[key] = ours.get(key)
        out[f"{key}_first_guess"] = start.get(key)
        out[f"{key}_paper"] = PAPER_TABLE1_SINGLE_VIEW[key]
        out[f"{key}_paper_copies"] = table2.get(key)
    out["relighting_noise_floor_db"] = _get(row["metrics"], "appearance", "relighting", "noise_floor_psnr_db")
    out["support_albedo_psnr_db"] = _get(row["metrics"], "appearance", "support", "albedo", "psnr_db")
    out["chamfer"] = _get(row["metrics"], "mesh", "chamfer_fraction_of_diagonal")
    out["rotation_error_deg"] = _get(row["metrics"], "poses", "after", "rotation", "error_deg", "mean")
    out["iterations"] = training.get("iterations")
    out["training_s"] = training.get("training_seconds")
    for step in ("inputs", "material", "bake", "evaluate"):
        out[f"{step}_s"] = _get(steps, step, "wall_s")
    # the material stage's own peak (training.json, getrusage) when this run did not time it
    out["material_peak_mb"] = _get(steps, "material", "peak_rss_mb") or training.get("peak_memory_mb")
    peaks = [s["peak_rss_mb"] for s in steps.values() if s and s.get("peak_rss_mb") is not None]
    out["peak_rss_mb"] = max(peaks + [out["material_peak_mb"] or 0]) or None
    out["better_than_paper"] = _verdict(out)
    return out


def pose_label(row: dict) -> str:
    """'truth', 'recovered' (bench duplicates' default variant) or 'recovered (VARIANT)'."""
    variant = row.get("pose_variant")
    return row["poses"] if variant in (None, VARIANT) else f"{row['poses']} ({variant})"


def _verdict(line: dict) -> str | None:
    """Which of the four columns beat the paper's single-view Table 1 ("4/4"), None without numbers."""
    if line["albedo_psnr_db"] is None:
        return None
    wins = [
        line[k] is not None and (line[k] > line[f"{k}_paper"] if k.endswith("_db") else line[k] < line[f"{k}_paper"])
        for k in METRICS
    ]
    return f"{sum(wins)}/{len(wins)}"


def _pairs(lines: list[dict]) -> list[dict]:
    """Truth and recovered poses of each scene on one line: what pose error costs."""
    out = []
    for scene in dict.fromkeys(line["scene"] for line in lines):
        by = {line["poses"].split(" ")[0]: line for line in lines if line["scene"] == scene}
        truth, recovered = by.get("truth", {}), by.get("recovered", {})
        pair = {"scene": scene, "rotation_error_deg": recovered.get("rotation_error_deg")}
        for key in METRICS:
            pair[f"{key}_truth"], pair[f"{key}_recovered"] = truth.get(key), recovered.get(key)
        out.append(pair)
    return out


TABLE1_COLUMNS = [
    ("scene", "scene", "s"),
    ("poses", "poses", "s"),
    ("albedo_psnr_db", "albedo PSNR [dB]", ".2f"),
    ("albedo_psnr_db_first_guess", "first guess", ".2f"),
    ("albedo_psnr_db_paper", "paper T1", ".2f"),
    ("albedo_psnr_db_paper_copies", "paper T2", ".2f"),
    ("roughness_mse", "roughness MSE", ".3f"),
    ("roughness_mse_first_guess", "first guess", ".3f"),
    ("roughness_mse_paper", "paper T1", ".3f"),
    ("roughness_mse_paper_copies", "paper T2", ".2f"),
    ("relighting_psnr_db", "relighting PSNR [dB]", ".2f"),
    ("relighting_psnr_db_first_guess", "first guess", ".2f"),
    ("relighting_psnr_db_paper", "paper T1", ".2f"),
    ("relighting_noise_floor_db", "noise floor", ".2f"),
    ("env_mse", "env MSE", ".3f"),
    ("env_mse_first_guess", "first guess", ".3f"),
    ("env_mse_paper", "paper T1", ".3f"),
    ("env_mse_paper_copies", "paper T2", ".3f"),
    ("better_than_paper", "beats T1", "s"),
]
POSE_COLUMNS = [
    ("scene", "scene", "s"),
    ("rotation_error_deg", "recovered rot. error mean [deg]", ".1f"),
    ("albedo_psnr_db_truth", "albedo PSNR, true poses", ".2f"),
    ("albedo_psnr_db_recovered", "recovered poses", ".2f"),
    ("roughness_mse_truth", "roughness MSE, true", ".3f"),
    ("roughness_mse_recovered", "recovered", ".3f"),
    ("relighting_psnr_db_truth", "relighting PSNR, true", ".2f"),
    ("relighting_psnr_db_recovered", "recovered", ".2f"),
    ("env_mse_truth", "env MSE, true", ".3f"),
    ("env_mse_recovered", "recovered", ".3f"),
]
COST_COLUMNS = [
    ("scene", "scene", "s"),
    ("poses", "poses", "s"),
    ("iterations", "iterations", "d"),
    ("training_s", "training [s]", ".0f"),
    ("inputs_s", "inputs [s]", ".1f"),
    ("material_s", "material stage [s]", ".0f"),
    ("bake_s", "bake [s]", ".1f"),
    ("evaluate_s", "evaluate [s]", ".0f"),
    ("material_peak_mb", "material peak RSS [MB]", ".0f"),
    ("peak_rss_mb", "peak RSS [MB]", ".0f"),
]


def write_markdown(out: Path, report: dict) -> str:
    lines, settings = report["table"], report["settings"]
    text = [
        f"# invrender bench duplicates-material ({report['mode']}; {report['seconds']:.0f} s)",
        "",
        f"The shared material and the sky from the one photograph (duplicates-material, preset "
        f"{settings['material_preset']}), baked and evaluated (evaluate --duplicates, {settings['evaluate_spp']} spp); "
        "'first guess': the bake without the material stage (the photograph's colours under a white sky), "
        "where the stage starts. Albedo PSNR: SfD's convention (clip, x^(1/2.2), per-channel scale); roughness "
        "MSE on ka^(1/4); env MSE on a 512 x 256 lat-long map, x^(1/2.2), no scale; relighting PSNR: the "
        "copies' pixels under two new skies, in place and rearranged (noise floor: the truth against "
        "itself at the same spp). Paper T1: SfD Table 1, single view; paper T2: SfD Table 2's colour box with "
        "the same number of copies (no relighting column there). Poses 'truth': the true mesh, poses and "
        "masks; 'recovered': a bench duplicates variant's (the default unless named in brackets: poses, "
        "shared mesh through the geometry stage, the masks it was solved from).",
        "",
        format_table("Material and light, beside the paper's Tables 1 and 2", TABLE1_COLUMNS, lines),
    ]
    pairs = [p for p in _pairs(lines) if p["albedo_psnr_db_truth"] is not None and p["albedo_psnr_db_recovered"]]
    if pairs:
        text.append(format_table("What pose error costs: true and recovered poses side by side", POSE_COLUMNS, pairs))
    text.append(format_table("Time and memory", COST_COLUMNS, lines))
    text.append(
        "Times: wall clock of each stage's Python entry point in this process ('-': not reached, or made by "
        "another run and reused); training: the material stage's own training seconds (training.json); peak "
        "RSS: this process's resident set while the steps ran (psutil, every 2 ms), the largest over the row's "
        "steps; the material stage's from its training.json (getrusage) when this run did not time it."
    )
    text.append("")
    text += [f"STOPPED: {line['scene']} {line['poses']}: {line['error']}" for line in lines if line["error"]]
    text.append("Machine: " + ", ".join(f"{k}={v}" for k, v in report["machine"].items()))
    text += [f"NOTE: {n}" for n in report["notes"]]
    markdown = "\n".join(text) + "\n"
    (out / "duplicates_material.md").write_text(markdown)
    return markdown


# ---------------------------------------------------------------------------------------------
# The benchmark
# ---------------------------------------------------------------------------------------------


def run(
    quick: bool = False, out="docs/benchmarks", device: str | None = None, scenes=None, poses=None, work=None,
    variants=None,
):  # fmt: skip
    """Every scene x pose source through the chain (resuming in `work`), the tables under `out`."""
    quiet_pyopencl()
    started, load_start = time.time(), os.getloadavg()
    settings = settings_from(quick, scenes, poses, work, variants)
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    Path(settings.work).mkdir(parents=True, exist_ok=True)

    def run_one(scene):
        log.info("bench duplicates-material: %s, poses %s", scene, settings.poses)
        return run_scene(scene, settings)

    note = "the -ci fixtures (320 x 240), the ci material preset: checks the plumbing, not accuracy"
    return run_scenes(
        "duplicates-material", settings, out, run_one, table_row, write_markdown, note, device,
        (started, load_start), poses_bench.capture_roots(),
    )  # fmt: skip
