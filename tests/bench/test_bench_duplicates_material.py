"""`invrender bench duplicates-material`'s tables from a tiny fake result set (no stage runs):
every cell is the number of the metrics.json / training.json / steps it names, the paper's Table 1
single-view column and Table 2's row of the same number of copies are beside it, true and
recovered poses sit side by side, a stopped row says why; the row's chain resumes (a material
folder without training.json is a killed run, resumed, not skipped). docs/benchmarks.md
("Structure from Duplicates: material and light") has the real run."""

import json
from pathlib import Path
from types import SimpleNamespace

import pytest

from invrender.bench import duplicates_material as bench
from invrender.bench import run_benchmark
from invrender.scene.types import SceneError


def metrics(albedo, roughness, relight, env, rotation=None):
    ours = {"albedo_psnr_db": albedo, "roughness_mse": roughness, "relighting_psnr_db": relight, "env_mse": env}
    return {
        "poses": {"after": {"rotation": None if rotation is None else {"error_deg": {"mean": rotation}}}},
        "mesh": {"chamfer_fraction_of_diagonal": 0.0123},
        "appearance": {
            "table1": {"ours": ours},
            "relighting": {"noise_floor_psnr_db": 24.5},
            "support": {"albedo": {"psnr_db": 19.75}},
        },
    }


def step(seconds, mb):
    return {"wall_s": seconds, "cpu_s": seconds, "peak_rss_mb": mb, "rss_growth_mb": 1.0}


def fake_row(scene, poses, ours, start, rotation=None, timed=True):
    steps = {"cameras": step(0.5, 200.0), "inputs": step(12.5, 600.0), "bake": step(3.25, 900.0)}
    if timed:
        steps["material"] = step(700.0, 1500.0)
    steps["evaluate"] = None  # made by another run: untimed
    return {
        "scene": scene,
        "poses": poses,
        "error": None,
        "steps": steps,
        "metrics": metrics(*ours, rotation=rotation),
        "first_guess": metrics(*start, rotation=rotation),
        "training": {"iterations": 300, "training_seconds": 640.0, "peak_memory_mb": 1600.0},
    }


def test_table_row_takes_each_number_from_its_source():
    line = bench.table_row(fake_row("box-10-hd", "truth", (21.5, 0.04, 26.5, 0.05), (17.8, 0.05, 24.0, 0.3)))
    assert (line["albedo_psnr_db"], line["roughness_mse"], line["relighting_psnr_db"], line["env_mse"]) == (
        21.5, 0.04, 26.5, 0.05,
    )  # fmt: skip
    assert (line["albedo_psnr_db_first_guess"], line["env_mse_first_guess"]) == (17.8, 0.3)
    # the paper, written out here (not imported): Table 1 single view, Table 2's colour box of 10 copies
    assert (line["albedo_psnr_db_paper"], line["roughness_mse_paper"]) == (17.629, 0.062)
    assert (line["relighting_psnr_db_paper"], line["env_mse_paper"]) == (21.374, 0.052)
    assert (line["albedo_psnr_db_paper_copies"], line["roughness_mse_paper_copies"]) == (18.99, 0.09)
    assert line["env_mse_paper_copies"] == 0.204 and line["relighting_psnr_db_paper_copies"] is None
    assert line["relighting_noise_floor_db"] == 24.5 and line["chamfer"] == 0.0123
    assert (line["training_s"], line["material_s"], line["bake_s"], line["evaluate_s"]) == (640.0, 700.0, 3.25, None)
    assert line["material_peak_mb"] == 1500.0 and line["peak_rss_mb"] == 1500.0  # the largest timed step
    assert line["better_than_paper"] == "4/4"  # env 0.05 < 0.052 just


def test_paper_row_follows_the_number_of_copies_and_verdict_counts_columns():
    for scene, albedo, env in (("box-6-hd", 18.48, 0.116), ("box-20-ci", 19.22, 0.063)):
        line = bench.table_row(fake_row(scene, "truth", (17.0, 0.07, 22.0, 0.06), (15.0, 0.1, 20.0, 0.3)))
        assert (line["copies"], line["albedo_psnr_db_paper_copies"], line["env_mse_paper_copies"]) == (
            int(scene.split("-")[1]), albedo, env,
        )  # fmt: skip
        assert line["better_than_paper"] == "1/4"  # relighting alone: 22.0 > 21.374


