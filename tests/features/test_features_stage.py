"""The features stage through the CLI, on a scene directory written to disk."""

import json

import pytest
from testscenes import box_room

from invrender.cli import main
from invrender.scene.format import write_scene


@pytest.fixture(scope="module")
def scene_dir(tmp_path_factory):
    path = tmp_path_factory.mktemp("stage") / "scene"
    scene = box_room(window=True, ks=0.3, ka=0.05)
    scene.cameras[0].name = "view.exr"
    write_scene(path, scene)
    return path


def test_features_stage_writes_its_evidence_and_takes_overrides(scene_dir, tmp_path):
    out = tmp_path / "features.json"
    assert main(["features", str(scene_dir), "--out", str(out), "--set", "specular=false", "--set", "max_bounces=2"]) == 0
    doc = json.loads(out.read_text())
    assert doc["features"]["specular"] is False and doc["features"]["max_bounces"] == 2
    assert doc["features"]["window"] is True and doc["evidence"]["max_ks"] == pytest.approx(0.3)
    assert doc["evidence"]["overrides"] == {"specular": False, "max_bounces": 2}
