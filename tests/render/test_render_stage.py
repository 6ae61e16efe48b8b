"""The features and render stages through the CLI, on a scene directory written to disk."""

import json

import numpy as np
import OpenEXR
import pytest
from testscenes import box_room

from invrender.cli import main
from invrender.scene.format import write_scene
from invrender.scene.images import read_image


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


def test_render_stage_writes_radiance_previews_and_exact_id_aovs(scene_dir, tmp_path):
    out = tmp_path / "renders"
    assert main(["render", str(scene_dir), "--out", str(out), "--spp", "4"]) == 0
    radiance = read_image(out / "view.exr")
    assert radiance.shape == (24, 32, 3) and np.isfinite(radiance).all() and radiance.mean() > 0
    assert (out / "view.png").stat().st_size > 100
    ids = OpenEXR.File(str(out / "aovs" / "view_triangle.exr")).channels()["Y"].pixels
    assert ids.dtype == np.uint32 and ids.min() >= 1 and ids.max() <= 18  # every pixel hits the closed room
    depth = read_image(out / "aovs" / "view_depth.exr")[..., 0]
    assert np.all((depth > 0.05) & (depth < 6.0))


def test_render_stage_names_a_missing_camera_and_writes_nothing(scene_dir, tmp_path):
    out = tmp_path / "renders"
    with pytest.raises(ValueError, match="no camera named nope"):
        main(["render", str(scene_dir), "--out", str(out), "--camera", "nope"])
    assert not out.exists()
