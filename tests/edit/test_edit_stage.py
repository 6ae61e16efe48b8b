"""The edit stage on the small synthetic room (the 2-view, 32 x 24 room of tests/stage_runs.py):
every kind of edit, light that is linear in ke, a switched-off room that is black, the truth
rendered beside, bad edit lists refused with one line, and the CLI's files."""

import json

import numpy as np
import pytest
import yaml
from stage_runs import SMALL_ROOM

from invrender.cli import main
from invrender.edit import run
from invrender.scene.atomic import MARKER
from invrender.scene.edits import sphere_mesh
from invrender.scene.format import write_scene
from invrender.scene.images import read_image
from invrender.scene.mesh_io import write_ply
from invrender.synthesize import make_room

ROOM = {**SMALL_ROOM, "cameras": {"count": 2, "width": 24, "height": 18}}


@pytest.fixture(scope="module")
def room_dirs(tmp_path_factory):
    """The room with its window and sky, and the same room without a sky (lit by its lamps only)."""
    root = tmp_path_factory.mktemp("edit")
    scene, metadata = make_room(ROOM)
    write_scene(root / "room", scene, metadata)
    scene.maps.kg[:] = 0.0
    write_scene(root / "lamps_only", scene, metadata)
    # The same room in another atlas, upside down: its lamps come in the other raster order.
    other, metadata = make_room(ROOM | {"atlas_resolution": 96})
    other.mesh.uvs[:, 1] = 1.0 - other.mesh.uvs[:, 1]
    for name in ("kd", "ks", "ka", "ke", "kw"):
        setattr(other.maps, name, np.ascontiguousarray(getattr(other.maps, name)[::-1]))
    write_scene(root / "room_96", other, metadata)
    return root


def views(out, edit, suffix=""):
    """An edit's images by camera: the scene's (suffix "") or the truth's ("_truth")."""
    paths = (out / edit).glob(f"*{suffix}.exr")
    return {p.stem.removesuffix(suffix): read_image(p) for p in paths if suffix or not p.stem.endswith("_truth")}


def test_every_kind_renders_and_the_truth_beside_it_is_the_same_edit(room_dirs, tmp_path):
    """With the room as its own truth, each truth image must equal the scene's bit for bit: the
    same edit (regions by 3D point and by centroid) at the same seed."""
    edits = [
        {"name": "off", "kind": "relight", "emission_scale": 0.0, "emitters": [1]},
        {"name": "ball", "kind": "insert", "object": "sphere", "center": [0.2, 1.1, 0.1], "radius": 0.35,
         "material": {"kd": [0.6, 0.2, 0.2], "ks": 0.3, "ka": 0.05}},
        {"name": "lamp", "kind": "insert", "object": "sphere", "center": [-0.4, 1.2, -0.2], "radius": 0.15,
         "material": {"ke": 10.0}},
        {"name": "dark_floor", "kind": "material", "box": {"min": [-3, -0.01, -3], "max": [3, 0.01, 3]},
         "values": {"kd": 0.02, "ks": 0.0}},
        {"name": "novel", "kind": "camera", "eye": [1.2, 1.5, 1.0], "target": [0, 0.8, 0], "fov_deg": 70,
         "width": 20, "height": 14},
    ]  # fmt: skip
    out = tmp_path / "edits"
    summary = run(room_dirs / "room", edits, out, truth_dir=room_dirs / "room", spp=4, seed=2, progress=False)
    assert (out / MARKER).read_text() == "edit\n"
    document = json.loads((out / "edits.json").read_text())
    assert document["edits"] == summary and [e["name"] for e in summary] == [e["name"] for e in edits]
    plain = run(
        room_dirs / "room", [edits[-1] | {"name": "plain", "kind": "camera"}], tmp_path / "p", spp=4, progress=False
    )
    for entry in summary:
        name = entry["name"]
        ours, truth = views(out, name), views(out, name, "_truth")
        assert set(ours) == set(truth) == ({"camera"} if name == "novel" else {"view_000", "view_001"})
        for stem in ours:
            np.testing.assert_array_equal(ours[stem], truth[stem])
            assert (out / name / f"{stem}.png").stat().st_size > 0 and (out / name / f"{stem}_truth.png").exists()
        assert entry["scene"] == entry["truth"] and entry["features"]["scene"] == entry["features"]["truth"]
    assert plain[0]["cameras"] == ["camera"]
    assert views(out, "novel")["camera"].shape == (14, 20, 3)
    # The room has two lamp panels: two regions with their texels and centroids under the ceiling.
    regions = summary[0]["scene"]["emitter_regions"]
    assert len(regions) >= 2 and all(r["texels"] > 0 for r in regions)
    assert all(abs(r["centroid"][1] - 2.6) < 0.05 for r in regions if r["centroid"])
    assert summary[0]["scene"]["scaled"] == [1]
    assert summary[1]["scene"] == {"triangles": 2 * 32 * 16 - 2 * 32, "texels": 64}
    assert summary[2]["features"]["scene"]["emission"] and summary[2]["features"]["scene"]["emitter_sampling"]
    assert summary[3]["scene"]["texels"] > 100, "the floor's texels"
    assert summary[3]["scene"]["texels_with_border"] >= summary[3]["scene"]["texels"]


