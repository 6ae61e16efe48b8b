"""The appearance of a duplicates scene against its truth (evaluate/appearance.py, relight.py) on
cases with a closed-form answer: a recovery that differs from the truth only in its object frame
(turned, scaled, shifted) scores the PSNR cap and zero MSE once aligned, and does not without the
alignment; an albedo halved scores exactly the PSNR of its encoded error without the channel scale
and the cap with it; a roughness quartered (ka / 256) the MSE of r / 4; a sky scaled or turned the
closed-form MSE; the rearranged copies rest where they did, apart and in view; a scene relit against
itself scores the cap; and the stage end to end through the CLI on an exact recovery."""

import json

import numpy as np
import pytest
from test_evaluate_duplicates import OFFSET, Q_TRUE, SCALE, SHIFT, recovered_pose, rot, tree  # noqa: F401

from invrender.cli import main
from invrender.evaluate import appearance as ap
from invrender.evaluate import relight
from invrender.evaluate.duplicates import surface_centroid
from invrender.evaluate.metrics import PSNR_CAP_DB
from invrender.scene.atlas import rasterize_atlas
from invrender.scene.cameras import project_points
from invrender.scene.cubemap import cube_texel_solid_angles, latlong_directions, lookup_cube, texel_directions
from invrender.scene.format import write_scene
from invrender.scene.packing import pack_scene
from invrender.scene.poses import placements
from invrender.scene.types import Atlas, Camera, SceneError, SceneObject
from invrender.synthesize.duplicates import make_duplicates, object_mesh

FRAME = ap.Similarity(SCALE, Q_TRUE, OFFSET)  # the recovered object frame in the true one
GAMMA = 2.2


@pytest.fixture(scope="module")
def box_truth():
    """A colour box (every face its own print) and its atlas; the box moved into a recovered frame
    p' = Q^T (p - o) / s with the same UVs."""
    scene, metadata = make_duplicates({"atlas_resolution": 64, "count": 3, "object": {"kind": "box"}})
    truth = object_mesh(scene, metadata)
    inverse = np.linalg.inv(FRAME.matrix())
    recovered = ap.Similarity(1.0, inverse[:3, :3], inverse[:3, 3]).mesh(truth)
    return truth, recovered, scene.maps.atlas


def errors(truth, recovered_mesh, recovered_atlas, atlas, frame=FRAME):
    corr = ap.aligned_correspondence(recovered_mesh, recovered_atlas.atlas_shape, frame, truth, atlas.atlas_shape)
    return ap.surface_errors(recovered_atlas, atlas, corr)


def scaled(atlas: Atlas, kd=1.0, ka=1.0) -> Atlas:
    return Atlas(kd=atlas.kd * kd, ks=atlas.ks, ka=atlas.ka * ka, ke=atlas.ke, kw=atlas.kw)


def test_the_constant_guess_is_the_surface_mean_and_a_perfect_recovery_beats_it(box_truth):
    truth, recovered, atlas = box_truth
    out = errors(truth, recovered, atlas, atlas)
    guess = out["constant_guess"]
    corr = ap.aligned_correspondence(recovered, atlas.atlas_shape, FRAME, truth, atlas.atlas_shape)
    kd = corr.truth_values(atlas.kd)
    assert guess["map_mse"]["kd"] == pytest.approx(kd.var(axis=0).mean(), rel=1e-5)
    flat = Atlas(
        kd=np.broadcast_to(kd.mean(axis=0), atlas.kd.shape), ks=atlas.ks, ka=atlas.ka, ke=atlas.ke, kw=atlas.kw
    )
    assert errors(truth, recovered, flat, atlas)["albedo"]["psnr_db"] == pytest.approx(
        guess["albedo"]["psnr_db"], rel=1e-9
    )
    assert guess["albedo"]["psnr_db"] < out["albedo"]["psnr_db"] - 10


def test_a_recovery_exact_up_to_its_object_frame_scores_the_cap_once_aligned(box_truth):
    truth, recovered, atlas = box_truth
    out = errors(truth, recovered, atlas, atlas)
    assert out["albedo"]["psnr_db"] == PSNR_CAP_DB and out["albedo"]["psnr_db_unaligned"] == PSNR_CAP_DB
    assert out["roughness"] == {"mse": 0.0, "mse_gamma": 0.0} and out["map_mse"] == {"kd": 0.0, "ks": 0.0, "ka": 0.0}
    assert out["correspondence"]["distance_m"]["max"] < 1e-8  # float32 positions
    # the same texels without the alignment land on other faces of the box
    wrong = errors(truth, recovered, atlas, atlas, ap.Similarity(SCALE, np.eye(3), np.zeros(3)))
    assert wrong["albedo"]["psnr_db"] < 25


