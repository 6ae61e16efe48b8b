"""The `invrender bench scaling` harness at its --quick sizes: it runs end to end through the
CLI, every size of every sweep is measured, the JSON, the CSVs and the fits agree with each
other, and the fitting and prediction arithmetic is exact on data with a known law. No timing is
asserted: the full run and its reading are in docs/benchmarks.md ("Scaling")."""

import csv
import json
import math

import numpy as np
import pytest

import invrender.mitsuba as mb  # noqa: I001 - first: it points drjit at a usable libLLVM
from invrender.bench.scaling import (
    QUICK,
    SECTIONS,
    from_the_points,
    loglog_interpolate,
    power_law,
    power_law_at,
    predict,
    sweep_factor,
)
from invrender.cli import main
from invrender.synthesize.room import make_room

MB = 2**20


def _finite_positive(value) -> bool:
    return isinstance(value, (int, float)) and math.isfinite(value) and value > 0


@pytest.fixture(scope="module")
def quick_run(tmp_path_factory):
    out = tmp_path_factory.mktemp("bench")
    assert main(["bench", "scaling", "--quick", "--out", str(out)]) == 0
    return out, json.loads((out / "scaling.json").read_text())


def test_quick_run_writes_every_table(quick_run):
    out, report = quick_run
    assert report["benchmark"] == "scaling" and report["mode"] == "quick"
    for key in SECTIONS:
        assert report[key], key
        assert (out / f"scaling_{key}.csv").exists(), key
    table = (out / "scaling_table.md").read_text()
    assert table.startswith("# invrender bench scaling (quick")
    assert f"commit {report['machine']['git_commit']}" in table.splitlines()[0]


def test_every_size_of_every_sweep_is_present(quick_run):
    _, report = quick_run
    base = len(make_room({"cell": QUICK.base_cell})[0].mesh.faces)
    # Each target t becomes base * n^2 triangles, n = round(sqrt(t / base)) (at least 1).
    expected = [base * max(1, round(math.sqrt(t / base))) ** 2 for t in QUICK.triangles]
    assert [row["triangles"] for row in report["triangles"]] == expected
    assert [(row["width"], row["height"]) for row in report["pixels"]] == list(QUICK.pixels)
    assert [row["spp"] for row in report["spp"]] == list(QUICK.spps)
    keys = ["build_s", "pack_rest_s", "device_mb", "forward_us_per_sample", "gradient_us_per_sample", "peak_rss_mb"]
    for row in report["triangles"]:
        assert all(_finite_positive(row[k]) for k in keys), row
        assert row["width"] * row["height"] == QUICK.tri_width * QUICK.tri_height and row["spp"] == QUICK.tri_spp
        # The device holds at least each triangle's three float4 vertices, three UVs, id,
        # instance and one-sidedness (48 + 24 + 4 + 4 + 1 bytes) besides the BVH.
        assert row["geometry_mb"] * MB >= 81 * row["triangles"]
        assert row["device_mb"] >= row["geometry_mb"]
    largest = report["triangles"][-1]
    assert largest["pack_rss_mb"] >= largest["geometry_mb"]  # RSS holds what packing made
    if mb.DEFAULT_VARIANT == "llvm_ad_rgb":
        for row in report["triangles"]:
            assert _finite_positive(row["mitsuba_us_per_sample"]) and _finite_positive(row["mitsuba_load_s"])
            assert row["ratio"] == pytest.approx(row["mitsuba_s"] / row["forward_s"])
    for row in report["pixels"] + report["spp"]:
        samples = row["width"] * row["height"] * row["spp"]
        assert row["forward_us_per_sample"] == pytest.approx(1e6 * row["forward_s"] / samples)
        assert _finite_positive(row["gradient_s"]) and row["gradient_rss_mb"] >= 0


def _csv_rows(path):
    with open(path, newline="") as handle:
        return list(csv.DictReader(handle))


def test_csv_and_json_hold_the_same_numbers(quick_run):
    out, report = quick_run
    for key in SECTIONS:
        rows = _csv_rows(out / f"scaling_{key}.csv")
        assert len(rows) == len(report[key]), key
        for csv_row, row in zip(rows, report[key]):
            for name, value in row.items():
                if isinstance(value, float):
                    assert float(csv_row[name]) == pytest.approx(value, rel=1e-12), (key, name)
                elif value is not None:
                    assert csv_row[name] == str(value), (key, name)


def test_fits_are_those_of_the_rows(quick_run):
    _, report = quick_run
    fits = {(f["sweep"], f["quantity"]): f for f in report["fits"]}
    for (sweep, quantity), x in (
        (("triangles", "forward_us_per_sample"), "triangles"),
        (("triangles", "pack_s"), "triangles"),
        (("pixels", "gradient_s"), "pixels"),
        (("spp", "forward_s"), "spp"),
    ):
        rows = report[sweep]
        again = power_law([r[x] for r in rows], [r[quantity] for r in rows])
        assert fits[sweep, quantity]["k"] == pytest.approx(again["k"])
        assert fits[sweep, quantity]["points"] == len(rows)


