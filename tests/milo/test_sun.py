"""The sun found from the patch it throws through a window (milo/sun.py): its direction against
the room generator's, its power after the milo stage against the truth's sky (evaluate's
sun_errors), and none under an overcast sky."""

import numpy as np
from milo_capture import WINDOW_ROOM, assert_same_weights, build_capture, kill_at_first_checkpoint, milo_args
from test_window import windows_of

from invrender.cli import main
from invrender.evaluate.maps import sun_errors
from invrender.milo.sun import directions_around, find_sun
from invrender.scene.cameras import read_cameras
from invrender.scene.capture import read_view
from invrender.scene.format import load_scene
from invrender.synthesize.room import ENVIRONMENT_DEFAULTS

OVERCAST = {**WINDOW_ROOM, "environment": {"sun_radiance": [0.0, 0.0, 0.0]}}
# The stage at its cheapest: what is scored is the sun it finds and fits, not the steps
CHEAP = {"iterations": 1, "reflectance_passes": 0, "reflectance_spp": 16, "rays": 1024, "spp": 1}


def texels_args(root, out, settings: dict, *extra: str) -> list[str]:
    args = milo_args(root, out, settings, *extra)
    args[args.index("demo")] = "texels"
    return args


def true_sun_direction() -> np.ndarray:
    el, az = np.radians(ENVIRONMENT_DEFAULTS["sun_elevation_deg"]), np.radians(ENVIRONMENT_DEFAULTS["sun_azimuth_deg"])
    return np.array([np.cos(el) * np.sin(az), np.sin(el), -np.cos(el) * np.cos(az)])


def sun_of(root):
    windows, pixels = windows_of(root)
    cameras = read_cameras(root / "cameras")
    radiance, seen = pixels.project([read_view(root / "cameras" / "images", c) for c in cameras])
    return find_sun(pixels, windows, radiance, seen)


def test_the_suns_direction_is_found_from_its_patch(window_room):
    sun = sun_of(window_room)
    assert sun is not None and sun.contrast > 1.5
    angle = np.degrees(np.arccos(np.clip(sun.direction @ true_sun_direction(), -1, 1)))
    assert angle < 3.0


def test_the_stage_lights_the_sun_at_the_truths_power(window_room, tmp_path):
    assert main(texels_args(window_room, tmp_path / "milo", CHEAP)) == 0
    kg = np.load(tmp_path / "milo" / "maps.npz")["kg"]
    truth = load_scene(window_room / "capture" / "ground_truth" / "scene").maps.kg
    errors = sun_errors(kg, truth)
    # the fit alone lands at about two thirds of the truth's power (the gradient steps raise it:
    # 0.96 on the benchmark's window room); no sun reads 0, one fitted twice over 2
    assert 0.5 < errors["power_ratio"] < 1.5
    assert errors["direction_error_deg"] < 8.0  # the sun in one texel of a 16 x 16 face


def test_a_run_with_a_window_and_a_sun_resumes_bit_for_bit(window_room, tmp_path):
    """Killed after its first checkpoint, resumed: the window, the sun's texel and the sky's
    smoothness without it are found again, the sun's radiance is the checkpoint's."""
    settings = {**CHEAP, "iterations": 4, "checkpoint_every": 2}

    assert main(texels_args(window_room, tmp_path / "straight", settings)) == 0
    kill_at_first_checkpoint(texels_args(window_room, tmp_path / "killed", settings), tmp_path / "killed")
    assert main(texels_args(window_room, tmp_path / "killed", settings, "--resume", "always")) == 0
    assert_same_weights(tmp_path / "straight" / "weights.pt", tmp_path / "killed" / "weights.pt")


def test_an_overcast_sky_has_no_sun(tmp_path):
    assert sun_of(build_capture(tmp_path, OVERCAST, spp=16)) is None


def test_the_fine_search_stays_within_its_cap():
    d = np.array([0.3, 0.5, -0.8]) / np.linalg.norm([0.3, 0.5, -0.8])
    around = directions_around(d, np.radians(6.0), 200)
    angles = np.degrees(np.arccos(np.clip(around @ d, -1, 1)))
    assert around[0] @ d > 1 - 1e-12 and angles.max() <= 6.0 + 1e-9 and np.median(angles) > 3.0
    np.testing.assert_allclose(np.linalg.norm(around, axis=1), 1.0)
