"""A mode per scene: what a capture of each mode must hold, checked when the workflow starts
(before any job, one message naming the scene, the key and the path), and what `all` asks for
in each mode. Dry runs on captures laid out in a temporary directory: the files are empty, since
the checks look at what is there, not inside (the stages that read the files check those)."""

from __future__ import annotations

import pytest
import yaml
from workflow_helpers import TEST_CONFIG, job_counts, snakemake

COLMAP = ["sparse/cameras.txt", "sparse/images.txt"]


def lay_out(root, files):
    """Empty files (and the folders they are in) at the given paths under ``root``."""
    for name in files:
        path = root / name
        path.parent.mkdir(parents=True, exist_ok=True)
        path.touch()


def dry_run(tmp_path, scenes, *targets, check=True):
    """`snakemake -n` with only ``scenes`` in the config."""
    config = tmp_path / "scenes.yaml"
    config.write_text(yaml.safe_dump({"scenes": scenes}))
    return snakemake(tmp_path, "-n", *targets, config=config, check=check)


# What a duplicates capture with cameras (a model, or a photograph's lens) builds: its one camera,
# the segment checkpoint, the poses and shared mesh, the mesh unwrapped, the scene baked, and what
# reads the scene. (duplicates_crop joins once the checkpoint has run.)
DUPLICATES_CHAIN = (
    "cameras",
    "segment",
    "duplicates",
    "geometry",
    "duplicates_material",
    "bake_duplicates",
    "features",
    "render",
    "export",
)
DUPLICATES_CHAIN += ("accuracy", "summary")


def test_duplicates_and_room_captures_with_only_a_photograph_pass(tmp_path):
    """One photograph (with masks, or with depth and a segmentation, or nothing else) is a valid
    duplicates or room capture. A duplicates photograph with a field of view or a focal length
    gets its camera from the cameras rule and goes the whole way; without either nothing can
    run, and the workflow says what each will get once its stages land."""
    lay_out(
        tmp_path,
        [
            "shelf/images/IMG_0001.jpg",
            "shelf/masks.png",
            "boxes/images/a.exr",
            "boxes/images/a.png",
            "boxes/masks/1.png",
            "boxes/masks/2.png",
            "tins/images/one.jpg",
            "tins/images/two.jpg",
            "living/images/photo.exr",
            "living/depth.exr",
            "living/panoptic.png",
            "living/labels.json",
            "bare/images/photo.png",
        ],
    )
    scenes = {
        "shelf": {"mode": "duplicates", "capture": {"path": "shelf", "masks": "masks.png", "field_of_view": 60}},
        "boxes": {
            "mode": "duplicates",
            "capture": {"path": "boxes", "masks": "masks", "focal_length": 900},
            "segment": {"backend": "provided"},
        },
        "tins": {"mode": "duplicates", "capture": {"path": "tins", "image": "images/two.jpg"}},
        "living": {
            "mode": "room",
            "capture": {
                "path": "living",
                "depth": "depth.exr",
                "field_of_view": 70,
                "segmentation": {"ids": "panoptic.png", "labels": "labels.json"},
            },
        },
        "bare": {"mode": "room", "capture": {"path": "bare"}},
    }
    result = dry_run(tmp_path, scenes, "-p")
    # shelf and boxes: the whole chain; living: its camera and its room box; bare (no depth, no
    # segmentation): nothing, with a warning saying what to provide
    assert job_counts(result.stdout) == {
        **dict.fromkeys(DUPLICATES_CHAIN, 2),
        "cameras": 3,
        "room_box": 1,
        "room_lights": 1,
        "room_objects": 1,
        "room_materials": 1,
        "bake_room": 1,  # living's room scene, with features, render and export on it
        "features": 3,
        "render": 3,
        "export": 3,
        "all": 1,
    }
    assert "room-box living --out results/living/room_box" in result.stdout
    assert "room-lights living --room results/living/room_box --out results/living/room_lights" in result.stdout
    assert "room-objects living --room results/living/room_box --out results/living/room_objects" in result.stdout
    assert "the room capture 'bare' lacks a depth map" in result.stdout
    assert "cameras shelf/images/IMG_0001.jpg --out results/shelf/cameras --field-of-view 60" in result.stdout
    assert "cameras boxes/images/a.exr --out results/boxes/cameras --focal-length 900" in result.stdout
    assert "segment shelf/images/IMG_0001.jpg --out results/shelf/segmentation --backend opencv" in result.stdout
    assert "--backend provided --min-instances 3 --masks boxes/masks" in result.stdout
    assert "scene 'shelf' (duplicates, a capture of your own): builds results/shelf/cameras, " in result.stdout
    assert "scene 'tins' (duplicates, a capture of your own): builds nothing yet" in result.stdout
    assert "the evaluation of the recovered material and light (issue 14)" in result.stdout
    assert "scene 'living' (room, a capture of your own): builds results/living/cameras, " in result.stdout
    assert "the object and material stages (issue 16), which bake_room takes into results/living/scene/" in (
        result.stdout
    )
    assert not (tmp_path / "results").exists()


