"""`invrender bench milo`: MILO recovery on the benchmark room, beside the paper's Table 3.

The room of ``config/benchmark.yaml`` (its one synthetic room scene) goes through the
workflow's chain, each stage's ``run`` called in this process with that config's settings:
synthesize (the capture and its truth), cameras (with images), geometry, then MILO-Net with the
config's preset (``cpu``), bake and evaluate. With the ablation (the default) milo, bake and
evaluate run a second time with ``template: false`` (the paper's Fig. 12: two plain MLPs, no
material template), on the same capture, cameras and geometry.

    WORK/capture, WORK/cameras, WORK/geometry     shared
    WORK/template/{milo,scene,report}             MILO-Net (the preset as configured)
    WORK/plain/{milo,scene,report}                the ablation

Measured here, around each milo stage: wall clock and process CPU time of the whole stage
(setup, the warm start of MLP 1, the iterations; its ``training.json`` has the iterations alone
as ``training_seconds``), and the peak resident set size of this process while it ran
(``harness.PeakRSS``: psutil polled every 2 ms, above the level at the stage's start as
"growth"). ``training.json``'s ``peak_memory_mb`` is getrusage's ``ru_maxrss``: the high-water
mark of the whole process, which here includes the stages before it, so it is reported beside
ours, not instead. Every accuracy number in the tables is read back from the evaluate stage's
``metrics.json`` (docs/evaluate.md lists its keys), so the tables cannot drift from it.

Writes ``OUT/milo.md`` (the tables, the machine, the notes) and ``OUT/milo.json`` (the report:
settings, machine, every row with its raw value, the stages' timings, the paths of the
metrics.json files). docs/benchmarks.md ("MILO recovery") says how to read them.
"""

from __future__ import annotations

import json
import logging
import math
import os
import shutil
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path

import yaml

from ..scene.atomic import check_output
from ..scene.types import SceneError
from . import milo_independent
from .harness import PeakRSS, capture_geometry, format_table, quiet_pyopencl, run_report

log = logging.getLogger("invrender.bench")

SCHEMA = Path(__file__).resolve().parents[2] / "schemas" / "config.schema.yaml"
DEFAULT_CONFIG = "config/benchmark.yaml"
DEFAULT_WORK = "results/bench/milo"
QUICK_ITERATIONS = 3  # --quick: the chain's plumbing, not a measurement
ARMS = {"template": {}, "plain": {"template": False}}  # overrides of each arm over the config's
PAPER_TIME = "~10 h (2000 iterations, two RTX 3090)"
SECTIONS = ["independent", "paper"]


@dataclass(frozen=True)
class Row:
    """One metric of the table: where its value is, how it is printed, the paper's number and
    the target (`op` "<=" or ">=", None: no target), and where its noise floor is."""

    label: str
    path: tuple  # ("metrics", key, ...) in metrics.json, or ("bench", key) in our measurements
    fmt: str
    paper: str = "-"
    op: str | None = None
    target: float | None = None
    floor: tuple | None = None
    unit: str = ""


