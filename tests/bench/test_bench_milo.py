"""`invrender bench milo` on a tiny room (4 views of 32 x 24, a 64^2 atlas, 3 iterations): the
chain runs through the CLI, milo.md has every row of both tables, and every number in it is the
one in the metrics.json of the evaluate run it made (the table cannot drift from the
measurements), judged against the issue's targets by arithmetic done here. Nothing here is a
measurement of recovery: docs/benchmarks.md ("MILO recovery") has the real run."""

import json
import re
from pathlib import Path

import pytest
import yaml
from bench_tables import printed, tables

from invrender.bench.milo import ABLATION_ROWS, ROWS
from invrender.cli import main

TINY = {
    "scenes": {
        "tiny": {
            "synthetic": {
                "kind": "room",
                "spp": 4,
                "config": {"atlas_resolution": 64, "cameras": {"count": 4, "width": 32, "height": 24}},
            },
            "holdout": ["view_002.exr"],
        }
    },
    "geometry": {"atlas_resolution": 64},
    "milo": {"preset": "cpu", "overrides": {"rays": 1024, "spp": 1, "warm_start_steps": 2}},
    "evaluate": {"spp": 2},
}
# The acceptance targets (Table 3 and section 4.1), written out here, not imported.
TARGETS = {
    "light maps MSE (ke, kw, kg; x/(1+x))": ("<=", 0.002),
    "material MSE (shading balls)": ("<=", 0.015),
    "insertion PSNR [dB]": (">=", 26.5),
    "insertion SSIM": (">=", 0.964),
    "insertion NCC": (">=", 0.978),
    "insertion MSE": ("<=", 0.002),
}
METRICS = {  # row -> (key path in metrics.json, noise floor's key path)
    "light maps MSE (ke, kw, kg; x/(1+x))": (("maps", "light_maps_mse"), None),
    "light maps MSE, linear radiance": (("maps", "light_maps_mse_linear"), None),
    "material MSE (shading balls)": (("maps", "material_mse"), None),
    "insertion PSNR [dB]": (("insertion", "mean", "psnr_db"), ("insertion", "noise_floor", "psnr_db")),
    "insertion SSIM": (("insertion", "mean", "ssim"), ("insertion", "noise_floor", "ssim")),
    "insertion NCC": (("insertion", "mean", "ncc"), ("insertion", "noise_floor", "ncc")),
    "insertion MSE": (("insertion", "mean", "mse"), ("insertion", "noise_floor", "mse")),
    "novel-view PSNR [dB]": (("novel_views", "mean", "psnr_db"), ("novel_views", "truth_floor", "psnr_db")),
    "novel-view SSIM": (("novel_views", "mean", "ssim"), ("novel_views", "truth_floor", "ssim")),
    "ke MSE": (("maps", "map_mse", "ke"), None),
    "kd MSE": (("maps", "map_mse", "kd"), None),
}


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    root = tmp_path_factory.mktemp("bench_milo")
    config = root / "tiny.yaml"
    config.write_text(yaml.safe_dump(TINY))
    out, work = root / "out", root / "work"
    argv = [
        "bench",
        "milo",
        "--sections",
        "paper",
        "--config",
        config,
        "--out",
        out,
        "--work",
        work,
        "--iterations",
        "3",
    ]
    assert main(list(map(str, argv))) == 0
    arms = {arm: json.loads((work / arm / "report" / "metrics.json").read_text()) for arm in ("template", "plain")}
    markdown = (out / "milo.md").read_text()
    return tables(markdown), arms, json.loads((out / "milo.json").read_text()), markdown


def at(document: dict, path):
    for key in path:
        document = document[key]
    return document


def test_both_tables_have_every_row(run):
    found, _, _, _ = run
    main_table = found["MILO-Net on the benchmark room, beside the paper (Table 3, section 4.1)"]
    ablation = found["Ablation (Fig. 12): MILO-Net against two plain MLPs, same room and settings"]
    assert [row["metric"] for row in main_table] == [row.label for row in ROWS]
    assert [row["metric"] for row in ablation] == [row.label for row in ABLATION_ROWS]
    assert set(TARGETS) | set(METRICS) <= {row.label for row in ABLATION_ROWS}
    curve = found["Accuracy against training time (the evaluate stage's snapshots)"]
    assert [(row["arm"], row["iteration"]) for row in curve] == [("template", "3"), ("plain", "3")]


