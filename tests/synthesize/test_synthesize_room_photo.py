"""The room photo generator (synthesize/room_photo.py): its captures agree with their truth
(room.json), checked by geometry written here, not by the renderer; and the field of view from
vanishing points (scene/vanishing.py) recovers each room's true one.

The photos are small (320 x 240) and rendered with direct light only (one bounce), to keep the
test fast; the line detector needs the resolution more than the indirect light."""

from __future__ import annotations

import json

import numpy as np
import pytest

from invrender.render.features import Features
from invrender.render.renderer import Renderer
from invrender.scene.room_photo import ROOM_CLASSES, load_room_photo
from invrender.scene.types import SceneError
from invrender.scene.vanishing import estimate_fov
from invrender.synthesize import stage
from invrender.synthesize.room_photo import ROOM_PHOTO_LAYOUTS, yaw_matrix

LAYOUTS = sorted(ROOM_PHOTO_LAYOUTS)
W, H = 320, 240


def _direct_light(scene):
    return Renderer(scene, Features(max_bounces=1, roulette_depth=0))


@pytest.fixture(scope="module")
def captures(tmp_path_factory):
    root = tmp_path_factory.mktemp("rooms")
    out = {}
    for layout in LAYOUTS:
        config = {"layout": layout, "camera": {"width": W, "height": H}, "atlas_resolution": 256}
        stage.run("room_photo", root / layout, config, spp=4, renderer_factory=_direct_light)
        out[layout] = root / layout
    return out


def _truth(capture):
    return json.loads((capture / "truth" / "room.json").read_text())


def test_three_layouts_differ_in_size_window_furniture_and_camera():
    rooms = [ROOM_PHOTO_LAYOUTS[name] for name in LAYOUTS]
    for key in ("size", "objects", "camera"):
        values = [json.dumps(room[key], sort_keys=True) for room in rooms]
        assert len(set(values)) == len(rooms), key
    assert len({room["window"]["wall"] for room in rooms}) == len(rooms)


@pytest.mark.parametrize("layout", LAYOUTS)
def test_the_label_table_is_complete(captures, layout):
    """Every id in the image has a label; every shell part and truth object has its segment."""
    room = load_room_photo(captures[layout], require=("depth", "segmentation"))
    truth = _truth(captures[layout])
    assert (room.width, room.height) == (W, H) and room.fov_y_deg == truth["camera"]["fov_y_deg"]
    assert set(np.unique(room.segments)) <= set(room.labels)  # no 0: the room is closed
    classes = [cls for cls, _ in room.labels.values()]
    assert set(classes) <= set(ROOM_CLASSES)
    assert classes.count("wall") == 4 and classes.count("floor") == classes.count("ceiling") == 1
    panels = [light for light in truth["lights"] if light["kind"] == "ceiling_panel"]
    objects = {obj["segment"]: obj["name"] for obj in truth["objects"]}
    lamps = {light["segment"] for light in truth["lights"] if light["kind"] == "lamp"}  # floor lamps
    assert {i: name for i, (cls, name) in room.labels.items() if cls == "object" or i in lamps} == objects
    assert all(room.labels[i][0] == "lamp" for i in lamps)
    assert classes.count("lamp") == len(panels) + len(lamps)
    assert sorted(room.labels) == list(range(1, len(room.labels) + 1))


def _pixel_points(truth, xs, ys, depth):
    """World points of pixel centres at the given camera z, from room.json's camera."""
    cam = truth["camera"]
    f = cam["height"] / 2 / np.tan(np.radians(cam["fov_y_deg"]) / 2)
    d_cam = np.stack([(xs + 0.5 - cam["width"] / 2) / f, (ys + 0.5 - cam["height"] / 2) / f, np.ones(len(xs))], 1)
    R, t = np.array(cam["R"]), np.array(cam["t"])
    eye = -R.T @ t
    return eye + (d_cam * depth[:, None]) @ R, eye, d_cam @ R


def _shell_plane(name, box):
    """(axis, value) of the plane a shell segment lies on, from the truth box (yaw 0)."""
    sx, sy, sz = box["size"]
    planes = {"floor": (1, 0.0), "ceiling": (1, sy), "wall_-x": (0, -sx / 2), "wall_+x": (0, sx / 2)}
    planes.update({"wall_-z": (2, -sz / 2), "wall_+z": (2, sz / 2)})
    return planes[name]


