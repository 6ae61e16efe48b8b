"""`invrender bench duplicates`'s tables from a tiny fake result set (no pipeline run): every
cell is the number of the metrics.json / duplicates.json / steps it names, the paper's Table 2 is
beside the row with the same number of copies, cans get their swing and twist, a stopped row says
why; resume skips a step whose output exists and keeps its recorded time. docs/benchmarks.md
("Structure from Duplicates: poses and shape") has the real run."""

import json
import re
from pathlib import Path
from types import SimpleNamespace

import pytest

from invrender.bench import duplicates as bench
from invrender.bench import run_benchmark
from invrender.scene.types import SceneError


def pose_block(mean, median, trans, evaluated, swing=None, twist=None):
    rotation = {"error_deg": {"mean": mean, "median": median, "max": mean * 2}}
    if swing is not None:
        rotation["symmetry"] = {"swing_deg": {"mean": swing}, "twist_deg": {"mean": twist}}
    return {
        "evaluated": evaluated,
        "rotation": rotation,
        "translation": {"error_fraction_of_diagonal": {"mean": trans, "median": trans}},
    }


def fake_row(scene, variant, swing=None, twist=None):
    metrics = {
        "masks": {"mean_iou": 0.9312},
        "counts": {"truth": 10, "segmented": 11},
        "poses": {
            "before": pose_block(3.25, 2.5, 0.0421, 7, swing, twist),
            "after": pose_block(0.1234, 0.0987, 0.0031, 10, swing and swing / 10, twist and twist / 10),
        },
        "mesh": {"chamfer_fraction_of_diagonal": 0.0275, "icp": {"chamfer_fraction_of_diagonal": 0.0211}},
    }
    solved = {
        "registered_by_colmap": [1, 2, 3, 5, 6, 7, 8],
        "placed": list(range(1, 11)),
        "pairs": [{}] * 55,
        "timings": {"match_and_map_s": 612.5},
    }
    step = lambda s, mb: {"wall_s": s, "cpu_s": s, "peak_rss_mb": mb, "rss_growth_mb": 1.0}
    steps = {
        "cameras": step(1.5, 300.0),
        "segment": step(2.25, 410.0),
        "crop": step(120.0, 1234.0),
        "solve": step(700.0, 980.0),
        "evaluate": None,  # made by another run: untimed
    }
    return {"scene": scene, "variant": variant, "metrics": metrics, "duplicates": solved, "steps": steps}


def test_table_row_takes_each_number_from_its_source():
    line = bench.table_row(fake_row("box-10-hd", "default"))
    assert line["iou"] == 0.9312
    assert line["instances"] == "10/11/7/10"
    assert (line["rot_before_mean"], line["rot_before_median"]) == (3.25, 2.5)
    assert (line["rot_after_mean"], line["rot_after_median"]) == (0.1234, 0.0987)
    assert (line["trans_before_mean"], line["trans_after_mean"]) == (0.0421, 0.0031)
    assert (line["chamfer"], line["chamfer_icp"]) == (0.0275, 0.0211)
    # the paper's Table 2, 10 copies (written out here, not imported)
    assert (line["paper_rot"], line["paper_trans"], line["paper_chamfer"]) == (0.186, 0.003, 0.029)
    assert (line["crop_s"], line["solve_s"], line["evaluate_s"], line["pairs"]) == (120.0, 700.0, None, 55)
    assert line["peak_rss_mb"] == 1234.0  # the largest over the timed steps
    assert line["swing_after_mean"] is None  # a box has no symmetry axis


def test_paper_row_follows_the_number_of_copies():
    for scene, rot in (("box-6-hd", 2.515), ("box-20-ci", 0.299), ("can-20-hd", 0.299)):
        assert bench.table_row(fake_row(scene, "sift"))["paper_rot"] == rot


def test_markdown_has_every_row_cans_split_and_the_stopped_row(tmp_path):
    rows = [fake_row("box-10-hd", "default"), fake_row("can-10-hd", "default", swing=4.5, twist=30.25)]
    stopped = {"scene": "box-10-hd", "variant": "no-rotation-search", "metrics": None, "duplicates": None}
    stopped |= {
        "steps": {},
        "segmented": 11,
        "error": "duplicates: registration: expected COLMAP to register at least 2",
    }
    rows.append(stopped)
    report = {
        "mode": "full",
        "seconds": 12.0,
        "table": [bench.table_row(row) for row in rows],
        "machine": {"cpus": 2},
        "notes": [],
    }
    text = bench.write_markdown(tmp_path, report)
    assert (tmp_path / "duplicates.md").read_text() == text
    main = text.split("### ")[1]
    box = next(line for line in main.splitlines() if line.startswith("| box-10-hd") and "| default" in line)
    cells = [c.strip() for c in box.strip("|").split("|")]
    assert cells[:9] == ["box-10-hd", "default", "0.931", "10/11/7/10", "3.250", "2.500", "0.123", "0.099", "0.186"]
    assert cells[9:] == ["0.0421", "0.0031", "0.003", "0.0275", "0.0211", "0.029"]
    cans = text.split("### ")[2]
    assert cans.startswith("Cans") and "box-10-hd" not in cans
    can = [c.strip() for c in cans.strip().splitlines()[-1].strip("|").split("|")]
    assert can == ["can-10-hd", "default", "4.500", "30.250", "0.450", "3.025", "0.123"]
    cost = text.split("### ")[3]
    first = [c.strip() for c in cost.splitlines()[4].strip("|").split("|")]
    assert first == ["box-10-hd", "default", "1.5", "2.2", "120.0", "55", "612.5", "700.0", "-", "1234"]
    assert re.search(r"STOPPED: box-10-hd no-rotation-search: duplicates: registration", text)
    assert "| no-rotation-search | -        | -/11/-/-" in main  # the segmentation's count without an evaluation


