"""Whole runs of the toy config: what re-runs when the config changes, the report, and a run
killed halfway then resumed."""

from __future__ import annotations

import base64
import csv
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
import yaml
from workflow_helpers import (
    FULL_RUN_JOBS,
    LOCAL_PROFILE,
    SNAKEFILE,
    TEST_CONFIG,
    job_counts,
    ran_jobs,
    read_json,
    snakemake,
    snakemake_env,
)

_SHARED = {
    "capture": "synthesize",
    "cameras": "cameras",
    "geometry": "geometry",
    "gradients": "gradients",
    "features.json": "features",
    "renders": "render",
    "export": "export",
    "accuracy": "accuracy",
    "summary": "summary",
}
# Each scene's outputs and the rule that writes each: the room (multiview) is recovered by MILO,
# the boxes (duplicates) from their one photograph.
RULE_OF_OUTPUT = {
    "room": {
        **_SHARED,
        "milo/weights.pt": "milo_train",
        "scene": "bake",
        "report": "evaluate",
        "edits": "edit",
        # the recovery sweep of the test config (accuracy.recovery.quick), a job per run
        **dict.fromkeys((f"accuracy_runs/{run}" for run in ("milo", "milo-layers3-width32")), "recovery_run"),
    },
    "boxes": {
        **{k: v for k, v in _SHARED.items() if k != "gradients"},
        "segmentation": "segment",
        "duplicates": "duplicates",
        "material/maps.npz": "duplicates_material",
        "scene": "bake_duplicates",
        "report": "evaluate_duplicates",
        "accuracy_runs/duplicates-material-iterations2": "recovery_run",
    },
}


@pytest.fixture(scope="module")
def complete(tmp_path_factory):
    """A working directory where the whole toy workflow has run."""
    workdir = tmp_path_factory.mktemp("complete")
    # 20 minutes: the recovery sweep's three runs and two checks train, bake and score as well
    # (about a minute and a half of CPU more); the wall time follows the machine's load, and at
    # load 20 the whole run took more than 15 minutes
    result = snakemake(workdir, "--workflow-profile", LOCAL_PROFILE, timeout=1200)
    assert job_counts(result.stdout) == FULL_RUN_JOBS  # the plan before the checkpoint
    instances = read_json(workdir / "results/boxes/segmentation/instances.json")["instances"]
    assert len(instances) >= 3
    assert ran_jobs(result.stdout) == FULL_RUN_JOBS | {"duplicates_crop": len(instances)}
    return workdir


def test_nothing_to_do_after_a_complete_run(complete):
    result = snakemake(complete, "-n")
    assert job_counts(result.stdout) == {}
    assert "Nothing to be done" in result.stdout


def test_changing_target_faces_reruns_geometry_and_what_follows(complete, tmp_path):
    override = tmp_path / "faces.yaml"
    override.write_text(yaml.safe_dump({"geometry": {"target_faces": 1000}}))
    result = snakemake(complete, "-n", config=[TEST_CONFIG, override])
    # Downstream of geometry: the room's gradients, recovery and all that reads them, and the
    # boxes' scene baked on the new mesh and what reads it (evaluate_duplicates scores its
    # appearance); segment and duplicates (upstream of geometry) do not run again.
    assert job_counts(result.stdout) == RERUN_AFTER_GEOMETRY
    assert "Params have changed since last execution" in result.stdout
    # The same through --config, as one would type it.
    result = snakemake(complete, "-n", "--config", "geometry={target_faces: 1000}")
    assert job_counts(result.stdout) == RERUN_AFTER_GEOMETRY


RERUN_AFTER_GEOMETRY = {
    "geometry": 2,
    **dict.fromkeys(("gradients", "milo_train", "duplicates_material", "bake", "bake_duplicates", "evaluate"), 1),
    **dict.fromkeys(("evaluate_duplicates", "edit"), 1),
    "recovery_run": 3,  # every run trains on the geometry
    **dict.fromkeys(("features", "render", "export", "accuracy", "summary"), 2),
    "all": 1,
}


def test_changing_render_spp_reruns_render_only(complete, tmp_path):
    """... and the accuracy sweep, whose highlighted default is the configured spp, and the
    summary that times them."""
    override = tmp_path / "spp.yaml"
    override.write_text(yaml.safe_dump({"render": {"spp": 8}}))
    result = snakemake(complete, "-n", config=[TEST_CONFIG, override])
    assert job_counts(result.stdout) == {"render": 2, "accuracy": 2, "summary": 2, "all": 1}


