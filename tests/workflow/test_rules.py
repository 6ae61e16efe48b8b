"""Each rule run alone on toy inputs, its outputs checked for content.

The synthetic captures are built once per module (that is the synthesize rule's test); every
other test targets one rule's outputs, so that rule and nothing else runs. Beside the two
synthetic scenes there is a user capture, `mine`: the room's capture copied the way a user
would bring it (mesh.ply, images/, cameras as a transforms.json instead of COLMAP), and
`binary`, the same with the cameras as a binary COLMAP model in COLMAP's own sparse/0/.
"""

from __future__ import annotations

import json
import shutil

import numpy as np
import pytest
import yaml
from workflow_helpers import colmap_image_names, job_counts, ran_jobs, read_image, read_json, snakemake

VIEWS = {"room": 2, "boxes": 1}
WIDTH, HEIGHT = 32, 24  # the room's views
SIZES = {"room": (HEIGHT, WIDTH), "boxes": (360, 480)}  # tests/workflow/config.yaml
GL_TO_CV = np.diag([1.0, -1.0, -1.0])


def write_transforms_json(cameras, path):
    """The nerfstudio convention: camera-to-world with OpenGL camera axes, intrinsics per frame."""
    frames = []
    for cam in cameras:
        fx, fy, cx, cy = cam.params[:4]
        c2w = np.eye(4)
        c2w[:3, :3] = cam.R.T @ GL_TO_CV
        c2w[:3, 3] = -cam.R.T @ cam.t
        frames.append(
            {
                "file_path": f"images/{cam.name}",
                "transform_matrix": c2w.tolist(),
                "fl_x": fx,
                "fl_y": fy,
                "cx": cx,
                "cy": cy,
                "w": cam.width,
                "h": cam.height,
            }
        )
    path.write_text(json.dumps({"frames": frames}, indent=1))


@pytest.fixture(scope="module")
def built(tmp_path_factory, test_config):
    """A working directory with both synthetic captures made (the synthesize rule alone) and
    the user capture `mine`; returns (workdir, config file)."""
    from invrender.scene.cameras import read_cameras

    workdir = tmp_path_factory.mktemp("rules")
    import pycolmap

    users = {name: {"capture": {"path": f"captures/{name}"}} for name in ("mine", "binary")}
    config = dict(test_config, scenes=dict(test_config["scenes"], **users))
    result = snakemake(workdir, "--cores", "2", "results/room/capture", "results/boxes/capture")
    assert job_counts(result.stdout) == {"synthesize": 2}

    capture = workdir / "captures" / "mine"
    (capture / "images").mkdir(parents=True)
    shutil.copy(workdir / "results/room/capture/mesh.ply", capture / "mesh.ply")
    for png in (workdir / "results/room/capture/images").glob("*.png"):
        shutil.copy(png, capture / "images" / png.name)
    cameras = read_cameras(workdir / "results/room/capture/sparse")
    for cam in cameras:  # transforms.json names the PNGs the user has
        cam.name = cam.name.rsplit(".", 1)[0] + ".png"
    write_transforms_json(cameras, capture / "transforms.json")
    binary = workdir / "captures" / "binary"
    (binary / "sparse" / "0").mkdir(parents=True)
    shutil.copytree(workdir / "results/room/capture/images", binary / "images")  # the EXRs it names
    shutil.copy(capture / "mesh.ply", binary / "mesh.ply")
    pycolmap.Reconstruction(str(workdir / "results/room/capture/sparse")).write_binary(str(binary / "sparse" / "0"))
    config_file = workdir / "config.yaml"
    config_file.write_text(yaml.safe_dump(config))
    return workdir, config_file


