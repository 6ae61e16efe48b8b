"""The room_materials stage end to end on a room whose photo is a render of the assembled scene
itself (scene/room_scene.assemble_room with known constant materials and light radiances, other
seed): materials.json in bake --room's format and its reports, the fitted lights.json, the
figures; the fitted values near the truth; errors for missing inputs."""

import json

import numpy as np
import pytest

from invrender.render.analysis import analyse
from invrender.render.renderer import Renderer
from invrender.room_materials import stage
from invrender.room_materials.optimise import Eq4Settings
from invrender.scene.cameras import pinhole_camera
from invrender.scene.room_photo import write_room_photo
from invrender.scene.room_scene import assemble_room
from invrender.scene.types import SceneError

BOX = {"center": [0.0, 1.25, 0.0], "size": [3.0, 2.5, 3.5], "yaw_deg": 0.0}
TRUTH = {"floor": [0.3, 0.35, 0.55], "wall": [0.7, 0.6, 0.5], "ceiling": [0.8, 0.8, 0.78]}
LIGHTS = {
    "lights": [
        {
            "kind": "ceiling",
            "name": "ceiling_0_0",
            "center": [-0.5, 2.5, -1.0],
            "e1": [0.7, 0, 0],
            "e2": [0, 0, 0.6],
            "normal": [0, -1, 0],
            "radiance": [6.0] * 3,
        },
        {
            "kind": "ceiling",
            "name": "ceiling_1_0",
            "center": [0.6, 2.5, -0.3],
            "e1": [0.7, 0, 0],
            "e2": [0, 0, 0.6],
            "normal": [0, -1, 0],
            "radiance": [9.0] * 3,
        },
    ],
    "lamps": [],
}
CLASS_IDS = {"wall": 1, "floor": 2, "ceiling": 3, "lamp": 4}
LABELS = {1: ("wall", "walls"), 2: ("floor", "floor"), 3: ("ceiling", "ceiling"), 4: ("lamp", "panels")}


def _room(camera):
    (fx, fy), (cx, cy) = camera.focal, camera.principal_point
    cam = {
        "width": camera.width,
        "height": camera.height,
        "params": [fx, fy, cx, cy],
        "R": camera.R.tolist(),
        "t": camera.t.tolist(),
    }
    return {"box": BOX, "camera": cam}


@pytest.fixture(scope="module")
def capture(tmp_path_factory):
    path = tmp_path_factory.mktemp("room_materials")
    camera = pinhole_camera("photo", [0.4, 1.1, 1.6], [-0.3, 1.55, -1.75], 48, 36, 90.0)
    room = _room(camera)
    materials = {name: {"kd": kd, "ks": 0.04, "ka": 0.25} for name, kd in TRUTH.items()}
    scene = assemble_room(room, [], LIGHTS, materials, texels_per_meter=8)
    out = Renderer(scene, analyse(scene)).render(camera, spp=256, seed=11)
    classes = {i["instance_id"]: i["class"] for i in scene.metadata["instances"]}
    ids = np.vectorize(lambda i: CLASS_IDS[classes[int(i)]])(out["instance_id"]).astype(np.uint16)
    fov_y = float(np.degrees(2 * np.arctan(0.5 * camera.height / camera.focal[1])))
    write_room_photo(path / "capture", out["radiance"].astype(np.float32), None, ids, LABELS, fov_y)
    (path / "room_box").mkdir()
    (path / "room_box" / "room.json").write_text(json.dumps(room))
    (path / "room_lights").mkdir()
    start = json.loads(json.dumps(LIGHTS))
    for q in start["lights"]:
        q["radiance"] = [2.0] * 3  # the room_lights stage's uniform guess
    (path / "room_lights" / "lights.json").write_text(json.dumps(start))
    return path


SETTINGS = stage.MaterialSettings(
    min_width=48, min_crop=8, crop_size=32, init_spp=16, retrieve=False, eval_width=48, eval_spp=16
)


def test_stage_writes_materials_and_lights_near_the_truth(capture):
    out = capture / "out"
    report = stage.run(
        capture / "capture",
        capture / "room_box",
        out,
        lights_dir=capture / "room_lights",
        settings=SETTINGS,
        eq4=Eq4Settings(rounds=4, steps=1, light_spp=32),
    )
    written = json.loads((out / "materials.json").read_text())
    assert written["materials"] == report["materials"]
    assert set(written["materials"]) == {"floor", "ceiling", "wall_mx", "wall_px", "wall_mz", "wall_pz"}
    for name, entry in written["materials"].items():
        truth = TRUTH["wall" if name.startswith("wall") else name]
        # Measured: every wall (wall_pz behind the camera too) 0.709/0.616/0.511, the floor
        # 0.309/0.358/0.565; the ceiling, lit by interreflection alone, 0.769/0.737/0.731 after
        # these 4 rounds (the damped closed form converges there more slowly). Before the damped
        # steps the walls drifted to 0.63 in red (0.51 once pooled), docs/room-materials.md.
        np.testing.assert_allclose(entry["kd"], truth, atol=0.08 if name == "ceiling" else 0.03, err_msg=name)
        assert entry["ka"] == pytest.approx(0.25) and entry["ks"] == pytest.approx(0.04)
    radiance = [written["lights"][f"light_{q['name']}"]["radiance"][0] for q in LIGHTS["lights"]]
    np.testing.assert_allclose(radiance, [6.0, 9.0], rtol=0.05)  # measured 6.02, 9.06
    lights = json.loads((out / "lights.json").read_text())
    assert [q["radiance"][0] for q in lights["lights"]] == pytest.approx(radiance, rel=1e-5)
    assert report["metrics"]["psnr_after"] > report["metrics"]["psnr_before"]
    assert report["crops"] and all(c["source"] == "auto" for c in report["crops"])
    for name in ("thumbnails.png", "room_materials.png"):
        assert (out / name).stat().st_size > 500


def test_stage_refuses_bad_inputs(capture):
    with pytest.raises(SceneError, match="lights.json"):
        stage.run(
            capture / "capture",
            capture / "room_box",
            capture / "bad",
            lights_dir=capture / "nowhere",
            settings=SETTINGS,
        )
    with pytest.raises(SceneError, match="material parts"):
        stage.run(
            capture / "capture",
            capture / "room_box",
            capture / "bad",
            lights_dir=capture / "room_lights",
            settings=SETTINGS,
            user_crops=[{"part": "sofa", "photo": [0, 0, 10, 10]}],
        )
    assert not (capture / "bad").exists()