ROWS = (
    Row("light maps MSE (ke, kw, kg; x/(1+x))", ("metrics", "maps", "light_maps_mse"), ".4g", "0.002", "<=", 0.002),
    # evaluate reports the light maps in linear radiance too (docs/evaluate.md): the paper does not
    # say its scale, so the table shows both and judges the compressed one.
    Row("light maps MSE, linear radiance", ("metrics", "maps", "light_maps_mse_linear"), ".4g"),
    Row("material MSE (shading balls)", ("metrics", "maps", "material_mse"), ".4g", "0.015", "<=", 0.015),
    Row(
        "insertion PSNR [dB]",
        ("metrics", "insertion", "mean", "psnr_db"),
        ".2f",
        "26.49",
        ">=",
        26.5,
        ("metrics", "insertion", "noise_floor", "psnr_db"),
        " dB",
    ),
    Row(
        "insertion SSIM",
        ("metrics", "insertion", "mean", "ssim"),
        ".4f",
        "0.964",
        ">=",
        0.964,
        ("metrics", "insertion", "noise_floor", "ssim"),
    ),
    Row(
        "insertion NCC",
        ("metrics", "insertion", "mean", "ncc"),
        ".4f",
        "0.978",
        ">=",
        0.978,
        ("metrics", "insertion", "noise_floor", "ncc"),
    ),
    Row(
        "insertion MSE",
        ("metrics", "insertion", "mean", "mse"),
        ".4g",
        "0.002",
        "<=",
        0.002,
        ("metrics", "insertion", "noise_floor", "mse"),
    ),
    Row(
        "novel-view PSNR [dB]",
        ("metrics", "novel_views", "mean", "psnr_db"),
        ".2f",
        floor=("metrics", "novel_views", "truth_floor", "psnr_db"),
    ),
    Row(
        "novel-view SSIM",
        ("metrics", "novel_views", "mean", "ssim"),
        ".4f",
        floor=("metrics", "novel_views", "truth_floor", "ssim"),
    ),
    Row("training time [s] (milo stage, wall)", ("bench", "milo_wall_s"), ".1f", PAPER_TIME),
    Row("peak memory [MB] (RSS during milo)", ("bench", "milo_peak_rss_mb"), ".0f"),
)
# The ablation is about the diffuse-emission ambiguity (Fig. 12): the emission and albedo maps
# show it directly, so its table has them as well.
ABLATION_ROWS = ROWS + (
    Row("ke MSE", ("metrics", "maps", "map_mse", "ke"), ".4g"),
    Row("kd MSE", ("metrics", "maps", "map_mse", "kd"), ".4g"),
)
TABLE_COLUMNS = [
    ("metric", "metric", "s"),
    ("paper", "paper (MILO)", "s"),
    ("target_text", "target", "s"),
    ("text", "invrender", "s"),
    ("met_text", "target met?", "s"),
    ("shortfall_text", "shortfall", "s"),
    ("floor_text", "noise floor", "s"),
]
CURVE_COLUMNS = [
    ("arm", "arm", "s"),
    ("iteration", "iteration", "d"),
    ("wall_time_s", "training [s]", ".1f"),
    ("light_maps_mse", "light maps MSE", ".4g"),
    ("material_mse", "material MSE", ".4g"),
    ("novel_view_psnr_db", "novel-view PSNR [dB] (4 spp)", ".2f"),
]


@dataclass(frozen=True)
class Settings:
    mode: str  # "full", or "N iterations" when --iterations overrides the preset's
    config: str
    scene: str
    work: str
    preset: str
    overrides: dict = field(default_factory=dict)  # the config's milo overrides, --iterations on top
    ablation: bool = True
    evaluate_spp: int = 64
    evaluate_seed: int = 0


# ---------------------------------------------------------------------------------------------
# The config
# ---------------------------------------------------------------------------------------------


def load_config(path) -> dict:
    """The workflow config at `path`, checked against the workflow's schema with its defaults
    filled in (snakemake's own validate, as the Snakefile does)."""
    from snakemake.utils import validate

    path = Path(path)
    try:
        config = yaml.safe_load(path.read_text())
    except yaml.YAMLError as error:
        raise SceneError(path, "(yaml)", f"a YAML file ({error})") from None
    if not isinstance(config, dict):
        raise SceneError(path, "(top level)", "a mapping of config keys (config/README.md)")
    try:
        validate(config, str(SCHEMA))
    except Exception as error:  # snakemake's WorkflowError: its first line names the key
        raise SceneError(path, "(schema)", f"a config valid for the workflow: {str(error).splitlines()[0]}") from None
    return config


