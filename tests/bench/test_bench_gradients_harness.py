"""The `invrender bench gradients` harness at its --quick sizes: it runs end to end through the
CLI, writes its tables, and its numbers are well formed. Nothing here is a measurement: the
full run and its reading are in docs/benchmarks.md ("Gradients")."""

import json
import math

import numpy as np
import pytest

import invrender.mitsuba as mb  # noqa: I001 - first: it points drjit at a usable libLLVM
from invrender.bench.gradients import QUICK, has_accumulation, lambertian_room
from invrender.cli import main

SECTIONS = ("equal_error", "one_time", "curves", "profile", "memory", "accumulation")
# Mitsuba's prb needs llvm_ad_rgb (libLLVM, FACTS.md); without it the quick run below is the
# scalar_rgb fallback, which measures invrender alone.
AD = mb.DEFAULT_VARIANT == "llvm_ad_rgb"


def _finite_positive(value) -> bool:
    return isinstance(value, (int, float)) and math.isfinite(value) and value > 0


@pytest.fixture(scope="module")
def quick_run(tmp_path_factory):
    out = tmp_path_factory.mktemp("bench")
    assert main(["bench", "gradients", "--quick", "--out", str(out)]) == 0
    return out, json.loads((out / "gradients.json").read_text())


def test_quick_run_writes_every_table(quick_run):
    out, report = quick_run
    assert report["benchmark"] == "gradients" and report["mode"] == "quick"
    for key in SECTIONS:
        assert (out / f"gradients_{key}.csv").exists(), key
    for key in ("equal_error", "one_time", "curves", "profile", "memory"):
        assert report[key], key
    assert (out / "gradients_table.md").read_text().startswith("# invrender bench gradients (quick")


def test_equal_error_rows_against_mitsuba_prb(quick_run):
    _, report = quick_run
    assert report["mitsuba_variant"] == mb.DEFAULT_VARIANT
    (row,) = report["equal_error"]
    assert row["bounces"] == QUICK.bounces[0]
    renderers = ("invrender", "mitsuba") if AD else ("invrender",)
    assert {(r["renderer"], r["spp"]) for r in report["curves"]} == {(n, s) for n in renderers for s in QUICK.ladder}
    assert all(_finite_positive(r["wall_s"]) for r in report["curves"])
    if not AD:  # invrender alone: test_without_an_ad_variant_invrender_is_measured_alone
        return
    for key in (
        "target_rel_rmse",
        "t_invrender_s",
        "t_mitsuba_s",
        "ratio",
        "ratio_fit",
        "ratio_cpu",
        "speed_ratio",
        "variance_ratio",
        "texel_mse_over_noise",
        "mean_rel_sigma",
    ):
        assert _finite_positive(row[key]), (key, row[key])
    assert row["ref_noise_rel_rmse"] < row["target_rel_rmse"]
    assert row["agreement"] == "not checked"  # quick references are far below the spp it takes to judge
    assert all(_finite_positive(r["rel_rmse"]) for r in report["curves"])
    assert [r["renderer"] for r in report["profile"]] == ["invrender", "mitsuba"]
    assert len(report["one_time"]) == 2


def test_memory_and_accumulation_rows(quick_run):
    _, report = quick_run
    modes = ("fixed", "buckets") if has_accumulation() else ("fixed",)
    rows = report["memory"]
    assert [(r["renderer"], r["accumulation"]) for r in rows] == [("invrender", m) for m in modes] + [
        ("mitsuba llvm_ad_rgb prb", "-")
    ] * AD
    for r in rows:
        assert r["rays"] == QUICK.memory_side**2 and r["bounces"] == QUICK.memory_bounces
        assert _finite_positive(r["rss_after_setup_mb"]) and r["peak_rss_mb"] >= r["rss_after_setup_mb"]
        assert _finite_positive(r["pass_s"])
    if has_accumulation():
        (acc,) = report["accumulation"]
        assert _finite_positive(acc["backward_ratio"]) and _finite_positive(acc["pass_ratio"])
        assert acc["max_rel_diff"] < 1e-3  # the same samples summed in another order and precision


def test_start_scene_keeps_lights_and_openings_black():
    true, start, covered = lambertian_room(16, 12)
    assert not np.any(true.maps.ks) and not np.any(start.maps.ks)
    assert np.all(start.maps.kd[covered] == 0.5) and not np.any(start.maps.kd[~covered])
    assert np.array_equal(covered, np.any(true.maps.kd > 0, -1))


@pytest.fixture(scope="module")
def fallback_run(quick_run, tmp_path_factory):
    """A quick run without an AD variant: without libLLVM, the quick run itself; with it, forced."""
    if not AD:
        return quick_run[1]
    from invrender.bench.gradients import run
    from invrender.bench.harness import VARIANT_ENV

    with pytest.MonkeyPatch.context() as patch:
        patch.setenv(VARIANT_ENV, "scalar_rgb")
        try:
            return run(quick=True, out=tmp_path_factory.mktemp("fallback"))
        finally:  # later tests in this process expect the default variant
            mb.set_variant(mb.DEFAULT_VARIANT)


def test_without_an_ad_variant_invrender_is_measured_alone(fallback_run):
    assert any("no automatic differentiation" in note for note in fallback_run["notes"])
    (row,) = fallback_run["equal_error"]
    assert "ratio" not in row and _finite_positive(row["samples_per_s_invrender"])
    assert {r["renderer"] for r in fallback_run["curves"]} == {"invrender"}
    assert all(r["renderer"] == "invrender" for r in fallback_run["memory"])