def test_synthesize_writes_captures(built):
    workdir, _ = built
    for scene, views in VIEWS.items():
        capture = workdir / "results" / scene / "capture"
        exrs = sorted((capture / "images").glob("*.exr"))
        assert len(exrs) == views
        for exr in exrs:
            image = read_image(exr)
            assert image.shape == (*SIZES[scene], 3)
            assert np.isfinite(image).all() and (image >= 0).all() and image.mean() > 0
            assert exr.with_suffix(".png").is_file()
            assert (capture / "ground_truth" / "masks" / f"{exr.stem}.png").is_file()
        assert not (capture / "masks").exists()  # the true masks are truth, not user input
        assert colmap_image_names(capture / "sparse") == [exr.name for exr in exrs]
        assert (capture / "mesh.ply").stat().st_size > 0
        assert read_json(capture / "ground_truth/scene/scene.json")
        assert (workdir / "results" / scene / "logs/synthesize.log").stat().st_size > 0
        assert (workdir / "results" / scene / "benchmarks/synthesize.tsv").is_file()
    poses = read_json(workdir / "results/boxes/capture/ground_truth/poses.json")
    assert len(poses["instances"]) == 5


def test_a_duplicates_scene_is_recovered_from_its_photograph(built):
    """segment (a checkpoint), one duplicates_crop per instance it found, duplicates, geometry on
    the recovered mesh, bake_duplicates: a v2 scene with one object per placed instance, all on
    one shared mesh, at the recovered poses. The truth is read by nothing of this."""
    from invrender.scene.format import load_scene
    from invrender.scene.poses import read_poses

    workdir, _ = built
    result = snakemake(workdir, "--cores", "2", "results/boxes/scene")
    instances = read_json(workdir / "results/boxes/segmentation/instances.json")["instances"]
    assert len(instances) >= 3
    assert ran_jobs(result.stdout) == {
        **dict.fromkeys(("cameras", "segment", "duplicates", "geometry", "duplicates_material", "bake_duplicates"), 1),
        "duplicates_crop": len(instances),
    }
    assert "ground_truth" not in result.stdout  # no job of the recovery reads the truth
    crops = workdir / "results/boxes/crops"
    for entry in instances:
        assert (crops / f"instance_{entry['id']:03d}.npz").is_file()
        assert (crops / f"instance_{entry['id']:03d}.features.npz").is_file()
    duplicates = workdir / "results/boxes/duplicates"
    for name in ("poses.json", "poses_colmap.json", "object.ply", "duplicates.json", "overlay.png", "sparse"):
        assert (duplicates / name).exists(), name
    poses = read_poses(duplicates / "poses.json")
    summary = read_json(duplicates / "duplicates.json")
    placed = summary["placed"]
    assert len(placed) >= 3 and set(placed) <= {entry["id"] for entry in instances}
    assert summary["settings"]["step_deg"] == 12 and summary["settings"]["crop_size"] == 160  # the config's
    colmap_names = colmap_image_names(duplicates / "sparse")
    assert len(colmap_names) == len(summary["registered_by_colmap"]) >= 2
    assert read_json(workdir / "results/boxes/geometry/geometry.json")["mesh"]["faces"] > 0
    scene = load_scene(workdir / "results/boxes/scene")
    copies = [obj for obj in scene.objects if obj.material == "object"]
    # the copies and the support plane the material stage recovered (its own material set)
    assert scene.version == 2 and len(copies) == len(placed) and len(scene.objects) == len(placed) + 1
    assert sorted({obj.material for obj in scene.objects}) == ["object", "support"]
    assert len({id(obj.mesh) for obj in copies}) == 1  # instances of one shared mesh
    assert read_json(workdir / "results/boxes/material/training.json")["iterations"] == 3  # the test config's
    for obj, pose in zip(sorted(copies, key=lambda o: o.instance_id), poses_of(poses, placed)):
        np.testing.assert_allclose(obj.transform, pose, atol=1e-5)


def poses_of(poses, ids):
    """The 4 x 4 T_obj2world of each id, in the order of ``ids``."""
    by_id = {entry["instance_id"]: entry["T_obj2world"] for entry in poses["instances"]}
    return [np.asarray(by_id[i]) for i in sorted(ids)]


