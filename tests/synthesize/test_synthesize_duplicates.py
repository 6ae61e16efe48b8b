"""synthesize.duplicates: true poses, shared object and atlas, camera, seed."""

import json

import numpy as np
import pytest

from invrender.scene.atlas import texel_index
from invrender.scene.cameras import project_points
from invrender.synthesize.duplicates import _label, build_object, make_duplicates, object_mesh
from invrender.assets.primitives import signed_volume


@pytest.fixture(scope="module")
def dup():
    return make_duplicates()


def poses_of(meta):
    return [np.array(p["T_obj2world"]) for p in meta["poses"]["instances"]]


def test_defaults(dup):
    scene, meta = dup
    assert len(meta["poses"]["instances"]) == 6 == len(meta["copies"])
    assert len(scene.cameras) == 1 and (scene.cameras[0].width, scene.cameras[0].height) == (96, 72)
    assert scene.maps.atlas_shape == (256, 256)
    json.dumps(meta, allow_nan=False)


def test_poses_json_form(dup):
    _, meta = dup
    poses = meta["poses"]
    assert set(poses) >= {"convention", "instances"} and "scale" in poses
    for i, inst in enumerate(poses["instances"], 1):
        assert set(inst) == {"instance_id", "mask_value", "registered", "T_obj2world"}
        assert inst["instance_id"] == inst["mask_value"] == i and inst["registered"] is True
        assert np.shape(inst["T_obj2world"]) == (4, 4)


def test_poses_are_rigid_transforms(dup):
    _, meta = dup
    for T in poses_of(meta):
        R = T[:3, :3]
        np.testing.assert_allclose(R.T @ R, np.eye(3), atol=1e-12)
        assert np.linalg.det(R) == pytest.approx(1.0)
        np.testing.assert_array_equal(T[3], [0, 0, 0, 1])


def test_placing_the_object_by_the_poses_reproduces_the_mesh(dup):
    scene, meta = dup
    obj = build_object(meta["config"])  # built independently of the scene
    corners = obj.positions[obj.faces]  # (F, 3, 3), object frame
    mesh = scene.mesh
    for copy, T in zip(meta["copies"], poses_of(meta)):
        f0, f1 = copy["faces"]
        placed = corners @ T[:3, :3].T + T[:3, 3]
        np.testing.assert_allclose(mesh.positions[mesh.faces[f0:f1]], placed, atol=1e-5)
        assert np.all(mesh.instance_ids[f0:f1] == copy["instance_id"])
    f0, f1 = meta["floor"]["faces"]
    assert np.all(mesh.instance_ids[f0:f1] == 0)


def test_object_faces_outwards(dup):
    scene, meta = dup
    obj = build_object(meta["config"])
    assert signed_volume(obj.positions, obj.faces) > 0
    for copy in meta["copies"]:
        f0, f1 = copy["faces"]
        assert signed_volume(scene.mesh.positions, scene.mesh.faces[f0:f1]) > 0


def test_copies_share_one_object_atlas_region(dup):
    scene, meta = dup
    uvs = [scene.mesh.uvs[c["vertices"][0] : c["vertices"][1]] for c in meta["copies"]]
    for other in uvs[1:]:
        np.testing.assert_array_equal(other, uvs[0])
    # The floor's UVs do not overlap the object's texels.
    f0, f1 = meta["floor"]["faces"]
    floor_uv = scene.mesh.uvs[scene.mesh.faces[f0:f1]].reshape(-1, 2)
    lo, hi = uvs[0].min(0), uvs[0].max(0)
    obj_rows, obj_cols = texel_index(uvs[0], scene.maps.atlas_shape)
    floor_rows, floor_cols = texel_index(floor_uv, scene.maps.atlas_shape)
    assert not set(zip(obj_rows, obj_cols)) & set(zip(floor_rows, floor_cols))
    # The object gets a fair share of the atlas despite its small area.
    assert (hi - lo).prod() > 0.1


def test_object_mesh_round_trip(dup):
    scene, meta = dup
    obj = build_object(meta["config"])
    for i in (1, 4):
        m = object_mesh(scene, meta, i)
        np.testing.assert_allclose(m.positions[m.faces], obj.positions[obj.faces], atol=1e-5)


