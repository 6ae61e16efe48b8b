"""`invrender bench milo --sections independent --quick` on tiny Mitsuba captures: a table per
layout and split, every arm's number the one in the metrics.json of the evaluate run it made, the
constant guess evaluate's own, the floor far below every guess. Nothing here measures recovery:
docs/milo.md has the real run."""

import json
from pathlib import Path

import pytest
import yaml
from bench_tables import printed, tables

from invrender.bench.milo_independent import COLUMNS, LAYOUTS, METRICS, SPLITS, room_config
from invrender.cli import main

TINY = {
    "scenes": {"tiny": {"synthetic": {"kind": "room", "spp": 4}, "holdout": ["view_002.exr"]}},
    "geometry": {"atlas_resolution": 64},
    "milo": {"preset": "demo", "overrides": {"rays": 512, "spp": 1, "warm_start_steps": 2, "layers": 2, "width": 16}},
}


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    root = tmp_path_factory.mktemp("bench_milo_independent")
    (root / "tiny.yaml").write_text(yaml.safe_dump(TINY))
    out, work = root / "out", root / "work"
    argv = ["bench", "milo", "--sections", "independent", "--quick", "--config", root / "tiny.yaml"]
    assert main([*map(str, argv), "--out", str(out), "--work", str(work)]) == 0
    return tables((out / "milo-independent.md").read_text()), json.loads((out / "milo-independent.json").read_text())


def test_every_layout_and_split_has_its_table_with_every_arm(run):
    found, report = run
    assert set(found) == {f"`{layout}`, {split} split" for layout in LAYOUTS for split in SPLITS}
    for rows in found.values():
        assert [row["metric"] for row in rows[: len(METRICS)]] == [label for label, _, _ in METRICS]
        assert set(rows[0]) == {"metric", *COLUMNS}


def test_numbers_are_the_evaluate_runs_own_and_the_floor_is_below_the_guesses(run):
    found, report = run
    for capture in report["captures"]:
        rows = found[f"`{capture['layout']}`, {capture['split']} split"]
        for (label, path, fmt), row in zip(METRICS, rows):
            for arm, where in capture["arms"].items():
                value = json.loads((Path(where) / "report" / "metrics.json").read_text())
                for key in path:
                    value = value.get(key) if isinstance(value, dict) else None
                assert row[arm] == "-" if value is None else printed(row[arm], value, fmt), (label, arm)
        material = {arm: float(cell) for arm, cell in rows[0].items() if arm != "metric"}
        assert material["floor"] < 0.2 * min(material["constant guess"], material["per-texel guess"])


def test_the_held_out_split_changes_what_tuning_never_saw():
    tuning, held_out = room_config("window", "tuning"), room_config("window", "held-out")
    assert tuning["seed"] != held_out["seed"] and "light_color" in held_out
    assert held_out["environment"]["sun_azimuth_deg"] != 20.0  # the generator's default sun
    assert room_config("lamps", "held-out")["environment"]["sun_radiance"] == [0.0, 0.0, 0.0]