def test_a_halved_albedo_and_a_quartered_roughness_score_their_closed_forms(box_truth):
    truth, recovered, atlas = box_truth
    out = errors(truth, recovered, scaled(atlas, kd=0.5, ka=1 / 256), atlas)
    mask = rasterize_atlas(truth, *atlas.atlas_shape).mask  # same UVs: the texels compared
    encoded = np.clip(atlas.kd[mask].astype(np.float64), 0, 1) ** (1 / GAMMA)
    expected = -10 * np.log10(np.mean(((0.5 ** (1 / GAMMA) - 1) * encoded) ** 2))
    assert out["albedo"]["psnr_db_unaligned"] == pytest.approx(expected, rel=1e-9)
    assert out["albedo"]["psnr_db"] == PSNR_CAP_DB  # the per-channel scale undoes the factor
    assert np.allclose(out["albedo"]["linear_scale"], 2.0, rtol=1e-9)
    r = atlas.ka[mask].astype(np.float64) ** 0.25  # ka / 256 is r / 4
    assert out["roughness"]["mse"] == pytest.approx(np.mean((0.75 * r) ** 2), rel=1e-6)


def face_sky(face: int, value: float = 1.0, n: int = 8) -> np.ndarray:
    kg = np.zeros((6, n, n, 3), np.float32)
    kg[face] = value
    return kg


def major_face(d) -> np.ndarray:
    """The cube face of each direction by its largest component (+X -X +Y -Y +Z -Z: 0..5)."""
    axis = np.argmax(np.abs(d), axis=-1)
    sign = np.take_along_axis(d, axis[..., None], -1)[..., 0] < 0
    return 2 * axis + sign


def test_a_scaled_sky_scores_its_closed_form_and_the_albedos_scale_undoes_it():
    truth = np.full((6, 8, 8, 3), 0.25, np.float32)
    out = ap.env_errors(2 * truth, truth, linear_scale=[2.0, 2.0, 2.0])
    expected = (0.5 ** (1 / GAMMA) - 0.25 ** (1 / GAMMA)) ** 2
    assert out["mse"] == pytest.approx(expected, rel=1e-12)
    assert out["mse_solid_angle"] == pytest.approx(expected, rel=1e-12)
    assert out["mse_linear"] == pytest.approx(0.25**2, rel=1e-12)
    assert out["mse_with_albedo_scale"] == 0.0  # kd * 2 and kg / 2 render the same
    assert ap.env_errors(truth, truth)["mse"] == 0.0


def test_a_turned_sky_is_not_turned_back():
    """One bright face (+X); the recovered sky turned 90 degrees about +Y puts it on -Z: the
    sphere-weighted MSE is the two faces' share of the sphere, 1/3; on the lat-long grid, the share
    of its directions on either face."""
    truth = face_sky(0)
    d = texel_directions(8)
    turned = lookup_cube(truth, d @ rot([0, 1, 0], 90.0))  # kg'(d) = kg(R^-1 d): R^-1 d as row d @ R
    assert np.array_equal(turned, face_sky(5))
    out = ap.env_errors(turned, truth)
    assert out["mse_solid_angle"] == pytest.approx(1 / 3, rel=1e-12)
    faces = major_face(latlong_directions(512, 256))
    assert out["mse"] == pytest.approx(np.mean((faces == 0) | (faces == 5)), rel=1e-12)
    assert cube_texel_solid_angles(8).sum() == pytest.approx(4 * np.pi / 6, rel=1e-12)


def copies(scene, metadata):
    return {p["instance_id"]: np.asarray(p["T_obj2world"]) for p in metadata["poses"]["instances"]}


def test_the_rearranged_copies_rest_as_they_did_apart_in_view_and_moved():
    scene, metadata = make_duplicates({"atlas_resolution": 64, "count": 6, "object": {"kind": "box"}})
    mesh, poses = object_mesh(scene, metadata), copies(scene, metadata)
    centroid = surface_centroid(mesh)
    new, info = relight.rearranged_poses(mesh, poses, centroid, scene.cameras[0], seed=3)
    p = np.asarray(mesh.positions, np.float64)
    radius = np.linalg.norm(p - centroid, axis=1).max()
    world = {i: p @ T[:3, :3].T + T[:3, 3] for i, T in new.items()}
    old = {i: p @ T[:3, :3].T + T[:3, 3] for i, T in poses.items()}
    for i in poses:
        assert world[i][:, 1].min() == pytest.approx(old[i][:, 1].min(), abs=1e-12)  # same height: still resting
        assert np.allclose(np.linalg.det(new[i][:3, :3]), 1.0) and 60 <= info["yaw_deg"][str(i)] <= 300
        uv = project_points(scene.cameras[0], world[i])
        assert (uv >= 0).all() and (uv[:, 0] <= scene.cameras[0].width).all() and (uv[:, 1] <= 72).all()
    centres = np.array([new[i][:3, :3] @ centroid + new[i][:3, 3] for i in sorted(new)])
    gaps = np.linalg.norm(centres[:, None, [0, 2]] - centres[None, :, [0, 2]], axis=2) + 9 * np.eye(len(centres))
    assert gaps.min() >= 2 * radius * (1 + relight.LATTICE_CLEARANCE) - 1e-9  # bounding spheres apart
    before = np.array([poses[i][:3, :3] @ centroid + poses[i][:3, 3] for i in sorted(poses)])
    assert np.linalg.norm(centres - before, axis=1).min() > 1e-3  # every copy moved
    # the recovered mesh at T' A lies where the true copy does
    inverse = np.linalg.inv(FRAME.matrix())
    ours = ap.Similarity(1.0, inverse[:3, :3], inverse[:3, 3]).mesh(mesh)
    q = np.asarray(ours.positions, np.float64)
    T = new[2] @ FRAME.matrix()
    assert np.allclose(q @ T[:3, :3].T + T[:3, 3], world[2], atol=1e-7)


