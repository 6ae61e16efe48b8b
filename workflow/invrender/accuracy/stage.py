"""The `accuracy` stage (`invrender accuracy`, rule accuracy): what accuracy costs in time.

out_dir/accuracy_vs_time.csv     one row per configuration: every knob, error, time, device
out_dir/accuracy.json            the rate, the knees with their config snippets and their check
                                 on another seed, the floors and their causes, the budget
out_dir/accuracy.md              the same as text (docs/accuracy.md reads it)
out_dir/accuracy.html            the same as tables, for the Snakemake report
out_dir/accuracy_forward.png     forward rendering: RMSE and relative MSE against time
out_dir/accuracy_gradients.png   gradients: relative error against time per pass (images given)
out_dir/accuracy_recovery.png    recovery: the training runs' errors against time (runs given)
"""

from __future__ import annotations

import html
import json
import logging
import tempfile
import time
from dataclasses import asdict
from pathlib import Path

from tqdm import tqdm

from ..render.features import Features
from ..render.measure import write_csv
from ..scene.atomic import atomic_dir, check_output
from ..scene.format import load_scene
from ..scene.types import SceneError, require_positive
from . import figures, forward, front, gradients, recovery
from . import runs as runs_module
from .budgets import BUDGETS
from .summary import html_table

log = logging.getLogger(__name__)
FORMAT_VERSION = 1
CHECK_SEED = 2  # the knee is rendered again with this seed (offset) to check what it states


def run(
    scene_dir,
    features_path,
    out_dir,
    images_dir=None,
    runs=(),
    budget: str = "quick",
    default_spp: int = 256,
    gradient_spp: int = 16,
    camera: str | None = None,
    seed: int = 0,
    device: str | None = None,
    knee_factor: float = front.KNEE_FACTOR,
    progress: bool = True,
) -> dict:
    """Sweep the scene ``scene_dir`` rendered with ``features_path``'s features; write ``out_dir``
    (module docstring) and return accuracy.json's document.

    ``images_dir``: the captured images (the gradient sweep's loss; None: no gradient sweep).
    ``runs``: training runs as dicts {"dir", "metrics" (evaluate's metrics.json or None),
    "source" (recovery.SOURCES), "label", "default" (the configured run), "overrides", "preset"
    (the config that selects the run), "spec" (a sweep run's run.json: runs.read_run)}. The
    recovery knee is trained again on another seed from a spec of its stage (checks.recovery).
    ``default_spp``, ``gradient_spp``: the configured render.spp and gradients.spp (the
    highlighted defaults). ``camera``: the view swept (default: the scene's first camera).
    """
    out_dir = Path(out_dir)
    check_output(out_dir, "accuracy")
    if budget not in BUDGETS:
        raise SceneError("accuracy --budget", "budget", f"one of {', '.join(BUDGETS)}, got {budget!r}")
    budget = BUDGETS[budget]
    default_spp = require_positive("accuracy --default-spp", "samples per pixel", default_spp)
    gradient_spp = require_positive("accuracy --gradient-spp", "samples per pixel", gradient_spp)
    if not knee_factor >= 1:
        raise SceneError("accuracy --knee-factor", "knee_factor", f"a factor >= 1, got {knee_factor!r}")
    started = time.perf_counter()
    scene = load_scene(scene_dir)
    features = Features.read(features_path)
    view = _camera(scene, scene_dir, camera)
    bar = (lambda jobs, desc: tqdm(jobs, desc=desc, leave=False)) if progress else (lambda jobs, desc: jobs)
    timings, rows, checks = {}, [], {}

    t0 = time.perf_counter()
    sweep = forward.ForwardSweep(scene, features, view, budget, device)
    forward_rows = forward.sweep(sweep, default_spp, seed, lambda jobs: bar(jobs, "forward"))
    rows += forward_rows
    timings["forward_s"] = time.perf_counter() - t0

    gradient_sweep = None
    if images_dir is not None:
        t0 = time.perf_counter()
        gradient_sweep = gradients.GradientSweep(scene, features, images_dir, budget, device, seed)
        rows += gradients.sweep(gradient_sweep, gradient_spp, seed, lambda jobs: bar(jobs, "gradients"))
        timings["gradients_s"] = time.perf_counter() - t0

    for run in runs:
        rows += recovery.run_rows(
            run["dir"],
            run.get("metrics"),
            run.get("source", "milo"),
            run.get("label", "configured"),
            run.get("default", True),
            run.get("overrides"),
            run.get("preset"),
        )

    analysis = _analyse(rows, features, knee_factor)
    t0 = time.perf_counter()
    checks["forward"] = _check_forward(sweep, analysis["knees"].get("forward"), seed)
    if gradient_sweep is not None:
        checks["gradients"] = _check_gradients(gradient_sweep, analysis["knees"].get("gradients"), seed)
    if "recovery" in analysis["knees"]:
        checks["recovery"] = _check_recovery(runs, analysis["knees"]["recovery"], device)
    timings["checks_s"] = time.perf_counter() - t0
    timings["total_s"] = time.perf_counter() - started

    document = {
        "version": FORMAT_VERSION,
        "budget": asdict(budget),
        "scene": str(scene_dir),
        "features": features.to_json()["features"],
        "camera": {"name": view.name, "width": sweep.camera.width, "height": sweep.camera.height},
        "device": sweep.device_name,
        "defaults": {"render_spp": default_spp, "gradients_spp": gradient_spp},
        "reference": {
            "spp": budget.reference_spp,
            "bounces": sweep.reference_features.max_bounces,
            "seconds": sweep.reference_seconds,
            "noise_rmse": float(sweep.reference_variance.mean() ** 0.5),
        },
        **analysis,
        "checks": checks,
        "seed": int(seed),
        "timings": timings,
    }
    with atomic_dir(out_dir, kind="accuracy") as tmp:
        tmp = Path(tmp)
        write_csv(tmp / "accuracy_vs_time.csv", [_flat(row) for row in rows])
        for name in ("forward", "gradients", "recovery"):
            family_rows = front.family(rows, name)
            if family_rows:
                knee = analysis["knees"].get(name)
                floors = [f for f in analysis["floors"] if f["family"] == name]
                figures.plot_family(tmp, name, family_rows, knee, floors)
        (tmp / "accuracy.json").write_text(json.dumps(document, indent=1, default=_json, allow_nan=False) + "\n")
        (tmp / "accuracy.md").write_text(markdown(document))
        (tmp / "accuracy.html").write_text(html_page(document, rows))
    log.info("accuracy: %d configurations in %.1f s; %s", len(rows), timings["total_s"], _headline(document))
    return document


