"""The quick sweep on the demo room (issue 15's acceptance): every plot drawn, RMSE falling at the
Monte Carlo rate, the floors named with their causes, and the knee meeting the error it states
on another seed, against a reference of its own."""

from __future__ import annotations

import csv
from dataclasses import replace

import pytest

from invrender.accuracy import forward, stage
from invrender.accuracy.budgets import QUICK
from invrender.bench.accuracy import demo_room
from invrender.scene.images import read_image
from invrender.scene.types import SceneError


@pytest.fixture(scope="module")
def room(tmp_path_factory):
    """The demo room (config/config.yaml's generator, two of its views), its features as the
    features stage decides them, and two captured images (bench accuracy's)."""
    root = tmp_path_factory.mktemp("accuracy")
    scene, features = demo_room(root)
    return root, scene, features


@pytest.fixture(scope="module")
def swept(room):
    root, _, _ = room
    document = stage.run(
        root / "scene",
        root / "features.json",
        root / "out",
        images_dir=root / "images",
        default_spp=64,
        gradient_spp=4,
        progress=False,
    )
    return root / "out", document


def test_quick_sweep_draws_every_plot(swept):
    out, document = swept
    for name in ("accuracy_forward.png", "accuracy_gradients.png"):
        image = read_image(out / name)
        assert image.shape[0] > 200 and image.shape[1] > 400, name
        assert image.std() > 0.01, name  # not blank
    with open(out / "accuracy_vs_time.csv", newline="") as handle:
        rows = list(csv.DictReader(handle))
    families = {row["family"] for row in rows}
    assert families == {"forward", "gradients"}
    sweeps = {row["sweep"] for row in rows if row["family"] == "forward"}
    assert sweeps == {"spp", "bounces", "effect", "estimator", "resolution"}
    for column in (
        "spp",
        "max_bounces",
        "specular",
        "emission",
        "environment",
        "nee",
        "width",
        "rmse",
        "rel_mse",
        "time_s",
        "samples_per_s",
        "device",
    ):
        assert all(row[column] not in ("", None) for row in rows if row["family"] == "forward"), column
    # the configured default is one highlighted row per family
    assert sum(row["default"] == "True" for row in rows if row["family"] == "forward") == 1
    assert sum(row["default"] == "True" for row in rows if row["family"] == "gradients") == 1
    text = (out / "accuracy.md").read_text()
    assert "```yaml\nrender:\n  spp:" in text


def test_rmse_falls_with_spp_at_the_monte_carlo_rate(swept):
    _, document = swept
    rate = document["rate"]
    assert rate["spp"][0] == 4 and rate["spp"][-1] >= 64
    assert -0.62 <= rate["slope"] <= -0.38, rate


def test_where_a_curve_flattens_the_report_names_the_cause(swept):
    out, document = swept
    floors = {floor["label"]: floor for floor in document["floors"] if floor["family"] == "forward"}
    # One bounce in a room lit by lamps and bounced light; the glossy table without its lobe.
    assert "bounce limit" in floors["1 bounces"]["cause"]
    assert "specular off" in floors["specular off"]["cause"]
    # the floor is the bias, well above the reference's noise, and above half the error at the top
    assert floors["1 bounces"]["floor"] > 5 * document["reference"]["noise_rmse"]
    # unbiased configurations flatten nowhere: the default (10 bounces) and the other estimator
    assert "default" not in floors
    assert not any(label.startswith(("NEE", "MILO mixture")) for label in floors)
    text = (out / "accuracy.md").read_text()
    assert "1 bounces" in text and "cause: bounce limit" in text and "cause: effect switched off" in text


def test_knee_meets_its_stated_error_on_a_second_seed(room, swept):
    root, scene, features = room
    _, document = swept
    knee = document["knees"]["forward"]
    assert knee["error"] <= knee["factor"] * knee["best"]["rmse"]
    assert document["checks"]["forward"]["met"]
    # a configuration with a floor is never the knee
    assert knee["row"]["label"] not in {floor["label"] for floor in document["floors"]}
    # Independently: a reference of its own (other samples), the knee rendered on another seed.
    again = forward.ForwardSweep(scene, features, scene.cameras[0], replace(QUICK, reference_spp=256))
    row = knee["row"]
    variant = forward.Variant(row["sweep"], row["label"], type(features)(**row["features"]))
    measured = again.measure(variant, row["spp"], seed=987_654_321)
    assert measured["rmse"] <= knee["stated_error"], (measured["rmse"], knee)


def test_unknown_budget_is_refused_before_any_work(room, tmp_path):
    root, _, _ = room
    with pytest.raises(SceneError, match="budget"):
        stage.run(root / "scene", root / "features.json", tmp_path / "out", budget="huge", progress=False)
    assert not (tmp_path / "out").exists()
