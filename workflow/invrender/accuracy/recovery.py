"""Recovery: what the training runs already recorded, as error against training time.

Nothing is trained here (runs.py trains the sweep's runs, each a job of its own). A training
run is a directory holding
- ``log.csv``: one row per iteration with at least ``iteration``, ``wall_time`` (seconds since
  the start) and a loss column (MILO's ``image``: the photometric loss on its ray batch);
- ``training.json`` (optional): ``{"preset": ..., "settings": {...}}``, the knobs of the run;
and, where a synthetic scene's truth scored its snapshots, the evaluate stage's training table
(metrics.json ``training``: per snapshot its iteration, wall time, light maps MSE, material MSE
and novel-view PSNR), which is then the error. MILO's `milo_train` writes such a directory
(results/{scene}/milo/); any other recovery stage that writes the same two files plugs in as it
is (``SOURCES`` names the loss column each stage's log.csv carries).
"""

from __future__ import annotations

import csv
import json
from pathlib import Path

from ..scene.types import SceneError

# The recovery stages and the column of their log.csv that is their loss.
SOURCES = {"milo": "image", "duplicates_material": "image"}
# The knobs of a run, from its training.json's settings (the preset, network size,
# rays per batch and iterations, with the path tracer's spp and bounces).
KNOBS = ("layers", "width", "rays", "spp", "max_bounces", "iterations", "materials")
LOG_BINS = 8  # a run without scored snapshots: its loss averaged over this many stretches


def read_log(path) -> list[dict]:
    path = Path(path)
    if not path.is_file():
        raise SceneError(path, "log.csv", "a training log (iteration, wall_time and a loss per row)")
    with open(path, newline="") as handle:
        rows = list(csv.DictReader(handle))
    for column in ("iteration", "wall_time"):
        if rows and column not in rows[0]:
            raise SceneError(path, column, f"a column {column!r}")
    return rows


def run_settings(run_dir) -> dict:
    path = Path(run_dir) / "training.json"
    if not path.is_file():
        return {"preset": None, "settings": {}}
    document = json.loads(path.read_text())
    return {"preset": document.get("preset"), "settings": document.get("settings", {})}


def _knobs(run: dict, source: str, label: str) -> dict:
    settings = run["settings"]
    return {
        "family": "recovery",
        "sweep": source,
        "label": label,
        "preset": run["preset"],
        **{k: settings.get(k) for k in KNOBS},
    }


def scored_rows(table: list[dict], run: dict, source: str, label: str) -> list[dict]:
    """One row per scored snapshot (evaluate's training table); material MSE is the error."""
    rows = []
    for entry in table:
        psnr = entry.get("novel_view_psnr_db")
        rows.append(
            {
                **_knobs(run, source, label),
                "iteration": int(entry["iteration"]),
                "time_s": float(entry["wall_time_s"]),
                "recovery_error": float(entry["material_mse"]),
                "error_name": "material MSE",
                "material_mse": float(entry["material_mse"]),
                "light_maps_mse": float(entry["light_maps_mse"]),
                "novel_view_psnr_db": psnr,
                "novel_view_mse": None if psnr is None else 10 ** (-psnr / 10),
            }
        )
    return rows


def appearance_rows(metrics: dict, run: dict, training: dict, source: str, label: str) -> list[dict]:
    """A duplicates material run scored by evaluate (its final maps, metrics.json's
    "appearance"): one row, the albedo's MSE the error (10^(-PSNR/10) of SfD's scaled, gamma
    encoded albedo), the sky's MSE and relighting beside; none without an albedo score."""
    ours = ((metrics.get("appearance") or {}).get("table1") or {}).get("ours") or {}
    if ours.get("albedo_psnr_db") is None:
        return []
    relit = ours.get("relighting_psnr_db")
    return [
        {
            **_knobs(run, source, label),
            "iteration": int(training.get("iterations", run["settings"].get("iterations", 0))),
            "time_s": float(training["training_seconds"]),
            "recovery_error": 10 ** (-ours["albedo_psnr_db"] / 10),
            "error_name": "albedo MSE (10^(-PSNR/10))",
            "albedo_psnr_db": ours["albedo_psnr_db"],
            "env_mse": ours.get("env_mse"),
            "relighting_psnr_db": relit,
            "relighting_mse": None if relit is None else 10 ** (-relit / 10),
        }
    ]


def log_rows(log: list[dict], run: dict, source: str, label: str, loss_column: str) -> list[dict]:
    """Without a truth: the training loss, averaged over LOG_BINS stretches of the run (one
    iteration's loss is one ray batch's, too noisy to read a curve from)."""
    if not log:
        return []
    if loss_column not in log[0]:
        raise SceneError("log.csv", loss_column, f"the loss column of a {source} log")
    size = max(1, len(log) // LOG_BINS)
    rows = []
    for start in range(0, len(log) - size + 1, size):
        stretch = log[start : start + size]
        loss = sum(float(r[loss_column]) for r in stretch) / len(stretch)
        rows.append(
            {
                **_knobs(run, source, label),
                "iteration": int(stretch[-1]["iteration"]),
                "time_s": float(stretch[-1]["wall_time"]),
                "recovery_error": loss,
                "error_name": f"training loss ({loss_column})",
            }
        )
    return rows


def run_rows(
    run_dir,
    metrics_path=None,
    source: str = "milo",
    label: str = "configured",
    default: bool = True,
    overrides: dict | None = None,
    preset: str | None = None,
) -> list[dict]:
    """The rows of one training run: scored snapshots when ``metrics_path`` (evaluate's
    metrics.json) has a training table, the final maps' appearance for a duplicates run, else
    its log's loss. ``default``: this is the configured run, whose last row is the configured
    default. ``overrides`` (and ``preset``, where the run changed it): the config that selects
    this run (the knee's snippet), for a variant run."""
    run = run_settings(run_dir)
    metrics = {}
    if metrics_path is not None and Path(metrics_path).is_file():
        metrics = json.loads(Path(metrics_path).read_text())
    rows = []
    if metrics.get("training"):
        rows = scored_rows(metrics["training"], run, source, label)
    elif metrics.get("appearance"):
        training = json.loads((Path(run_dir) / "training.json").read_text())
        rows = appearance_rows(metrics, run, training, source, label)
    if not rows:
        rows = log_rows(read_log(Path(run_dir) / "log.csv"), run, source, label, SOURCES.get(source, "image"))
    for row in rows:
        row["default"] = False
        row["overrides"] = overrides or {}
        row["snippet_preset"] = preset
        row["pasteable"] = True
        row["cause"] = None
    if rows and default:
        rows[-1]["default"] = True
    return rows
