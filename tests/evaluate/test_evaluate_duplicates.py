"""The duplicates evaluation (evaluate/duplicates.py) on exact cases: a recovery that differs from
the truth only by what cannot be known (the object frame, the world's scale and offset) scores 0;
known per-instance rotations score exactly their angle, a can's twist as twist; IoU of shifted
rectangles is the closed form; the Hungarian matching undoes a permutation; Chamfer of parallel
squares is their gap; and the stage end to end on a synthetic capture's truth, with its CLI."""

import json

import cv2
import numpy as np
import pytest
from scipy.spatial.transform import Rotation
from trimesh.triangles import closest_point

from invrender.assets.primitives import box
from invrender.cli import main
from invrender.evaluate import duplicates as dup
from invrender.evaluate.stage import run_duplicates
from invrender.scene.atomic import MARKER
from invrender.scene.cameras import project_points
from invrender.scene.format import write_scene
from invrender.scene.images import write_mask, write_png_preview
from invrender.scene.mesh_io import write_ply
from invrender.scene.poses import write_poses
from invrender.scene.types import Mesh, SceneError
from invrender.synthesize.duplicates import make_duplicates, object_mesh

X, Y, Z = np.eye(3)


def rot(axis, degrees) -> np.ndarray:
    return Rotation.from_rotvec(np.radians(degrees) * np.asarray(axis, np.float64)).as_matrix()


def random_rotations(n, seed=0) -> np.ndarray:
    return Rotation.random(n, random_state=seed).as_matrix()


def pairs_of(axes, degrees) -> list[np.ndarray]:
    """+-degrees about each axis: their chordal mean is the identity (the sum is symmetric)."""
    return [rot(a, sign * degrees) for a in axes for sign in (1, -1)]


# --- rotations ---------------------------------------------------------------------------------


@pytest.mark.parametrize("degrees", [1e-7, 0.186, 30.0, 179.9])
def test_the_geodesic_angle_is_exact_near_zero_and_near_a_half_turn(degrees):
    axis = np.array([0.3, -0.5, 0.8]) / np.linalg.norm([0.3, -0.5, 0.8])
    assert dup.rotation_angle_deg(rot(axis, degrees)) == pytest.approx(degrees, rel=1e-9)


def test_rotations_that_differ_by_one_object_frame_rotation_score_zero():
    R_true = random_rotations(8)
    Q = random_rotations(1, seed=1)[0]
    metrics = dup.rotation_metrics(R_true, R_true @ Q, axis=Y)
    assert np.allclose(metrics["Q"], Q, atol=1e-12)
    assert metrics["error_deg"]["max"] < 1e-9 and metrics["alignment_inliers"] == 8
    assert metrics["symmetry"]["modded_out_deg"]["max"] < 1e-9


@pytest.mark.parametrize("degrees", [0.3, 2.5, 20.0])
def test_known_per_instance_rotation_noise_is_reported_as_its_angle(degrees):
    noise = pairs_of((X, Y, Z), degrees)  # in the true object frame: R'_i = R_i N_i Q
    R_true = random_rotations(len(noise), seed=2)
    Q = random_rotations(1, seed=3)[0]
    metrics = dup.rotation_metrics(R_true, R_true @ np.stack(noise) @ Q)
    assert np.allclose(metrics["Q"], Q, atol=1e-12)
    assert np.allclose(metrics["per_instance_deg"], degrees, rtol=1e-9)
    assert metrics["error_deg"]["mean"] == pytest.approx(degrees, rel=1e-9)


def test_a_flipped_instance_does_not_tilt_the_alignment_of_the_others():
    R_true = random_rotations(7, seed=4)
    Q = random_rotations(1, seed=5)[0]
    R_rec = R_true @ Q
    R_rec[3] = R_true[3] @ rot(X, 180) @ Q  # a can end over end
    metrics = dup.rotation_metrics(R_true, R_rec, axis=Y)
    errors = np.array(metrics["per_instance_deg"])
    assert errors[3] == pytest.approx(180.0) and np.delete(errors, 3).max() < 1e-9
    assert metrics["alignment_inliers"] == 6
    symmetry = metrics["symmetry"]  # turning the axis over is no symmetry of the can
    assert symmetry["per_instance"]["swing_deg"][3] == pytest.approx(180.0)
    assert symmetry["per_instance"]["modded_out_deg"][3] == pytest.approx(180.0)


