"""The recovery sweep's runs as the accuracy stage reads them (run.json, the scored snapshots, a
duplicates run's appearance), and the knee trained again on another seed: what is trained, and
the verdict against the error the knee states. Hand-made runs; the training is a stand-in that
writes what `invrender accuracy-run` writes (tests/workflow trains for real)."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from invrender.accuracy import front, recovery, runs, stage
from invrender.scene.types import SceneError


def write_run(out: Path, label: str, errors: dict, seconds_per_iteration: float, settings: dict, preset="demo"):
    """A run directory as runs.train_and_score leaves it: run.json, train/, score/metrics.json
    with evaluate's training table (``errors``: iteration -> material MSE)."""
    (out / "train").mkdir(parents=True)
    (out / "score").mkdir()
    (out / "train" / "training.json").write_text(json.dumps({"preset": preset, "settings": settings}))
    (out / "train" / "log.csv").write_text("iteration,wall_time,image\n1,0.1,1\n")
    table = [
        {
            "iteration": i,
            "wall_time_s": i * seconds_per_iteration,
            "material_mse": e,
            "light_maps_mse": 2 * e,
            "novel_view_psnr_db": 20.0,
        }
        for i, e in errors.items()
    ]
    (out / "score" / "metrics.json").write_text(json.dumps({"training": table}))
    spec = {
        "source": "milo",
        "label": label,
        "preset": preset,
        "overrides": {k: v for k, v in settings.items() if k in ("rays", "iterations")},
        "inputs": {"geometry": "g", "cameras": "c", "images": "i", "truth": "t"},
        "score": {"spp": 4, "seed": 0},
        "seconds": {},
    }
    (out / runs.RUN_JSON).write_text(json.dumps(spec))
    return runs.read_run(out)


@pytest.fixture
def sweep(tmp_path):
    """Two runs: 8192 rays (better, slower) and 2048 (within 2x of it, four times cheaper)."""
    settings = {"rays": 8192, "iterations": 30, "seed": 5, "layers": 3, "width": 64, "holdout": ["v.exr"]}
    big = write_run(tmp_path / "milo", "milo", {10: 0.04, 20: 0.03, 30: 0.02}, 4.0, settings)
    small = write_run(tmp_path / "milo-rays2048", "milo-rays2048", {10: 0.05, 20: 0.035, 30: 0.033}, 1.0,
                      settings | {"rays": 2048})  # fmt: skip
    rows = []
    for run in (big, small):
        rows += recovery.run_rows(run["dir"], run["metrics"], run["source"], run["label"], False, run["overrides"])
    knee = front.state_training_error(front.knee(stage._scored(rows), "recovery_error"))
    return [big, small], knee


def fake_training(error: float, calls: list):
    """Stands in for runs.train_and_score: records what it was asked to train, writes a run
    whose last snapshot scores ``error``."""

    def train(out, source, inputs, preset, overrides, label=None, spp=4, seed=0, device=None):
        calls.append({"source": source, "inputs": inputs, "preset": preset, "overrides": overrides, "spp": spp})
        write_run(Path(out), label, {overrides["iterations"]: error}, 1.0, overrides, preset)
        return {"seconds": {"train": 1.0}}

    return train


def test_the_knee_is_the_cheap_run_and_its_snippet_selects_it(sweep):
    _, knee = sweep
    row = knee["row"]
    assert (row["label"], row["iteration"]) == ("milo-rays2048", 20)  # 0.035 <= 2 x 0.02, in 20 s
    assert front.snippet(row) == {"milo": {"overrides": {"rays": 2048, "iterations": 20}}}
    # the scene's held-out views are its own setting, not pasted into milo's
    assert front.snippet(row | {"overrides": {"holdout": ["v.exr"]}}) == {"milo": {"overrides": {"iterations": 20}}}


def test_a_training_knee_states_at_least_the_bound_it_was_chosen_by(sweep):
    _, knee = sweep
    assert knee["stated_error"] == pytest.approx(0.035 * 1.25)  # above 2 x 0.02
    row = knee["row"] | {"recovery_error": 0.03}  # plus 25 %: 0.0375, below 2 x 0.02
    looser = front.state_training_error(front.knee([knee["best"], row], "recovery_error"))
    assert looser["stated_error"] == pytest.approx(2 * 0.02) and "2x of the best" in looser["stated_basis"]


