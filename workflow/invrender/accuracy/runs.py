"""The recovery sweep's training runs (rule recovery_run, `invrender accuracy-run`): one
configuration of a recovery stage trained, baked and scored against the truth, each step by
that stage's own command line (stages talk through files and the CLI, never an import).

    OUT/run.json   source, label, preset, overrides, the inputs, the commands, seconds per step
    OUT/train/     the recovery stage's directory (log.csv, training.json, maps, snapshots/)
    OUT/scene/     the bake stage's scene of the recovered maps
    OUT/score/     the evaluate stage's metrics.json: for MILO every snapshot scored (its
                   "training" table, as evaluate scores the configured run's); for the
                   duplicates material the final maps' appearance (albedo, sky, relighting)

``run.json`` says how to train the configuration again, so the accuracy stage can train its
knee on another seed (``train_and_score`` with other overrides).
"""

from __future__ import annotations

import json
import logging
import subprocess
import sys
import time
from pathlib import Path

from ..scene.atomic import atomic_dir, check_output
from ..scene.types import SceneError, require_positive

log = logging.getLogger(__name__)
RUN_JSON = "run.json"
KIND = "accuracy-run"

# Each recovery stage: the inputs a run needs (NAME=PATH) and its three command lines, built
# from them (``_commands``).
SOURCES = {
    "milo": ("geometry", "cameras", "images", "truth"),
    "duplicates_material": ("geometry", "cameras", "duplicates", "masks", "segmentation", "truth", "images"),
}


def check_inputs(source: str, inputs: dict) -> dict:
    """The source's inputs, each given and existing, as Paths; nothing else."""
    if source not in SOURCES:
        raise SceneError("accuracy-run --source", "source", f"one of {', '.join(SOURCES)}, got {source!r}")
    wanted = SOURCES[source]
    unknown = sorted(set(inputs) - set(wanted))
    if unknown:
        raise SceneError("accuracy-run --input", unknown[0], f"one of {', '.join(wanted)} (a {source} run's inputs)")
    out = {}
    for name in wanted:
        if name not in inputs:
            raise SceneError("accuracy-run --input", name, f"{name}=PATH (a {source} run needs it)")
        path = Path(inputs[name])
        if not path.exists():
            raise SceneError(path, name, f"an existing path (the {source} run's {name})")
        out[name] = path
    return out


def _train_command(source, inputs, out, preset, overrides) -> list[str]:
    sets = [arg for key, value in overrides.items() for arg in ("--set", f"{key}={json.dumps(value)}")]
    if source == "milo":
        where = ["--geometry", inputs["geometry"], "--cameras", inputs["cameras"], "--images", inputs["images"]]
        return ["milo", *where, "--out", out / "train", "--preset", preset, *sets]
    where = [
        "--geometry", inputs["geometry"], "--poses", inputs["duplicates"] / "poses.json",
        "--cameras", inputs["cameras"], "--masks", inputs["masks"],
    ]  # fmt: skip
    return ["duplicates-material", *where, "--out", out / "train", "--preset", preset, *sets]


def _bake_command(source, inputs, out) -> list[str]:
    if source == "milo":
        maps = ["--maps", out / "train" / "maps.npz", "--training", out / "train" / "training.json"]
    else:
        maps = ["--poses", inputs["duplicates"] / "poses.json", "--masks", inputs["masks"], "--material", out / "train"]
    return ["bake", *maps, "--geometry", inputs["geometry"], "--cameras", inputs["cameras"], "--out", out / "scene"]


def _score_command(source, inputs, out, spp, seed) -> list[str]:
    """evaluate on the run's scene; MILO's snapshots scored, its held-out views (from the run's
    own training.json) as novel views."""
    common = ["--out", out / "score", "--spp", str(spp), "--seed", str(seed)]
    if source == "milo":
        settings = json.loads((out / "train" / "training.json").read_text())["settings"]
        holdout = [arg for name in settings.get("holdout", []) for arg in ("--holdout", name)]
        return [
            "evaluate", "--scene", out / "scene", "--truth", inputs["truth"], "--atlas",
            inputs["geometry"] / "atlas.npz", "--images", inputs["images"],
            "--snapshots", out / "train" / "snapshots", *holdout, *common,
        ]  # fmt: skip
    return [
        "evaluate", "--duplicates", inputs["duplicates"], "--segmentation", inputs["segmentation"],
        "--truth", inputs["truth"], "--images", inputs["images"], "--scene", out / "scene",
        "--training", out / "train" / "training.json", *common,
    ]  # fmt: skip


def _invrender(args: list, log_path: Path, device: str | None) -> float:
    """One `invrender` command in a child process (this interpreter's package); its wall seconds.
    A failure raises with the end of its output."""
    command = [sys.executable, "-m", "invrender.cli", "--log", str(log_path), *map(str, args)]
    if device and args[0] != "bake":
        command += ["--device", device]
    t0 = time.perf_counter()
    done = subprocess.run(command, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    if done.returncode != 0:
        tail = "\n".join(done.stdout.splitlines()[-20:])
        raise RuntimeError(f"accuracy-run: `invrender {args[0]}` failed ({done.returncode}):\n{tail}")
    return time.perf_counter() - t0


def train_and_score(
    out_dir,
    source: str,
    inputs: dict,
    preset: str,
    overrides: dict | None = None,
    label: str | None = None,
    spp: int = 4,
    seed: int = 0,
    device: str | None = None,
) -> dict:
    """Train ``source`` with ``preset`` and ``overrides`` on ``inputs`` (SOURCES), bake and score
    it into ``out_dir`` (written whole or not at all); returns run.json's document. ``spp``,
    ``seed``: evaluate's (its renders of the final scene; snapshots at evaluate's own spp)."""
    out_dir = check_output(Path(out_dir), KIND)
    inputs = check_inputs(source, inputs)
    spp = require_positive("accuracy-run --spp", "samples per pixel", spp)
    overrides = dict(overrides or {})
    label = label or out_dir.name
    seconds = {}
    with atomic_dir(out_dir, kind=KIND) as tmp:
        tmp = Path(tmp)
        (tmp / "logs").mkdir()
        seconds["train"] = _invrender(
            _train_command(source, inputs, tmp, preset, overrides), tmp / "logs/train.log", device
        )
        seconds["bake"] = _invrender(_bake_command(source, inputs, tmp), tmp / "logs/bake.log", None)
        seconds["score"] = _invrender(_score_command(source, inputs, tmp, spp, seed), tmp / "logs/score.log", device)
        document = {
            "source": source,
            "label": label,
            "preset": preset,
            "overrides": overrides,
            "inputs": {name: str(path) for name, path in inputs.items()},
            "score": {"spp": spp, "seed": int(seed)},
            "seconds": seconds,
        }
        (tmp / RUN_JSON).write_text(json.dumps(document, indent=1) + "\n")
    log.info("accuracy-run %s: %s (%s)", label, out_dir, ", ".join(f"{k} {v:.1f} s" for k, v in seconds.items()))
    return document


def read_run(run_dir) -> dict:
    """A run directory as the accuracy stage's run entry (stage.run's ``runs``)."""
    run_dir = Path(run_dir)
    path = run_dir / RUN_JSON
    if not path.is_file():
        raise SceneError(path, RUN_JSON, "a recovery run written by `invrender accuracy-run`")
    document = json.loads(path.read_text())
    return {
        "dir": run_dir / "train",
        "metrics": run_dir / "score" / "metrics.json",
        "source": document["source"],
        "label": document["label"],
        "default": False,
        "overrides": document["overrides"],
        "preset": document["preset"],
        "spec": document,
    }