def test_evaluate_duplicates_scores_the_recovery(built):
    """The report of a synthetic duplicates scene: metrics.json with the keys docs/evaluate.md
    lists, the segmentation scored against the true masks, the recovered scene's appearance, and
    the figures."""
    workdir, _ = built
    snakemake(workdir, "--cores", "2", "results/boxes/scene")  # upstream, if not built here yet
    result = snakemake(workdir, "--cores", "2", "results/boxes/report")
    assert ran_jobs(result.stdout) == {"evaluate_duplicates": 1}
    report = workdir / "results/boxes/report"
    metrics = read_json(report / "metrics.json")
    assert metrics["mode"] == "duplicates"
    assert {"version", "inputs", "paper", "counts", "object", "masks", "poses", "mesh"} <= set(metrics)
    assert metrics["counts"]["truth"] == 5
    segmented = len(read_json(workdir / "results/boxes/segmentation/instances.json")["instances"])
    assert metrics["counts"]["segmented"] == segmented
    assert 0.5 <= metrics["masks"]["mean_iou_matched"] <= 1
    assert metrics["masks"]["matched"] >= 3
    after = metrics["poses"]["after"]
    assert after["registered"] >= 3 and after["rotation"]["error_deg"]["median"] >= 0
    assert metrics["mesh"] is None or metrics["mesh"]["chamfer_m"] > 0
    assert list(report.glob("outlines_*.png"))
    look = metrics["appearance"]  # the scene with the material stage's maps, its time and memory
    assert metrics["inputs"]["scene"] == "results/boxes/scene"
    assert look["material_stage"]["training_seconds"] > 0 and look["material_stage"]["peak_memory_mb"] > 100
    assert 0 < look["env"]["mse"] < 1 and 5 < look["relighting"]["in_place_psnr_db"] < 60
    assert len(list(report.glob("relight_*_in_place.png"))) == 2 and (report / "env_kg.png").is_file()


def test_a_multiview_scene_is_recovered_not_copied(built):
    """The room's scene directory comes from milo_train and bake: its maps are MILO-Net's
    (maps.npz), not the truth's, on the geometry stage's mesh."""
    import shutil

    import numpy as np

    from invrender.scene.format import load_scene

    original, _ = built
    workdir = original.parent / "recovered"  # a copy: the other tests count the jobs they run
    shutil.copytree(original, workdir, symlinks=True)
    result = snakemake(workdir, "--cores", "2", "results/room/scene")
    assert "bake_duplicates" not in job_counts(result.stdout)
    assert {"milo_train", "bake"} <= set(job_counts(result.stdout))
    scene = load_scene(workdir / "results/room/scene")
    with np.load(workdir / "results/room/milo/maps.npz") as maps:
        np.testing.assert_array_equal(scene.maps.kd, maps["kd"])
    truth = load_scene(workdir / "results/room/capture/ground_truth/scene")
    assert scene.maps.kd.shape != truth.maps.kd.shape or not np.array_equal(scene.maps.kd, truth.maps.kd)
    assert read_json(workdir / "results/room/scene/scene.json")["metadata"]["recovered_by"] == "invrender milo + bake"
    assert len((workdir / "results/room/milo/log.csv").read_text().splitlines()) == 1 + 3


def test_cameras_normalises_colmap_and_transforms_json(built):
    from invrender.scene.cameras import read_cameras

    workdir, config = built
    targets = [f"results/{scene}/cameras" for scene in ("room", "mine", "binary")]
    result = snakemake(workdir, "--cores", "2", *targets, config=config)
    assert job_counts(result.stdout) == {"cameras": 3}
    room = read_cameras(workdir / "results/room/cameras")
    assert [c.name for c in room] == colmap_image_names(workdir / "results/room/capture/sparse")
    assert (workdir / "results/room/cameras/cameras.txt").is_file()  # a text model
    assert (workdir / "captures/binary/sparse/0/cameras.bin").is_file()
    for scene in ("mine", "binary"):
        theirs = read_cameras(workdir / "results" / scene / "cameras")
        assert (workdir / "results" / scene / "cameras/images.txt").is_file()
        assert len(theirs) == VIEWS["room"]
        for a, b in zip(room, theirs):  # the same cameras, whichever format they came in
            assert (b.width, b.height) == (WIDTH, HEIGHT)
            np.testing.assert_allclose(b.R, a.R, atol=1e-9)
            np.testing.assert_allclose(b.t, a.t, atol=1e-9)
            np.testing.assert_allclose(b.params[:4], a.params[:4])