@pytest.mark.parametrize("layout", LAYOUTS)
def test_depth_is_the_truth_geometrys_camera_z_under_each_segment(captures, layout):
    """At sampled pixels: a shell segment's depth is the camera z where the pixel's ray meets its
    plane of the truth box (exactly); an object's point lies in its box placed by the truth's
    position, yaw and size, and a box object's on one of its faces."""
    room = load_room_photo(captures[layout])
    truth = _truth(captures[layout])
    assert truth["box"]["yaw_deg"] == 0.0 and truth["box"]["center"][1] == truth["box"]["size"][1] / 2
    rng = np.random.default_rng(1)
    ys, xs = rng.integers(0, H, 400), rng.integers(0, W, 400)
    depth, ids = room.depth[ys, xs].astype(np.float64), room.segments[ys, xs]
    points, eye, rays = _pixel_points(truth, xs, ys, depth)
    window = next(light for light in truth["lights"] if light["kind"] == "window")
    objects = {obj["segment"]: obj for obj in truth["objects"]}
    checked = {"shell": 0, "object": 0}
    for k, sid in enumerate(ids):
        cls, name = room.labels[int(sid)]
        if int(sid) not in objects:  # the shell: walls, floor, ceiling, window, ceiling panels
            plane = (
                name
                if cls in ("wall", "floor", "ceiling")
                else "ceiling"
                if cls == "lamp"
                else "wall_" + window["wall"]
            )
            axis, value = _shell_plane(plane, truth["box"])
            z = (value - eye[axis]) / rays[k, axis]  # rays are camera-z scaled: the hit's z is z
            assert depth[k] == pytest.approx(z, rel=1e-4), (name, xs[k], ys[k])
            checked["shell"] += 1
        else:
            obj = objects[int(sid)]
            local = yaw_matrix(obj["yaw_deg"]).T @ (points[k] - np.array(obj["position"]))
            half = np.array(obj["size"]) / 2
            lo, hi = np.array([-half[0], 0, -half[2]]), np.array([half[0], obj["size"][1], half[2]])
            assert np.all(local >= lo - 1e-3) and np.all(local <= hi + 1e-3), (obj["name"], local)
            if obj["category"] == "box":
                assert np.min(np.minimum(np.abs(local - lo), np.abs(local - hi))) < 1e-3, (obj["name"], local)
            checked["object"] += 1
    assert checked["shell"] > 100 and checked["object"] > 10


def test_objects_rest_on_their_support(captures):
    truth = _truth(captures["living"])
    by_segment = {obj["segment"]: obj for obj in truth["objects"]}
    on_top = [obj for obj in truth["objects"] if obj["support"] != "floor"]
    assert on_top  # the crate on the coffee table
    for obj in truth["objects"]:
        below = (
            0.0
            if obj["support"] == "floor"
            else sum(by_segment[int(obj["support"])][key][1] for key in ("position", "size"))
        )
        assert obj["position"][1] == pytest.approx(below)
        assert obj["scale"] == pytest.approx(max(obj["size"]))


@pytest.mark.parametrize("layout", LAYOUTS)
def test_field_of_view_from_vanishing_points(captures, layout):
    """Within 3 degrees of the true vertical field of view (measured at 320 x 240: 0.3 to 2.2 degrees)."""
    room = load_room_photo(captures[layout])
    estimate = estimate_fov(room.image)
    assert estimate is not None and estimate.segments > 50
    assert estimate.fov_y_deg == pytest.approx(room.fov_y_deg, abs=3.0)


@pytest.mark.parametrize(
    "config, field",
    [
        ({"layout": "kitchen"}, "config.layout"),
        (
            {"objects": [{"name": "bed", "kind": "box", "size": [2, 0.5, 2], "position": [2.0, 0.0]}]},
            "objects[0] (bed)",
        ),
        ({"objects": [{"name": "vase", "kind": "box", "size": [0.2] * 3, "position": [0, 0], "on": "table"}]}, "on"),
        ({"camera": {"eye": [9.0, 1.5, 0.0]}}, "config.camera.eye"),
    ],
)
def test_a_room_it_cannot_build_is_refused_naming_the_key(tmp_path, config, field):
    with pytest.raises(SceneError) as info:
        stage.run("room_photo", tmp_path / "capture", config, spp=1, renderer_factory=_direct_light)
    assert field in info.value.expected
    assert not (tmp_path / "capture").exists()


def test_without_camera_json_the_field_of_view_comes_from_vanishing_points(captures, tmp_path):
    import shutil

    capture = tmp_path / "office"
    shutil.copytree(captures["office"], capture)
    (capture / "camera.json").unlink()
    fov, source = load_room_photo(capture).field_of_view()
    assert source == "vanishing points" and fov == pytest.approx(_truth(capture)["camera"]["fov_y_deg"], abs=3.0)