def test_knee_trained_again_on_another_seed_meets_its_stated_error(sweep, monkeypatch):
    entries, knee = sweep
    calls = []
    monkeypatch.setattr(runs, "train_and_score", fake_training(0.9 * knee["stated_error"], calls))
    check = stage._check_recovery(entries, knee, device=None)
    assert check["checked"] and check["met"] and check["iteration"] == 20
    assert check["error"] == pytest.approx(0.9 * knee["stated_error"])
    (call,) = calls
    # the knee's run as it was trained (every setting, the preset), for the knee's iterations, on
    # another seed, with the inputs and the score of the sweep's runs
    assert call["preset"] == "demo" and call["inputs"] == entries[1]["spec"]["inputs"] and call["spp"] == 4
    assert call["overrides"]["rays"] == 2048 and call["overrides"]["holdout"] == ["v.exr"]
    assert call["overrides"]["iterations"] == 20 and call["overrides"]["seed"] == 5 + stage.CHECK_SEED


def test_a_knee_that_misses_its_stated_error_on_another_seed_is_reported(sweep, monkeypatch):
    entries, knee = sweep
    monkeypatch.setattr(runs, "train_and_score", fake_training(1.1 * knee["stated_error"], []))
    check = stage._check_recovery(entries, knee, device=None)
    assert check["checked"] and not check["met"]
    knee["snippet_text"] = front.snippet_text(front.snippet(knee["row"]))
    text = stage.markdown(
        {
            "budget": {"name": "quick"},
            "scene": "s",
            "camera": {"name": "v", "width": 1, "height": 1},
            "device": "d",
            "reference": {"spp": 1, "bounces": 1, "noise_rmse": 0.0},
            "rate": {"slope": -0.5, "expected": -0.5},
            "knees": {"recovery": knee},
            "checks": {"recovery": check},
            "floors": [],
        }
    )
    assert f"by training it again with seed {5 + stage.CHECK_SEED}" in text and "(NOT met)" in text


def test_without_a_sweep_run_the_knee_is_not_checked(sweep, tmp_path):
    entries, knee = sweep
    configured = dict(entries[1], spec=None)
    assert stage._check_recovery([configured], knee, device=None)["checked"] is False


def test_a_duplicates_run_is_scored_by_its_albedo(tmp_path):
    (tmp_path / "training.json").write_text(
        json.dumps(
            {"preset": "ci", "settings": {"rays": 2048, "iterations": 20}, "iterations": 20, "training_seconds": 7.5}
        )
    )
    (tmp_path / "log.csv").write_text("iteration,wall_time,image\n1,0.1,1\n")
    ours = {"albedo_psnr_db": 20.0, "env_mse": 0.01, "relighting_psnr_db": 30.0}
    (tmp_path / "metrics.json").write_text(json.dumps({"appearance": {"table1": {"ours": ours}}}))
    (row,) = recovery.run_rows(tmp_path, tmp_path / "metrics.json", "duplicates_material", "dup", False, {"rays": 2048})
    assert row["recovery_error"] == pytest.approx(0.01) and row["relighting_mse"] == pytest.approx(0.001)
    assert (row["iteration"], row["time_s"], row["rays"]) == (20, 7.5, 2048)
    assert front.snippet(row) == {"duplicates_material": {"overrides": {"rays": 2048, "iterations": 20}}}
    # a training loss is another quantity: the knee compares the scored rows only
    loss = recovery.run_rows(tmp_path, None, "duplicates_material", "configured")
    assert stage._scored(loss + [row]) == [row]


def test_a_run_with_missing_inputs_is_refused_before_any_work(tmp_path):
    with pytest.raises(SceneError, match="truth"):
        runs.train_and_score(tmp_path / "run", "milo", {"geometry": tmp_path, "cameras": tmp_path, "images": tmp_path},
                             "demo")  # fmt: skip
    with pytest.raises(SceneError, match="source"):
        runs.train_and_score(tmp_path / "run", "nerf", {}, "demo")
    assert not (tmp_path / "run").exists()
