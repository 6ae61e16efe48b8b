"""Fuzz suite over the stages' inputs (issue 10): meshes (geometry), cameras (cameras), capture
images (gradients), scene directories (render, features, export) and instance masks (read_mask: no stage reads them
yet). Every generated input must give the property of fuzz_runs.check_property: exit 0 with
finite outputs, or exit 2 with one line naming the file and the field.

Two profiles, chosen by the environment variable INVRENDER_FUZZ:
- quick (default, in the normal suite): a few derandomised examples per input kind;
- long: many random examples, a benchmark run by hand (docs/reliability.md):
      INVRENDER_FUZZ=long pytest tests/fuzz/test_fuzz_inputs.py -n 0 --hypothesis-show-statistics
"""

import json
import os
import tempfile
from pathlib import Path

import cv2
import numpy as np
import OpenEXR
from fuzz_runs import check_property
from hypothesis import HealthCheck, assume, given, settings
from hypothesis import strategies as st
from inputs import (
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

from invrender.scene.images import read_mask
from invrender.scene.types import SceneError

settings.register_profile(
    "fuzz-quick",
    max_examples=int(os.environ.get("INVRENDER_FUZZ_EXAMPLES", 10)),
    deadline=None,
    derandomize=True,
    database=None,
    suppress_health_check=[HealthCheck.too_slow],
)
settings.register_profile(
    "fuzz-long",
    max_examples=int(os.environ.get("INVRENDER_FUZZ_EXAMPLES", 150)),
    deadline=None,
    database=None,
    suppress_health_check=[HealthCheck.too_slow],
)
PROFILE = settings.get_profile(f"fuzz-{os.environ.get('INVRENDER_FUZZ', 'quick')}")

NASTY = [0.0, -1.0, float("nan"), float("inf"), -float("inf"), 1e-300, 1e300]


def truncate(path: Path, fraction: float) -> None:
    data = path.read_bytes()
    path.write_bytes(data[: int(len(data) * fraction)])


# ---------------------------------------------------------------------------- meshes -> geometry


MESH_FAULTS = [
    "none",
    "index",
    "negative_index",
    "nan",
    "inf",
    "far_vertex",
    "truncate",
    "no_faces",
    "garbage",
    "empty",
    "two_vertex_face",
    "huge_index",
    "collinear",
    "header_lie",
    "cloud",
    "cloud_zero_normal",
    "cloud_nan_normal",
]


def write_cloud(path: Path, positions, normals, fmt: str) -> None:
    """A point cloud with normals: PLY x, y, z, nx, ny, nz, or OBJ v and vn lines, no faces."""
    if fmt == "obj":
        path.write_text(
            "".join(f"v {x!r} {y!r} {z!r}\n" for x, y, z in positions.tolist())
            + "".join(f"vn {x!r} {y!r} {z!r}\n" for x, y, z in normals.tolist())
        )
        return
    header = [
        "ply",
        f"format {'binary_little_endian' if fmt == 'ply_binary' else 'ascii'} 1.0",
        f"element vertex {len(positions)}",
        *[f"property float {c}" for c in ("x", "y", "z", "nx", "ny", "nz")],
        "end_header",
    ]
    rows = np.hstack([positions, normals]).astype("<f4")
    body = (
        rows.tobytes()
        if fmt == "ply_binary"
        else "".join(" ".join(map(repr, r)) + "\n" for r in rows.tolist()).encode()
    )
    path.write_bytes(("\n".join(header) + "\n").encode() + body)


@PROFILE
@given(
    fmt=st.sampled_from(["obj", "ply_ascii", "ply_binary"]),
    n=st.integers(3, 10),
    log_scale=st.sampled_from([-30, -6, -3, -1, 0, 0, 0, 1, 2, 3, 5, 30]),
    fault=st.sampled_from(MESH_FAULTS),
    where=st.floats(0, 1),
    fraction=st.floats(0.05, 0.99),
)
def test_fuzz_meshes_through_geometry(fmt, n, log_scale, fault, where, fraction):
    positions, faces = grid_mesh(n, 10.0**log_scale)
    v, f = int(where * (len(positions) - 1)), int(where * (len(faces) - 1))
    faces, positions = faces.astype(np.int64), positions.astype(np.float64)
    if fault == "index":
        faces[f, 1] = len(positions) + 99998
    elif fault == "negative_index":
        faces[f, 2] = -99999 - 1  # OBJ: -99999, past the start; PLY: negative
    elif fault == "huge_index":
        faces[f, 0] = 10**12
    elif fault in ("nan", "inf"):
        positions[v, 1] = float(fault)
    elif fault == "far_vertex":
        positions[v] = [1e30, 0, 0]
    elif fault == "no_faces":
        faces = faces[:0]
    elif fault == "empty":
        positions, faces = positions[:0], faces[:0]
    elif fault == "collinear":
        positions[:, 1:] = 0.0  # every face has zero area
    with tempfile.TemporaryDirectory() as tmp:
        root = Path(tmp)
        source = root / f"mesh.{fmt.split('_')[0]}"
        if fault.startswith("cloud"):
            rng = np.random.default_rng(n)
            points = rng.normal(size=(400, 3)) * 10.0**log_scale
            normals = points / np.linalg.norm(points, axis=1, keepdims=True)  # a blob: normals outward
            normals[int(where * 399)] = {"cloud": normals[0], "cloud_zero_normal": 0.0, "cloud_nan_normal": np.nan}[
                fault
            ]
            write_cloud(source, points, normals, fmt)
        elif fmt == "obj":
            write_obj(source, positions, faces)
        else:
            write_ply(source, np.clip(positions, -3e38, 3e38), np.clip(faces, -(2**31), 2**31 - 1), fmt == "ply_binary")
        if fault == "truncate":
            truncate(source, fraction)
        elif fault == "garbage":
            source.write_bytes(
                source.read_bytes()[: int(fraction * source.stat().st_size)] + b"\x00\xff garbage f 1 x\n"
            )
        elif fault == "header_lie" and fmt != "obj":  # the header counts more faces than follow
            data = source.read_bytes()
            source.write_bytes(
                data.replace(f"element face {len(faces)}".encode(), f"element face {len(faces) + 7}".encode())
            )
        elif fault == "two_vertex_face":
            source.write_text(source.read_text(errors="replace") + "f 1 2\n") if fmt == "obj" else None
        out = root / "out"
        outcome = check_property(
            root,
            out,
            ["geometry", source, "--out", out, "--atlas-resolution", "64"],
            subprocess_run=True,
            names=("mesh.",),
        )
    if (
        fault
        in (
            "index",
            "negative_index",
            "huge_index",
            "nan",
            "inf",
            "far_vertex",
            "no_faces",
            "empty",
            "collinear",
            "cloud_zero_normal",
            "cloud_nan_normal",
        )
        or (fault == "header_lie" and fmt != "obj")
        or abs(log_scale) >= 6
    ):
        assert outcome.code == 2, (fault, log_scale, "accepted")
    if fault == "none" and -3 <= log_scale <= 3 and n >= 4:  # n = 3: 8 faces, below min_island_faces
        assert outcome.code == 0, outcome.errors


# ---------------------------------------------------------------------------- cameras -> cameras


@st.composite
def colmap_camera(draw):
    model = draw(st.sampled_from(["PINHOLE", "SIMPLE_PINHOLE", "OPENCV"]))
    w, h = draw(st.sampled_from([(32, 24), (1, 1), (0, 24), (4000, 3000)]))
    params = {
        "PINHOLE": [30.0, 30.0, w / 2, h / 2],
        "SIMPLE_PINHOLE": [30.0, w / 2, h / 2],
        "OPENCV": [30.0, 30.0, w / 2, h / 2, 0.01, 0.0, 0.0, 0.0],
    }[model]
    if draw(st.booleans()):
        params[draw(st.integers(0, len(params) - 1))] = draw(st.sampled_from(NASTY + [-5e3, 5e3]))
    if draw(st.booleans()):
        params = params[: draw(st.integers(0, len(params) - 1))]  # a wrong parameter count
    qvec = draw(
        st.sampled_from(
            [
                [1.0, 0, 0, 0],
                [0.0, 0, 0, 0],
                [2.0, 0, 0, 0],
                [float("nan"), 0, 0, 0],
                [0.5, 0.5, 0.5, 0.5],
                [1.0, 1e300, 0, 0],
            ]
        )
    )
    tvec = draw(st.sampled_from([[0.0, 0, 2], [float("nan"), 0, 0], [1e300, 0, 0], [0, float("inf"), 0]]))
    return (1, model, w, h, params), (1, qvec, tvec, 1, "view.png")


@PROFILE
@given(case=colmap_camera(), binary=st.booleans(), cut=st.one_of(st.none(), st.floats(0.0, 0.99)))
def test_fuzz_colmap_models_through_cameras(case, binary, cut):
    camera, image = case
    with tempfile.TemporaryDirectory() as tmp:
        root = Path(tmp)
        (write_colmap_binary if binary else write_colmap_text)(root / "sparse", [camera], [image])
        if cut is not None:
            truncate(root / "sparse" / f"cameras.{'bin' if binary else 'txt'}", cut)
        out = root / "out"
        check_property(root, out, ["cameras", root / "sparse", "--out", out], subprocess_run=True, names=("sparse",))


JSON_VALUES = NASTY + [None, "30", [], {}, True, -100.0, 1e6]


@PROFILE
@given(
    key=st.sampled_from(
        [
            "fl_x",
            "cx",
            "w",
            "h",
            "k1",
            "camera_angle_x",
            "camera_model",
            "frames",
            "transform_matrix",
            "file_path",
            "(document)",
        ]
    ),
    value=st.sampled_from(JSON_VALUES),
    matrix=st.sampled_from(["eye", "scaled", "mirror", "nan", "short"]),
)
def test_fuzz_transforms_json_through_cameras(key, value, matrix):
    matrices = {
        "eye": np.eye(4),
        "scaled": 3 * np.eye(4),
        "mirror": np.diag([-1.0, 1, 1, 1]),
        "nan": np.full((4, 4), np.nan),
        "short": np.eye(3),
    }
    doc = transforms_doc(matrix=matrices[matrix].tolist())
    if key == "(document)":
        doc = value
    elif key in ("transform_matrix", "file_path"):
        doc["frames"][0][key] = value
    else:
        doc[key] = value
    with tempfile.TemporaryDirectory() as tmp:
        root = Path(tmp)
        write_json(root / "transforms.json", doc)
        cv2.imwrite(str(root / "view.png"), np.zeros((24, 32, 3), np.uint8))
        out = root / "out"
        check_property(
            root,
            out,
            ["cameras", root / "transforms.json", "--out", out],
            subprocess_run=True,
            names=("transforms.json",),
        )


# ---------------------------------------------------------------------------- captures -> gradients


@PROFILE
@given(
    fmt=st.sampled_from(["exr", "exr_half", "png8", "png16"]),
    size=st.sampled_from([(24, 32), (24, 31), (1, 1)]),
    channels=st.sampled_from([1, 2, 3, 4]),
    bad=st.sampled_from([None, np.nan, np.inf, -np.inf, 1e5, -1.0]),
    pixel=st.tuples(st.integers(0, 23), st.integers(0, 31)),
    cut=st.one_of(st.none(), st.floats(0.0, 0.99)),
)
def test_fuzz_capture_images_through_gradients(fmt, size, channels, bad, pixel, cut):
    assume(channels != 2 and not (fmt.startswith("exr") and channels == 4))  # what OpenEXR / OpenCV write
    with tempfile.TemporaryDirectory() as tmp:
        root = Path(tmp)
        path_name = "view.exr" if fmt.startswith("exr") else "view.png"
        geometry, sparse, images = gradient_inputs(root, path_name)
        image = np.full((*size, channels), 0.5, np.float32)
        if bad is not None:
            image[min(pixel[0], size[0] - 1), min(pixel[1], size[1] - 1), channels - 1] = bad
        path = images / path_name
        if fmt.startswith("exr"):
            dtype = np.float16 if fmt == "exr_half" else np.float32  # 1e5 overflows half to inf: bad too
            names = "RGB" if channels == 3 else "Y"
            with np.errstate(over="ignore"):
                planes = {c: np.ascontiguousarray(image[..., i], dtype) for i, c in enumerate(names)}
            header = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage}
            with OpenEXR.File(header, planes) as exr:
                exr.write(str(path))
        else:
            scale = 255 if fmt == "png8" else 65535
            pixels = (np.clip(np.nan_to_num(image), 0, 1) * scale).astype(np.uint8 if fmt == "png8" else np.uint16)
            ok, data = cv2.imencode(".png", pixels)
            path.write_bytes(data.tobytes())
        if cut is not None:
            truncate(path, cut)
        out = root / "gradients"
        outcome = check_property(
            root,
            out,
            [
                "gradients",
                "--geometry",
                geometry,
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
            subprocess_run=False,
            names=(path_name,),
        )
    if bad is not None and not np.isfinite(bad) and fmt.startswith("exr") and cut is None:
        assert outcome.code == 2


# ---------------------------------------------------------------------------- scene directories -> render


SCENE_KEYS = ["version", "mesh", "cameras", "maps", "maps.kd", "maps.kg", "metadata", "(extra)"]


@PROFILE
@given(
    key=st.sampled_from(SCENE_KEYS),
    action=st.sampled_from(["delete", "replace"]),
    value=st.sampled_from([None, "", -1, 3, 1e308, "nope.exr", "../outside.ply", [], {}, True]),
    nan_map=st.sampled_from([None, "kd", "ke", "kg"]),
    stage=st.sampled_from(["render", "features", "export"]),
)
def test_fuzz_scene_directories_through_render_features_export(key, action, value, nan_map, stage):
    from invrender.scene.images import write_exr

    with tempfile.TemporaryDirectory() as tmp:
        root = Path(tmp)
        scene = render_inputs(root)
        doc = json.loads((scene / "scene.json").read_text())
        parent, name = (doc["maps"], key.split(".")[1]) if "." in key else (doc, key)
        if action == "delete":
            parent.pop(name, None)
        else:
            parent[name] = value
        (scene / "scene.json").write_text(json.dumps(doc))
        if nan_map:
            maps = json.loads((scene / "scene.json").read_text()).get("maps")
            target = scene / (
                maps[nan_map] if isinstance(maps, dict) and isinstance(maps.get(nan_map), str) else f"{nan_map}.exr"
            )
            if target.suffix == ".exr" and target.is_file():
                from invrender.scene.images import read_image

                image = read_image(target)
                image.reshape(-1)[0] = np.nan
                write_exr(target, image)
        out = root / {"render": "renders", "features": "features.json", "export": "usd"}[stage]
        extra = ["--spp", "1"] if stage == "render" else []
        # export runs usd-core (native): in a subprocess
        check_property(
            root, out, [stage, scene, "--out", out, *extra], subprocess_run=stage == "export", names=("scene",)
        )


# ---------------------------------------------------------------------------- masks


@PROFILE
@given(
    depth=st.sampled_from([np.uint8, np.uint16]),
    channels=st.sampled_from([1, 3, 4]),
    cut=st.one_of(st.none(), st.floats(0.0, 0.99)),
    values=st.integers(0, 65535),
)
def test_fuzz_instance_masks(depth, channels, cut, values):
    """read_mask gives an (H, W) uint16 mask of the stored ids or one SceneError naming the file."""
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "mask.png"
        ids = np.full((8, 8, channels), values % (np.iinfo(depth).max + 1), depth)
        cv2.imwrite(str(path), ids if channels > 1 else ids[..., 0])
        if cut is not None:
            truncate(path, cut)
        try:
            mask = read_mask(path)
        except SceneError as error:
            assert str(path) in str(error) and ": expected " in str(error)
            return
        assert channels == 1 and mask.dtype == np.uint16 and mask.shape == (8, 8)
        assert (mask == ids[..., 0]).all()


# ---------------------------------------------------------------------------- textured OBJ files -> import


IMPORT_FAULTS = [
    "none",
    "sky_nan",
    "sky_empty",
    "texture_truncated",
    "texture_missing",
    "mtl_kd_nan",
    "mtl_ke_negative",
    "obj_index",
    "obj_far_vertex",
    "obj_truncated",
    "camera_focal_0",
    "no_camera",
]


@PROFILE
@given(fault=st.sampled_from(IMPORT_FAULTS), fraction=st.floats(0.05, 0.95))
def test_fuzz_textured_obj_files_through_import(fault, fraction):
    from objscene import write_room

    from invrender.scene.cubemap import latlong_directions
    from invrender.scene.images import write_exr

    def write_sky(path, radiance):
        sky = radiance(latlong_directions(32, 16)).astype(np.float32)
        if fault == "sky_nan":
            sky[int(fraction * 15), 3, 2] = np.nan
        write_exr(path, sky)

    with tempfile.TemporaryDirectory() as tmp:
        root = Path(tmp)
        files = write_room(root / "files", write_sky)
        box, mtl = files / "box.obj", files / "room.mtl"
        if fault == "sky_empty":
            (files / "sky.exr").write_bytes(b"")
        elif fault == "texture_truncated":
            truncate(files / "walls.png", fraction)
        elif fault == "texture_missing":
            (files / "floor.png").unlink()
        elif fault == "mtl_kd_nan":
            mtl.write_text(mtl.read_text().replace("Kd 0.7 0.3 0.2", "Kd nan 0.3 0.2"))
        elif fault == "mtl_ke_negative":
            mtl.write_text(mtl.read_text().replace("Ke 6 6 5", "Ke -6 6 5"))
        elif fault == "obj_index":
            box.write_text(box.read_text() + "f 1/1 2/2 99999/3\n")
        elif fault == "obj_far_vertex":
            box.write_text(box.read_text().replace("v -0.6 0.0 -0.9", "v -0.6 1e30 -0.9", 1))
        elif fault == "obj_truncated":
            truncate(box, fraction)
        elif fault == "camera_focal_0":
            text = (files / "sparse" / "cameras.txt").read_text().splitlines()
            fields = text[-1].split()
            (files / "sparse" / "cameras.txt").write_text(
                "\n".join(text[:-1] + [" ".join(fields[:4] + ["0", "0"] + fields[6:])]) + "\n"
            )
        elif fault == "no_camera":
            for f in (files / "sparse").iterdir():
                f.unlink()
            (files / "sparse").rmdir()
        out = root / "scene"
        outcome = check_property(
            root,
            out,
            [
                "import",
                files,
                "--out",
                out,
                "--environment",
                files / "sky.exr",
                "--cube-size",
                "8",
                "--max-atlas",
                "256",
            ],
            subprocess_run=True,
            names=("files",),
        )
    if fault in (
        "sky_nan",
        "sky_empty",
        "texture_missing",
        "mtl_kd_nan",
        "obj_index",
        "obj_far_vertex",
        "camera_focal_0",
    ):
        assert outcome.code == 2, (fault, "accepted")
    if fault == "none":
        assert outcome.code == 0, outcome.errors
