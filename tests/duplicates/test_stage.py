"""duplicates/stage.py: what it refuses, with one message naming the file, the field and what was
expected, and nothing written. (The whole pipeline runs in tests/workflow and the benchmark.)"""

import json

import numpy as np
import pytest

from invrender.duplicates import stage
from invrender.scene.cameras import write_colmap_text
from invrender.scene.images import write_exr, write_mask
from invrender.scene.types import Camera, SceneError


@pytest.fixture
def photo(tmp_path):
    """A black photograph (nothing to match) with four square instances, and its camera."""
    cameras = tmp_path / "cameras"
    (cameras / "images").mkdir(parents=True)
    camera = Camera("photo.exr", "PINHOLE", 160, 120, np.array([150.0, 150, 80, 60]), np.eye(3), np.zeros(3))
    write_colmap_text(cameras, [camera])
    write_exr(cameras / "images" / "photo.exr", np.zeros((120, 160, 3), np.float32))
    ids = np.zeros((120, 160), np.uint16)
    for k, (x, y) in enumerate([(10, 10), (60, 10), (110, 10), (60, 70)], 1):
        ids[y : y + 30, x : x + 30] = k
    write_mask(tmp_path / "ids.png", ids)
    instances = {"instances": [{"id": k} for k in range(1, 5)]}
    (tmp_path / "instances.json").write_text(json.dumps(instances))
    return tmp_path


def settings(**values):
    return stage.settings_from({"matcher": "sift", "step_deg": 90.0, "crop_size": 64, **values})


def crop_all(root, ids=range(1, 5)):
    (root / "crops").mkdir(exist_ok=True)
    for k in ids:
        stage.run_crop(
            root / "cameras",
            root / "ids.png",
            k,
            root / "crops" / f"instance_{k:03d}.npz",
            root / "crops" / f"instance_{k:03d}.features.npz",
            settings(),
        )


def solve(root):
    return stage.run(
        root / "cameras",
        root / "ids.png",
        root / "instances.json",
        root / "crops",
        root / "crops",
        root / "out",
        settings(),
        progress=False,
    )


def test_fewer_than_three_instances_stop_with_what_was_found(photo):
    (photo / "instances.json").write_text(json.dumps({"instances": [{"id": 1}, {"id": 2}]}))
    with pytest.raises(SceneError, match=r"instances.*at least 3 instances of the object; found 2"):
        solve(photo)
    assert not (photo / "out").exists()


def test_no_matches_between_crops_stop_the_stage(photo):
    crop_all(photo)
    with pytest.raises(SceneError, match="matches between some of the 4 crops; found none in any pair"):
        solve(photo)
    assert not (photo / "out").exists()


def test_masks_of_another_size_than_the_photograph_are_refused(photo):
    write_mask(photo / "ids.png", np.ones((60, 80), np.uint16))
    with pytest.raises(SceneError, match=r"ids.png.*size.*160 x 120, got 80 x 60"):
        crop_all(photo, ids=[1])


def test_an_unknown_setting_or_matcher_is_named():
    with pytest.raises(SceneError, match="colour_space"):
        stage.settings_from({"colour_space": "srgb"})
    with pytest.raises(SceneError, match="matcher.*sift, xfeat.*'orb'"):
        stage.settings_from({"matcher": "orb"})
    with pytest.raises(SceneError, match="hull_photo.*hull_snap true too"):
        stage.settings_from({"hull_photo": True})
    with pytest.raises(SceneError, match="photo_tracks.*hull_photo true and subpixel_rounds > 0 too"):
        stage.settings_from({"hull_snap": True, "hull_photo": True, "photo_tracks": True})
    assert stage.settings_from({"hull_snap": True, "hull_photo": True, "subpixel_rounds": 1, "photo_tracks": True})


def test_the_object_frame_moves_poses_with_the_mesh():
    """reframe: p_colmap = centre + scale * p_obj; the camera sees the same point."""
    rng = np.random.default_rng(0)
    q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
    T = np.eye(4)
    T[:3, :3], T[:3, 3] = q * np.sign(np.linalg.det(q)), [0.1, -0.2, 3.0]
    centre, scale, p_obj = np.array([0.3, 0.1, -0.2]), 2.5, rng.normal(size=3)
    p_cam = T[:3, :3] @ (centre + scale * p_obj) + T[:3, 3]
    T2 = stage.reframe(T, centre, scale)
    np.testing.assert_allclose(T2[:3, :3] @ p_obj + T2[:3, 3], p_cam / scale)


def test_hull_outliers_reach_the_carve_and_default_to_a_tenth(monkeypatch):
    """`hull_outliers` is the k of hull.carve (copies that may call a kept voxel outside); None
    leaves hull.py's own default, a tenth of the copies."""
    from invrender.duplicates import hull

    seen = []
    monkeypatch.setattr(hull, "visual_hull", lambda *a, k=None, **kw: (seen.append(k), (None, None))[1])
    monkeypatch.setattr(hull, "bounds_from_masks", lambda *a: None)
    for value in (0, None):
        stage._carve(None, {}, None, np.zeros((0, 3)), settings(hull_outliers=value))
    assert seen == [0, None] and hull.default_vote(20) == 2


