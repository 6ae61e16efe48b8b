"""evaluate --room: a room scene against the synthetic truth of its photo.

References: analytic power of a one-sided emitter (pi L A) and of a window under a uniform sky
(pi L A); the truth's own box, objects and lights assembled in the truth's world, whose classes,
emitters and surface must come back as the truth's."""

from __future__ import annotations

import json

import numpy as np
import pytest

from invrender.assets.library import library
from invrender.evaluate import room as evaluate_room
from invrender.scene.format import write_scene
from invrender.scene.room_scene import assemble_room, truth_lights
from invrender.scene.types import Camera, Maps, Mesh


def _quad(normal_sign: float, uv) -> Mesh:
    """A 2 x 0.5 m quad at z = 1, facing -z * normal_sign, all its UVs on one texel."""
    p = np.array([[-1, 0, 1], [1, 0, 1], [1, 0.5, 1], [-1, 0.5, 1]], np.float32)
    faces = np.array([[0, 1, 2], [0, 2, 3]]) if normal_sign > 0 else np.array([[0, 2, 1], [0, 3, 2]])
    return Mesh(p, faces.astype(np.int32), np.tile(np.asarray(uv, np.float32), (4, 1)))


def test_power_of_an_emitter_and_of_a_window_is_pi_radiance_area():
    maps = Maps.uniform((2, 2), ke=0.0, kg=0.0)
    maps.ke[0, 0] = [2.0, 1.0, 0.5]  # texel row 0, col 0: uv (0.25, 0.75)
    maps.kw[1, 1] = 1.0  # uv (0.75, 0.25)
    maps.kg[:] = 3.0  # a uniform sky: irradiance through a window pi * 3
    emitter = evaluate_room.emitted_power(_quad(1, (0.25, 0.75)), maps, room_center=[0, 0, 0])
    assert np.allclose(emitter["emitters"], np.pi * np.array([2.0, 1.0, 0.5]) * 1.0)
    assert np.allclose(emitter["windows"], 0.0)
    for sign in (1, -1):  # either winding: the outward side is the one away from the room
        window = evaluate_room.emitted_power(_quad(sign, (0.75, 0.25)), maps, room_center=[0, 0, 0], scale=2.0)
        assert np.allclose(window["windows"], np.pi * 3.0 * 4.0, rtol=2e-3)  # area 1 m^2 x scale^2


def test_class_iou():
    truth = np.array([[0, 0, 1], [2, 2, 6]])
    ours = np.array([[0, 1, 1], [2, 2, 2]])
    iou = evaluate_room.class_iou(truth, ours)
    assert iou["per_class"]["wall"] == 0.5 and iou["per_class"]["floor"] == 0.5
    assert iou["per_class"]["ceiling"] == 2 / 3 and iou["per_class"]["lamp"] is None
    assert np.isclose(iou["pixel_agreement"], 4 / 6)


def test_the_recovered_world_is_taken_into_the_truths_through_the_photo_camera():
    rng = np.random.default_rng(0)
    q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
    R_t = q * np.sign(np.linalg.det(q))
    truth = Camera("t", "PINHOLE", 4, 3, np.array([2.0, 2, 2, 1.5]), R_t, rng.normal(size=3))
    recovered = Camera("r", "PINHOLE", 4, 3, truth.params, np.eye(3), np.array([0.3, -0.2, 1.0]))
    points = rng.normal(size=(5, 3))  # in the recovered world
    moved = evaluate_room.truth_similarity(recovered, truth, 2.0).matrix()
    in_truth = points @ moved[:3, :3].T + moved[:3, 3]
    # the truth camera sees them where the recovered camera does, scaled by 2
    assert np.allclose(in_truth @ R_t.T + truth.t, 2.0 * (points + recovered.t))


@pytest.fixture(scope="module")
def living_capture(tmp_path_factory):
    """The living room at 96 x 72 (4 spp) written as a capture with its truth."""
    from invrender.synthesize.room_photo import make_room_photo, write_room_capture

    scene, metadata = make_room_photo(
        {"layout": "living", "camera": {"width": 96, "height": 72}, "atlas_resolution": 256, "environment": {"size": 8}}
    )
    out = tmp_path_factory.mktemp("living") / "capture"
    write_room_capture(scene, metadata, out, spp=4)
    return out


def test_the_truth_assembled_scores_as_the_truth(living_capture, tmp_path):
    truth = json.loads((living_capture / "truth" / "room.json").read_text())
    labels = {
        s["id"]: (s["class"], s["name"]) for s in json.loads((living_capture / "panoptic.json").read_text())["segments"]
    }
    lights = truth_lights(truth)
    scene = assemble_room(truth, truth["objects"], lights, assets=library(), labels=labels, texels_per_meter=24)
    write_scene(tmp_path / "scene", scene, scene.metadata)
    (tmp_path / "room_box").mkdir()
    (tmp_path / "room_box" / "room.json").write_text(json.dumps({"box": truth["box"], "metrics": {}}))
    doc = evaluate_room.run(tmp_path / "scene", living_capture, tmp_path / "room_box", tmp_path / "report", spp=2)
    iou = doc["masks"]["per_class"]
    assert all(iou[c] > 0.9 for c in ("wall", "floor", "ceiling", "window", "object")), iou
    assert iou["lamp"] > 0.75  # a few pixels each at 96 x 72
    # Emitters: the panels at their mean radiance and the lamp's shade are the truth's power; the
    # window stands in as an emitter of radiance 1 (pi * its area), the truth's is the sky through it.
    window = next(q for q in lights["lights"] if q["kind"] == "window")
    window_power = np.pi * np.linalg.norm(window["e1"]) * np.linalg.norm(window["e2"])
    power = doc["lights"]["power_w"]
    assert np.allclose(np.subtract(power["recovered"]["emitters"], window_power), power["truth"]["emitters"], rtol=0.02)
    assert power["truth"]["windows"][0] > 0 and power["recovered"]["windows"] == [0.0, 0.0, 0.0]
    # The surface is the truth's: every texel within a centimetre of it.
    assert doc["material"]["correspondence"]["distance_m"]["p95"] < 0.01
    assert (tmp_path / "report" / "photo.png").is_file() and (tmp_path / "report" / "classes.png").is_file()