def test_power_law_recovers_a_known_exponent_and_ignores_one_wild_point():
    x = np.array([1e3, 4e3, 1.6e4, 6.4e4, 2.56e5])
    y = 3.0 * x**1.7
    fit = power_law(x, y)
    assert fit["k"] == pytest.approx(1.7, abs=1e-12) and fit["a"] == pytest.approx(3.0, rel=1e-9)
    assert fit["k_ls"] == pytest.approx(1.7, abs=1e-12) and fit["k_ls_se"] == pytest.approx(0.0, abs=1e-9)
    assert fit["k_q25"] == pytest.approx(1.7) and fit["k_q75"] == pytest.approx(1.7)
    assert fit["k_top"] == pytest.approx(1.7)
    wild = y.copy()
    wild[2] *= 5.0  # one point timed during a burst of load
    robust = power_law(x, wild)
    assert robust["k"] == pytest.approx(1.7, abs=1e-12)  # two pairwise slopes up, two down, six exact
    assert abs(robust["k_ls"] - 1.7) > 1e-3 or robust["k_ls_se"] > 0.05  # least squares is moved
    assert power_law([1.0, 2.0], [0.0, -1.0]) is None  # nothing positive to fit


def test_prediction_arithmetic_on_exact_laws():
    """Per-sample time 2 N^0.25 us in the triangle sweep; the pixel and spp sweeps' per-sample
    time halves from their smallest to their largest point: the prediction is the law at N times
    the samples times the measured factors, held beyond the sweeps."""
    settings = QUICK
    triangles = [1e3, 1e4, 1e5, 1e6]
    rows = [
        {"triangles": n, "forward_us_per_sample": 2 * n**0.25, "gradient_us_per_sample": 6 * n**0.25} for n in triangles
    ]
    p0, s0 = settings.tri_width * settings.tri_height, settings.tri_spp
    pixels = [
        {"pixels": p, "forward_us_per_sample": 1.0 * (p0 / p) ** 0.5, "gradient_us_per_sample": 1.0}
        for p in (p0, 4 * p0)
    ]
    spps = [{"spp": s, "forward_us_per_sample": 1.0, "gradient_us_per_sample": 1.0} for s in (s0, 64 * s0)]
    results = {"triangles": rows, "pixels": pixels, "spp": spps}
    fits = []
    for sweep, key in (("triangles", "forward_us_per_sample"), ("triangles", "gradient_us_per_sample")):
        fits.append({"sweep": sweep, "quantity": key, **power_law(triangles, [r[key] for r in rows])})
    settings = type(settings)(**{**settings.__dict__, "predict": (500_000, 640, 480, 256)})
    out = {r["what"]: r for r in predict(results, fits, settings)}
    forward, gradient = out["forward render, wall [s]"], out["gradient pass, wall [s]"]
    samples = 640 * 480 * 256
    assert forward["us_per_sample"] == pytest.approx(2 * 500_000**0.25)
    assert forward["pixel_factor"] == pytest.approx(0.5)  # 640 x 480 lies beyond 4 p0: held at 4 p0
    assert forward["spp_factor"] == pytest.approx(1.0)
    assert forward["predicted"] == pytest.approx(1e-6 * 2 * 500_000**0.25 * samples * 0.5)
    assert forward["power_law"] == pytest.approx(forward["predicted"])
    assert gradient["predicted"] == pytest.approx(1e-6 * 6 * 500_000**0.25 * samples)
    assert not any(what.startswith("mitsuba") or "CPU" in what for what in out)  # nothing fitted, nothing predicted


def test_loglog_interpolation_and_sweep_factor_are_exact_on_power_laws():
    xs = [1.0, 10.0, 100.0]
    assert loglog_interpolate(xs, [x**0.5 for x in xs], 40.0) == pytest.approx(40.0**0.5)
    assert loglog_interpolate(xs, [1.0, 2.0, 3.0], 1000.0) is None
    # A fixed cost plus a linear part: beyond the points, the largest one scaled by the top
    # exponent, not the overall power law (which the fixed cost bends).
    xs = [1e3, 1e4, 1e5, 1e6]
    ys = [5.0 + 1e-2 * x for x in xs]
    fit, truth = power_law(xs, ys), 5.0 + 1e-2 * 4e6
    assert fit["k"] < fit["k_top"] < 1.0
    assert from_the_points(xs, ys, 4e6, fit) == pytest.approx(ys[-1] * 4.0 ** fit["k_top"])
    assert from_the_points(xs, ys, 4e6, fit) == pytest.approx(truth, rel=0.02)
    assert abs(power_law_at(fit, 4e6) / truth - 1) > 0.05
    assert from_the_points(xs, ys, 1e4, fit) == pytest.approx(ys[1])
    rows = [{"spp": s, "t": 5.0 * s**-0.3} for s in (1, 4, 16, 64)]
    assert sweep_factor(rows, "spp", "t", 4, 32) == pytest.approx((32 / 4) ** -0.3)
    assert sweep_factor(rows, "spp", "t", 4, 256) == pytest.approx((64 / 4) ** -0.3)  # held beyond 64


def test_scaling_refuses_options_of_bench_milo(tmp_path):
    assert main(["bench", "scaling", "--quick", "--iterations", "3", "--out", str(tmp_path)]) == 2