def test_copies_rest_on_or_above_the_floor_apart(dup):
    scene, meta = dup
    max_lift = meta["config"]["placement"]["max_lift"]
    centres = []
    for copy in meta["copies"]:
        v0, v1 = copy["vertices"]
        y = scene.mesh.positions[v0:v1, 1]
        assert -1e-5 <= y.min() <= max_lift + 1e-5
        centres.append(scene.mesh.positions[v0:v1].mean(0))
    c = np.array(centres)
    d = np.linalg.norm(c[:, None, [0, 2]] - c[None, :, [0, 2]], axis=-1) + np.eye(len(c)) * 1e9
    assert d.min() > 0.1  # bounding spheres of a 6.6 x 12.2 cm can do not overlap


def test_camera_sees_every_copy(dup):
    scene, meta = dup
    cam = scene.cameras[0]
    assert cam.R[2] @ [0, -1, 0] > 0.5  # looking down
    for T in poses_of(meta):
        ((u, v),) = project_points(cam, T[None, :3, 3])
        assert 0 < u < cam.width and 0 < v < cam.height


def test_label_has_no_rotational_symmetry(dup):
    _, meta = dup
    r, h = meta["config"]["object"]["radius"], meta["config"]["object"]["height"]
    phi = np.linspace(0, 2 * np.pi, 180, endpoint=False)
    y = np.linspace(-h / 2, h / 2, 60)
    P, Y = np.meshgrid(phi, y, indexing="ij")
    pos = np.stack([r * np.cos(P), Y, -r * np.sin(P)], -1).reshape(-1, 3)
    img = _label(r, h)(pos, None).reshape(180, 60, 3)
    for shift in range(1, 180):  # rotations by 2 .. 358 degrees about the axis
        change = np.abs(np.roll(img, shift, axis=0) - img).mean()
        assert change > (0.02 if 10 <= shift <= 170 else 0.005)
    # And it is what the maps hold: label texels are not uniform.
    scene, _ = dup
    f0, f1 = meta["copies"][0]["faces"]
    rows, cols = texel_index(scene.mesh.uvs[scene.mesh.faces[f0:f1]].mean(1), scene.maps.atlas_shape)
    assert scene.maps.kd[rows, cols].std(0).max() > 0.1


def test_seed_determines_everything():
    a, meta_a = make_duplicates({"seed": 7, "count": 3, "atlas_resolution": 128})
    b, meta_b = make_duplicates({"seed": 7, "count": 3, "atlas_resolution": 128})
    c, meta_c = make_duplicates({"seed": 8, "count": 3, "atlas_resolution": 128})
    assert meta_a == meta_b and len(meta_a["copies"]) == 3
    np.testing.assert_array_equal(a.mesh.positions, b.mesh.positions)
    np.testing.assert_array_equal(a.maps.kd, b.maps.kd)
    assert meta_a["poses"] != meta_c["poses"]


def test_impossible_placement_says_so():
    with pytest.raises(ValueError, match="placement"):
        make_duplicates({"count": 40, "placement": {"attempts": 200}})


# ---------------------------------------------------------------------------- fixtures of issue 13

from scipy.spatial import ConvexHull  # noqa: E402

from invrender.synthesize.duplicates import (  # noqa: E402
    DUPLICATES_DEFAULTS,
    DUPLICATES_PRESETS,
    ConvexShape,
    _box_print,
    convex_gap,
    resolve_config,
)
from invrender.assets.primitives import BOX_SIDES  # noqa: E402
from invrender.synthesize.room import merge_config  # noqa: E402

PRESET_NAMES = sorted(DUPLICATES_PRESETS)


@pytest.fixture(scope="module")
def presets():
    """Every preset, built with a small atlas (the atlas does not move a copy)."""
    return {name: make_duplicates({"preset": name, "atlas_resolution": 64}) for name in PRESET_NAMES}


def copy_vertices(scene, copy):
    v0, v1 = copy["vertices"]
    return scene.mesh.positions[v0:v1].astype(np.float64)