def test_recovery_sweep_trains_each_run_and_the_knee_meets_its_error_on_a_second_seed(complete):
    """Each configuration of the test config's recovery sweep is a run of its own, scored against
    the truth and plotted; the recovery knee, trained again with another seed for its
    iterations, meets the error it states (issue 15: "the knee recommendation, applied, meets its
    stated error on a second seed")."""
    for scene, outputs in RULE_OF_OUTPUT.items():
        labels = {name.split("/")[1] for name, rule in outputs.items() if rule == "recovery_run"}
        for label in labels:
            run = read_json(complete / f"results/{scene}/accuracy_runs/{label}/run.json")
            assert run["label"] == label and (complete / f"results/{scene}/accuracy_runs/{label}/score").is_dir()
        with open(complete / f"results/{scene}/accuracy/accuracy_vs_time.csv", newline="") as handle:
            rows = [row for row in csv.DictReader(handle) if row["family"] == "recovery"]
        assert labels < {row["label"] for row in rows}  # and the configured run
        assert all(row["recovery_error"] and not row["error_name"].startswith("training loss") for row in rows)
        document = read_json(complete / f"results/{scene}/accuracy/accuracy.json")
        knee, check = document["knees"]["recovery"], document["checks"]["recovery"]
        assert (
            check["checked"]
            and check["seed"]
            != read_json(complete / f"results/{scene}/accuracy_runs/{sorted(labels)[0]}/train/training.json")[
                "settings"
            ]["seed"]
        )
        assert check["iteration"] == knee["row"]["iteration"]
        # the knee's error plus 25 %, or within 2x of the best if that is larger (a training
        # run's spread over seeds is not known from one seed: front.state_training_error)
        best = knee["best"]["recovery_error"]
        assert check["stated_error"] == knee["stated_error"] == pytest.approx(max(knee["error"] * 1.25, 2 * best))
        assert check["error"] <= check["stated_error"], (scene, knee["row"]["label"], check)
        assert check["met"]
        assert (
            "Checked by training it again with seed" in (complete / f"results/{scene}/accuracy/accuracy.md").read_text()
        )


def test_unknown_device_keeps_the_built_capture(complete):
    """Issue 10, defect 7, as reported: on a built demo `--config device=NoSuchGPU` re-ran
    synthesize (its params changed), whose job failed after snakemake had deleted the capture.
    Now it stops before any job, and the capture is the one that was built."""
    capture = complete / "results" / "room" / "capture"
    before = {p: (p.stat().st_mtime_ns, p.read_bytes()) for p in sorted(capture.rglob("*")) if p.is_file()}
    result = snakemake(complete, "--cores", "1", "--config", "device=NoSuchGPU", check=False)
    assert result.returncode != 0
    assert "config: device: no OpenCL device matches 'NoSuchGPU'; available: " in result.stdout, result.stdout
    assert {p: (p.stat().st_mtime_ns, p.read_bytes()) for p in sorted(capture.rglob("*")) if p.is_file()} == before
    assert job_counts(snakemake(complete, "-n").stdout) == {}


def test_report_shows_the_renders(complete):
    report = complete / "report.html"
    snakemake(complete, "--report", report)
    html = report.read_text(errors="replace")
    assert "Renders" in html and "Geometry" in html and "Features" in html and "Export" in html
    for view in ("view_000.png", "view_001.png", "features.json", "geometry.json", "export.json"):
        assert view in html
    # the duplicates scene's figures: the segmentation, the recovered poses, the outlines
    assert "Segmentation" in html and "Duplicates" in html
    assert "overlay.png" in html and "outlines_view_000.png" in html


def _mtimes(workdir: Path, outputs_of: dict = RULE_OF_OUTPUT) -> dict[str, float]:
    """Modification times of the stage outputs that exist, by path relative to workdir."""
    return {
        str(path.relative_to(workdir)): path.stat().st_mtime
        for scene, outputs in outputs_of.items()
        for name in outputs
        if (path := workdir / "results" / scene / name).exists()
    }


def _marked_incomplete(workdir: Path) -> set[str]:
    """Outputs Snakemake marks incomplete: files under .snakemake/incomplete/ named by the
    urlsafe base64 of the output path (long names split into '@'-prefixed parts)."""
    root = workdir / ".snakemake" / "incomplete"
    marked = set()
    for record in root.rglob("*") if root.exists() else []:
        if record.is_file() and record.name != "migration_underway":
            parts = [p.lstrip("@") for p in record.relative_to(root).parts]
            marked.add(base64.urlsafe_b64decode("".join(parts)).decode())
    return marked


def _leftovers(workdir: Path) -> list[str]:
    temporary = [str(p.relative_to(workdir)) for p in (workdir / "results").rglob("*.tmp-*")]
    incomplete = workdir / ".snakemake" / "incomplete"
    markers = [p.name for p in incomplete.iterdir()] if incomplete.exists() else []
    return temporary + markers


