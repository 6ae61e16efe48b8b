"""The `invrender bench render` harness at its --quick sizes: it runs end to end through the
CLI, writes its tables, and its numbers are well formed. Nothing here is a measurement: the
full run and its reading are in docs/benchmarks.md."""

import json
import math

import numpy as np
import pytest

import invrender.mitsuba as mb  # noqa: I001 - first: it points drjit at a usable libLLVM
from invrender.bench.harness import portable, time_at_rmse
from invrender.bench.render import EFFECT_SCENES, MITSUBA_SPLIT, MIXTURE, QUICK, scalar_settings, subdivide_mesh
from invrender.cli import main
from invrender.synthesize.room import make_room

TABLES = ("equal_rmse", "one_time", "curves", "bvh", "features", "profile")


def _finite_positive(value) -> bool:
    return isinstance(value, (int, float)) and math.isfinite(value) and value > 0


@pytest.fixture(scope="module")
def quick_run(tmp_path_factory):
    out = tmp_path_factory.mktemp("bench")
    assert main(["bench", "render", "--quick", "--out", str(out)]) == 0
    return out, json.loads((out / "render.json").read_text())


def test_quick_run_writes_every_table(quick_run, capsys):
    out, report = quick_run
    for key in TABLES:
        assert (out / f"render_{key}.csv").stat().st_size > 0
        assert report[key], key
    assert (out / "render_table.md").read_text().startswith("# invrender bench render (quick")
    try:
        import matplotlib  # noqa: F401

        assert (out / "render_rmse_vs_time.png").exists()
    except ImportError:
        assert any("matplotlib" in note for note in report["notes"])


def test_equal_rmse_rows_for_3_and_10_bounces(quick_run):
    _, report = quick_run
    rows = report["equal_rmse"]
    assert [row["bounces"] for row in rows] == [3, 10]
    for row in rows:
        for key in (
            "target_rmse",
            "t_invrender_s",
            "t_mitsuba_s",
            "ratio",
            "ratio_fit",
            "speed_ratio",
            "variance_ratio",
            "ref_noise_rmse",
        ):
            assert _finite_positive(row[key]), (key, row[key])
        assert row["ref_noise_rmse"] < row["target_rmse"]
        assert math.isfinite(row["mean_rel_diff"])
    assert {(r["bounces"], r["renderer"]) for r in report["curves"]} == {
        (b, n) for b in (3, 10) for n in ("invrender", MIXTURE, "mitsuba", MITSUBA_SPLIT)
    }
    assert len(report["one_time"]) == 4
    settings = QUICK if report["mitsuba_variant"] == "llvm_ad_rgb" else scalar_settings(QUICK)
    assert [row["width"] for row in rows] == [settings.width] * 2


def test_bvh_and_profile_rows(quick_run):
    _, report = quick_run
    (bvh,) = report["bvh"]
    assert 15_000 < bvh["triangles"] < 30_000
    for key in ("build_s", "traced_peak_mb", "device_bytes_per_tri", "invrender_bare_rays_per_s"):
        assert _finite_positive(bvh[key]), key
    cases = [row["case"] for row in report["profile"]]
    assert any(case.startswith("mitsuba") for case in cases)
    assert all(_finite_positive(row["t_per_sample_us"]) for row in report["profile"])


def test_effects_rows_per_scene(quick_run):
    """Every scene has the analysed kernel, the all-features control, the switches the analysis
    implies, the estimator and roulette; numbers finite; dropped terms only darken the image."""
    _, report = quick_run
    rows = report["features"]
    assert list(dict.fromkeys(row["scene"] for row in rows)) == [name for name, _ in EFFECT_SCENES]
    by_scene = {name: {row["switch"]: row for row in rows if row["scene"] == name} for name, _ in EFFECT_SCENES}
    for name, mine in by_scene.items():
        kinds = [row["kind"] for row in mine.values()]
        assert kinds[:2] == ["analysed", "control"] and {"estimator", "roulette"} <= set(kinds), (name, kinds)
        for switch, row in mine.items():
            for key in ("t_per_sample_us", "speedup", "var_per_sample"):
                assert _finite_positive(row[key]), (name, switch, key, row[key])
            if row["kind"] == "analysed":
                assert row["speedup"] == 1.0 and row["efficiency"] == 1.0
                continue
            for key in ("speedup_sigma", "mean_rel_diff", "mean_rel_sigma", "pixel_mse_over_noise"):
                assert math.isfinite(row[key]), (name, switch, key)
            if row["kind"] == "bias":
                assert row["efficiency"] is None and row["mean_rel_diff"] < 0, (name, switch)
            else:
                assert _finite_positive(row["efficiency"]) and row["agreement"] in ("agree", "not checked")
    diffuse, window, glossy = by_scene.values()
    assert {"specular on", "environment on", "window on", "env_sampling on"} <= set(diffuse)
    assert "specular on" in window and "specular off" in glossy
    assert all("environment off (window, env sampling with it)" in scene for scene in (window, glossy))
    for mine in by_scene.values():
        analysed = next(iter(mine.values()))
        assert analysed["features"]["nee"] and analysed["features"]["roulette_depth"] == 3
        (mixture,) = [row for row in mine.values() if row["kind"] == "estimator"]
        assert not mixture["features"]["nee"]
        (off,) = [row for row in mine.values() if row["kind"] == "roulette"]
        assert off["features"]["roulette_depth"] == 0 and off["bounces"] == 10