def test_preset_names_counts_and_resolutions(presets):
    assert PRESET_NAMES == sorted(f"{k}-{n}-{s}" for k in ("box", "can") for n in (6, 10, 20) for s in ("ci", "hd"))
    for name, (scene, meta) in presets.items():
        kind, count, size = name.split("-")
        cam = scene.cameras[0]
        assert (cam.width, cam.height) == ((1600, 1200) if size == "hd" else (320, 240))
        assert len(meta["copies"]) == len(meta["poses"]["instances"]) == int(count)
        assert meta["object"]["kind"] == kind and meta["config"]["preset"] == name
        assert {c["orientation"] for c in meta["copies"]} == {"upright", "upside_down", "lying"}
        touching = meta["config"]["placement"]["touching"]
        assert len(meta["touching"]) == touching >= 2
        np.testing.assert_array_equal(np.unique(scene.mesh.instance_ids), np.arange(int(count) + 1))


def test_ci_and_hd_presets_are_one_scene(presets):
    """A CI fixture is its HD fixture at a fifth of the resolution: the same poses."""
    for name in PRESET_NAMES:
        if name.endswith("-ci"):
            np.testing.assert_allclose(
                poses_of(presets[name][1]), poses_of(presets[name.replace("-ci", "-hd")][1]), atol=1e-12
            )


def test_presets_pass_the_workflows_override_check():
    """What rules/common.smk does with a scene's config: merge_config against the defaults, and
    every value of the type of its default (its JSON schema is built from them)."""

    def same_types(value, default, where):
        if isinstance(default, dict):
            for key in value:
                same_types(value[key], default[key], f"{where}.{key}")
        elif isinstance(default, list) and default and isinstance(default[0], (int, float)):
            assert len(value) == len(default) and all(isinstance(v, (int, float)) for v in value), where
        else:
            assert type(value) is type(default), where

    for name, preset in DUPLICATES_PRESETS.items():
        merge_config(DUPLICATES_DEFAULTS, {"preset": name, "seed": 3})
        merge_config(DUPLICATES_DEFAULTS, preset)
        same_types(preset, DUPLICATES_DEFAULTS, name)
    cfg = resolve_config({"preset": "box-6-ci", "camera": {"width": 200}, "placement": {"touching": 1}})
    assert cfg["camera"]["width"] == 200 and cfg["camera"]["height"] == 240  # overrides win over the preset
    assert cfg["placement"]["touching"] == 1 and cfg["object"]["kind"] == "box"
    with pytest.raises(ValueError, match=r"config\.preset: unknown preset 'box-7-hd'.*'box-10-ci'"):
        make_duplicates({"preset": "box-7-hd"})


def test_bad_kind_orientation_or_touching_says_which():
    with pytest.raises(ValueError, match=r"config\.object\.kind: 'ball'"):
        make_duplicates({"object": {"kind": "ball"}})
    with pytest.raises(ValueError, match=r"config\.placement\.orientations: \['sideways'\]"):
        make_duplicates({"placement": {"orientations": ["sideways"]}})
    with pytest.raises(ValueError, match=r"config\.placement\.touching: 6; expected 0 \.\. count - 1 = 5"):
        make_duplicates({"placement": {"touching": 6}})


def test_symmetry_is_recorded(presets):
    can, box = presets["can-6-ci"][1], presets["box-6-ci"][1]
    assert can["object"]["symmetry"]["type"] == "axis" and can["object"]["symmetry"]["axis"] == [0.0, 1.0, 0.0]
    assert box["object"]["symmetry"]["type"] == "none" and box["object"]["symmetry"]["axis"] is None
    for meta in (can, box):
        assert meta["poses"]["symmetry"] == meta["object"]["symmetry"]  # poses.json carries it
    assert "label seam at +X" in can["poses"]["convention"] and "edges along x, y, z" in box["poses"]["convention"]
    json.dumps(can, allow_nan=False)