def test_killed_run_resumes_without_redoing_finished_work(tmp_path):
    """Ctrl-C (SIGINT to the process group) while a downstream job runs, then run again. On the
    room alone: what is tested is Snakemake's bookkeeping around a killed job, the same for both
    modes, and the boxes' chain would double the test's time (the complete run covers them)."""
    config = tmp_path / "room.yaml"
    test_config = yaml.safe_load(TEST_CONFIG.read_text())
    config.write_text(yaml.safe_dump(dict(test_config, scenes={"room": test_config["scenes"]["room"]})))
    outputs_of = {"room": RULE_OF_OUTPUT["room"]}
    cmd = [
        sys.executable,
        "-m",
        "snakemake",
        "-s",
        str(SNAKEFILE),
        "--directory",
        str(tmp_path),
        "--configfile",
        str(config),
        "--workflow-profile",
        str(LOCAL_PROFILE),
    ]
    with open(tmp_path / "first.log", "w") as log:
        process = subprocess.Popen(
            cmd, stdout=log, stderr=subprocess.STDOUT, env=snakemake_env(), start_new_session=True
        )
        try:
            deadline = time.monotonic() + 300
            # features runs after the capture and the scene it reads: wait until one starts.
            while not list(tmp_path.glob("results/*/logs/features.log")):
                assert process.poll() is None, (tmp_path / "first.log").read_text()[-3000:]
                assert time.monotonic() < deadline, "no features job started"
                time.sleep(0.02)
            os.killpg(process.pid, signal.SIGINT)
            assert process.wait(timeout=120) != 0
        finally:
            if process.poll() is None:
                os.killpg(process.pid, signal.SIGKILL)
    killed = [p.parent.parent.name for p in tmp_path.glob("results/*/logs/features.log")]
    assert all((tmp_path / "results" / scene / "capture").is_dir() for scene in killed)
    assert not list(tmp_path.glob("results/*/*.tmp-*"))  # the killed job left no partial output
    # An output whose job was still marked incomplete when the kill came (its stage had
    # renamed it into place, Snakemake had not yet recorded the job as done) is not finished
    # work: --rerun-incomplete rightly runs it again.
    unconfirmed = _marked_incomplete(tmp_path)
    before = {path: mtime for path, mtime in _mtimes(tmp_path, outputs_of).items() if path not in unconfirmed}
    assert before, "nothing had finished before the kill"

    result = snakemake(tmp_path, "--workflow-profile", LOCAL_PROFILE, config=config)
    # Exactly the jobs whose outputs were missing run again, the killed one among them.
    expected = {}
    for scene, outputs in outputs_of.items():
        for name, rule in outputs.items():
            if f"results/{scene}/{name}" not in before:
                expected[rule] = expected.get(rule, 0) + 1
    assert "features" in expected
    assert job_counts(result.stdout) == expected | {"all": 1}
    after = _mtimes(tmp_path, outputs_of)
    assert {path: after[path] for path in before} == before  # nothing finished was redone
    assert set(after) == {f"results/{s}/{name}" for s, outputs in outputs_of.items() for name in outputs}
    assert _leftovers(tmp_path) == []
    assert job_counts(snakemake(tmp_path, "-n", config=config).stdout) == {}


# What the report must show of each scene of the toy config: the input, recovered maps, renders,
# edits, the metrics beside the papers', the accuracy plots and tables, time and memory per rule.
REPORT_FIGURES = {
    "room": {
        "view_000.png",  # the capture and the renders
        "maps_kd.png",  # recovered maps against the truth
        "accuracy_forward.png",
        "accuracy_gradients.png",
        "accuracy_recovery.png",
        "accuracy.html",
        "metrics.html",
        "runtime.html",
        "runtime.png",
    },
    "boxes": {
        "overlay.png",
        "outlines_view_000.png",
        "accuracy_forward.png",
        "accuracy_recovery.png",  # the material stage's training log
        "accuracy.html",
        "metrics.html",
        "runtime.html",
        "runtime.png",
    },
}


@pytest.fixture(scope="module")
def report_html(complete):
    report = complete / "report.html"
    if not report.exists():
        snakemake(complete, "--report", report)
    return report


def test_report_in_a_browser_loads_every_image_and_table(report_html):
    from report_browser import report_problems

    assert report_problems(report_html, REPORT_FIGURES) == []


def test_report_check_fails_without_a_figure(report_html, tmp_path):
    """The same check on copies of the report: one figure dropped, one image's bytes broken."""
    from report_browser import edit_results, report_problems

    def drop(results):
        del results[next(p for p in results if p.endswith("room/accuracy/accuracy_forward.png"))]

    def corrupt(results):
        entry = next(r for p, r in results.items() if p.endswith("boxes/accuracy/accuracy_forward.png"))
        entry["data_uri"] = entry["data_uri"][:60] + "AAAA" + entry["data_uri"][-60:]

    problems = report_problems(edit_results(report_html, tmp_path / "dropped.html", drop), REPORT_FIGURES)
    assert problems == ["missing from the report: results/room/.../accuracy_forward.png"]
    problems = report_problems(edit_results(report_html, tmp_path / "corrupt.html", corrupt), REPORT_FIGURES)
    assert len(problems) == 1 and problems[0].startswith("image does not load:") and "boxes" in problems[0]