def test_ledger_resumes_with_the_recorded_time(tmp_path):
    calls = []

    def step(path):
        calls.append(path)
        path.mkdir()

    ledger = bench.Ledger(tmp_path)
    first = ledger.run("solve", tmp_path / "out", step, tmp_path / "out")
    assert calls == [tmp_path / "out"] and first["wall_s"] >= 0 and first["peak_rss_mb"] > 0
    again = bench.Ledger(tmp_path).run("solve", tmp_path / "out", step, tmp_path / "out")
    assert calls == [tmp_path / "out"] and again == json.loads(json.dumps(first))
    (tmp_path / "other").mkdir()  # made by another run: skipped, untimed
    assert bench.Ledger(tmp_path).run("evaluate", tmp_path / "other", step, tmp_path / "other") is None


def test_a_stopped_step_is_kept_and_not_run_again(tmp_path):
    calls = []

    def register(path):
        calls.append(path)
        raise SceneError("duplicates", "registration", "COLMAP to register at least 2; it registered 0")

    with pytest.raises(bench.Stopped, match="it registered 0"):
        bench.Ledger(tmp_path).run("solve", tmp_path / "out", register, tmp_path / "out")
    kept = json.loads((tmp_path / "steps.json").read_text())["solve"]
    assert "it registered 0" in kept["error"] and kept["wall_s"] >= 0
    with pytest.raises(bench.Stopped, match="it registered 0"):
        bench.Ledger(tmp_path).run("solve", tmp_path / "out", register, tmp_path / "out")
    assert len(calls) == 1 and not (tmp_path / "out").exists()


def test_scenes_and_variants():
    quick = bench.settings_from(True, None, None, None)
    assert quick.scenes == ["box-6-ci", "can-6-ci"] and all(v == ["default"] for v in quick.variants.values())
    full = bench.settings_from(False, None, None, "work")
    assert full.variants["box-10-hd"] == ["default", "no-rotation-search", "sift", "asift", "provided-asift-refine"]
    assert full.variants["can-20-hd"] == ["provided-asift-refine"]
    chosen = bench.settings_from(False, "box-20-hd,can-6-ci", "sift", None)
    assert chosen.variants == {"box-20-hd": ["sift"], "can-6-ci": ["sift"]}
    with pytest.raises(SceneError, match="variants"):
        bench.settings_from(False, None, "orb", None)
    with pytest.raises(SceneError, match="scenes"):
        bench.settings_from(False, "box-7-hd", None, None)


def test_duplicates_options_refused_elsewhere():
    args = SimpleNamespace(quick=True, out="x", device=None, scenes="box-6-ci")
    with pytest.raises(SceneError, match="--scenes"):
        run_benchmark("milo", args)


def test_a_provided_variant_segments_the_capture_masks_once_and_apart(tmp_path, monkeypatch):
    """A variant with `masks: provided` reads the capture's instance-id image through segment's
    provided backend into its own folder; the opencv backend runs only for a variant that needs it."""
    from invrender.cameras import stage as cameras
    from invrender.segment import stage as segment

    calls = []
    monkeypatch.setattr(cameras, "run", lambda sparse, out, **k: Path(out).mkdir(parents=True))
    monkeypatch.setattr(
        segment, "run", lambda image, out, **k: (calls.append((Path(out).name, k)), Path(out).mkdir(parents=True))
    )
    capture, scene_dir = tmp_path / "capture", tmp_path / "box-20-hd"
    sources = {bench.mask_source(v) for v in ("provided-tracks-subpixel", "provided-track-search")}
    bench.shared_steps(capture, scene_dir, bench.Ledger(scene_dir), sources)
    masks = capture / "ground_truth" / "masks" / "view_000.png"
    assert calls == [("segmentation-provided", {"backend": "provided", "masks": masks})]
    assert bench.segmentation_of(scene_dir, "provided-track-search") == scene_dir / "segmentation-provided"
    assert bench.segmentation_of(scene_dir, "tracks-subpixel") == scene_dir / "segmentation"
    calls.clear()
    bench.shared_steps(capture, scene_dir, bench.Ledger(scene_dir), {"opencv", "provided"})
    assert calls == [("segmentation", {})]  # the provided one exists: resumed, not run again