def test_resting_copies_lie_as_stated_on_the_floor(presets):
    """Object +Y along world +Y (upright), -Y (upside down) or horizontal (lying; a box on an x
    or z side); the lowest vertex 0 .. max_lift above the floor; yaws all different."""
    for name in ("box-20-hd", "can-20-hd", "box-6-ci"):
        scene, meta = presets[name]
        max_lift = meta["config"]["placement"]["max_lift"]
        yaws = []
        for copy, T in zip(meta["copies"], poses_of(meta)):
            up = T[:3, 1]  # the object's +Y in the world
            expected = {"upright": 1.0, "upside_down": -1.0, "lying": 0.0}[copy["orientation"]]
            assert up[1] == pytest.approx(expected, abs=1e-12)
            if meta["object"]["kind"] == "box" and copy["orientation"] == "lying":
                assert max(abs(T[1, 0]), abs(T[1, 2])) == pytest.approx(1.0, abs=1e-12)  # an x or z side down
            y = copy_vertices(scene, copy)[:, 1]
            assert -1e-6 <= y.min() <= max_lift + 1e-6
            axis = T[:3, 0] if copy["orientation"] != "lying" else T[:3, 1]  # horizontal in every case
            yaws.append(np.degrees(np.arctan2(axis[2], axis[0])))
        assert np.ptp(yaws) > 180 and len(np.unique(np.round(yaws, 3))) == len(yaws)


def inside_depth(hull: ConvexHull, points: np.ndarray) -> float:
    """How deep the deepest of ``points`` lies inside a convex hull (negative: outside)."""
    centre = hull.points[hull.vertices].mean(0)
    radius = np.linalg.norm(hull.points[hull.vertices] - centre, axis=1).max()
    near = points[np.linalg.norm(points - centre, axis=1) <= radius]  # only these can be inside
    if len(near) == 0:
        return -np.inf
    return float(-(near @ hull.equations[:, :3].T + hull.equations[:, 3]).max(axis=1).min())


def surface_samples(scene, copy, spacing=5e-4):
    """Points along every triangle edge, ``spacing`` apart: two convex bodies that overlap have
    a vertex or an edge of one inside the other."""
    f0, f1 = copy["faces"]
    tri = scene.mesh.positions[scene.mesh.faces[f0:f1]].astype(np.float64)
    p = np.concatenate([tri[:, 0], tri[:, 1], tri[:, 2]])
    q = np.concatenate([tri[:, 1], tri[:, 2], tri[:, 0]])
    n = np.ceil(np.linalg.norm(q - p, axis=1) / spacing).astype(np.int64) + 1  # samples per edge
    edge = np.repeat(np.arange(len(p)), n)
    s = (np.arange(n.sum()) - np.repeat(np.cumsum(n) - n, n)) / np.repeat(n - 1, n)
    return p[edge] + s[:, None] * (q - p)[edge]


def test_no_copies_overlap_and_touching_pairs_touch(presets):
    """Checked on the meshes with scipy's convex hulls, not with the generator's own test:
    copies that do not touch keep their bounding spheres gap apart; a touching pair does not
    overlap, and does once one is moved 0.5 mm towards the other (distance ~0)."""
    for name in ("box-10-hd", "can-10-hd", "box-20-hd", "can-20-hd"):
        scene, meta = presets[name]
        copies = meta["copies"]
        radius = np.linalg.norm(build_object(meta["config"]).positions, axis=1).max()
        gap = meta["config"]["placement"]["gap"]
        touching = {tuple(p) for p in meta["touching"]}
        centres = np.array([T[:3, 3] for T in poses_of(meta)])
        for i in range(len(copies)):
            for j in range(i + 1, len(copies)):
                if (i + 1, j + 1) not in touching:
                    apart = np.linalg.norm(centres[i, [0, 2]] - centres[j, [0, 2]])
                    assert apart >= 2 * radius + gap - 1e-9, (name, i + 1, j + 1)
        for a, b in touching:  # b was pushed out from a's centre along the floor
            i, j = a - 1, b - 1
            hull_i, samples_i = ConvexHull(copy_vertices(scene, copies[i])), surface_samples(scene, copies[i])
            samples_j = surface_samples(scene, copies[j])
            hull_j = ConvexHull(copy_vertices(scene, copies[j]))
            assert inside_depth(hull_i, samples_j) < 1e-6, (name, a, b)
            assert inside_depth(hull_j, samples_i) < 1e-6, (name, a, b)
            towards = centres[i] - centres[j]
            towards[1] = 0
            shift = 5e-4 * towards / np.linalg.norm(towards)
            moved_hull = ConvexHull(copy_vertices(scene, copies[j]) + shift)
            depth = max(inside_depth(hull_i, samples_j + shift), inside_depth(moved_hull, samples_i))
            assert depth > 1e-5, (name, a, b)
        assert {c["instance_id"] for c in copies if c["touches"]} == {k for pair in touching for k in pair}


