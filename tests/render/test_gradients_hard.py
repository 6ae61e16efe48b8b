"""Gradients on the path tracer's hard cases: never a NaN or an Inf, and the fixed-point
accumulation keeps its range and resolution however large or small the numbers get."""

import logging

import numpy as np
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from testscenes import box_room, hard_room, look_at_camera

from invrender.render.adjoint import backward
from invrender.render.features import Features
from invrender.render.renderer import Renderer, pixel_requests

CAMERAS = {
    "room": None,  # the room's own view
    "grazing": look_at_camera((-1.9, 0.001, 1.4), (1.9, 0.0, -1.4), width=16, height=12, fov_x_deg=40),
    "inside the table": look_at_camera((-0.8, 0.4, -0.3), (0, 0.4, 0), width=12, height=8),
}


@settings(max_examples=30, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(
    ks=st.sampled_from([0.0, 0.02, 0.5, 1.0]),
    ka=st.sampled_from([1e-6, 1e-4, 0.01, 0.3, 1.0]),
    light=st.sampled_from([0.0, 1.0, 1e3, 1e6]),
    kd=st.sampled_from([0.0, 0.5, 1.0]),
    open_top=st.booleans(),
    camera=st.sampled_from(list(CAMERAS)),
    bounces=st.sampled_from([1, 3, 10]),
    adjoint_scale=st.sampled_from([1e-12, 1.0, 1e6]),
    accumulation=st.sampled_from(["fixed", "buckets"]),
    seed=st.integers(0, 2**32 - 1),
)
def test_hard_cases_never_give_nan_or_inf_gradients(
    ks, ka, light, kd, open_top, camera, bounces, adjoint_scale, accumulation, seed
):
    scene = hard_room(ks, ka, light, kd, open_top)
    cam = CAMERAS[camera] or scene.cameras[0]
    scene.cameras = [cam]
    requests = pixel_requests(cam)
    rng = np.random.default_rng(seed)
    adjoint = (rng.uniform(-1, 1, (len(requests), 3)) * adjoint_scale).astype(np.float32)
    renderer = Renderer(scene, Features.everything(max_bounces=bounces))
    grads = backward(renderer, [cam], requests, adjoint, spp=4, seed=seed, accumulation=accumulation)
    for name, grad in grads.items():
        assert np.isfinite(grad).all(), name


def test_fixed_point_follows_the_numbers_up_and_down(caplog):
    """Emission 1e6 seen in a mirror with an adjoint of 1e6 (additions far beyond the first
    scale's headroom) and an adjoint of 1e-12 (far below its resolution) give the same gradients
    as float accumulation, and scaling the adjoint scales the gradient exactly."""
    scene = box_room(ks=1.0, ka=1e-4, light=1e6, window=True)
    cam = scene.cameras[0]
    requests = pixel_requests(cam)
    adjoint = np.random.default_rng(3).uniform(-1, 1, (len(requests), 3)).astype(np.float32)
    renderer = Renderer(scene, Features.everything(max_bounces=3))
    unit = backward(renderer, [cam], requests, adjoint, spp=8, seed=1, accumulation="buckets")
    caplog.set_level(logging.DEBUG, logger="invrender.render.adjoint")
    for factor in (1e6, 1e-12):
        caplog.clear()
        fixed = backward(renderer, [cam], requests, adjoint * np.float32(factor), spp=8, seed=1)
        assert "running again" in caplog.text  # the near-mirror's d/dka needs its own scale
        for name in unit:
            scale = np.abs(unit[name]).max() * factor
            assert scale > 0, name
            np.testing.assert_allclose(fixed[name], unit[name] * factor, rtol=0, atol=1e-4 * scale, err_msg=name)


def test_an_ordinary_scene_takes_one_fixed_point_pass(caplog):
    scene = box_room(ks=0.3, ka=0.05, window=True)
    cam = scene.cameras[0]
    requests = pixel_requests(cam)
    adjoint = np.random.default_rng(4).uniform(-1e-6, 1e-6, (len(requests), 3)).astype(np.float32)
    caplog.set_level(logging.DEBUG, logger="invrender.render.adjoint")
    backward(Renderer(scene, Features.everything(max_bounces=10)), [cam], requests, adjoint, spp=8, seed=1)
    assert "running again" not in caplog.text
