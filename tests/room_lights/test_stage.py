"""The room_lights stage end to end on a photo that is itself s_true times a unit-radiance render
of the true box and its lights (independent seed): lights.json's lights are initial_lights',
the scale is s_true within the noise, the figure is written; bad inputs stop with a SceneError."""

import json

import numpy as np
import pytest

from invrender.room_box.box import CEILING, FLOOR, WALL, RoomBox, cast_box
from invrender.room_lights import stage
from invrender.room_lights.lights import initial_lights
from invrender.room_lights.radiance import light_scene, unit_render
from invrender.scene.cameras import pinhole_camera
from invrender.scene.room_photo import write_room_photo
from invrender.scene.types import SceneError

BOX = RoomBox([0.0, 1.5, 0.0], [4.0, 3.0, 6.0], 10.0)
LABELS = {1: ("wall", "walls"), 2: ("floor", "floor"), 3: ("ceiling", "ceiling"), 4: ("lamp", "lamp_a")}
S_TRUE = 2.5


def _room_dir(path, camera):
    (fx, fy), (cx, cy) = camera.focal, camera.principal_point
    cam = {"width": camera.width, "height": camera.height, "params": [fx, fy, cx, cy]}
    cam |= {"R": camera.R.tolist(), "t": camera.t.tolist()}
    path.mkdir()
    (path / "room.json").write_text(json.dumps({"box": BOX.to_json(), "camera": cam}))
    return path


def test_stage_recovers_the_scale_of_a_rendered_photo(tmp_path):
    camera = pinhole_camera("photo", [0.3, 1.4, 2.4], [-0.2, 1.6, -2.5], 64, 48, 60.0)
    classes, _ = cast_box(BOX, camera)
    segments = np.vectorize({WALL: 1, FLOOR: 2, CEILING: 3}.get)(classes).astype(np.int32)
    segments[:4, :4] = 4
    # the lamp in the corner is on the ceiling: a panel among the lights, as the stage finds it
    lights = initial_lights(BOX, camera, segments=segments, labels=LABELS).lights
    assert [q.kind for q in lights].count("lamp") == 1
    scene = light_scene(BOX, lights, camera)
    photo = S_TRUE * unit_render(scene, camera, spp=16, seed=7)["radiance"]
    fov_y = float(np.degrees(2 * np.arctan(0.5 * camera.height / camera.focal[1])))
    write_room_photo(tmp_path / "capture", photo.astype(np.float32), None, segments, LABELS, fov_y)
    room = _room_dir(tmp_path / "room_box", camera)

    report = stage.run(tmp_path / "capture", room, tmp_path / "out", spp=16, max_width=64)
    written = json.loads((tmp_path / "out" / "lights.json").read_text())
    assert written["radiance_scale"] == report["radiance_scale"]
    assert report["radiance_scale"] == pytest.approx(S_TRUE, rel=0.03)
    expected = initial_lights(BOX, camera, segments=segments, labels=LABELS)
    assert [q["name"] for q in written["lights"]] == [q.name for q in expected.lights]
    assert written["lamps"] == [] and "lamp_a" in [q["name"] for q in written["lights"]]
    assert (tmp_path / "out" / "room_lights.png").stat().st_size > 1000

    (room / "room.json").write_text(json.dumps({"box": {"center": [0, 0, 0]}}))
    with pytest.raises(SceneError, match="room.json"):
        stage.run(tmp_path / "capture", room, tmp_path / "out2")
    assert not (tmp_path / "out2").exists()