def test_convex_gap_is_the_separation_of_two_boxes():
    """Two upright boxes side by side along x, d apart: the separating-axis gap is d (and
    negative by the overlap when they overlap), at any common yaw."""
    obj = build_object({"object": {"kind": "box"}})
    shape = ConvexShape(obj.positions, obj.faces)
    w = 0.08
    for yaw in (0.0, 0.7, 2.0):
        c, s = np.cos(yaw), np.sin(yaw)
        R = np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]])
        for d in (0.02, 0.0, -0.01):
            Ta, Tb = np.eye(4), np.eye(4)
            Ta[:3, :3] = Tb[:3, :3] = R
            Tb[:3, 3] = R @ [w + d, 0, 0]
            assert convex_gap(shape, Ta, Tb) == pytest.approx(d, abs=1e-9)


def test_every_vertex_projects_inside_the_image(presets):
    for name, (scene, meta) in presets.items():
        cam, margin = scene.cameras[0], meta["config"]["placement"]["margin_px"]
        for copy in meta["copies"]:
            uv = project_points(cam, copy_vertices(scene, copy))
            assert uv.min() >= margin - 1e-6 and np.all(
                uv.max(0) <= [cam.width - margin + 1e-6, cam.height - margin + 1e-6]
            )


def test_hd_copies_span_a_useful_number_of_pixels(presets):
    """At 1600 x 1200 each copy's projection is 120-300 px across (the issue's photo scale)."""
    for name in PRESET_NAMES:
        if name.endswith("-hd"):
            scene, meta = presets[name]
            spans = [
                np.ptp(project_points(scene.cameras[0], copy_vertices(scene, c)), axis=0).max() for c in meta["copies"]
            ]
            assert 120 <= min(spans) and max(spans) <= 300, (name, min(spans), max(spans))


def test_the_floor_fills_every_view(presets):
    """The rays through the image's corners and edge midpoints meet the floor quad."""
    for name, (scene, meta) in presets.items():
        cam = scene.cameras[0]
        fx, fz = np.asarray(meta["config"]["floor"]["size"]) / 2
        (f, _), (cx, cy) = cam.focal, cam.principal_point
        eye = -cam.R.T @ cam.t
        for u in (0, cam.width / 2, cam.width):
            for v in (0, cam.height / 2, cam.height):
                d = cam.R.T @ [(u - cx) / f, (v - cy) / f, 1]
                hit = eye - eye[1] / d[1] * d
                assert d[1] < 0 and abs(hit[0]) < fx and abs(hit[2]) < fz, (name, u, v)


def face_image(size, side, n=48):
    """A side's print sampled on an n x n grid over its own (u, v), as seen from outside."""
    name = BOX_SIDES[side]
    axis = "xyz".index(name[1])
    s, t = np.meshgrid(np.linspace(-0.97, 0.97, n), np.linspace(-0.97, 0.97, n), indexing="ij")
    # Points on the side whose (u, v) of _face_coordinates are (s * hu, t * hv).
    ia, ib = {0: (1, 2), 1: (2, 0), 2: (0, 1)}[axis]
    sign = 1.0 if name[0] == "+" else -1.0
    pos = np.zeros((n * n, 3))
    pos[:, axis] = sign * size[axis] / 2
    pos[:, ia] = sign * s.ravel() * size[ia] / 2
    pos[:, ib] = t.ravel() * size[ib] / 2
    return _box_print(size, side)(pos, None).reshape(n, n, 3)