def room_scene(config: dict, path) -> str:
    """The name of the config's one synthetic room (the benchmark's scene)."""
    rooms = [name for name, s in config["scenes"].items() if s.get("synthetic", {}).get("kind") == "room"]
    if len(rooms) != 1:
        raise SceneError(path, "scenes", f"exactly one synthetic room scene, got {rooms or 'none'}")
    return rooms[0]


def settings_from(config: dict, path, work, iterations: int | None, ablation: bool) -> Settings:
    scene = room_scene(config, path)
    overrides = dict(config["milo"]["overrides"])
    if iterations is not None:
        if iterations < 1:
            raise SceneError("bench milo --iterations", "iterations", f"a positive integer, got {iterations}")
        overrides["iterations"] = int(iterations)
    return Settings(
        mode="full" if iterations is None else f"{iterations} iterations",
        config=str(path),
        scene=scene,
        work=str(work),
        preset=config["milo"]["preset"],
        overrides=overrides,
        ablation=ablation,
        evaluate_spp=config["evaluate"]["spp"],
        evaluate_seed=config["evaluate"]["seed"],
    )


# ---------------------------------------------------------------------------------------------
# The chain
# ---------------------------------------------------------------------------------------------


def shared_stages(config: dict, settings: Settings, work: Path, device, progress: bool) -> dict:
    """synthesize, cameras, geometry: what both arms start from. Returns each stage's seconds."""
    from ..cameras import stage as cameras
    from ..synthesize import stage as synthesize

    synthetic = config["scenes"][settings.scene]["synthetic"]
    seconds = {}
    t0 = time.perf_counter()
    synthesize.run(
        "room", work / "capture", synthetic["config"], spp=synthetic["spp"], seed=synthetic["seed"], device=device
    )
    seconds["synthesize"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    cameras.run(work / "capture" / "sparse", work / "cameras", images_dir=work / "capture" / "images", progress=False)
    seconds["cameras"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    capture_geometry(work, config, progress)
    seconds["geometry"] = time.perf_counter() - t0
    return seconds


def fresh_milo_dir(path: Path) -> Path:
    """An earlier milo directory here is removed whole: the stage fills its directory file by
    file and keeps what it finds, and an earlier longer run's snapshots would enter this run's
    accuracy-against-time table."""
    check_output(path, "milo")  # only a directory the milo stage wrote (or nothing) is removed
    if path.exists():
        shutil.rmtree(path)
    return path


def run_arm(name: str, config: dict, settings: Settings, work: Path, device, progress: bool) -> dict:
    """milo, bake and evaluate for one arm; its measurements and its metrics.json, read back."""
    from ..bake import stage as bake
    from ..evaluate import stage as evaluate
    from ..milo import stage as milo

    holdout = list(config["scenes"][settings.scene]["holdout"])
    arm = work / name
    overrides = {**settings.overrides, **ARMS[name], "holdout": holdout}
    milo_dir = fresh_milo_dir(arm / "milo")
    log.info("bench milo: %s arm, %s preset, overrides %s", name, settings.preset, overrides)
    wall, cpu = time.perf_counter(), time.process_time()
    with PeakRSS() as memory:
        summary = milo.run(
            work / "geometry",
            work / "cameras",
            work / "cameras" / "images",
            milo_dir,
            preset=settings.preset,
            overrides=overrides,
            resume="never",
            device=device,
            progress=progress,
        )
    wall, cpu = time.perf_counter() - wall, time.process_time() - cpu
    t0 = time.perf_counter()
    bake.run(milo_dir / "maps.npz", work / "geometry", work / "cameras", arm / "scene", milo_dir / "training.json")
    bake_s = time.perf_counter() - t0
    t0 = time.perf_counter()
    evaluate.run(
        arm / "scene",
        work / "capture" / "ground_truth" / "scene",
        work / "geometry" / "atlas.npz",
        work / "cameras" / "images",
        arm / "report",
        holdout=holdout,
        snapshots_dir=milo_dir / "snapshots",
        spp=settings.evaluate_spp,
        seed=settings.evaluate_seed,
        device=device,
        progress=progress,
    )
    evaluate_s = time.perf_counter() - t0
    metrics_path = arm / "report" / "metrics.json"
    bench = {
        "milo_wall_s": wall,
        "milo_cpu_s": cpu,
        "training_seconds": summary["training_seconds"],
        "iterations": summary["iterations"],
        "milo_peak_rss_mb": memory.peak / 2**20,
        "milo_rss_growth_mb": memory.growth / 2**20,
        "process_maxrss_mb": summary["peak_memory_mb"],
        "texels": summary["texels"],
        "bake_s": bake_s,
        "evaluate_s": evaluate_s,
    }
    return {
        "overrides": overrides,
        "settings": summary["settings"],
        "metrics_path": str(metrics_path),
        "metrics": json.loads(metrics_path.read_text()),
        "bench": bench,
    }


# ---------------------------------------------------------------------------------------------
# The tables
# ---------------------------------------------------------------------------------------------


def lookup(arm: dict, path: tuple | None):
    """The value at `path` in an arm's metrics.json ("metrics", ...) or measurements ("bench",
    ...); None where the document has none (novel views without held-out views)."""
    if path is None:
        return None
    value = arm[path[0]]
    for key in path[1:]:
        if value is None:
            return None
        value = value[key]
    return value


def judge(row: Row, value) -> tuple[bool | None, float | None]:
    """(target met?, shortfall: how far the value is on the wrong side of the target, in the
    metric's units; 0 when met). None, None without a target or a value."""
    if row.op is None or value is None:
        return None, None
    gap = value - row.target if row.op == "<=" else row.target - value
    return gap <= 0, max(gap, 0.0)


def shortfall_text(row: Row, met, gap) -> str:
    if met is None:
        return "-" if row.op is None else "no value"
    if met:
        return "-"
    worse = "above" if row.op == "<=" else "below"
    text = f"{format(gap, row.fmt)}{row.unit} {worse}"
    if row.op == "<=" and row.target > 0:  # an error: by what factor too large
        text += f" ({(gap + row.target) / row.target:.3g}x the target)"
    return text


def table_row(row: Row, arm: dict) -> dict:
    value = lookup(arm, row.path)
    floor = lookup(arm, row.floor)
    met, gap = judge(row, value)
    return {
        "metric": row.label,
        "source": ".".join(row.path),
        "value": value,
        "text": "-" if value is None else format(value, row.fmt),
        "paper": row.paper,
        "target": None if row.op is None else {"op": row.op, "value": row.target},
        "target_text": "-" if row.op is None else f"{row.op} {row.target:g}",
        "met": met,
        "met_text": {None: "-", True: "yes", False: "NO"}[met],
        "shortfall": gap,
        "shortfall_text": shortfall_text(row, met, gap),
        "floor": floor,
        "floor_text": "-" if floor is None else format(floor, row.fmt),
    }


def noise_removed(metrics: dict) -> dict | None:
    """Insertion MSE with the renders' noise taken out: E[(recovered - truth)^2] = bias^2 +
    var_recovered + var_truth, and the noise floor (truth against truth) is 2 var_truth; with
    var_recovered ~ var_truth (the same room, spp and tone mapping), MSE - floor MSE estimates the
    recovery's own error. PSNR from it as evaluate takes PSNR (10 log10(1 / MSE), [0, 1] values)."""
    insertion = metrics["insertion"]
    if not insertion or not insertion.get("noise_floor"):
        return None
    mse = insertion["mean"]["mse"] - insertion["noise_floor"]["mse"]
    return {"mse": mse, "psnr_db": 10 * math.log10(1 / mse) if mse > 0 else None}


def ablation_table(arms: dict) -> list[dict]:
    rows = []
    for row in ABLATION_ROWS:
        out = {"metric": row.label, "target_text": "-" if row.op is None else f"{row.op} {row.target:g}"}
        for name, arm in arms.items():
            value = lookup(arm, row.path)
            met, _ = judge(row, value)
            out[name] = value
            out[f"{name}_text"] = "-" if value is None else format(value, row.fmt)
            out[f"{name}_met"] = {None: "-", True: "yes", False: "NO"}[met]
        rows.append(out)
    return rows


ABLATION_COLUMNS = [
    ("metric", "metric", "s"),
    ("target_text", "target", "s"),
    ("template_text", "MILO-Net (template)", "s"),
    ("template_met", "met?", "s"),
    ("plain_text", "plain MLPs (Fig. 12)", "s"),
    ("plain_met", "met?", "s"),
]


def curves(arms: dict) -> list[dict]:
    """The evaluate stage's accuracy against training time, both arms."""
    return [{"arm": name, **row} for name, arm in arms.items() for row in arm["metrics"]["training"] or []]


def describe(config: dict, settings: Settings, arms: dict) -> str:
    scene = config["scenes"][settings.scene]
    cams = {"count": 6, "width": 96, "height": 72} | scene["synthetic"]["config"].get("cameras", {})
    arm = arms["template"]
    s = arm["settings"]
    return (
        f"room `{settings.scene}` of {settings.config}: {cams['count']} views of {cams['width']} x {cams['height']}, "
        f"{len(scene['holdout'])} held out, capture {scene['synthetic']['spp']} spp; atlas "
        f"{config['geometry']['atlas_resolution']}^2 ({arm['bench']['texels']} covered texels); MILO-Net "
        f"`{settings.preset}` preset: {s['iterations']} iterations of {s['rays']} rays x {s['spp']} spp, "
        f"{s['max_bounces']} bounces, {s['layers']} layers x {s['width']}, Q = {s['materials']}; evaluate "
        f"{settings.evaluate_spp} spp"
    )


def write_markdown(out: Path, report: dict, config: dict, settings: Settings) -> str:
    arms = report["arms"]
    template = arms["template"]["bench"]
    text = [
        f"# invrender bench milo ({settings.mode}; {report['seconds']:.0f} s)",
        "",
        describe(config, settings, arms),
        "",
        format_table(
            "MILO-Net on the benchmark room, beside the paper (Table 3, section 4.1)", TABLE_COLUMNS, report["table"]
        ),
        f"Training time: the milo stage's wall clock (setup, MLP 1's warm start, the iterations); "
        f"its iterations alone {template['training_seconds']:.1f} s (training.json), CPU time of the stage "
        f"{template['milo_cpu_s']:.1f} s. Peak memory: this process's RSS while the stage ran (psutil, polled "
        f"every 2 ms), {template['milo_rss_growth_mb']:.0f} MB above its start; getrusage's high-water mark of "
        f"the whole process {template['process_maxrss_mb']:.0f} MB. Noise floor: the same comparison between "
        "two renders of the truth (insertion) or of the truth against the capture (novel views): what a perfect "
        "recovery scores at this spp.",
        "",
    ]
    removed = report["insertion_noise_removed"]["template"]
    if removed is not None:
        psnr = "-" if removed["psnr_db"] is None else f"{removed['psnr_db']:.2f} dB"
        text += [
            f"Insertion with the renders' noise taken out (MSE minus the noise floor's MSE, assuming both "
            f"renders equally noisy): MSE {removed['mse']:.4g}, PSNR {psnr}.",
            "",
        ]
    if "plain" in arms:
        text.append(
            format_table(
                "Ablation (Fig. 12): MILO-Net against two plain MLPs, same room and settings",
                ABLATION_COLUMNS,
                report["ablation"],
            )
        )
    if report["curves"]:
        text.append(
            format_table(
                "Accuracy against training time (the evaluate stage's snapshots)", CURVE_COLUMNS, report["curves"]
            )
        )
    text.append("Machine: " + ", ".join(f"{k}={v}" for k, v in report["machine"].items()))
    text += [f"NOTE: {n}" for n in report["notes"]]
    markdown = "\n".join(text) + "\n"
    (out / "milo.md").write_text(markdown)
    return markdown


# ---------------------------------------------------------------------------------------------
# The benchmark
# ---------------------------------------------------------------------------------------------


def run(
    quick: bool = False,
    out="docs/benchmarks",
    device: str | None = None,
    config=DEFAULT_CONFIG,
    iterations: int | None = None,
    ablation: bool = True,
    work=DEFAULT_WORK,
    sections: str | None = None,
) -> dict:
    """The sections (SECTIONS; default all): `independent`, the recovery on rooms Mitsuba
    rendered against the baselines (milo_independent.py), and `paper`, the chain on the
    config's room beside the paper (both arms with `ablation`); the tables under `out`.
    `quick`: QUICK_ITERATIONS iterations unless `iterations` says otherwise."""
    quiet_pyopencl()
    config_data = load_config(config)
    work, out = Path(work), Path(out)
    chosen = _sections(sections)
    if "paper" in chosen:  # its config is checked before any section runs
        settings_from(config_data, config, work, iterations, ablation)
    report = {}
    if "independent" in chosen:
        out.mkdir(parents=True, exist_ok=True)
        report["independent"] = milo_independent.run_study(
            config_data, work / "independent", out, iterations, quick, device
        )
    if "paper" in chosen:
        report["paper"] = _paper(quick, out, device, config, config_data, iterations, ablation, work)
    return report


def _sections(sections: str | None) -> list[str]:
    chosen = SECTIONS if sections is None else [s.strip() for s in sections.split(",") if s.strip()]
    unknown = [s for s in chosen if s not in SECTIONS]
    if unknown or not chosen:
        raise SceneError("bench milo --sections", ", ".join(unknown) or "(empty)", f"some of {', '.join(SECTIONS)}")
    return chosen


def _paper(quick, out: Path, device, config, config_data, iterations, ablation, work: Path) -> dict:
    started, load_start = time.time(), os.getloadavg()
    if quick and iterations is None:
        iterations = QUICK_ITERATIONS
    settings = settings_from(config_data, config, work, iterations, ablation)
    out.mkdir(parents=True, exist_ok=True)
    work.mkdir(parents=True, exist_ok=True)
    progress = sys.stderr.isatty()
    notes = []
    if iterations is not None:
        notes.append(
            f"--iterations {iterations} overrides the preset's iterations: the numbers check the plumbing, "
            "they do not measure recovery"
        )
    shared = shared_stages(config_data, settings, work, device, progress)
    arms = {}
    for name in ("template", "plain") if ablation else ("template",):
        arms[name] = run_arm(name, config_data, settings, work, device, progress)
    results = {
        "scene": settings.scene,
        "work": str(work),
        "shared_stage_seconds": shared,
        "arms": arms,
        "table": [table_row(row, arms["template"]) for row in ROWS],
        "ablation": ablation_table(arms) if ablation else [],
        "curves": curves(arms),
        "insertion_noise_removed": {name: noise_removed(arm["metrics"]) for name, arm in arms.items()},
    }
    notes += missed_notes(results["table"])
    report = run_report("milo", settings, "not used", notes, started, load_start, device, results)
    (out / "milo.json").write_text(json.dumps(report, indent=1, default=float, allow_nan=False) + "\n")
    markdown = write_markdown(out, report, config_data, settings)
    sys.stdout.write(markdown)
    sys.stdout.flush()
    return report


def missed_notes(table: list[dict]) -> list[str]:
    """A note per missed target that the noise floor misses as well: then more samples per pixel
    in evaluate, not a better recovery, is the first thing to change."""
    notes = []
    for row, line in zip(ROWS, table):
        if line["met"] is False and judge(row, line["floor"])[0] is False:
            notes.append(
                f"{row.label}: even the noise floor ({line['floor_text']}) misses the target: "
                "raise evaluate.spp before reading this row"
            )
    return notes