def test_time_at_rmse_interpolates_log_log_and_extrapolates_as_one_over_sqrt_t():
    times = np.array([1.0, 2.0, 4.0, 8.0])
    rmses = 3.0 / np.sqrt(times)
    assert time_at_rmse(times, rmses, 3.0 / math.sqrt(3.0)) == (pytest.approx(3.0), False)
    t, extrapolated = time_at_rmse(times, rmses, 3.0 / 4.0)
    assert extrapolated and t == pytest.approx(16.0)


def test_subdivision_is_watertight_and_keeps_area_and_winding():
    scene, _ = make_room()
    mesh, fine = scene.mesh, subdivide_mesh(scene.mesh, 3)
    assert len(fine.faces) == 9 * len(mesh.faces)

    def normals(m):
        p = m.positions.astype(np.float64)
        return np.cross(p[m.faces[:, 1]] - p[m.faces[:, 0]], p[m.faces[:, 2]] - p[m.faces[:, 0]])

    n0, n1 = normals(mesh), normals(fine)
    assert np.linalg.norm(n1, axis=1).sum() == pytest.approx(np.linalg.norm(n0, axis=1).sum(), rel=1e-6)
    assert np.all(np.einsum("ij,ij->i", np.repeat(n0, 9, 0), n1) > 0)

    def open_edges(m):  # edges (by vertex position) used by one face only
        ids = np.unique(m.positions, axis=0, return_inverse=True)[1].ravel()[m.faces]
        edges = np.sort(np.concatenate([ids[:, [0, 1]], ids[:, [1, 2]], ids[:, [2, 0]]]), 1)
        return int(np.sum(np.unique(edges, axis=0, return_counts=True)[1] == 1))

    assert open_edges(fine) == 3 * open_edges(mesh)  # the room's own open edges, each cut in 3


@pytest.fixture(scope="module")
def fallback_run(quick_run, tmp_path_factory):
    """A quick run against scalar_rgb: without libLLVM, the quick run itself; with it, forced."""
    if mb.DEFAULT_VARIANT == "scalar_rgb":
        return quick_run[1]
    from invrender.bench.harness import VARIANT_ENV
    from invrender.bench.render import run

    with pytest.MonkeyPatch.context() as patch:
        patch.setenv(VARIANT_ENV, "scalar_rgb")
        try:
            return run(quick=True, out=tmp_path_factory.mktemp("fallback"))
        finally:  # later tests in this process expect the default variant
            mb.set_variant(mb.DEFAULT_VARIANT)


def test_default_variant_is_llvm_if_libllvm_is_there(quick_run):
    assert quick_run[1]["mitsuba_variant"] == ("llvm_ad_rgb" if mb.llvm_available() else "scalar_rgb")


def test_scalar_fallback_says_so(fallback_run):
    assert fallback_run["mitsuba_variant"] == "scalar_rgb"
    assert any("scalar_rgb" in note for note in fallback_run["notes"])
    assert fallback_run["equal_rmse"][0]["width"] == 16
    assert all(_finite_positive(row["ratio"]) for row in fallback_run["equal_rmse"])


def test_a_report_names_its_folders_by_placeholder(tmp_path):
    work, captures = tmp_path / "work", "/somewhere/captures"
    report = {
        "work": str(work),
        "rows": [{"capture": f"{captures}/box-10-hd", "note": f"reused {captures}/box-10-hd (x.json)", "n": 3}],
        "inputs": [str(work / "living" / "scene")],
    }
    out = portable(report, {str(work): "WORK", captures: "CAPTURES"})
    assert out == {
        "work": "WORK",
        "rows": [{"capture": "CAPTURES/box-10-hd", "note": "reused CAPTURES/box-10-hd (x.json)", "n": 3}],
        "inputs": ["WORK/living/scene"],
    }