def dihedral(img):
    """The eight turns and mirrors of a square image, identity first."""
    out = []
    for k in range(4):
        r = np.rot90(img, k)
        out += [r, r[::-1]]
    return out


def test_box_faces_and_their_turns_are_distinguishable():
    size = np.array(DUPLICATES_DEFAULTS["object"]["size"])
    faces = [face_image(size, k) for k in range(6)]
    for k, img in enumerate(faces):
        assert img.std(axis=(0, 1)).max() > 0.15  # printed, not plain
        for m in dihedral(img)[1:]:  # no turn or mirror maps a side's print onto itself
            assert np.abs(m - img).mean() > 0.05, k
        for j in range(k + 1, 6):  # nor onto another side's
            assert min(np.abs(m - faces[j]).mean() for m in dihedral(img)) > 0.1, (k, j)


def test_box_object_and_its_baked_print(presets):
    scene, meta = presets["box-6-ci"]
    obj = build_object(meta["config"])
    np.testing.assert_allclose(np.ptp(obj.positions, axis=0), meta["config"]["object"]["size"])
    assert signed_volume(obj.positions, obj.faces) == pytest.approx(np.prod(meta["config"]["object"]["size"]))
    assert [p["name"] for p in meta["object"]["parts"]] == list(BOX_SIDES)
    # Each side's texels in the maps hold its own colour: side means differ pairwise.
    f0 = meta["copies"][0]["faces"][0]
    means = []
    for p in meta["object"]["parts"]:
        a, b = p["faces"]
        uv = scene.mesh.uvs[scene.mesh.faces[f0 + a : f0 + b]].mean(1)
        rows, cols = texel_index(uv, scene.maps.atlas_shape)
        means.append(scene.maps.kd[rows, cols].mean(0))
    means = np.array(means)
    d = np.linalg.norm(means[:, None] - means[None], axis=-1) + np.eye(6)
    assert d.min() > 0.05


@pytest.mark.parametrize("preset", ["box-6-ci", "can-6-ci"])
def test_rendered_masks_hold_every_copy(tmp_path, preset):
    """Through the synthesize stage with the OpenCL renderer: each copy's id covers the inside
    of its projected outline (the convex hull of its projected vertices: the objects are
    convex) and nothing outside it; a copy that no other hides covers all of it; both copies
    of a touching pair show and share a border."""
    from scipy.ndimage import binary_dilation

    from invrender.scene.images import read_mask
    from invrender.synthesize import run as synthesize

    meta = synthesize("duplicates", tmp_path / "capture", {"preset": preset, "atlas_resolution": 128}, spp=2)
    ids = read_mask(tmp_path / "capture" / "ground_truth" / "masks" / "view_000.png")
    scene, again = make_duplicates(meta["config"])
    assert again["poses"] == meta["poses"]
    cam = scene.cameras[0]
    assert ids.shape == (cam.height, cam.width) == (240, 320)
    ys, xs = np.mgrid[0 : cam.height, 0 : cam.width]
    centres = np.stack([xs.ravel() + 0.5, ys.ravel() + 0.5], 1)
    outlines = []
    for copy in meta["copies"]:
        hull = ConvexHull(project_points(cam, copy_vertices(scene, copy)))
        inside = (centres @ hull.equations[:, :2].T + hull.equations[:, 2]).max(1) <= 0
        outlines.append((inside.reshape(ids.shape), hull.volume, hull.area))  # 2-d: area, perimeter
    for k, (copy, (inside, area, perimeter)) in enumerate(zip(meta["copies"], outlines)):
        mine = ids == copy["instance_id"]
        assert not (mine & ~binary_dilation(inside)).any(), copy["instance_id"]
        hidden = any((inside & other).any() for j, (other, _, _) in enumerate(outlines) if j != k)
        assert mine.sum() <= area + perimeter / 2
        assert mine.sum() >= (0.5 * area if hidden else area - perimeter / 2), copy["instance_id"]
    assert len(meta["touching"]) == 2
    for a, b in meta["touching"]:
        assert (binary_dilation(ids == a) & (ids == b)).sum() >= 5, (a, b)