def _camera(scene, scene_dir, name):
    if not scene.cameras:
        raise SceneError(scene_dir, "cameras", "a camera to sweep the renders from")
    if name is None:
        return scene.cameras[0]
    for camera in scene.cameras:
        if camera.name == name:
            return camera
    raise SceneError(scene_dir, "cameras", f"a camera named {name!r} (accuracy --camera)")


def _analyse(rows, features: Features, knee_factor: float) -> dict:
    """Rate, knees with snippets, floors."""
    out = {"knees": {}, "floors": [], "rate": None}
    defaults = asdict(features)
    for name in ("forward", "gradients", "recovery"):
        family_rows = front.family(rows, name)
        if not family_rows:
            continue
        key = front.ERROR_KEY[name]
        floors = front.floors(family_rows, name) if name != "recovery" else []  # training converges
        out["floors"] += floors
        candidates = front.unbiased(family_rows, floors)
        if name == "recovery":
            candidates = _scored(candidates)
        knee = front.knee(candidates, key, knee_factor)
        if knee is not None and name == "recovery":
            knee = front.state_training_error(knee)
        if knee is not None:
            knee["snippet"] = front.snippet(knee["row"], defaults)
            knee["snippet_text"] = front.snippet_text(knee["snippet"])
            out["knees"][name] = knee
    forward_rows = front.family(rows, "forward")
    out["rate"] = front.spp_slope([r for r in forward_rows if r["label"] == "default"])
    return out


def _scored(rows) -> list[dict]:
    """The recovery knee compares one error: the truth's score where any run has one (a run
    without it reads its training loss, another quantity), else the losses."""
    scored = [r for r in rows if not r["error_name"].startswith("training loss")]
    if not scored:
        return rows
    return [r for r in scored if r["error_name"] == scored[0]["error_name"]]


