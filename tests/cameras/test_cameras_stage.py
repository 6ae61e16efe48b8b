"""The cameras stage through the CLI: a transforms.json in, a COLMAP text model out that
projects like the OpenGL camera it came from; a file with no camera stops with exit 2."""

import json

import numpy as np

from invrender.cli import main
from invrender.scene.cameras import project_points, read_cameras


def test_transforms_json_becomes_a_colmap_text_model_that_projects_the_same(tmp_path):
    # An OpenGL camera at (0, 0, 3) looking down -z at the origin: a point on the axis lands
    # on the principal point, one 1 m to the right at x = cx + f / 3.
    c2w = np.eye(4)
    c2w[2, 3] = 3.0
    doc = {
        "fl_x": 300,
        "fl_y": 300,
        "cx": 32,
        "cy": 24,
        "w": 64,
        "h": 48,
        "frames": [{"file_path": "images/a.png", "transform_matrix": c2w.tolist()}],
    }
    (tmp_path / "transforms.json").write_text(json.dumps(doc))
    out = tmp_path / "cameras"
    assert main(["cameras", str(tmp_path / "transforms.json"), "--out", str(out)]) == 0
    assert {"cameras.txt", "images.txt"} <= {p.name for p in out.iterdir()}
    (camera,) = read_cameras(out)
    pixels = project_points(camera, np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0]]))
    np.testing.assert_allclose(pixels, [[32, 24], [32 + 100, 24]], atol=1e-9)


def test_a_model_without_cameras_is_refused_and_nothing_is_written(tmp_path):
    (tmp_path / "transforms.json").write_text(json.dumps({"fl_x": 300, "w": 64, "h": 48, "frames": []}))
    out = tmp_path / "cameras"
    assert main(["cameras", str(tmp_path / "transforms.json"), "--out", str(out)]) == 2
    assert not out.exists()
