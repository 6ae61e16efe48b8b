"""The Pareto front, the knee and the recovery rows on hand-made numbers."""

from __future__ import annotations

import json

import numpy as np
import pytest

from invrender.accuracy import front, recovery


def rows(points, family="forward", sweep="spp", label="default"):
    return [
        {"family": family, "sweep": sweep, "label": label, "spp": s, "time_s": t, "rmse": e, "pasteable": True}
        for s, t, e in points
    ]


def test_pareto_keeps_only_the_unbeaten():
    data = rows([(1, 1.0, 1.0), (2, 2.0, 0.5), (4, 3.0, 0.7), (8, 4.0, 0.25)])
    assert [r["spp"] for r in front.pareto(data, "rmse")] == [1, 2, 8]


def test_knee_is_the_cheapest_within_the_factor_of_the_best():
    data = rows([(s, s / 10, 1 / np.sqrt(s)) for s in (1, 4, 16, 64, 256)])
    knee = front.knee(data, "rmse", factor=2.0)
    assert knee["row"]["spp"] == 64  # 1/8 <= 2 x 1/16; 16 spp (1/4) is not
    assert knee["stated_error"] == pytest.approx(0.125 * (1 + front.SEED_MARGIN))
    assert front.snippet(knee["row"] | {"features": {"nee": True}}, {"nee": True}) == {"render": {"spp": 64}}


def test_spp_slope_of_a_pure_monte_carlo_ladder():
    data = rows([(s, s, 0.3 / np.sqrt(s)) for s in (1, 2, 4, 8, 16)])
    assert front.spp_slope(data)["slope"] == pytest.approx(-0.5)


def test_a_training_log_becomes_rows_against_wall_time(tmp_path):
    """The hook every recovery stage plugs into: log.csv (iteration, wall_time, its loss) and
    training.json; the configured run's last row is the default, its iteration the snippet."""
    lines = ["iteration,wall_time,image"] + [f"{i},{0.5 * i},{1.0 / i}" for i in range(1, 81)]
    (tmp_path / "log.csv").write_text("\n".join(lines) + "\n")
    (tmp_path / "training.json").write_text(json.dumps({"preset": "demo", "settings": {"width": 64, "rays": 8192}}))
    out = recovery.run_rows(tmp_path)
    assert len(out) == recovery.LOG_BINS and out[-1]["default"] and out[-1]["iteration"] == 80
    assert out[0]["recovery_error"] == pytest.approx(np.mean([1.0 / i for i in range(1, 11)]))
    assert out[-1]["time_s"] == 40.0 and out[0]["width"] == 64 and out[0]["preset"] == "demo"
    knee = front.knee(out, "recovery_error", factor=2.0)
    assert front.snippet(knee["row"]) == {"milo": {"overrides": {"iterations": knee["row"]["iteration"]}}}


def test_scored_snapshots_are_the_recovery_error(tmp_path):
    table = [
        {
            "iteration": 50 * k,
            "wall_time_s": 10.0 * k,
            "material_mse": 0.1 / k,
            "light_maps_mse": 0.02,
            "novel_view_psnr_db": 20.0,
        }
        for k in (1, 2, 3)
    ]
    (tmp_path / "metrics.json").write_text(json.dumps({"training": table}))
    (tmp_path / "log.csv").write_text("iteration,wall_time,image\n1,0.1,1\n")
    out = recovery.run_rows(tmp_path, tmp_path / "metrics.json")
    assert [r["recovery_error"] for r in out] == pytest.approx([0.1, 0.05, 0.1 / 3])
    assert out[0]["novel_view_mse"] == pytest.approx(0.01)
