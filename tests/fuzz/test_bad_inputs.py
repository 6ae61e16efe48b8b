"""Issue 10's bad inputs (defects 2, 4, 5, 6 and 9), each run as the report ran it: one clear
error (exit 2, one line naming the file and the field) or a run that works, never a signal, a
traceback or a NaN written. docs/reliability.md's "Inputs" table points here."""

import json

import numpy as np
import pytest
from fuzz_runs import check_property
from inputs import (
    good_camera,
    good_image,
    gradient_inputs,
    grid_mesh,
    render_inputs,
    transforms_doc,
    write_colmap_binary,
    write_colmap_text,
    write_json,
    write_obj,
    write_ply,
)

from invrender.render.analysis import unphysical_albedo
from invrender.render.bsdf import directional_albedo, max_albedo
from invrender.scene.images import write_exr
from invrender.scene.types import Maps


def geometry(tmp_path, source, expect_code=2, names=()):
    out = tmp_path / "out"
    outcome = check_property(
        tmp_path,
        out,
        ["geometry", source, "--out", out, "--atlas-resolution", "64"],
        subprocess_run=True,
        names=names or (source.name,),
    )
    assert outcome.code == expect_code, outcome.errors
    return outcome


# ---------------------------------------------------------------------------- defect 2: segfault


@pytest.mark.parametrize("kind", ["obj", "ply_ascii", "ply_binary"])
def test_a_face_index_past_the_vertices_is_a_clear_error_not_a_segfault(tmp_path, kind):
    positions, faces = grid_mesh(6)
    faces[0] = [0, 1, 99998]  # the report's `f 1 2 99999`, 1-based in OBJ
    source = tmp_path / f"bad.{kind.split('_')[0]}"
    write_obj(source, positions, faces) if kind == "obj" else write_ply(source, positions, faces, kind == "ply_binary")
    error = geometry(tmp_path, source).errors[0]
    # OBJ counts from 1 (the file's 99999), PLY from 0 (its 99998)
    assert "face 0" in error and ("99999" if kind == "obj" else "99998") in error, error


# ---------------------------------------------------------------------------- defect 6: degenerate scale


def test_one_vertex_at_1e30_is_refused_naming_the_vertex(tmp_path):
    positions, faces = grid_mesh(12)
    positions[37] = [1e30, 0, 0]
    write_obj(tmp_path / "far.obj", positions, faces)
    error = geometry(tmp_path, tmp_path / "far.obj").errors[0]
    assert "vertex 37" in error and "1e+30" in error, error


@pytest.mark.parametrize("scale, words", [(1e30, "got 1.44e+30 m"), (1e-6, "got 1.44e-06 m")])
def test_a_mesh_scaled_beyond_any_capture_is_refused_at_once(tmp_path, scale, words):
    positions, faces = grid_mesh(12, scale)
    write_ply(tmp_path / "scaled.ply", positions, faces, binary=True)
    error = geometry(tmp_path, tmp_path / "scaled.ply").errors[0]  # the 1e30 mesh hung in xatlas before
    assert "extent" in error and words in error, error


def test_a_stray_vertex_a_kilometre_from_a_one_metre_mesh_is_refused(tmp_path):
    positions, faces = grid_mesh(12)
    positions[5] = [1000.0, 0, 0]  # inside the 10 km box: only the outlier test sees it
    write_obj(tmp_path / "stray.obj", positions, faces)
    assert "vertex 5" in geometry(tmp_path, tmp_path / "stray.obj").errors[0]


def test_a_one_metre_mesh_still_works(tmp_path):
    positions, faces = grid_mesh(12)
    write_obj(tmp_path / "sheet.obj", positions, faces)
    geometry(tmp_path, tmp_path / "sheet.obj", expect_code=0)
    report = json.loads((tmp_path / "out" / "geometry.json").read_text())
    assert report["atlas"]["covered_texels"] > 0.3 * 64 * 64, report["atlas"]