def test_a_room_with_its_lamps_and_sky_off_is_black_and_twice_the_emission_is_twice_the_light(room_dirs, tmp_path):
    edits = [
        {"name": "black", "kind": "relight", "emission_scale": 0.0, "sky": 0.0},
        {"name": "one", "kind": "relight", "emission_scale": 1.0},
        {"name": "two", "kind": "relight", "emission_scale": 2.0},
        {"name": "half_off", "kind": "relight", "emission_scale": 0.0, "emitters": [2]},
    ]
    out = tmp_path / "edits"
    summary = run(room_dirs / "room", edits[:1], tmp_path / "room_black", spp=4, progress=False)
    for image in views(tmp_path / "room_black", "black").values():
        assert not image.any(), "no light at all: exactly 0"
    assert not summary[0]["features"]["scene"]["emission"] and not summary[0]["features"]["scene"]["environment"]
    run(room_dirs / "lamps_only", edits[1:], out, spp=8, seed=4, progress=False)
    one, two, half = views(out, "one"), views(out, "two"), views(out, "half_off")
    for stem in one:
        assert one[stem].mean() > 0.01
        # The same paths with every emitted radiance doubled (light sampling is by relative power).
        np.testing.assert_allclose(two[stem], 2 * one[stem], rtol=1e-5, atol=1e-7)
    assert 0.1 < sum(h.mean() for h in half.values()) / sum(o.mean() for o in one.values()) < 0.9


def test_an_emitter_is_carried_to_the_truth_by_its_place_in_the_room(room_dirs, tmp_path):
    """A truth with another atlas numbers its lamps its own way: each chosen lamp is the truth's
    lamp at the same place, and switching it off there darkens the truth as much."""
    edits = [{"name": f"off{i}", "kind": "relight", "emission_scale": 0.0, "emitters": [i]} for i in (1, 2)]
    out = tmp_path / "edits"
    summary = run(room_dirs / "room", edits, out, truth_dir=room_dirs / "room_96", spp=16, progress=False)
    for entry in summary:
        mine = {r["region"]: r["centroid"] for r in entry["scene"]["emitter_regions"]}
        theirs = {r["region"]: r["centroid"] for r in entry["truth"]["emitter_regions"]}
        ((chosen,), (matched,)) = entry["scene"]["scaled"], entry["truth"]["scaled"]
        assert np.linalg.norm(np.subtract(mine[chosen], theirs[matched])) < 0.01  # lamps 1.8 m apart
        ours, truth = views(out, entry["name"]), views(out, entry["name"], "_truth")
        ratio = sum(o.mean() for o in ours.values()) / sum(t.mean() for t in truth.values())
        assert abs(ratio - 1) < 0.1, ratio  # two atlases of one room: the same light, within texel detail
    assert [e["truth"]["scaled"] for e in summary] == [[2], [1]], "numbered the other way round"