def test_geometry_simplifies_and_unwraps(built, test_config):
    from plyfile import PlyData

    workdir, config = built
    result = snakemake(workdir, "--cores", "2", "results/room/geometry", "results/mine/geometry", config=config)
    assert job_counts(result.stdout) == {"geometry": 2}
    target = test_config["geometry"]["target_faces"]
    resolution = test_config["geometry"]["atlas_resolution"]
    for scene in ("room", "mine"):
        geometry = workdir / "results" / scene / "geometry"
        info = read_json(geometry / "geometry.json")
        faces = info["mesh"]["faces"]
        assert 0 < faces <= max(target, info["input"]["faces"]) * 1.05
        assert len(PlyData.read(geometry / "mesh.ply")["face"]) == faces
        with np.load(geometry / "atlas.npz") as atlas:
            assert {"triangle", "barycentric", "position", "normal", "mask"} <= set(atlas.files)
            assert atlas["mask"].shape == (resolution, resolution)
            assert atlas["mask"].mean() > 0.2  # charts cover a good part of the atlas
            assert atlas["triangle"][atlas["mask"]].max() < faces
    # The user's copy of the room gives the room's geometry.
    assert read_json(workdir / "results/mine/geometry/geometry.json")["mesh"]["faces"] == faces


def test_features_analyses_the_scene(built, test_config):
    workdir, _ = built
    snakemake(workdir, "--cores", "2", "results/room/scene")  # upstream, if not built here yet
    result = snakemake(workdir, "--cores", "2", "results/room/features.json")
    assert job_counts(result.stdout) == {"features": 1}
    document = read_json(workdir / "results/room/features.json")
    assert set(document["features"]) == {
        "specular",
        "emission",
        "emitter_sampling",
        "environment",
        "window",
        "env_sampling",
        "one_sided",
        "nee",
        "max_bounces",
        "roulette_depth",
        "w_env",
        "w_emit",
    }
    # The recovered room: emission where its maps emit, the specular lobe where they are glossy.
    from invrender.scene.format import load_scene

    maps = load_scene(workdir / "results/room/scene").maps
    assert document["features"]["emission"] == bool(maps.ke.max() > 0)
    assert document["features"]["specular"] == bool(maps.ks.max() > settings_of(document)["specular_threshold"])
    settings = document["evidence"]["settings"]
    assert settings["bounce_fraction"] == 0.01 and settings["max_bounces"] == 10


def settings_of(document):
    return document["evidence"]["settings"]


def test_gradients_writes_every_map(built, test_config):
    workdir, config = built
    snakemake(workdir, "--cores", "2", "results/room/geometry", "results/room/cameras", config=config)
    result = snakemake(workdir, "--cores", "2", "results/room/gradients", config=config)
    assert job_counts(result.stdout) == {"gradients": 1}
    gradients = workdir / "results/room/gradients"
    report = read_json(gradients / "gradients.json")
    assert report["rays"] == test_config["gradients"]["batch"] and report["loss"] > 0
    atlas = test_config["geometry"]["atlas_resolution"]
    for name in ("kd", "ks", "ka", "ke", "kw", "kg"):
        values = read_image(gradients / f"{name}.exr")
        assert np.isfinite(values).all() and np.abs(values).sum() > 0, name
        if name != "kg":
            assert values.shape[:2] == (atlas, atlas), (name, values.shape)
        assert (gradients / f"{name}.png").is_file()