def test_untimed_material_takes_the_stage_own_peak():
    line = bench.table_row(fake_row("box-10-hd", "truth", (21.5, 0.04, 26.5, 0.05), (17.8, 0.05, 24, 0.3), timed=False))
    assert line["material_s"] is None and line["material_peak_mb"] == 1600.0 and line["peak_rss_mb"] == 1600.0


def cells(table: str, starts: str) -> list[str]:
    row = next(line for line in table.splitlines() if line.startswith(starts))
    return [c.strip() for c in row.strip("|").split("|")]


def test_markdown_has_the_paper_beside_the_poses_side_by_side_and_the_stopped_row(tmp_path):
    rows = [
        fake_row("box-10-hd", "truth", (21.5, 0.04, 26.5, 0.05), (17.8, 0.05, 24.0, 0.3)),
        fake_row("box-10-hd", "recovered", (9.25, 0.08, 18.0, 0.4), (8.5, 0.09, 17.5, 0.5), rotation=62.5),
    ]
    stopped = {"scene": "box-20-hd", "poses": "recovered", "metrics": None, "first_guess": None, "training": None}
    rows.append(stopped | {"steps": {}, "error": "duplicates: registration: expected at least 2"})
    report = {
        "mode": "full",
        "seconds": 12.0,
        "settings": {"material_preset": "default", "evaluate_spp": 16},
        "table": [bench.table_row(row) for row in rows],
        "machine": {"cpus": 2},
        "notes": [],
    }
    text = bench.write_markdown(tmp_path, report)
    assert (tmp_path / "duplicates_material.md").read_text() == text
    main, poses, cost = text.split("### ")[1:4]
    assert cells(main, "| box-10-hd | truth")[2:] == [
        "21.50", "17.80", "17.63", "18.99", "0.040", "0.050", "0.062", "0.09",
        "26.50", "24.00", "21.37", "24.50", "0.050", "0.300", "0.052", "0.204", "4/4",
    ]  # fmt: skip
    assert cells(main, "| box-20-hd | recovered")[2:5] == ["-", "-", "17.63"]
    assert poses.startswith("What pose error costs")
    assert cells(poses, "| box-10-hd") == [
        "box-10-hd", "62.5", "21.50", "9.25", "0.040", "0.080", "26.50", "18.00", "0.050", "0.400",
    ]  # fmt: skip
    assert "box-20-hd" not in poses  # no numbers on either side
    assert cells(cost, "| box-10-hd | truth") == [
        "box-10-hd", "truth", "300", "640", "12.5", "700", "3.2", "-", "1500", "1500",
    ]  # fmt: skip
    assert "STOPPED: box-20-hd recovered: duplicates: registration" in text


def test_the_chain_resumes_and_a_killed_material_run_is_resumed(tmp_path, monkeypatch):
    from invrender.bake import duplicates as bake
    from invrender.duplicates_material import stage as material
    from invrender.evaluate import stage as evaluate

    calls = []

    def made(name, path, file=None):
        calls.append(name)
        Path(path).mkdir(parents=True, exist_ok=True)
        if file:
            (Path(path) / file).write_text("{}")

    monkeypatch.setattr(bench, "make_truth_inputs", lambda capture, out, res: made(f"inputs {res}", out))
    monkeypatch.setattr(material, "run", lambda *a, resume, preset, **k: made(f"material {preset} {resume}", a[4]))
    monkeypatch.setattr(bake, "run", lambda *a, material_dir: made(f"bake {material_dir is not None}", a[4]))
    monkeypatch.setattr(evaluate, "run_duplicates", lambda *a, training, spp, **k: made(f"evaluate {spp}", a[4]))
    settings = bench.settings_from(False, "box-10-hd", "truth", tmp_path)
    scene_dir, capture = tmp_path / "box-10-hd", tmp_path / "capture"
    row = scene_dir / "appearance" / "truth"
    bench.row_steps("truth", capture, scene_dir, settings, bench.Ledger(row))
    # the stage was "killed": its folder but no training.json; run again, with resume=auto
    assert calls == [
        "inputs 512", "material default auto", "bake True", "evaluate 16", "bake False", "evaluate 16",
    ]  # fmt: skip
    assert (row / "first_guess" / "scene").is_dir() and (row / "first_guess" / "report").is_dir()
    calls.clear()
    bench.row_steps("truth", capture, scene_dir, settings, bench.Ledger(row))
    assert calls == ["material default auto"]
    (row / "material" / "training.json").write_text("{}")
    calls.clear()
    bench.row_steps("truth", capture, scene_dir, settings, bench.Ledger(row))
    assert calls == []
    steps = json.loads((row / "steps.json").read_text())
    assert set(steps) == {"inputs", "material", "bake", "evaluate", "bake first guess", "evaluate first guess"}