def test_a_cans_twist_shows_as_twist_and_its_tilt_as_swing():
    R_true = random_rotations(6, seed=6)
    Q = random_rotations(1, seed=7)[0]
    twisted = dup.rotation_metrics(R_true, R_true @ np.stack(pairs_of((Y,), 4.0) * 3) @ Q, axis=Y)["symmetry"]
    assert np.allclose(twisted["per_instance"]["twist_deg"], 4.0, rtol=1e-9)
    assert max(twisted["per_instance"]["swing_deg"]) < 1e-9 and twisted["modded_out_deg"]["max"] < 1e-9
    tilted = dup.rotation_metrics(R_true, R_true @ np.stack(pairs_of((X, Z), 3.0) + [np.eye(3)] * 2) @ Q, axis=Y)
    swing = np.array(tilted["symmetry"]["per_instance"]["swing_deg"])
    assert (
        np.allclose(swing, [3, 3, 3, 3, 0, 0], atol=1e-9)
        and max(tilted["symmetry"]["per_instance"]["twist_deg"]) < 1e-9
    )
    assert np.allclose(tilted["symmetry"]["per_instance"]["modded_out_deg"], swing, atol=1e-9)


def test_the_symmetry_modded_out_ignores_arbitrary_twists():
    """Random twists (no pattern that keeps their mean) move Q, not the axis: the full error is
    not 0, the error with the symmetry modded out is."""
    R_true = random_rotations(6, seed=8)
    twists = np.stack([rot(Y, a) for a in (5, 70, -120, 33, 160, -10)])
    metrics = dup.rotation_metrics(R_true, R_true @ twists @ random_rotations(1, seed=9)[0], axis=Y)
    assert metrics["error_deg"]["mean"] > 10
    assert metrics["symmetry"]["modded_out_deg"]["max"] < 1e-9


def test_twist_and_swing_compose_to_the_rotation():
    swing, twist = rot(X, 7.0), rot(Y, 11.0)
    t, s = dup.twist_swing_deg((swing @ twist)[None], Y)
    assert t[0] == pytest.approx(11.0, rel=1e-9) and s[0] == pytest.approx(7.0, rel=1e-9)


# --- similarities ------------------------------------------------------------------------------


def test_umeyama_recovers_a_similarity_and_the_robust_fit_sets_an_outlier_aside():
    rng = np.random.default_rng(10)
    src = rng.normal(size=(8, 3))
    R, s, t = random_rotations(1, seed=11)[0], 0.37, np.array([1.0, -2.0, 0.5])
    dst = s * src @ R.T + t
    s_fit, R_fit, t_fit = dup.umeyama(src, dst)
    assert s_fit == pytest.approx(s, rel=1e-12) and np.allclose(R_fit, R, atol=1e-12) and np.allclose(t_fit, t)
    dst[2] += [0.5, 0.0, 0.0]
    s_fit, R_fit, t_fit, inliers = dup.robust_umeyama(src, dst, floor=1e-3)
    assert list(np.flatnonzero(~inliers)) == [2] and s_fit == pytest.approx(s, rel=1e-12)


def posed(rotations, rng) -> np.ndarray:
    T = np.tile(np.eye(4), (len(rotations), 1, 1))
    T[:, :3, :3] = rotations
    T[:, :3, 3] = rng.uniform(-0.5, 0.5, (len(rotations), 3)) + [0.0, 0.0, 2.0]
    return T


