"""The features stage through the CLI, on a scene directory written to disk."""

import json

import pytest

from invrender.cli import main


def test_features_stage_writes_its_evidence_and_takes_overrides(stage_scene_dir, tmp_path):
    out = tmp_path / "features.json"
    assert (
        main(["features", str(stage_scene_dir), "--out", str(out), "--set", "specular=false", "--set", "max_bounces=2"])
        == 0
    )
    doc = json.loads(out.read_text())
    assert doc["features"]["specular"] is False and doc["features"]["max_bounces"] == 2
    assert doc["features"]["window"] is True and doc["evidence"]["max_ks"] == pytest.approx(0.3)
    assert doc["evidence"]["overrides"] == {"specular": False, "max_bounces": 2}
