"""The gradients stage: the starting scene's loss gradients written per map, with the signs an
optimiser needs (a too-dark light wants more emission)."""

import json

import numpy as np
from testscenes import box_room

from invrender.cli import main
from invrender.render.analysis import analyse
from invrender.render.renderer import Renderer, pixel_requests
from invrender.scene.cameras import write_colmap
from invrender.scene.images import read_image, write_exr
from invrender.scene.mesh_io import write_ply


def test_gradients_of_a_dark_start_ask_for_more_light(tmp_path):
    truth = box_room(light=80.0)  # far brighter than the uniform start everywhere it lights
    truth.cameras[0].name = "view.exr"
    # what the geometry and synthesize stages would have written
    geometry, capture = tmp_path / "geometry", tmp_path / "capture"
    geometry.mkdir()
    write_ply(geometry / "mesh.ply", truth.mesh)
    np.savez(geometry / "atlas.npz", mask=np.ones(truth.maps.atlas_shape, bool))
    (capture / "images").mkdir(parents=True)
    write_colmap(capture / "sparse", truth.cameras)
    image = Renderer(truth, analyse(truth)).render(truth.cameras[0], spp=256, seed=1, aovs=False)["radiance"]
    write_exr(capture / "images" / "view.exr", image)

    def gradients(out, *flags):
        inputs = [
            "--geometry",
            str(geometry),
            "--cameras",
            str(capture / "sparse"),
            "--images",
            str(capture / "images"),
        ]
        return main(["gradients", *inputs, "--out", str(out), "--spp", "16", *flags])

    out = tmp_path / "gradients"
    assert gradients(out) == 0
    report = json.loads((out / "gradients.json").read_text())
    assert report["rays"] == len(pixel_requests(truth.cameras[0]))
    assert all(np.isfinite(v) and v > 0 for v in report["norms"].values()), report["norms"]
    light = read_image(out / "ke.exr")[0, 1]  # texel 1: the ceiling light
    assert np.all(light < 0), light  # the start is too dark: more emission lowers the loss
    assert read_image(out / "kg.exr").shape == (6 * 16, 16, 3)
    for name in ("kd", "ks", "ka", "ke", "kw", "kg"):
        assert (out / f"{name}.png").stat().st_size > 0

    # MILO's float buckets: the same sums in another order
    floats = tmp_path / "buckets"
    assert gradients(floats, "--accumulation", "buckets") == 0
    assert json.loads((floats / "gradients.json").read_text())["accumulation"] == "buckets"
    for name in ("kd", "ke", "kg"):
        fixed, bucketed = read_image(out / f"{name}.exr"), read_image(floats / f"{name}.exr")
        np.testing.assert_allclose(bucketed, fixed, rtol=0, atol=1e-4 * np.abs(fixed).max(), err_msg=name)