def test_exact_poses_of_a_mesh_whose_centroid_is_elsewhere_score_no_translation_error():
    # The recovered frame: the true one scaled by s, turned by Q and shifted by o (p = s Q p' + o),
    # and its mesh is not the truth's, so its centroid c' is the true point p0 (2 cm from the true
    # centroid), not the true centroid. The poses are exact: the error must be 0. Taking the true
    # centroid for c' (the earlier protocol) charged every copy its 2 cm offset turned by its pose.
    rng = np.random.default_rng(4)
    T_true = posed(random_rotations(8, seed=5), rng)
    s, Q, o = 1.7, random_rotations(1, seed=6)[0], np.array([0.1, -0.3, 0.2])
    frame = np.eye(4)  # p_true = frame @ p_rec
    frame[:3, :3], frame[:3, 3] = s * Q, o
    T_rec = T_true @ frame
    T_rec[:, :3, :] /= s  # T_obj2world of the recovered frame, the world scaled by 1 / s
    centroid_true, p0 = np.array([0.0, 0.01, 0.0]), np.array([0.02, 0.01, 0.0])
    c_rec = Q.T @ (p0 - o) / s
    truth = {i: T for i, T in enumerate(T_true)}
    recovered = {i: T for i, T in enumerate(T_rec)}
    match = {i: i for i in truth}
    out = dup.pose_metrics(truth, recovered, match, (centroid_true, c_rec), 0.1, None)
    # within 1e-7 m: the weak pull towards the true centroid (1e-6 of a copy's weight, squared) moves p by ~1e-9
    assert out["translation"]["error_m"]["max"] < 1e-7
    assert np.allclose(out["translation"]["corresponding_point"], p0, atol=1e-7)
    assert out["translation"]["centroid_offset_m"] == pytest.approx(0.02, abs=1e-7)
    # the earlier protocol: the true centroid's centres against the recovered ones
    centres_true = np.einsum("iab,b->ia", T_true[:, :3, :3], centroid_true) + T_true[:, :3, 3]
    centres_rec = np.einsum("iab,b->ia", T_rec[:, :3, :3], c_rec) + T_rec[:, :3, 3]
    assert dup.translation_metrics(centres_true, centres_rec, 0.1)["error_m"]["mean"] > 0.005


# --- masks -------------------------------------------------------------------------------------


def rectangles(shape, boxes: dict) -> np.ndarray:
    ids = np.zeros(shape, np.uint16)
    for label, (x0, y0, x1, y1) in boxes.items():
        ids[y0:y1, x0:x1] = label
    return ids


def test_iou_of_identical_and_shifted_rectangles_is_the_closed_form():
    truth = rectangles((60, 80), {1: (10, 10, 30, 40), 2: (50, 5, 70, 25)})
    shift = 4  # rectangle 2 moved right: (w - k) h / ((w + k) h)
    recovered = rectangles((60, 80), {7: (10, 10, 30, 40), 3: (50 + shift, 5, 70 + shift, 25)})
    metrics = dup.mask_metrics(truth, recovered, [1, 2], [3, 7])
    assert [(r["truth_id"], r["recovered_id"]) for r in metrics["instances"]] == [(1, 7), (2, 3)]
    assert metrics["instances"][0]["iou"] == 1.0
    assert metrics["instances"][1]["iou"] == pytest.approx((20 - shift) / (20 + shift))
    assert metrics["mean_iou"] == pytest.approx((1 + 16 / 24) / 2)


def test_the_hungarian_matching_undoes_a_permutation_and_reports_the_unmatched():
    rng = np.random.default_rng(12)
    boxes = {k + 1: (10 * k, 0, 10 * k + 8, 8) for k in range(6)}
    truth = rectangles((10, 60), boxes)
    permutation = rng.permutation(np.arange(20, 26))
    recovered = rectangles((10, 60), {int(permutation[k - 1]): b for k, b in boxes.items() if k != 4})
    recovered[0:3, 52:58] = 99  # a false positive over a third of instance 6: below MIN_IOU with it
    recovered[0:8, 30:33] = 98  # three eighths of instance 4, below MIN_IOU
    labels = [*permutation.tolist(), 98, 99]
    metrics = dup.mask_metrics(truth, recovered, list(boxes), labels)
    match = {r["truth_id"]: r["recovered_id"] for r in metrics["instances"]}
    assert match == {
        1: permutation[0],
        2: permutation[1],
        3: permutation[2],
        4: None,
        5: permutation[4],
        6: permutation[5],
    }
    assert metrics["unmatched_truth"] == [4] and metrics["unmatched_recovered"] == sorted([int(permutation[3]), 98, 99])
    assert metrics["instances"][3]["iou"] == 0.0 and metrics["matched"] == 5
    iou6 = (64 - 18) / 64  # 18 of its 64 pixels went to the false positive
    assert metrics["instances"][5]["iou"] == pytest.approx(iou6)
    assert metrics["mean_iou"] == pytest.approx((4 + iou6) / 6) and metrics["mean_iou_matched"] == pytest.approx(
        (4 + iou6) / 5
    )