def test_poses_that_leave_no_voxel_stop_with_the_setting_to_change(monkeypatch):
    from invrender.duplicates import hull

    def empty(*args, **kwargs):
        raise hull.EmptyHull("hull_mesh: the hull is empty")

    monkeypatch.setattr(hull, "visual_hull", empty)
    poses = {1: np.eye(4), 2: np.eye(4), 3: np.eye(4)}
    with pytest.raises(SceneError, match=r"duplicates.*hull.*3 posed copies.*hull_outliers 0.*hull_outliers null"):
        stage._carve(None, poses, None, np.ones((30, 3)) * np.arange(30)[:, None], settings(hull_outliers=0))


def test_hull_snap_moves_the_carved_hull_onto_the_points(monkeypatch):
    """With `hull_snap` the carve's mesh (here a sphere of radius 1.1 standing in for a hull) comes
    back moved onto COLMAP's points (on the unit sphere), with what snap.py did; without, as carved."""
    import trimesh

    from invrender.duplicates import hull
    from invrender.scene.types import Mesh

    ball = trimesh.creation.icosphere(subdivisions=3, radius=1.1)
    carved = Mesh(positions=ball.vertices.astype(np.float32), faces=ball.faces.astype(np.int32), uvs=None)
    monkeypatch.setattr(hull, "visual_hull", lambda *a, **kw: (carved, None))
    directions = np.random.default_rng(0).normal(size=(2000, 3))
    points = directions / np.linalg.norm(directions, axis=1, keepdims=True)
    kept, plain, none = stage._carve(None, {}, None, points, settings())
    snapped, report, _ = stage._carve(None, {}, None, points, settings(hull_snap=True))
    assert kept is carved and plain == {"floor": None, "snap": None, "photo": None, "set_aside": {}}
    assert none.shape == (0, 3)
    radius = np.linalg.norm(snapped.positions, axis=1)
    assert np.abs(radius - 1.0).max() < 0.01 and report["snap"]["points"] == 2000


def test_poses_name_each_copy_by_the_users_own_mask_too():
    """poses.json: `instance_id` the segment's renumbered id, `mask_value` the value of the copy's
    pixels in the user's id image (or `mask_file` in their folder of masks)."""
    names = stage.mask_names([{"id": 1, "source": 10}, {"id": 2, "source": "cup.png"}, {"id": 3}])
    doc = stage.poses_document({1: np.eye(4), 3: np.eye(4)}, names, np.eye(4), "note", "COLMAP")
    got = [(e["instance_id"], e.get("mask_value"), e.get("mask_file"), e["registered"]) for e in doc["instances"]]
    assert got == [(1, 10, None, True), (2, None, "cup.png", False), (3, 3, None, True)]


def test_a_copy_given_a_wrong_pose_is_set_aside_and_the_hull_kept(monkeypatch):
    """Strict carving (hull_outliers 0) of nine boxes, one of them posed over the floor between
    three others, off its own silhouette: that copy alone carves every voxel away. The stage sets
    it aside, carves the hull from the other eight (as large as the true poses' hull) and places
    the eight, not the ninth."""
    from posed_copies import box_scene, ids_for

    from invrender.duplicates import hull, mapping

    mesh, poses, K, _ = box_scene(9)
    ids = ids_for(mesh, poses, K)
    wrong = {i: T.copy() for i, T in poses.items()}
    wrong[4][:3, 3] = np.linalg.inv(K) @ [230.0, 260.0, 1.0] * poses[4][2, 3]  # background there
    bounds = hull.bounds_from_masks(ids, poses, K)
    with pytest.raises(hull.EmptyHull):  # what stopped the stage before
        hull.visual_hull(ids, wrong, K, bounds, resolution=48, k=0)

    found = {(1, 2): (np.ones((8, 2)), np.ones((8, 2)))}
    monkeypatch.setattr(stage, "match_all", lambda *args: (found, []))
    registration = mapping.Registration(poses=wrong, unregistered=[], points=np.zeros((0, 3)), reconstruction=None)
    monkeypatch.setattr(mapping, "register", lambda *args, **kwargs: registration)
    photo = np.zeros((*ids.shape, 3), np.float32)
    solved = stage.solve(photo, ids, K, {}, {}, None, settings(hull_outliers=0, hull_resolution=48), progress=False)

    assert solved["shape"]["set_aside"].keys() == {4}
    assert sorted(solved["poses"]) == [i for i in sorted(poses) if i != 4]
    truth, _ = hull.visual_hull(ids, poses, K, bounds, resolution=48, k=0)
    size = np.ptp(solved["mesh"].positions, axis=0)
    np.testing.assert_allclose(size, np.ptp(truth.positions, axis=0), rtol=0.05)


def test_a_floor_that_leaves_no_hull_is_dropped_not_the_stage(monkeypatch):
    """A floor fitted over the copies (a wrong model tilts the fit) would carve every voxel:
    the hull is carved without it, and duplicates.json's hull_shape.floor says so."""
    from posed_copies import box_scene, ids_for

    from invrender.duplicates import floor

    mesh, poses, K, up = box_scene(9)
    ids = ids_for(mesh, poses, K)
    above = floor.Floor(normal=up, offset=10.0, misposed=[])  # n . X >= 10 m: nothing is above it
    monkeypatch.setattr(floor, "fit_floor", lambda *args: above)
    carved, report, _ = stage._carve(ids, poses, K, np.zeros((0, 3)), settings(hull_outliers=0, hull_resolution=48,
                                                                                hull_floor=True))  # fmt: skip
    assert report["floor"]["carved"] is False and report["set_aside"] == {}
    assert len(carved.faces) > 0