def test_bad_edit_lists_are_refused_with_one_line_before_any_render(room_dirs, tmp_path, capsys):
    sphere = {"name": "s", "kind": "insert", "object": "sphere", "center": [0, 1, 0], "material": {"kd": 0.5}}
    mesh = {"name": "m", "kind": "insert", "mesh": "nowhere.obj"}
    relight = {"name": "r", "kind": "relight"}
    box = {"name": "b", "kind": "material", "box": {"min": [9, 9, 9], "max": [10, 10, 10]}, "values": {"kd": 0.1}}
    cases = [
        ([{"name": "x", "kind": "paint"}], 'edits[0].kind: expected one of "relight", "insert", "material", "camera"'),
        ([sphere], "edits[0].radius: expected this required field (it is missing)"),
        ([mesh | {"material": {}}], "edits[0].material: expected"),
        ([mesh | {"material": {"kd": 0.2}}], "edits[0].mesh: expected an existing mesh file"),
        ([sphere | {"radius": 0.2, "material": {"kd": 1.5}}], "edits[0].material.kd: expected values in [0, 1]"),
        ([relight], "edits[0]: expected one of the fields emission_scale, sky_scale, sky"),
        (
            [relight | {"emission_scale": 0, "emitters": [9]}],
            "edits[0].emitters: expected emitter regions of the scene",
        ),
        ([box], "edits[0].box: expected a box holding some surface"),
        ([relight | {"sky": 1}, relight | {"sky": 2}], "edits[1].name: expected a name no other edit has"),
        (
            [relight | {"sky": 1, "cameras": ["view_7"]}],
            "edits[0].cameras: expected cameras of the scene (view_000, view_001)",
        ),
    ]
    for k, (edits, message) in enumerate(cases):
        path = tmp_path / f"edits{k}.yaml"
        path.write_text(yaml.safe_dump(edits))
        out = tmp_path / f"out{k}"
        capsys.readouterr()
        assert main(["edit", "--scene", str(room_dirs / "room"), "--edits", str(path), "--out", str(out)]) == 2
        lines = capsys.readouterr().err.strip().splitlines()
        assert len(lines) == 1 and f"ERROR {path}: {message}" in lines[0], (message, lines)
        assert not out.exists() and not list(tmp_path.glob(f".out{k}*"))


def test_the_cli_inserts_a_mesh_file_and_writes_every_file(room_dirs, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)  # a relative mesh path is relative to the working directory
    write_ply(tmp_path / "rock.ply", sphere_mesh((0, 0, 0), 1.0, 12))
    edits = {
        "edits": [  # a config's `edits:` key works as well as a bare list
            {"name": "rock", "kind": "insert", "mesh": "rock.ply", "material": {"kd": 0.6},
             "transform": [[0.2, 0, 0, 0.3], [0, 0.2, 0, 0.9], [0, 0, 0.2, 0.0], [0, 0, 0, 1]],
             "cameras": ["view_001"]},
            {"name": "dim", "kind": "relight", "emission_scale": 0.5, "sky_scale": 0.5},
        ]
    }  # fmt: skip
    (tmp_path / "edits.json").write_text(json.dumps(edits))
    out = tmp_path / "out"
    args = ["edit", "--scene", str(room_dirs / "room"), "--edits", "edits.json", "--out", str(out)]
    assert main([*args, "--spp", "2", "--truth", str(room_dirs / "room")]) == 0
    names = sorted(p.relative_to(out).as_posix() for p in out.rglob("*") if p.is_file())
    assert names == sorted(
        [MARKER, "edits.json", "rock/view_001.exr", "rock/view_001.png", "rock/view_001_truth.exr"]
        + ["rock/view_001_truth.png"]
        + [f"dim/view_00{i}{s}.{e}" for i in (0, 1) for s in ("", "_truth") for e in ("exr", "png")]
    )
    document = json.loads((out / "edits.json").read_text())
    assert document["edits"][0]["scene"] == {"triangles": 2 * 12 * 6 - 2 * 12, "texels": 64}
    assert np.isfinite(views(out, "rock")["view_001"]).all()
    assert main([*args, "--spp", "2"]) == 0
    assert not (out / "rock" / "view_001_truth.exr").exists(), "a rerun replaces the whole output"