def test_a_photograph_with_cameras_is_recovered_without_truth(tmp_path):
    """A duplicates photograph with a COLMAP model goes the whole way; with no truth there is
    nothing to evaluate, and asking for it says why."""
    lay_out(tmp_path, ["shelf/images/IMG_0001.jpg", *(f"shelf/{name}" for name in COLMAP)])
    scenes = {"shelf": {"mode": "duplicates", "capture": {"path": "shelf"}}}
    assert job_counts(dry_run(tmp_path, scenes).stdout) == {**dict.fromkeys(DUPLICATES_CHAIN, 1), "all": 1}
    for rule in ("gradients", "milo_train", "bake", "evaluate", "evaluate_duplicates"):
        assert f"rule {rule}:" not in dry_run(tmp_path, scenes).stdout
    result = dry_run(tmp_path, scenes, "results/shelf/report", check=False)
    assert result.returncode != 0 and "results/shelf/report" in result.stdout


def test_a_multiview_capture_is_recovered_end_to_end(tmp_path):
    """The default mode of a capture; an OBJ mesh does as well as mesh.ply. With no truth there
    is no evaluate: the scene directory comes from milo_train and bake."""
    lay_out(tmp_path, ["kitchen/images/v0.png", "kitchen/mesh.obj", *(f"kitchen/{name}" for name in COLMAP)])
    result = dry_run(tmp_path, {"kitchen": {"capture": {"path": "kitchen"}}}, "-p")
    stages = ("cameras", "geometry", "gradients", "milo_train", "bake", "features", "render", "export")
    stages += ("accuracy", "summary", "all")
    assert job_counts(result.stdout) == dict.fromkeys(stages, 1)
    assert "geometry kitchen/mesh.obj --out results/kitchen/geometry" in result.stdout
    assert "cameras kitchen/sparse --out results/kitchen/cameras --images kitchen/images" in result.stdout
    assert "milo --geometry results/kitchen/geometry --cameras results/kitchen/cameras" in result.stdout


MULTIVIEW = ["images/v0.exr", *COLMAP]
PHOTOGRAPH = ["images/photo.jpg"]

# name: (files under kitchen/, the scene's config, texts the message must hold)
BAD_CAPTURES = {
    "a multiview scene without a mesh": (
        MULTIVIEW,
        {"mode": "multiview"},
        ["scenes.kitchen.capture.mesh", "neither mesh.ply nor mesh.obj"],
    ),
    "a named mesh that is not there": (
        MULTIVIEW,
        {"mesh": "scans/room.ply"},
        ["scenes.kitchen.capture.mesh", "kitchen/scans/room.ply"],
    ),
    "a multiview scene without images": (
        ["mesh.ply", *COLMAP],
        {},
        ["scenes.kitchen.capture.path", "kitchen/images", "no images"],
    ),
    "a photograph among several, unnamed": (
        ["images/a.jpg", "images/b.exr", "images/b.png"],
        {"mode": "duplicates"},
        ["scenes.kitchen.capture.image", "kitchen/images", "2 images"],
    ),
    "masks that are not there": (
        PHOTOGRAPH,
        {"mode": "duplicates", "masks": "masks.png"},
        ["scenes.kitchen.capture.masks", "kitchen/masks.png"],
    ),
    "a masks folder without a PNG": (
        [*PHOTOGRAPH, "masks/readme.txt"],
        {"mode": "duplicates", "masks": "masks"},
        ["scenes.kitchen.capture.masks", "kitchen/masks", "no PNG"],
    ),
    "a key of another mode": (
        [*PHOTOGRAPH, "depth.exr"],
        {"mode": "duplicates", "depth": "depth.exr"},
        ["scenes.kitchen.capture.depth", "a duplicates scene takes no depth", "room"],
    ),
    "a depth map that is no EXR": (
        [*PHOTOGRAPH, "depth.png"],
        {"mode": "room", "depth": "depth.png"},
        ["scenes.kitchen.capture.depth", ".exr"],
    ),
    "a segmentation without its labels": (
        [*PHOTOGRAPH, "panoptic.png"],
        {"mode": "room", "segmentation": {"ids": "panoptic.png", "labels": "labels.json"}},
        ["scenes.kitchen.capture.segmentation.labels", "kitchen/labels.json"],
    ),
    "a field of view beside a COLMAP model": (
        [*PHOTOGRAPH, *COLMAP],
        {"mode": "room", "field_of_view": 60},
        ["scenes.kitchen.capture.field_of_view", "sparse"],
    ),
    "a field of view and a focal length": (
        PHOTOGRAPH,
        {"mode": "room", "field_of_view": 60, "focal_length": 500},
        ["scenes.kitchen.capture.focal_length", "not both"],
    ),
}