# ---------------------------------------------------------------------------- defect 4: silent NaN cameras


def cameras(tmp_path, source, names):
    out = tmp_path / "out"
    return check_property(tmp_path, out, ["cameras", source, "--out", out], subprocess_run=True, names=names)


@pytest.mark.parametrize("writer", [write_colmap_text, write_colmap_binary])
@pytest.mark.parametrize(
    "params, field",
    [
        ([0.0, 0.0, 16.0, 12.0], "focal length"),  # the report's camera
        ([-30.0, 30.0, 16.0, 12.0], "focal length"),
        ([30.0, 30.0, 500.0, 12.0], "principal point"),
        ([30.0, 30.0, float("nan"), 12.0], "params"),
    ],
)
def test_a_camera_that_cannot_image_is_refused_naming_file_camera_and_field(tmp_path, writer, params, field):
    writer(tmp_path / "sparse", [(1, "PINHOLE", 32, 24, params)], [good_image()])
    outcome = cameras(tmp_path, tmp_path / "sparse", ("cameras.txt", "cameras.bin"))
    # COLMAP's text reader refuses a NaN itself (VerifyParams), without naming the camera
    named = "camera 1" in outcome.errors[0] or (field == "params" and writer is write_colmap_text)
    assert outcome.code == 2 and named and field in outcome.errors[0], outcome.errors


def test_a_non_finite_pose_is_refused(tmp_path):
    write_colmap_text(tmp_path / "sparse", [good_camera()], [(1, [1, 0, 0, 0], [0, float("inf"), 0], 1, "v.png")])
    outcome = cameras(tmp_path, tmp_path / "sparse", ("sparse", "images.txt", "cameras.txt"))
    assert outcome.code == 2, outcome


@pytest.mark.parametrize(
    "doc, field",
    [
        (transforms_doc(fl_x=0.0), "fl_x"),
        (transforms_doc(cx=-100.0), "principal point"),
        (transforms_doc(matrix=np.diag([1.0, 1.0, -1.0, 1.0]).tolist()), "transform_matrix"),  # det -1
        (transforms_doc(matrix=(2 * np.eye(4)).tolist()), "transform_matrix"),  # scale
    ],
)
def test_transforms_json_cameras_are_checked_alike(tmp_path, doc, field):
    write_json(tmp_path / "transforms.json", doc)
    outcome = cameras(tmp_path, tmp_path / "transforms.json", ("transforms.json",))
    assert outcome.code == 2 and "frames[0]" in outcome.errors[0] and field in outcome.errors[0], outcome.errors


def test_render_refuses_a_scene_whose_camera_has_focal_length_0(tmp_path):
    scene = render_inputs(tmp_path)
    doc = json.loads((scene / "scene.json").read_text())
    sparse = scene / doc["cameras"]
    for f in sparse.iterdir():
        f.unlink()
    write_colmap_text(sparse, [(1, "PINHOLE", 32, 24, [0.0, 0.0, 16.0, 12.0])], [good_image("view.exr")])
    out = tmp_path / "renders"
    outcome = check_property(tmp_path, out, ["render", scene, "--out", out, "--spp", "1"], False, ("cameras.txt",))
    assert outcome.code == 2 and "focal length" in outcome.errors[0]


# ---------------------------------------------------------------------------- defect 5: non-finite pixels


@pytest.mark.parametrize("value", [np.nan, np.inf])
def test_a_non_finite_capture_pixel_is_refused_naming_file_and_pixel(tmp_path, value):
    geometry_dir, sparse, images = gradient_inputs(tmp_path)
    image = np.full((24, 32, 3), 0.5, np.float32)
    image[2, 3, 1] = value
    write_exr(images / "view.exr", image)
    out = tmp_path / "gradients"
    outcome = check_property(
        tmp_path,
        out,
        [
            "gradients",
            "--geometry",
            geometry_dir,
            "--cameras",
            sparse,
            "--images",
            images,
            "--out",
            out,
            "--spp",
            "1",
            "--batch",
            "64",
        ],
        False,
        ("view.exr",),
    )
    assert outcome.code == 2 and "pixel (x 3, y 2) channel 1" in outcome.errors[0], outcome.errors