def _check_recovery(runs, knee, device) -> dict:
    """The knee's configuration trained again on another seed, for the knee's iterations, and
    scored as its run was (runs.py: the stages' own commands). How to train comes from a sweep
    run of the same stage (its run.json), the settings from the knee run's training.json."""
    row = knee["row"]
    run = next(r for r in runs if r.get("label", "configured") == row["label"])
    spec = run.get("spec") or next(
        (r["spec"] for r in runs if r.get("spec") and r["spec"]["source"] == row["sweep"]), None
    )
    if spec is None:
        return {"checked": False, "why": f"no sweep run of {row['sweep']} says how to train it (run.json)"}
    trained = recovery.run_settings(run["dir"])
    settings = dict(trained["settings"])
    seed = int(settings.get("seed", 0)) + CHECK_SEED
    # every setting as the run had it (the preset's and the overrides alike), the knee's length,
    # another seed; one snapshot, at the end
    overrides = settings | {"iterations": row["iteration"], "seed": seed, "snapshot_every": row["iteration"]}
    with tempfile.TemporaryDirectory(prefix="invrender-recovery-check-") as tmp:
        again = runs_module.train_and_score(
            Path(tmp) / "run",
            spec["source"],
            spec["inputs"],
            trained["preset"] or spec["preset"],
            overrides,
            label=f"{row['label']} (seed {seed})",
            spp=spec["score"]["spp"],
            seed=spec["score"]["seed"],
            device=device,
        )
        entry = runs_module.read_run(Path(tmp) / "run")
        rows = recovery.run_rows(entry["dir"], entry["metrics"], entry["source"], entry["label"], default=False)
    if not rows or rows[-1]["error_name"] != row["error_name"]:
        return {"checked": False, "why": "the run trained again was not scored by the truth"}
    last = rows[-1]
    verdict = _verdict(knee, last["recovery_error"], last["time_s"])
    return verdict | {
        "seed": seed,
        "iteration": last["iteration"],
        "label": row["label"],
        **{k: last[k] for k in ("novel_view_psnr_db", "relighting_psnr_db") if last.get(k) is not None},
        "seconds": again["seconds"],
    }


def _check_forward(sweep, knee, seed) -> dict | None:
    """The knee rendered again on another seed, against the error it states."""
    if knee is None:
        return None
    row = knee["row"]
    variant = next(v for v in forward.variants(sweep.features, sweep.budget) if v.label == row["label"])
    variant = forward.Variant(
        variant.sweep, variant.label, Features(**row["features"]), variant.scale, variant.cause, variant.pasteable
    )
    again = sweep.measure(variant, row["spp"], forward.measured_seed(seed + CHECK_SEED, 900_000))
    return _verdict(knee, again["rmse"], again["time_s"])


def _check_gradients(sweep, knee, seed) -> dict | None:
    if knee is None:
        return None
    row = knee["row"]
    features = sweep.features.with_bounces(row["max_bounces"])
    again = sweep.measure(
        row["label"], row["sweep"], features, row["spp"], forward.measured_seed(seed + CHECK_SEED, 900_000)
    )
    return _verdict(knee, again["grad_rel_error"], again["time_s"])


def _verdict(knee, error, seconds) -> dict:
    return {
        "checked": True,
        "seed_offset": CHECK_SEED,
        "error": error,
        "stated_error": knee["stated_error"],
        "stated_basis": knee["stated_basis"],
        "within_measured_plus_margin": bool(error <= knee["error"] * (1 + front.SEED_MARGIN)),
        "time_s": seconds,
        "met": bool(error <= knee["stated_error"]),
    }


def _flat(row: dict) -> dict:
    """A CSV row: the features dict is spread into the knob columns already; drop it."""
    return {k: v for k, v in row.items() if k not in ("features",)}


def _json(value):
    if hasattr(value, "item"):
        return value.item()
    raise TypeError(f"not JSON: {type(value).__name__}")


def _headline(document) -> str:
    parts = []
    if document["rate"]:
        parts.append(f"RMSE slope {document['rate']['slope']:.2f} against spp")
    for name, knee in document["knees"].items():
        parts.append(f"{name} knee: {_describe(knee['row'])}")
    parts += [f"floor: {f['label']}" for f in document["floors"]]
    return "; ".join(parts)


# ---------------------------------------------------------------------------------------------
# The report's text and tables
# ---------------------------------------------------------------------------------------------

KNEE_WHAT = {
    "forward": "render.spp and features",
    "gradients": "the adjoint pass (gradients, MILO's training)",
    "recovery": "the recovery stage's training (preset, network, rays, iterations)",
}


def _describe(row) -> str:
    if row["family"] == "recovery":
        return f"{row['label']} run, iteration {row['iteration']} ({row['error_name']})"
    return f"{row['label']}, {row['spp']} spp"