def test_numbers_are_the_evaluate_runs_own(run):
    found, arms, _, markdown = run
    fmt = {row.label: row.fmt for row in ABLATION_ROWS}
    main_table = found["MILO-Net on the benchmark room, beside the paper (Table 3, section 4.1)"]
    ablation = found["Ablation (Fig. 12): MILO-Net against two plain MLPs, same room and settings"]
    for row in main_table:
        if row["metric"] not in METRICS:
            continue
        path, floor = METRICS[row["metric"]]
        assert printed(row["invrender"], at(arms["template"], path), fmt[row["metric"]]), row
        if floor is not None:
            assert printed(row["noise floor"], at(arms["template"], floor), fmt[row["metric"]]), row
        else:
            assert row["noise floor"] == "-"
    for row in ablation:
        if row["metric"] in METRICS:
            path, _ = METRICS[row["metric"]]
            assert printed(row["MILO-Net (template)"], at(arms["template"], path), fmt[row["metric"]]), row
            assert printed(row["plain MLPs (Fig. 12)"], at(arms["plain"], path), fmt[row["metric"]]), row
    # the insertion with the noise floor's MSE taken out
    line = re.search(r"noise taken out .*: MSE ([-0-9.e+]+), PSNR", markdown).group(1)
    insertion = arms["template"]["insertion"]
    assert printed(line, insertion["mean"]["mse"] - insertion["noise_floor"]["mse"], ".4g")
    # the ablation really is the other network: the two arms' maps differ
    assert arms["template"]["maps"]["map_mse"] != arms["plain"]["maps"]["map_mse"]


def test_targets_and_shortfalls_follow_from_the_numbers(run):
    found, arms, _, _ = run
    main_table = found["MILO-Net on the benchmark room, beside the paper (Table 3, section 4.1)"]
    judged = 0
    for row in main_table:
        if row["metric"] not in TARGETS:
            assert (row["target"], row["target met?"], row["shortfall"]) == ("-", "-", "-"), row
            continue
        op, target = TARGETS[row["metric"]]
        value = at(arms["template"], METRICS[row["metric"]][0])
        met = value <= target if op == "<=" else value >= target
        assert row["target"] == f"{op} {target:g}"
        assert row["target met?"] == ("yes" if met else "NO"), row
        if met:
            assert row["shortfall"] == "-"
        else:  # "<gap> above (...)" or "<gap> dB below"
            gap = float(re.match(r"[-+0-9.e]+", row["shortfall"]).group())
            assert gap == pytest.approx(abs(value - target), rel=1e-3, abs=0.006), row
            assert ("above" if op == "<=" else "below") in row["shortfall"]
        judged += 1
    assert judged == len(TARGETS)


def test_time_and_memory_are_the_measured_ones(run):
    found, _, report, _ = run
    title = "MILO-Net on the benchmark room, beside the paper (Table 3, section 4.1)"
    main_table = {row["metric"]: row for row in found[title]}
    for name in ("template", "plain"):
        bench = report["arms"][name]["bench"]
        arm_dir = Path(report["arms"][name]["metrics_path"]).parents[1]
        training = json.loads((arm_dir / "milo" / "training.json").read_text())
        assert bench["iterations"] == training["iterations"] == 3
        assert 0 < training["training_seconds"] == bench["training_seconds"] <= bench["milo_wall_s"]
        assert 100 < bench["milo_peak_rss_mb"] < 24_000  # a Python process with torch, on this machine
        assert 0 <= bench["milo_rss_growth_mb"] <= bench["milo_peak_rss_mb"]
    template = report["arms"]["template"]["bench"]
    assert printed(main_table["training time [s] (milo stage, wall)"]["invrender"], template["milo_wall_s"], ".1f")
    assert printed(main_table["peak memory [MB] (RSS during milo)"]["invrender"], template["milo_peak_rss_mb"], ".0f")


def test_options_of_another_benchmark_and_a_config_without_one_room_are_refused(tmp_path):
    assert main(["bench", "render", "--iterations", "3", "--out", str(tmp_path)]) == 2
    config = tmp_path / "two.yaml"
    config.write_text(yaml.safe_dump({"scenes": {"a": TINY["scenes"]["tiny"], "b": TINY["scenes"]["tiny"]}}))
    assert main(["bench", "milo", "--config", str(config), "--out", str(tmp_path / "out")]) == 2
    assert not (tmp_path / "out" / "milo.md").exists()
    assert not (tmp_path / "out" / "milo-independent.md").exists()  # refused before any section ran
    assert main(["bench", "milo", "--sections", "papr", "--out", str(tmp_path / "out")]) == 2


def test_the_benchmark_config_is_a_room_where_recovery_can_be_judged():
    """config/benchmark.yaml: valid for the workflow, one room of >= 20 views above the demo's
    96 x 72, held-out views that are its cameras, the cpu preset."""
    from invrender.bench.milo import load_config, room_scene

    path = Path(__file__).resolve().parents[2] / "config" / "benchmark.yaml"
    config = load_config(path)
    scene = config["scenes"][room_scene(config, path)]
    cameras = scene["synthetic"]["config"]["cameras"]
    assert cameras["count"] >= 20 and cameras["width"] * cameras["height"] > 96 * 72
    names = {f"view_{i:03d}.exr" for i in range(cameras["count"])}  # synthesize's camera names
    assert 0 < len(scene["holdout"]) < cameras["count"] and set(scene["holdout"]) <= names
    assert config["milo"]["preset"] == "cpu" and config["milo"]["overrides"] == {}