def test_a_scene_relit_against_itself_scores_the_cap_and_a_darker_albedo_does_not():
    scene, metadata = make_duplicates({"atlas_resolution": 64, "count": 3, "object": {"kind": "box"}})
    mesh, poses, atlas, camera = (
        object_mesh(scene, metadata),
        copies(scene, metadata),
        scene.maps.atlas,
        scene.cameras[0],
    )
    sky = relight.overcast_sky(16)
    truth = relight.placed_scene(mesh, atlas, poses, sky, camera)
    same, images = relight.compare(truth, relight.placed_scene(mesh, atlas, poses, sky, camera), spp=4, seed=0)
    assert same["psnr_db"] == PSNR_CAP_DB and images[2].sum() == same["pixels"] > 100
    assert 10 < same["noise_floor_psnr_db"] < 60  # another seed's noise
    darker = relight.placed_scene(mesh, scaled(atlas, kd=0.7), poses, sky, camera)
    assert relight.compare(darker, truth, spp=4, seed=0)[0]["psnr_db"] < 35


def test_the_skies_are_new_light():
    warm, overcast = relight.warm_sun_sky(32), relight.overcast_sky(32)
    d = texel_directions(32)
    assert np.unravel_index(np.argmax(warm[..., 0]), warm.shape[:3]) == np.unravel_index(
        np.argmax(d @ relight._unit(20.0, 250.0)), d.shape[:3]
    )  # the sun is where it was put
    assert warm.max() > 50 and overcast.max() < 1.3 and (warm >= 0).all() and (overcast > 0).all()
    up = d[..., 1] > 0
    assert overcast[up][..., 2].mean() > overcast[up][..., 0].mean()  # cool


def test_the_material_stages_cost_is_read_when_there(tmp_path):
    assert ap.read_training(tmp_path / "missing.json") is None
    (tmp_path / "t.json").write_text(json.dumps({"training_seconds": 12.5, "peak_memory_mb": 800, "other": 1}))
    assert ap.read_training(tmp_path / "t.json") == {"training_seconds": 12.5, "peak_memory_mb": 800.0}
    (tmp_path / "bad.json").write_text(json.dumps({"training_seconds": "long"}))
    with pytest.raises(SceneError, match="training_seconds: expected a number >= 0"):
        ap.read_training(tmp_path / "bad.json")


@pytest.fixture(scope="module")
def recovered_scene(tree):  # noqa: F811
    """The recovery of the duplicates tests' tree as a v2 scene directory, exact up to its object
    frame and world (x' = (x - SHIFT) / SCALE): the can at its recovered poses with the true atlas,
    the floor as support, the true sky, the camera moved into that world."""
    scene, metadata = make_duplicates({"atlas_resolution": 64})
    can = object_mesh(scene, metadata)
    world = ap.Similarity(1 / SCALE, np.eye(3), -SHIFT / SCALE)
    inverse = np.linalg.inv(FRAME.matrix())
    mesh = ap.Similarity(1.0, inverse[:3, :3], inverse[:3, 3]).mesh(can)
    poses = {i: p for i, p in copies(scene, metadata).items() if i <= 4}  # registered after refinement
    doc = {"instances": [{"instance_id": i, "T_obj2world": recovered_pose(T)} for i, T in poses.items()]}
    floor = ap._faces_of(scene.mesh, slice(*metadata["floor"]["faces"]))
    objects = [SceneObject("support", world.mesh(floor), "support", instance_id=0)]
    objects += placements(doc, mesh, "object")
    cam = scene.cameras[0]
    centre = (cam.center - SHIFT) / SCALE
    camera = Camera(cam.name, cam.model, cam.width, cam.height, cam.params, cam.R, -cam.R @ centre)
    atlas = scene.maps.atlas
    support = Atlas(**{m: getattr(atlas, m).copy() for m in ("kd", "ks", "ka", "ke", "kw")})
    out = tree["root"] / "scene"
    write_scene(out, pack_scene(objects, {"object": atlas, "support": support}, scene.maps.kg, [camera]))
    training = tree["root"] / "training.json"
    training.write_text(json.dumps({"training_seconds": 61.0, "peak_memory_mb": 512.0}))
    return out, training


