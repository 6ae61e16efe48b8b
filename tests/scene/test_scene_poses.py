"""scene/poses.py: poses.json read, written and checked (the form its docstring gives)."""

import json
import re

import numpy as np
import pytest

from invrender.scene.poses import placements, read_poses, validate_poses, write_poses
from invrender.scene.types import SceneError


def _doc(*transforms, registered=True):
    return {
        "convention": "p_world = T_obj2world @ [p_obj, 1]",
        "instances": [
            {"instance_id": k, "mask_value": k, "registered": registered, "T_obj2world": T.tolist()}
            for k, T in enumerate(transforms, 1)
        ],
    }


def _pose(angle, t):
    c, s = np.cos(angle), np.sin(angle)
    T = np.eye(4)
    T[:3, :3] = [[c, 0, s], [0, 1, 0], [-s, 0, c]]
    T[:3, 3] = t
    return T


def test_round_trip_keeps_the_document_and_the_transforms(tmp_path):
    doc = _doc(_pose(0.3, (1, 0, 2)), _pose(-1.2, (0, 0.5, 0)))
    write_poses(tmp_path / "poses.json", doc)
    assert read_poses(tmp_path / "poses.json") == json.loads(json.dumps(doc))
    poses = validate_poses(read_poses(tmp_path / "poses.json"), "x")
    assert [p["instance_id"] for p in poses] == [1, 2]
    assert np.array_equal(poses[0]["T"], _pose(0.3, (1, 0, 2)))


def test_unregistered_copies_are_skipped():
    assert validate_poses(_doc(np.eye(4), registered=False), "poses.json") == []


@pytest.mark.parametrize(
    "edit, field",
    [
        (lambda d: d["instances"][0].update(T_obj2world=(2 * np.eye(4)).tolist()), "instances[0].T_obj2world"),
        (lambda d: d["instances"][0].update(T_obj2world=np.diag([1.0, 1, -1, 1]).tolist()), "instances[0].T_obj2world"),
        (lambda d: d["instances"][0].update(T_obj2world=[[1, 0], [0, 1]]), "instances[0].T_obj2world"),
        (lambda d: d["instances"][0].update(instance_id="one"), "instances[0].instance_id"),
        (lambda d: d.pop("instances"), "instances"),
    ],
)
def test_bad_poses_are_one_scene_error_naming_the_field(tmp_path, edit, field):
    doc = _doc(np.eye(4))
    edit(doc)
    with pytest.raises(SceneError, match=re.escape(f"poses.json: {field}: expected")):
        write_poses(tmp_path / "poses.json", doc)
    assert not (tmp_path / "poses.json").exists()


def test_missing_and_unreadable_files(tmp_path):
    with pytest.raises(SceneError, match="expected an existing poses.json"):
        read_poses(tmp_path / "poses.json")
    (tmp_path / "poses.json").write_text("{")
    with pytest.raises(SceneError, match="expected a readable JSON document"):
        read_poses(tmp_path / "poses.json")


def test_placements_are_v2_objects_sharing_one_mesh_and_set():
    from testscenes import cube_mesh

    cube = cube_mesh()
    doc = _doc(_pose(0.3, (1, 0, 2)), _pose(-1.2, (0, 0.5, 0)))
    doc["instances"].append({"instance_id": 3, "mask_value": 3, "registered": False, "T_obj2world": np.eye(4).tolist()})
    objects = placements(doc, cube, "paint", "can")
    assert [(o.name, o.instance_id, o.material) for o in objects] == [("can_1", 1, "paint"), ("can_2", 2, "paint")]
    assert all(o.mesh is cube for o in objects)
    assert np.array_equal(objects[1].transform, _pose(-1.2, (0, 0.5, 0)))