# --- meshes ------------------------------------------------------------------------------------


def square(y: float, size: float = 1.0) -> Mesh:
    positions = np.array([[0, y, 0], [size, y, 0], [size, y, size], [0, y, size]], np.float64)
    return Mesh(positions=positions, faces=np.array([[0, 2, 1], [0, 3, 2]], np.int32), uvs=None)


def test_chamfer_of_parallel_squares_is_their_gap_and_of_a_mesh_with_itself_zero():
    result = dup.chamfer(square(0.0), square(0.03), samples=2000)
    assert result["chamfer_m"] == pytest.approx(0.03, rel=1e-12)
    assert result["accuracy_m"] == pytest.approx(0.03, rel=1e-12) and result["completeness_m"] == pytest.approx(0.03)
    can = object_mesh(*make_duplicates({"atlas_resolution": 64}))
    assert dup.chamfer(can, can, samples=2000)["chamfer_m"] < 1e-12


def test_the_distance_to_a_surface_is_the_brute_force_minimum_over_its_triangles():
    mesh = object_mesh(*make_duplicates({"atlas_resolution": 64}))
    points = np.random.default_rng(13).normal(scale=0.05, size=(300, 3))
    triangles = np.asarray(mesh.positions, np.float64)[mesh.faces]
    brute = np.array(
        [
            np.linalg.norm(closest_point(triangles, np.repeat(p[None], len(triangles), 0)) - p, axis=1).min()
            for p in points
        ]
    )
    assert np.allclose(dup.distance_to_surface(points, mesh), brute, rtol=1e-12, atol=1e-15)


def test_icp_undoes_a_small_rigid_motion():
    brick = box([-0.05, -0.03, -0.015], [0.05, 0.03, 0.015], cell=0.01)
    truth = Mesh(positions=brick.positions, faces=brick.faces, uvs=None)
    moved = dup.transformed(truth, 1.0, rot([0.6, 0.8, 0.0], 3.0), [0.004, -0.002, 0.001])
    assert dup.chamfer(moved, truth, samples=2000)["chamfer_m"] > 1e-3
    R, t = dup.icp(moved, truth)
    assert dup.rotation_angle_deg(R) == pytest.approx(3.0, abs=1e-9)
    assert dup.chamfer(dup.transformed(moved, 1.0, R, t), truth, samples=2000)["chamfer_m"] < 1e-12


def test_icp_leaves_a_cans_twist_alone_when_told_its_axis():
    can = object_mesh(*make_duplicates({"atlas_resolution": 64}))
    shift = np.array([0.003, 0.001, -0.002])
    moved = dup.transformed(can, 1.0, rot(Y, 4.0), shift)  # its facets would pull the twist back
    R, t = dup.icp(moved, can, axis=Y)
    twist, swing = dup.twist_swing_deg(R[None], Y)
    # the twisted facets are sampled a little unevenly: a tilt of thousandths of a degree is left
    assert twist[0] < 1e-6 and swing[0] < 0.01 and np.allclose(t, -shift, atol=2e-5)
    R, t = dup.icp(moved, can)
    assert dup.twist_swing_deg(R[None], Y)[0][0] > 1.0