def test_a_nan_loss_is_never_written_as_json(tmp_path, monkeypatch):
    """Should a NaN reach a report by another road, the write fails (allow_nan=False) and the
    output is not created: gradients.json never holds the invalid token NaN again."""
    from invrender.gradients import stage

    geometry_dir, sparse, images = gradient_inputs(tmp_path)
    nan_radiance = lambda self, cameras, requests, spp, seed: (np.full((len(requests), 3), np.nan), None, None)
    monkeypatch.setattr(stage.Renderer, "render_requests", nan_radiance)
    with pytest.raises(ValueError, match="not JSON compliant"):
        stage.run(geometry_dir, sparse, images, tmp_path / "gradients", batch=64, spp=1)
    assert not (tmp_path / "gradients").exists()


# ---------------------------------------------------------------------------- defect 9: accepted nonsense


@pytest.mark.parametrize("spp", ["0", "-4"])
def test_render_refuses_a_sample_count_below_1(tmp_path, spp):
    scene = render_inputs(tmp_path)
    out = tmp_path / "renders"
    outcome = check_property(tmp_path, out, ["render", scene, "--out", out, "--spp", spp], False, ("--spp",))
    assert outcome.code == 2 and f"got {spp}" in outcome.errors[0]


@pytest.mark.parametrize("flag", ["--spp", "--batch"])
def test_gradients_refuses_a_count_below_1(tmp_path, flag):
    geometry_dir, sparse, images = gradient_inputs(tmp_path)
    out = tmp_path / "gradients"
    argv = ["gradients", "--geometry", geometry_dir, "--cameras", sparse, "--images", images, "--out", out, flag, "0"]
    assert check_property(tmp_path, out, argv, False, (flag,)).code == 2


def test_render_refuses_a_scene_without_cameras(tmp_path):
    scene = render_inputs(tmp_path)
    doc = json.loads((scene / "scene.json").read_text())
    del doc["cameras"]
    (scene / "scene.json").write_text(json.dumps(doc))
    out = tmp_path / "renders"
    outcome = check_property(tmp_path, out, ["render", scene, "--out", out, "--spp", "1"], False, ("scene.json",))
    assert outcome.code == 2 and "cameras" in outcome.errors[0]


def test_an_albedo_above_1_renders_with_one_warning_naming_map_and_texel(tmp_path):
    scene = render_inputs(tmp_path, ks=1.0, kd=(0.8, 0.8, 0.8))  # the report's ks = 1
    out = tmp_path / "renders"
    assert check_property(tmp_path, out, ["render", scene, "--out", out, "--spp", "1"], False).code == 0
    warnings = [line for line in (tmp_path / "run.log").read_text().splitlines() if " WARNING " in line]
    albedo = [line for line in warnings if "directional albedo" in line]
    assert len(albedo) == 1 and "map ks" in albedo[0] and "texel (x 0, y 0)" in albedo[0], warnings
    rho = float(albedo[0].split("directional albedo ")[1].split()[0])
    reference = float(directional_albedo(0.0, np.full(3, 0.8), np.ones(3), 0.1, n=256).max())
    assert abs(rho - reference) < 0.01 * reference and reference > 1.5, (albedo, reference)


def test_ordinary_materials_raise_no_albedo_warning():
    # MILO's lobes exceed 1 towards grazing for kd 0.9, ks 0.04 (max_albedo 1.4): not worth a warning
    assert max_albedo(np.full(3, 0.9), np.full(3, 0.04), 0.1).max() > 1.3
    assert unphysical_albedo(Maps.uniform(size=(4, 4), kd=0.9, ks=0.04, ka=0.1)) is None
    assert unphysical_albedo(Maps.uniform(size=(4, 4), kd=0.99, ks=0.0, ka=0.1)) is None