def test_the_stage_scores_an_exact_recovery_through_the_cli(tree, recovered_scene, tmp_path):  # noqa: F811
    scene_dir, training = recovered_scene
    args = ["evaluate", "--duplicates", tree["duplicates"], "--segmentation", tree["segmentation"]]
    args += ["--truth", tree["truth"], "--images", tree["images"], "--scene", scene_dir, "--training", training]
    assert main([str(a) for a in [*args, "--spp", "4", "--out", tmp_path / "report"]]) == 0
    doc = json.loads((tmp_path / "report" / "metrics.json").read_text())
    look = doc["appearance"]
    assert doc["inputs"]["scene"] == str(scene_dir) and look["material_stage"] == {
        "training_seconds": 61.0,
        "peak_memory_mb": 512.0,
    }
    for surface in ("object", "support"):
        assert look[surface]["albedo"]["psnr_db"] == PSNR_CAP_DB, surface
        assert look[surface]["roughness"]["mse"] == 0.0 and look[surface]["map_mse"]["kd"] == 0.0
    assert look["env"]["mse"] == 0.0 and look["env"]["mse_linear"] == 0.0
    ours = look["table1"]["ours"]
    assert ours["albedo_psnr_db"] == PSNR_CAP_DB and ours["chamfer_m"] < 1e-8
    relit = look["relighting"]
    assert set(relit["skies"]) == {"warm_sun", "overcast"}
    # rearranged: all six copies at T' A, the support moved back: the truth to float precision
    assert relit["psnr_db"] > 60 and relit["psnr_db"] > relit["noise_floor_psnr_db"] + 30  # 100 (exact) here
    # in place: copies 5 and 6 were never recovered, so their pixels are missing
    assert relit["in_place_psnr_db"] < relit["psnr_db"]
    names = {p.name for p in (tmp_path / "report").iterdir()}
    assert {"object_kd.png", "object_ka.png", "support_kd.png", "env_kg.png"} <= names
    assert {f"relight_{s}_{a}.png" for s in ("warm_sun", "overcast") for a in ("in_place", "rearranged")} <= names
    with pytest.raises(SceneError, match="scene.json: version: expected a v2 scene"):
        ap.recovered_side(tree["truth"] / "scene")


def test_without_an_alignment_the_surface_and_the_rearrangement_are_null(tree, recovered_scene, tmp_path):  # noqa: F811
    ours, truth = ap.recovered_side(recovered_scene[0]), ap.truth_side(tree["truth"])
    look = ap.evaluate(ours, truth, None, tmp_path, spp=1)
    assert look["object"] is None and look["support"] is None and look["table1"]["ours"]["albedo_psnr_db"] is None
    relit = look["relighting"]
    assert relit["psnr_db"] is None and "no alignment" in relit["arrangement"]["reason"]
    assert relit["in_place_psnr_db"] > 5 and look["env"]["mse"] == 0.0 and "mse_with_albedo_scale" not in look["env"]
    small = Camera("view_000.exr", "PINHOLE", 48, 36, np.array([40.0, 40.0, 24.0, 18.0]), np.eye(3), np.zeros(3))
    ours.camera = small
    with pytest.raises(SceneError, match="camera: expected the photograph's 96 x 72, got 48 x 36"):
        ap.evaluate(ours, truth, None, tmp_path / "x", spp=1)


@pytest.mark.parametrize(
    ("model", "params"),
    [("PINHOLE", [1400.0, 1350.0, 800.0, 600.0]), ("SIMPLE_PINHOLE", [1400.0, 790.0, 610.0]),
     ("OPENCV", [1400.0, 1350.0, 800.0, 600.0, -0.1, 0.02, 0.001, -0.002])],
)  # fmt: skip
def test_an_hd_camera_is_scaled_to_the_relighting_size_pixel_for_pixel(model, params):
    R = rot([0.3, 1.0, 0.2], 25.0)
    hd = Camera("view_000.exr", model, 1600, 1200, np.array(params), R, np.array([0.1, -0.2, 1.5]))
    small = relight.scaled_camera(hd)
    assert (small.width, small.height) == (640, 480) and small.model == model
    points = np.random.default_rng(0).uniform(-0.3, 0.3, (50, 3))
    assert np.allclose(project_points(small, points), 0.4 * project_points(hd, points), atol=1e-9)
    assert relight.scaled_camera(small) is small  # already small enough