def test_the_mesh_alignment_fits_the_true_faces_past_the_poses_offset_and_a_bulge():
    """A hull-like recovery (the truth with a 6 mm bulge on a sixth of it) whose poses put its
    frame 0.8 mm off: the trimmed shift lands the faces the bulge leaves on the truth."""
    brick = box([-0.04, -0.05, -0.03], [0.04, 0.05, 0.03], cell=0.005)
    truth = Mesh(positions=brick.positions, faces=brick.faces, uvs=None)
    positions = np.asarray(truth.positions, np.float64).copy()
    on_top = positions[:, 0] > 0.04 - 1e-9
    positions[on_top, 0] += 0.006 * np.clip(1 - np.hypot(positions[on_top, 1], positions[on_top, 2]) / 0.03, 0, 1)
    bulged = Mesh(positions=positions, faces=truth.faces, uvs=None)
    off = np.array([0.0003, 0.0007, -0.0002])  # the poses' error in the frame's offset
    centroids = (dup.surface_centroid(truth), dup.surface_centroid(bulged))
    poses = {
        "rotation": {"Q": np.eye(3).tolist()},
        "translation": {"similarity": {"scale": 1.0}, "corresponding_point": (centroids[1] + off).tolist()},
    }
    mesh = dup.mesh_metrics(bulged, truth, poses, centroids, dup.diagonal_of(truth))
    assert np.allclose(mesh["alignment"]["offset_from_poses"], off, atol=1e-12)
    assert mesh["alignment"]["surface_shift_m"] == pytest.approx(np.linalg.norm(off), rel=1e-9)
    assert np.linalg.norm(mesh["alignment"]["offset"]) < 1e-9  # 0.8 mm off -> exact
    # an untrimmed fit is pulled towards the bulge (0.49 mm): the reason for trimming
    _, t = dup.icp(dup.transformed(bulged, 1.0, np.eye(3), off), truth, rotate=False)
    assert np.linalg.norm(off + t) > 3e-4


# --- symmetry from the generator's metadata ---------------------------------------------------------


def test_the_symmetry_axis_comes_from_the_metadata_or_the_object_kind():
    axis_of = lambda metadata: dup.symmetry_axis(metadata)[0]  # noqa: E731
    assert axis_of({"object": {"kind": "can", "symmetry": {"type": "axis", "axis": [0, 0, 2]}}}) == [0, 0, 1]
    assert axis_of({"object": {"kind": "box", "symmetry": {"type": "none", "axis": None}}}) is None
    assert axis_of({"object": {"kind": "box"}}) is None
    assert axis_of({"config": {"object": {"kind": "box"}}}) is None
    assert axis_of({"object": {"vertex_count": 3}}) == [0, 1, 0]  # before kinds: a can
    assert axis_of(None) is None
    with pytest.raises(SceneError, match="symmetry"):
        dup.symmetry_axis({"object": {"symmetry": {"axis": [0, 0]}}})


# --- the stage on a synthetic truth ------------------------------------------------------------------

Q_TRUE = rot([0.2, 0.9, -0.4], 130.0)  # the recovered object frame in the true one
SCALE, SHIFT = 2.5, np.array([0.3, -0.2, 1.0])  # recovered world = (true world - SHIFT) / SCALE
OFFSET = np.array([0.0, 0.02, 0.0])  # the true object point at the recovered frame's origin (on the axis)
TWIST_DEG = 3.0
FLOAT32_M = 1e-8  # the recovered mesh goes through a float32 PLY: its centroid moves by ~1e-10 m


def instance_ids(camera, mesh: Mesh, poses: dict) -> np.ndarray:
    """The true id image: each copy's triangles filled, far copies first (painter's order)."""
    ids = np.zeros((camera.height, camera.width), np.uint16)
    depth = {i: np.linalg.norm(T[:3, 3] - camera.center) for i, T in poses.items()}
    for i in sorted(poses, key=depth.get, reverse=True):
        world = np.asarray(mesh.positions, np.float64) @ poses[i][:3, :3].T + poses[i][:3, 3]
        uv = project_points(camera, world)
        for face in mesh.faces:
            cv2.fillPoly(ids, [np.round(uv[face] * 16).astype(np.int32)], int(i), shift=4)
    return ids


def recovered_pose(T, noise=np.eye(3)) -> list:
    """The pose of a true copy in the recovered frame and world (R' = R N Q, t' from OFFSET)."""
    R, t = T[:3, :3], T[:3, 3]
    out = np.eye(4)
    out[:3, :3], out[:3, 3] = R @ noise @ Q_TRUE, (R @ OFFSET + t - SHIFT) / SCALE
    return out.tolist()