@pytest.mark.parametrize("name", BAD_CAPTURES)
def test_bad_capture_is_refused_naming_scene_key_and_path(tmp_path, name):
    files, settings, expected = BAD_CAPTURES[name]
    lay_out(tmp_path / "kitchen", files)
    capture = {"path": "kitchen", **{k: v for k, v in settings.items() if k != "mode"}}
    scene = {"capture": capture, **({"mode": settings["mode"]} if "mode" in settings else {})}
    result = dry_run(tmp_path, {"kitchen": scene}, check=False)
    assert result.returncode != 0
    assert "config: scene 'kitchen': " in result.stdout, result.stdout[-2000:]
    for text in expected:
        assert text in result.stdout, result.stdout[-2000:]
    assert not (tmp_path / "results").exists()


def test_a_synthetic_room_photo_is_a_room_scene_made_by_synthesize(tmp_path):
    """Kind room_photo (the fixture tests/workflow/room_photo.yaml) gives mode room: its capture
    is built by synthesize (no cameras rule: its field of view is in camera.json), then its box."""
    result = snakemake(tmp_path, "-n", "-p", config=TEST_CONFIG.with_name("room_photo.yaml"))
    room_scene = {
        "room_objects": 1,
        "room_materials": 1,
        "bake_room": 1,
        "features": 1,
        "render": 1,
        "export": 1,
        "evaluate_room": 1,
    }
    assert job_counts(result.stdout) == {"synthesize": 1, "room_box": 1, "room_lights": 1, **room_scene, "all": 1}
    assert "room-box results/living/capture --out results/living/room_box" in result.stdout
    assert "synthesize room_photo --out results/living/capture" in result.stdout
    refused = dry_run(tmp_path, {"living": {"mode": "multiview", "synthetic": {"kind": "room_photo"}}}, check=False)
    assert "'multiview' disagrees with synthetic.kind 'room_photo', whose capture is room" in refused.stdout


def test_a_room_capture_in_its_own_layout_says_what_it_lacks(tmp_path):
    """photo.exr at the top of the capture is its photograph; without depth.exr and panoptic.png
    + panoptic.json the workflow says so when it starts (the room stages need them), and that the
    field of view will come from vanishing points."""
    lay_out(
        tmp_path,
        [
            "den/photo.exr",
            "den/photo.png",
            "full/photo.jpg",
            "full/depth.exr",
            "full/panoptic.png",
            "full/panoptic.json",
            "full/camera.json",
        ],
    )
    scenes = {
        "den": {"mode": "room", "capture": {"path": "den"}},
        "full": {"mode": "room", "capture": {"path": "full"}},
    }
    result = dry_run(tmp_path, scenes)
    assert "scene 'den': the room capture 'den' lacks a depth map (capture.depth, or depth.exr" in result.stdout
    lacks = "panoptic.png and panoptic.json or panoptic.csv in the capture): the room stages will stop asking for them"
    assert lacks in result.stdout
    assert "scene 'den': no field of view" in result.stdout and "vanishing points" in result.stdout
    assert "scene 'full': the room capture" not in result.stdout and "scene 'full': no field" not in result.stdout