@pytest.mark.parametrize(
    "flags, field",
    [
        (["--max-bounces", "-1"], "max_bounces"),
        (["--min-bounces", "5", "--max-bounces", "2"], "min_bounces"),
        (["--bounce-fraction", "2"], "bounce_fraction"),
        (["--set", "nope=1"], "nope"),
    ],
)
def test_features_refuses_settings_outside_their_meaning(tmp_path, flags, field):
    scene = render_inputs(tmp_path)
    out = tmp_path / "features.json"
    outcome = check_property(tmp_path, out, ["features", scene, "--out", out, *flags], False, ("features --",))
    assert outcome.code == 2 and field in outcome.errors[0], outcome.errors


def test_colmap_verify_params_names_the_cameras_file(tmp_path):
    write_colmap_text(tmp_path / "sparse", [(1, "PINHOLE", 32, 24, [30.0, 30.0])], [good_image()])
    outcome = cameras(tmp_path, tmp_path / "sparse", ("cameras.txt",))
    assert outcome.code == 2 and "camera params" in outcome.errors[0] and "Check failed" not in outcome.errors[0]


def test_colmap_missing_rig_names_the_frames_file(tmp_path):
    sparse = tmp_path / "sparse"
    write_colmap_text(sparse, [good_camera()], [good_image()])
    (sparse / "rigs.txt").write_text("1 1 CAMERA 1\n")
    (sparse / "frames.txt").write_text("1 42 1 0 0 0 0 0 0 1 CAMERA 1 1\n")
    outcome = cameras(tmp_path, sparse, ("frames.txt",))
    assert outcome.code == 2 and "rig_id" in outcome.errors[0] and "42" in outcome.errors[0], outcome.errors


# ---------------------------------------------------------------------------- found by the fuzz suite


@pytest.mark.parametrize("reader", ["read_image", "read_mask"])
def test_an_empty_image_file_is_a_clear_error(tmp_path, reader):
    """Fuzz finding: OpenCV raises cv2.error (a traceback naming no file) on an empty buffer."""
    from invrender.scene import images

    (tmp_path / "mask.png").write_bytes(b"")
    with pytest.raises(images.SceneError, match=r"mask\.png: \(file\): expected"):
        getattr(images, reader)(tmp_path / "mask.png")


def test_a_mesh_a_few_millimetres_across_is_unwrapped(tmp_path):
    """Fuzz finding: xatlas took every face of a 1.4 mm sheet as degenerate and made no atlas (a
    RuntimeError traceback); it now charts a copy scaled by a power of two."""
    positions, faces = grid_mesh(4, 1e-3)
    write_obj(tmp_path / "tiny.obj", positions, faces)
    geometry(tmp_path, tmp_path / "tiny.obj", expect_code=0)
    atlas = json.loads((tmp_path / "out" / "geometry.json").read_text())["atlas"]
    assert atlas["utilisation"] > 0.5, atlas
    # 64 texels across a 1 mm sheet, less the padding: about 60,000 texels per metre
    assert 4e4 < atlas["texel_density_per_m"] < 6.4e4, atlas


def test_import_names_the_obj_file_of_a_far_vertex(tmp_path):
    """Fuzz finding: `import` read OBJ parts unchecked, so a vertex at 1e30 was refused only when
    the scene was written, naming "(scene in memory)" instead of the file."""
    from objscene import write_room

    files = write_room(tmp_path / "files", lambda path, radiance: write_exr(path, np.ones((8, 16, 3), np.float32)))
    box = files / "box.obj"
    box.write_text(box.read_text().replace("v -0.6 0.0 -0.9", "v -0.6 1e30 -0.9", 1))
    out = tmp_path / "scene"
    outcome = check_property(tmp_path, out, ["import", files, "--out", out, "--cube-size", "8"], True, ("box.obj",))
    assert outcome.code == 2 and "extent" in outcome.errors[0], outcome.errors