@pytest.fixture(scope="module")
def tree(tmp_path_factory):
    """capture/ground_truth (scene.json, masks, poses, object), segmentation/ and duplicates/ of a
    recovery exact up to the unknowable: ids renumbered, copy 6 not segmented, copy 5 not
    registered after refinement; before it, copies 1-4 twisted +-3 degrees about the can's axis."""
    root = tmp_path_factory.mktemp("duplicates")
    scene, metadata = make_duplicates({"atlas_resolution": 64})
    can = object_mesh(scene, metadata)
    truth = root / "capture" / "ground_truth"
    write_scene(truth / "scene", scene, metadata)
    write_poses(truth / "poses.json", metadata["poses"])
    write_ply(truth / "object.ply", can)
    poses = {p["instance_id"]: np.asarray(p["T_obj2world"]) for p in metadata["poses"]["instances"]}
    ids = instance_ids(scene.cameras[0], can, poses)
    write_mask(truth / "masks" / "view_000.png", ids)
    (root / "capture" / "images").mkdir()
    write_png_preview(root / "capture" / "images" / "view_000.png", np.full((*ids.shape, 3), 0.5, np.float32))

    renumber = {i: 10 + 7 * i for i in poses if i != 6}
    seg = root / "segmentation"
    write_mask(seg / "masks" / "view_000.png", np.vectorize(lambda v: renumber.get(v, 0))(ids).astype(np.uint16))
    table = [{"id": r, "box": [0, 0, 1, 1], "area": int((ids == t).sum()), "score": 1.0} for t, r in renumber.items()]
    (seg / "instances.json").write_text(
        json.dumps({"image": "view_000.png", "width": 96, "height": 72, "instances": table})
    )

    dup_dir = root / "duplicates"
    dup_dir.mkdir()
    positions = (np.asarray(can.positions, np.float64) - OFFSET) @ Q_TRUE / SCALE  # p' = Q^T (p - o) / s
    write_ply(dup_dir / "object.ply", Mesh(positions=positions.astype(np.float32), faces=can.faces, uvs=None))
    after = [
        {"instance_id": r, "mask_value": 100 + t, "registered": t != 5, "T_obj2world": recovered_pose(poses[t])}
        for t, r in renumber.items()  # the segment's id names the pixels; mask_value is the user's own
    ]
    twists = dict(zip([1, 2, 3, 4], pairs_of((Y,), TWIST_DEG) * 2, strict=True))
    before = [
        {
            "instance_id": r,
            "registered": True,
            "T_obj2world": recovered_pose(poses[t], twists.get(t, np.eye(3))),
        }
        for t, r in renumber.items()
    ]
    write_poses(dup_dir / "poses.json", {"convention": "test", "instances": after})
    write_poses(dup_dir / "poses_colmap.json", {"convention": "test", "instances": before})
    return {
        "root": root,
        "truth": truth,
        "segmentation": seg,
        "duplicates": dup_dir,
        "images": root / "capture" / "images",
    }


@pytest.fixture(scope="module")
def evaluated(tree):
    out = tree["root"] / "report"
    doc = run_duplicates(tree["segmentation"], tree["duplicates"], tree["truth"], tree["images"], out)
    return out, doc


def test_it_writes_metrics_and_the_outline_figure(evaluated):
    out, doc = evaluated
    assert {p.name for p in out.iterdir()} == {MARKER, "metrics.json", "outlines_view_000.png"}
    assert json.loads((out / "metrics.json").read_text()) == doc
    assert doc["mode"] == "duplicates" and doc["paper"]["table2_color_box"]["10"]["rotation_deg"] == 0.186
    figure = cv2.imread(str(out / "outlines_view_000.png"))
    assert figure.shape[0] >= 256 and (figure == [0, 255, 255]).all(axis=2).any()  # outlines that agree