def markdown(document: dict) -> str:
    lines = [
        f"# Accuracy against time ({document['budget']['name']} budget)",
        "",
        f"Scene {document['scene']}, camera {document['camera']['name']} at {document['camera']['width']} x "
        f"{document['camera']['height']}, device {document['device']}. Reference: {document['reference']['spp']} spp, "
        f"{document['reference']['bounces']} bounces (noise RMSE {document['reference']['noise_rmse']:.3g}, taken out "
        "of every error).",
        "",
    ]
    rate = document["rate"]
    lines += [
        f"RMSE against spp along the default's ladder: slope {rate['slope']:.3f} on log-log axes "
        f"(Monte Carlo: {rate['expected']}).",
        "",
    ]
    for name, knee in document["knees"].items():
        row, check = knee["row"], document["checks"].get(name) or {}
        lines += [
            f"## Knee: {KNEE_WHAT[name]}",
            "",
            f"{_describe(row)}: {knee['error_key']} {knee['error']:.4g} in {row['time_s']:.3g} s, within "
            f"{knee['factor']:g}x of the best measured ({_describe(knee['best'])}: "
            f"{knee['best'][knee['error_key']]:.4g} "
            f"in {knee['best']['time_s']:.3g} s, {knee['speedup_over_best']:.1f}x longer). Stated for another seed: "
            f"{knee['error_key']} <= {knee['stated_error']:.4g} ({knee['stated_basis']}).",
            "",
        ]
        if check.get("checked"):
            how = f"by training it again with seed {check['seed']}" if "seed" in check else "on another seed"
            lines += [f"Checked {how}: {check['error']:.4g} ({'met' if check['met'] else 'NOT met'}).", ""]
        elif check:
            lines += [f"Not checked on another seed: {check['why']}.", ""]
        lines += ["Paste into the config:", "", "```yaml", knee["snippet_text"].rstrip(), "```", ""]
    lines += ["## Floors: where a curve stops falling, and why", ""]
    if not document["floors"]:
        lines += ["No curve flattened within these ladders.", ""]
    for floor in document["floors"]:
        lines.append(
            f"- {floor['family']}, {floor['label']}: floor {floor['error_key']} {floor['floor']:.4g} "
            f"(error {floor['error_at_top']:.4g} at {floor['spp']} spp); cause: {floor['cause']}"
        )
    return "\n".join(lines) + "\n"


def html_page(document: dict, rows: list[dict]) -> str:
    """accuracy.md's content as HTML tables (the Snakemake report shows HTML in a frame)."""
    knees = [
        {
            "family": name,
            "configuration": _describe(k["row"]),
            "error": k["error"],
            "stated error": k["stated_error"],
            "stated as": k.get("stated_basis"),
            "seconds": k["row"]["time_s"],
            "best": _describe(k["best"]),
            "best error": k["best"][k["error_key"]],
            "second seed": (document["checks"].get(name) or {}).get("error"),
            "config snippet": k["snippet_text"].strip(),
        }
        for name, k in document["knees"].items()
    ]
    floors = [
        {
            "family": f["family"],
            "configuration": f["label"],
            "floor": f["floor"],
            "error": f["error_at_top"],
            "spp": f["spp"],
            "cause": f["cause"],
        }
        for f in document["floors"]
    ]
    columns = []
    for row in rows:
        columns += [k for k in _flat(row) if k not in columns]
    rate = document["rate"]
    parts = [
        "<!doctype html><html><head><meta charset='utf-8'><title>accuracy</title>",
        "<style>table{border-collapse:collapse;font:12px sans-serif}td,th{border:1px solid #ccc;padding:2px 6px}"
        "td{white-space:pre}</style></head><body>",
        f"<h2>Accuracy against time ({html.escape(document['budget']['name'])} budget)</h2>",
        f"<p>RMSE slope against spp: {rate['slope']:.3f} (Monte Carlo: -0.5). Reference "
        f"{document['reference']['spp']} spp, {document['reference']['bounces']} bounces.</p>",
        "<h3>Knees</h3>",
        html_table(list(knees[0]) if knees else ["family"], knees),
        "<h3>Floors</h3>",
        html_table(["family", "configuration", "floor", "error", "spp", "cause"], floors)
        if floors
        else "<p>No curve flattened.</p>",
        "<h3>Every configuration</h3>",
        html_table(columns, [_flat(r) for r in rows]),
        "</body></html>",
    ]
    return "\n".join(parts) + "\n"
