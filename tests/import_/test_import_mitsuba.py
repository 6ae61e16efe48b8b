"""An imported scene renders like Mitsuba 3 rendering the same files: Mitsuba loads the OBJ
geometry itself (one file per material part: Mitsuba's obj loader has no usemtl), the PNG
textures through its own bitmap plugin (sRGB decoded by Mitsuba, nearest filtering, tiling by
its own wrap mode), the lamp as its one-sided `area` emitter, the sky as an `envmap` of the same
radiance function, the camera from the same COLMAP model. Nothing of our import pipeline is
on Mitsuba's side."""

import numpy as np
from objscene import camera, sky_radiance, write_room
from test_import_stage import write_sky

from invrender import mitsuba as bridge
from invrender.cli import main
from invrender.scene.images import read_image

import mitsuba as mi  # isort: skip  (after invrender.mitsuba, which points drjit at libLLVM)

BOUNCES, SPP, BLOCK = 3, 256, 6


def split_by_material(obj_path, out_dir):
    """One OBJ per usemtl part (all v/vt lines kept; Mitsuba drops unused vertices)."""
    parts, header, current = {}, [], None
    for line in obj_path.read_text().splitlines():
        if line.startswith("usemtl"):
            current = line.split()[1]
            parts.setdefault(current, [])
        elif line.startswith("f "):
            parts[current].append(line)
        elif line.startswith(("v ", "vt ")):
            header.append(line)
    paths = {}
    for material, faces in parts.items():
        paths[material] = out_dir / f"{obj_path.stem}.{material}.obj"
        paths[material].write_text("\n".join(header + faces) + "\n")
    return paths


def mitsuba_scene(files, seed):
    bridge.set_variant()
    black = {"type": "diffuse", "reflectance": {"type": "rgb", "value": [0.0, 0.0, 0.0]}}

    def textured(name):
        return {
            "type": "diffuse",
            "reflectance": {"type": "bitmap", "filename": str(files / name), "filter_type": "nearest"},
        }

    bsdfs = {
        "walls": textured("walls.png"),
        "floor": textured("floor.png"),
        "box": {"type": "diffuse", "reflectance": {"type": "rgb", "value": [0.7, 0.3, 0.2]}},
        "lamp": black,
    }
    scene = {
        "type": "scene",
        "integrator": bridge.path_integrator(BOUNCES),
        "sensor": bridge.sensor_dict(camera(), SPP, seed),
    }
    for obj in ("room", "box", "lamp"):
        for material, path in split_by_material(files / f"{obj}.obj", files).items():
            shape = {"type": "obj", "filename": str(path), "bsdf": bsdfs[material]}
            if material == "lamp":
                shape["emitter"] = {"type": "area", "radiance": {"type": "rgb", "value": [6.0, 6.0, 5.0]}}
            scene[f"{obj}_{material}"] = shape
    width = 512
    sky = sky_radiance(bridge.envmap_directions(width, width // 2))
    scene["sky"] = {"type": "envmap", "bitmap": mi.Bitmap(sky.astype(np.float32))}
    return scene


def blocks(image):
    h, w = image.shape[0] // BLOCK * BLOCK, image.shape[1] // BLOCK * BLOCK
    return image[:h, :w].reshape(h // BLOCK, BLOCK, w // BLOCK, BLOCK, -1).mean(axis=(1, 3))


def test_an_imported_room_renders_like_mitsuba_rendering_its_files(tmp_path):
    files = write_room(tmp_path / "files", write_sky)
    scene_dir, renders = tmp_path / "scene", tmp_path / "renders"
    assert (
        main(
            [
                "import",
                str(files),
                "--out",
                str(scene_dir),
                "--environment",
                str(files / "sky.exr"),
                "--cube-size",
                "32",
            ]
        )
        == 0
    )
    assert (
        main(
            [
                "render",
                str(scene_dir),
                "--out",
                str(renders),
                "--spp",
                str(SPP),
                "--seed",
                "3",
                "--max-bounces",
                str(BOUNCES),
            ]
        )
        == 0
    )
    ours, our_var = read_image(renders / "view.exr"), read_image(renders / "aovs" / "view_variance.exr")
    theirs = [np.array(mi.render(mi.load_dict(mitsuba_scene(files, seed), parallel=False)))[..., :3] for seed in (1, 2)]
    mitsuba = 0.5 * (theirs[0] + theirs[1])
    # Per pixel, (a - b)^2 / 4 estimates the variance of Mitsuba's mean of two renders
    their_var = blocks((theirs[0] - theirs[1]) ** 2 / 4)
    assert abs(ours.mean() / mitsuba.mean() - 1) < 0.02, (ours.mean(), mitsuba.mean())
    sigma = np.sqrt((blocks(our_var) + their_var) / BLOCK**2)  # of the difference of block means
    excess = np.abs(blocks(ours) - blocks(mitsuba)) - 0.02 * blocks(mitsuba)
    z = excess / np.maximum(sigma, 1e-6)
    assert z.max() < 4.0, z.max()