def test_counts_and_masks(evaluated):
    doc = evaluated[1]
    assert doc["counts"] == {
        "truth": 6, "segmented": 5, "matched": 5,
        "registered": {"before": 5, "after": 4}, "listed": {"before": 5, "after": 5},
    }  # fmt: skip
    masks = doc["masks"]
    assert masks["unmatched_truth"] == [6] and masks["unmatched_recovered"] == []
    assert masks["mean_iou_matched"] == 1.0 and masks["mean_iou"] == pytest.approx(5 / 6)
    assert [r["recovered_id"] for r in masks["instances"]] == [17, 24, 31, 38, 45, None]


def test_a_recovery_exact_up_to_frame_scale_and_offset_scores_zero(evaluated):
    doc = evaluated[1]
    after = doc["poses"]["after"]
    assert after["pairs"] == [[1, 17], [2, 24], [3, 31], [4, 38]] and after["evaluated"] == 4
    assert after["rotation"]["error_deg"]["max"] < 1e-9 and np.allclose(after["rotation"]["Q"], Q_TRUE, atol=1e-12)
    assert after["translation"]["error_m"]["max"] < FLOAT32_M
    assert after["translation"]["similarity"]["scale"] == pytest.approx(SCALE, rel=1e-8)
    assert doc["object"]["symmetry_axis"] == [0.0, 1.0, 0.0]
    mesh = doc["mesh"]
    assert np.allclose(mesh["alignment"]["offset"], OFFSET, atol=1e-9)
    assert mesh["chamfer_m"] < FLOAT32_M and mesh["icp"]["chamfer_m"] < FLOAT32_M and mesh["icp"]["rotation_deg"] < 1e-6


def test_before_refinement_the_twists_are_reported_as_twist(evaluated):
    before = evaluated[1]["poses"]["before"]
    assert before["evaluated"] == 5
    assert np.allclose(before["rotation"]["per_instance_deg"], [TWIST_DEG] * 4 + [0], atol=1e-9)
    symmetry = before["rotation"]["symmetry"]
    assert np.allclose(symmetry["per_instance"]["twist_deg"], [TWIST_DEG] * 4 + [0], atol=1e-9)
    assert symmetry["swing_deg"]["max"] < 1e-9 and symmetry["modded_out_deg"]["max"] < 1e-9
    assert before["translation"]["error_m"]["max"] < FLOAT32_M  # the twist turns the centroid about itself


def test_the_cli_runs_the_duplicates_evaluation_and_refuses_bad_input(tree, tmp_path, capsys):
    only_after = tmp_path / "duplicates"  # no poses_colmap.json: nothing before refinement
    only_after.mkdir()
    for name in ("poses.json", "object.ply"):
        (only_after / name).write_bytes((tree["duplicates"] / name).read_bytes())
    args = ["evaluate", "--duplicates", only_after, "--segmentation", tree["segmentation"]]
    args += ["--truth", tree["truth"], "--images", tree["images"]]
    assert main([str(a) for a in [*args, "--out", tmp_path / "cli"]]) == 0
    written = json.loads((tmp_path / "cli" / "metrics.json").read_text())
    assert written["poses"]["before"] is None and written["counts"]["registered"] == {"before": None, "after": 4}
    assert (
        main(
            [
                str(a)
                for a in ["evaluate", "--truth", tree["truth"], "--images", tree["images"], "--out", tmp_path / "x"]
            ]
        )
        == 2
    )
    assert "--scene: expected the recovered scene directory" in capsys.readouterr().err

    small = tmp_path / "segmentation"
    (small / "masks").mkdir(parents=True)
    (small / "instances.json").write_text((tree["segmentation"] / "instances.json").read_text())
    write_mask(small / "masks" / "view_000.png", np.zeros((36, 48), np.uint16))
    with pytest.raises(SceneError, match="size: expected 96 x 72 as the true mask, got 48 x 36"):
        run_duplicates(small, tree["duplicates"], tree["truth"], tree["images"], tmp_path / "a")
    write_mask(small / "masks" / "view_000.png", np.full((72, 96), 5, np.uint16))
    with pytest.raises(SceneError, match="ids: expected only ids of instances.json"):
        run_duplicates(small, tree["duplicates"], tree["truth"], tree["images"], tmp_path / "b")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["cli", "duplicates", "segmentation"]  # nothing half-written
