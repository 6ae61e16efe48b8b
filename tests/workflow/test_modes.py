"""A mode per scene: what a capture of each mode must hold, checked when the workflow starts
(before any job, one message naming the scene, the key and the path), and what `all` asks for
in each mode. Dry runs on captures laid out in a temporary directory: the files are empty, since
the checks look at what is there, not inside (the stages that read the files check those)."""

from __future__ import annotations

import json
import re

import pytest
import yaml
from workflow_helpers import TEST_CONFIG, job_counts, snakemake

COLMAP = ["sparse/cameras.txt", "sparse/images.txt"]


def lay_out(root, files):
    """Files (and the folders they are in) at the given paths under ``root``: empty for a list of
    paths, with the given text for a mapping of paths to texts."""
    items = files.items() if isinstance(files, dict) else ((name, "") for name in files)
    for name, text in items:
        path = root / name
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(text)


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
    assert "scene 'living' (room, a capture of your own): builds results/living/cameras, " in result.stdout
    # every mode's stages have landed: each capture's line ends saying so
    for name, kind in (("shelf", "duplicates"), ("tins", "duplicates"), ("living", "room")):
        assert re.search(
            rf"scene '{name}' \({kind}, a capture of your own\): builds [^\n]*; once its stages land, "
            r"nothing more: the mode is complete",
            result.stdout,
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


# ---------------------------------------------------------------------------- documented layouts
# Every capture layout that config/README.md ("Your own capture"), docs/captures.md and
# docs/scene-format.md ("Room photo") describe, one scene per dry run. The text files hold what
# their tools write (a COLMAP text model naming the photograph relative to the folder it is in, a
# transforms.json naming it relative to the file's folder, the room's label table and camera.json);
# the images, meshes and binary models are empty: the workflow only looks at what is there.


def colmap_model(*images, folder="sparse"):
    """A COLMAP text model (pycolmap 4's five files) of one pinhole camera per image name, at
    the origin looking down +z."""
    ids = range(1, len(images) + 1)
    return {
        f"{folder}/cameras.txt": "".join(f"{i} PINHOLE 640 480 500 500 320 240\n" for i in ids),
        f"{folder}/images.txt": "".join(f"{i} 1 0 0 0 0 0 0 {i} {name}\n\n" for i, name in zip(ids, images)),
        f"{folder}/points3D.txt": "",
        f"{folder}/rigs.txt": "".join(f"{i} 1 CAMERA {i}\n" for i in ids),
        f"{folder}/frames.txt": "".join(f"{i} {i} 1 0 0 0 0 0 0 1 CAMERA {i} {i}\n" for i in ids),
    }


def transforms_json(*file_paths):
    """A nerfstudio transforms.json: one camera-to-world pose (OpenGL axes) per image."""
    pose = [[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]]
    frames = [{"file_path": path, "transform_matrix": pose} for path in file_paths]
    intrinsics = {"fl_x": 500, "fl_y": 500, "cx": 320, "cy": 240, "w": 640, "h": 480}
    return {"transforms.json": json.dumps({**intrinsics, "frames": frames})}


BINARY_MODEL = {f"sparse/0/{name}.bin": "" for name in ("cameras", "images", "points3D", "rigs", "frames")}
ROOM_LABELS = json.dumps({"segments": [{"id": 1, "class": "wall"}, {"id": 2, "class": "floor"}]})
ROOM_SEGMENTATION = {"panoptic.png": "", "panoptic.json": ROOM_LABELS}
ROOM_INPUTS = {"depth.exr": "", **ROOM_SEGMENTATION}
MULTIVIEW_CHAIN = ("cameras", "geometry", "gradients", "milo_train", "bake", "features", "render", "export")
MULTIVIEW_CHAIN += ("accuracy", "summary")
# A room capture with depth and a segmentation: the box, its lights, objects and materials, the
# room scene and what reads it; its camera too where it brings cameras or a lens.
ROOM_CHAIN = ("room_box", "room_lights", "room_objects", "room_materials", "bake_room", "features", "render", "export")

# name: (files under mine/, the scene's mode and capture keys, the rules planned besides `all`,
#        texts of the plan: the cameras command is `cameras SOURCE --out results/mine/cameras FLAGS`)
LAYOUTS = {
    # multiview: images/, cameras (sparse/, sparse/0/ or transforms.json), a mesh
    "multiview: sparse/ text, mesh.ply": (
        {"images/v0.png": "", "images/v1.png": "", **colmap_model("v0.png", "v1.png"), "mesh.ply": ""},
        {},
        MULTIVIEW_CHAIN,
        ["cameras mine/sparse --out results/mine/cameras --images mine/images\n", "geometry mine/mesh.ply "],
    ),
    "multiview: sparse/0/ binary, EXRs with PNG previews": (
        {"images/v0.exr": "", "images/v0.png": "", **BINARY_MODEL, "mesh.ply": ""},
        {},
        MULTIVIEW_CHAIN,
        ["cameras mine/sparse/0 --out results/mine/cameras --images mine/images\n"],
    ),
    "multiview: transforms.json, mesh.obj": (
        {"images/v0.jpg": "", **transforms_json("images/v0.jpg"), "mesh.obj": ""},
        {"mode": "multiview"},
        MULTIVIEW_CHAIN,
        ["cameras mine/transforms.json --out results/mine/cameras --images mine/images\n", "geometry mine/mesh.obj "],
    ),
    "multiview: a named mesh": (
        {"images/v0.png": "", **colmap_model("v0.png"), "scans/room.ply": ""},
        {"mesh": "scans/room.ply"},
        MULTIVIEW_CHAIN,
        ["geometry mine/scans/room.ply "],
    ),
    # duplicates: the photograph in images/, at the top as photo.*, or named by `image`; its
    # camera from a model, a field of view or a focal length, or none yet
    "duplicates: images/ with one, sparse/": (
        {"images/IMG_0001.jpg": "", **colmap_model("IMG_0001.jpg")},
        {"mode": "duplicates"},
        DUPLICATES_CHAIN,
        [
            "cameras mine/sparse --out results/mine/cameras --images mine/images\n",
            "segment mine/images/IMG_0001.jpg --out results/mine/segmentation",
            "--masks results/mine/segmentation/masks/IMG_0001.png",
        ],
    ),
    "duplicates: images/ with an EXR and its preview, sparse/0/": (
        {"images/a.exr": "", "images/a.png": "", **BINARY_MODEL},
        {"mode": "duplicates"},
        DUPLICATES_CHAIN,
        ["cameras mine/sparse/0 --out results/mine/cameras --images mine/images\n", "segment mine/images/a.exr "],
    ),
    "duplicates: images/ with one, transforms.json": (
        {"images/IMG_0001.jpg": "", **transforms_json("images/IMG_0001.jpg")},
        {"mode": "duplicates"},
        DUPLICATES_CHAIN,
        ["cameras mine/transforms.json --out results/mine/cameras --images mine/images\n"],
    ),
    "duplicates: photo.exr at the top with its preview, sparse/": (
        {"photo.exr": "", "photo.png": "", **colmap_model("photo.exr")},
        {"mode": "duplicates"},
        DUPLICATES_CHAIN,
        ["cameras mine/sparse --out results/mine/cameras --images mine\n", "segment mine/photo.exr "],
    ),
    "duplicates: photo.jpg at the top, transforms.json": (
        {"photo.jpg": "", **transforms_json("photo.jpg")},
        {"mode": "duplicates"},
        DUPLICATES_CHAIN,
        ["cameras mine/transforms.json --out results/mine/cameras --images mine\n", "segment mine/photo.jpg "],
    ),
    "duplicates: photo.png at the top, focal_length": (
        {"photo.png": ""},
        {"mode": "duplicates", "focal_length": 900},
        DUPLICATES_CHAIN,
        ["cameras mine/photo.png --out results/mine/cameras --focal-length 900\n"],
    ),
    "duplicates: image at the top, sparse/": (
        {"image.exr": "", **colmap_model("image.exr")},
        {"mode": "duplicates", "image": "image.exr"},
        DUPLICATES_CHAIN,
        ["cameras mine/sparse --out results/mine/cameras --images mine\n", "segment mine/image.exr "],
    ),
    "duplicates: image among several in images/, field_of_view": (
        {"images/one.jpg": "", "images/two.jpg": ""},
        {"mode": "duplicates", "image": "images/two.jpg", "field_of_view": 60},
        DUPLICATES_CHAIN,
        ["cameras mine/images/two.jpg --out results/mine/cameras --field-of-view 60\n", "segment mine/images/two.jpg "],
    ),
    "duplicates: masks.png for the provided backend": (
        {"images/IMG_0001.jpg": "", "masks.png": ""},
        {"mode": "duplicates", "field_of_view": 60, "masks": "masks.png", "segment": {"backend": "provided"}},
        DUPLICATES_CHAIN,
        ["--backend provided --min-instances 3 --masks mine/masks.png"],
    ),
    "duplicates: masks/ of one PNG per instance": (
        {"photo.exr": "", "masks/1.png": "", "masks/2.png": ""},
        {"mode": "duplicates", "focal_length": 900, "masks": "masks", "segment": {"backend": "provided"}},
        DUPLICATES_CHAIN,
        ["--backend provided --min-instances 3 --masks mine/masks"],
    ),
    "duplicates: a photograph without cameras": (
        {"photo.jpg": ""},
        {"mode": "duplicates"},
        (),
        ["scene 'mine' (duplicates, a capture of your own): builds nothing yet"],
    ),
    # room: the photograph (photo.*, images/ or `image`), depth and a panoptic segmentation in
    # the layout or named, and its field of view from nothing, camera.json, the config or cameras
    "room: its own layout, photo.exr with its preview": (
        {"photo.exr": "", "photo.png": "", **ROOM_INPUTS},
        {"mode": "room"},
        ROOM_CHAIN,
        ["room-box mine --out results/mine/room_box\n", "scene 'mine': no field of view"],
    ),
    "room: its own layout, the labels as panoptic.csv": (
        {"photo.jpg": "", "depth.exr": "", "panoptic.png": "", "panoptic.csv": "id,class,name\n1,wall,\n2,floor,\n"},
        {"mode": "room"},
        ROOM_CHAIN,
        ["room-box mine --out results/mine/room_box\n"],
    ),
    "room: its own layout with camera.json": (
        {"photo.png": "", **ROOM_INPUTS, "camera.json": json.dumps({"width": 640, "height": 480, "fov_y_deg": 55.0})},
        {"mode": "room"},
        ROOM_CHAIN,
        ["room-box mine --out results/mine/room_box\n"],
    ),
    "room: photo.png at the top, field_of_view": (
        {"photo.png": "", **ROOM_INPUTS},
        {"mode": "room", "field_of_view": 70},
        ("cameras", *ROOM_CHAIN),
        [
            "cameras mine/photo.png --out results/mine/cameras --field-of-view 70\n",
            "room-box mine --out results/mine/room_box --fov-x 70\n",
        ],
    ),
    "room: photo.jpg at the top, focal_length": (
        {"photo.jpg": "", **ROOM_INPUTS},
        {"mode": "room", "focal_length": 800},
        ("cameras", *ROOM_CHAIN),
        ["cameras mine/photo.jpg --out results/mine/cameras --focal-length 800\n"],
    ),
    "room: photo.exr at the top, sparse/": (
        {"photo.exr": "", **ROOM_INPUTS, **colmap_model("photo.exr")},
        {"mode": "room"},
        ("cameras", *ROOM_CHAIN),
        ["cameras mine/sparse --out results/mine/cameras --images mine\n"],
    ),
    "room: image at the top, sparse/": (
        {"image.exr": "", **ROOM_INPUTS, **colmap_model("image.exr")},
        {"mode": "room", "image": "image.exr"},
        ("cameras", *ROOM_CHAIN),
        [
            "cameras mine/sparse --out results/mine/cameras --images mine\n",
            "room-box mine --out results/mine/room_box --photo image.exr\n",
        ],
    ),
    "room: images/ with one, transforms.json": (
        {"images/IMG_0001.jpg": "", **ROOM_INPUTS, **transforms_json("images/IMG_0001.jpg")},
        {"mode": "room"},
        ("cameras", *ROOM_CHAIN),
        ["cameras mine/transforms.json --out results/mine/cameras --images mine/images\n"],
    ),
    "room: images/ with one, depth and segmentation named, field_of_view": (
        {"images/photo.exr": "", "maps/depth.exr": "", "maps/ids.png": "", "maps/labels.json": ROOM_LABELS},
        {
            "mode": "room",
            "depth": "maps/depth.exr",
            "segmentation": {"ids": "maps/ids.png", "labels": "maps/labels.json"},
            "field_of_view": 70,
        },
        ("cameras", *ROOM_CHAIN),
        [
            "cameras mine/images/photo.exr --out results/mine/cameras --field-of-view 70\n",
            "room-box mine --out results/mine/room_box --depth maps/depth.exr --ids maps/ids.png"
            " --labels maps/labels.json --fov-x 70\n",
        ],
    ),
    "room: a photograph with a field of view, no depth nor segmentation": (
        {"photo.exr": ""},
        {"mode": "room", "field_of_view": 70},
        ("cameras",),
        ["the room capture 'mine' lacks a depth map", "cameras mine/photo.exr --out results/mine/cameras"],
    ),
}


@pytest.mark.parametrize("name", LAYOUTS)
def test_every_documented_layout_builds_its_plan(tmp_path, name):
    """A dry run on a capture in the layout builds its DAG: the mode's rules, and the cameras
    rule reading the photograph where it is (the folder it is in for a model's image names)."""
    files, settings, rules, texts = LAYOUTS[name]
    lay_out(tmp_path / "mine", files)
    scene = {key: settings[key] for key in ("mode", "segment") if key in settings}
    capture = {key: value for key, value in settings.items() if key not in scene}
    result = dry_run(tmp_path, {"mine": {**scene, "capture": {"path": "mine", **capture}}}, "-p")
    assert job_counts(result.stdout) == {**dict.fromkeys(rules, 1), "all": 1}, result.stdout[-3000:]
    plan = "".join(f"{line.rstrip()}\n" for line in result.stdout.splitlines())  # a command ends at \n
    for text in texts:
        assert text in plan, result.stdout[-3000:]
    assert not (tmp_path / "results").exists()


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
    "a photograph at the top under another name": (
        ["IMG_0001.jpg", *COLMAP],
        {"mode": "duplicates"},
        ["scenes.kitchen.capture.image", "none of photo.exr, photo.png, photo.jpg at its top (it has IMG_0001.jpg)"],
    ),
    "a room capture without a photograph": (
        ["depth.exr", "panoptic.png", "panoptic.json"],
        {"mode": "room"},
        ["scenes.kitchen.capture.image", "kitchen/images", "0 images", "alone in images/"],
    ),
    "a named photograph that is not there": (
        ["photo.exr"],
        {"mode": "duplicates", "image": "image.exr", "field_of_view": 60},
        ["scenes.kitchen.capture.image", "kitchen/image.exr", "does not exist"],
    ),
    "a named photograph that is no image": (
        ["photo.txt"],
        {"mode": "room", "image": "photo.txt"},
        ["scenes.kitchen.capture.image", "kitchen/photo.txt", "expected .exr or .png"],
    ),
    "half a COLMAP model": (
        [*PHOTOGRAPH, "sparse/cameras.txt"],
        {"mode": "duplicates"},
        ["scenes.kitchen.capture.path", "kitchen/sparse' holds cameras.txt but no images.txt or images.bin"],
    ),
    "half a COLMAP model beside a multiview's": (
        [*MULTIVIEW, "mesh.ply", "sparse/0/images.bin"],
        {},
        ["scenes.kitchen.capture.path", "kitchen/sparse/0", "images.bin but no cameras.txt or cameras.bin"],
    ),
    "segment ids without their labels": (
        [*PHOTOGRAPH, "depth.exr", "panoptic.png"],
        {"mode": "room"},
        ["scenes.kitchen.capture.segmentation", "kitchen/panoptic.png", "panoptic.json or panoptic.csv"],
    ),
    "segment labels without their ids": (
        ["photo.png", "depth.exr", "panoptic.csv"],
        {"mode": "room"},
        ["scenes.kitchen.capture.segmentation", "kitchen/panoptic.csv", "put panoptic.png beside it"],
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
    # one line says it all (snakemake adds where in common.smk it was raised), not a DAG error
    # (MissingInputException, InputFunctionException) with the traceback of an input function
    [message] = [line for line in result.stdout.splitlines() if "config: scene 'kitchen': " in line]
    for text in expected:
        assert text in message, result.stdout[-2000:]
    assert "Exception" not in result.stdout and "Traceback" not in result.stdout, result.stdout[-2000:]
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