def test_scenes_poses_and_presets():
    quick = bench.settings_from(True, None, None, None)
    assert quick.scenes == ["box-6-ci", "box-10-ci", "box-20-ci"] and quick.poses == ["truth"]
    assert quick.material_preset == "ci" and quick.atlas_resolution["box-6-ci"] == 256
    full = bench.settings_from(False, None, None, "work")
    assert full.scenes == ["box-6-hd", "box-10-hd", "box-20-hd"] and full.poses == ["truth", "recovered"]
    assert full.material_preset == "default" and full.atlas_resolution["box-20-hd"] == 512
    assert full.work == "work" and bench.settings_from(False, None, None, None).work == "results/bench/duplicates"
    with pytest.raises(SceneError, match="poses"):
        bench.settings_from(False, None, "colmap", None)
    with pytest.raises(SceneError, match="scenes"):
        bench.settings_from(False, "box-7-hd", None, None)


def test_recovered_poses_from_a_named_variant_keep_their_own_folder_and_label():
    settings = bench.settings_from(False, "box-20-hd", "truth,recovered", None, "provided-tracks-subpixel")
    assert settings.pose_variant == "provided-tracks-subpixel"
    assert bench.settings_from(False, None, None, None).pose_variant == "default"
    assert bench.row_folder("recovered", "provided-tracks-subpixel") == "recovered-provided-tracks-subpixel"
    assert bench.row_folder("recovered", "default") == "recovered" and bench.row_folder("truth", "sift") == "truth"
    assert bench.pose_label({"poses": "recovered", "pose_variant": "sift"}) == "recovered (sift)"
    assert bench.pose_label({"poses": "recovered", "pose_variant": "default"}) == "recovered"
    assert bench.pose_label({"poses": "truth", "pose_variant": None}) == "truth"
    with pytest.raises(SceneError, match="one bench duplicates variant"):
        bench.settings_from(False, None, None, None, "default,sift")
    with pytest.raises(SceneError, match="variants"):
        bench.settings_from(False, None, None, None, "orb")


def test_poses_option_belongs_to_this_bench():
    args = SimpleNamespace(quick=True, out="x", device=None, poses="truth")
    with pytest.raises(SceneError, match="--poses"):
        run_benchmark("duplicates", args)


def test_truth_segmentation_keeps_the_true_ids(tmp_path):
    import numpy as np

    from invrender.scene.images import read_mask, write_mask

    ids = np.zeros((6, 8), np.uint16)
    ids[4:6, 0:2] = 1  # copy 1 is last in reading order: segment's provided backend would call it 2
    ids[0:2, 5:8] = 2
    write_mask(tmp_path / "view_000.png", ids)
    bench.write_truth_segmentation(tmp_path / "view_000.png", tmp_path / "segmentation")
    assert (read_mask(tmp_path / "segmentation" / "masks" / "view_000.png") == ids).all()
    table = json.loads((tmp_path / "segmentation" / "instances.json").read_text())
    assert (table["image"], table["width"], table["height"]) == ("view_000.exr", 8, 6)
    assert [(e["id"], e["area"]) for e in table["instances"]] == [(1, 4), (2, 6)]