def test_render_writes_every_view(built):
    workdir, _ = built
    snakemake(workdir, "--cores", "2", "results/room/features.json")  # upstream, if not built here yet
    result = snakemake(workdir, "--cores", "2", "results/room/renders")
    assert job_counts(result.stdout) == {"render": 1}
    renders = workdir / "results/room/renders"
    exrs = sorted(renders.glob("*.exr"))
    assert [p.stem for p in exrs] == [p.stem for p in sorted((workdir / "results/room/capture/images").glob("*.exr"))]
    for exr in exrs:
        image = read_image(exr)
        assert image.shape == (HEIGHT, WIDTH, 3) and np.isfinite(image).all() and image.mean() > 0
        assert exr.with_suffix(".png").is_file()
        for aov in ("depth", "normal", "uv", "instance", "triangle"):
            assert (renders / "aovs" / f"{exr.stem}_{aov}.exr").is_file()


def test_export_writes_valid_usd_with_instanced_duplicates(built, test_config):
    from pxr import Usd, UsdGeom, UsdLux

    from invrender.export import validate_usd

    workdir, _ = built
    snakemake(workdir, "--cores", "2", "results/room/scene", "results/boxes/scene")  # upstream, if not built here yet
    result = snakemake(
        workdir, "--cores", "2", "-p", "results/room/export", "results/boxes/export", "--config", "export={usdc: true}"
    )
    assert job_counts(result.stdout) == {"export": 2}
    for scene in ("room", "boxes"):
        export = workdir / "results" / scene / "export"
        for layer in ("scene.usda", "scene.usdc"):
            assert validate_usd(export / layer) == [], (scene, layer)
        stage = Usd.Stage.Open(str(export / "scene.usda"))
        assert UsdGeom.GetStageMetersPerUnit(stage) == 1.0 and UsdGeom.GetStageUpAxis(stage) == "Y"
        cameras = [p for p in stage.Traverse() if p.IsA(UsdGeom.Camera)]
        assert len(cameras) == VIEWS[scene]
        summary = read_json(export / "export.json")
        assert summary["prims"]["cameras"] == VIEWS[scene] and summary["prims"]["dome"]
        # a v2 scene (the boxes: one material set, "object") keeps each set's textures in its folder
        kd = export / "textures" / ("object/kd.exr" if scene == "boxes" else "kd.exr")
        assert kd.is_file() and (export / "textures" / "sky_latlong.exr").is_file()
        assert (workdir / "results" / scene / "logs/export.log").stat().st_size > 0
        assert (workdir / "results" / scene / "benchmarks/export.tsv").is_file()
    room = Usd.Stage.Open(str(workdir / "results/room/export/scene.usda"))
    # the recovered room's lights: one per emitting region of its maps (after a few iterations of
    # training, not yet the truth's two panels)
    from invrender.scene.edits import emitter_regions
    from invrender.scene.format import load_scene

    _, regions = emitter_regions(load_scene(workdir / "results/room/scene"))
    assert len([p for p in room.Traverse() if p.HasAPI(UsdLux.MeshLightAPI)]) == regions > 0
    # the boxes: one instance of the one recovered mesh per placed copy
    boxes = Usd.Stage.Open(str(workdir / "results/boxes/export/scene.usda"))
    placed = read_json(workdir / "results/boxes/duplicates/duplicates.json")["placed"]
    assert len([p for p in boxes.Traverse() if p.IsInstance()]) == len(placed) and len(boxes.GetPrototypes()) == 1


def test_user_capture_is_recovered_without_truth(built):
    """A multiview capture of one's own goes the whole way (milo_train, bake, render, export);
    with no truth there is nothing to evaluate, and asking for it says why."""
    workdir, config = built
    result = snakemake(workdir, "-n", "results/mine/renders", "results/mine/export", config=config)
    assert {"milo_train", "bake", "render", "export"} <= set(job_counts(result.stdout))
    assert "bake_duplicates" not in job_counts(result.stdout)
    result = snakemake(workdir, "-n", "results/mine/report", config=config, check=False)
    assert result.returncode != 0 and "results/mine/report" in result.stdout
