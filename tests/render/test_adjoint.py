"""The adjoint kernel (kernels/adjoint.cl) against central finite differences with common
random numbers, and its determinism. Groundwork of the gradients issue: the torch Function,
the stage and the Mitsuba comparison build on it."""

import copy

import numpy as np
import pytest
from testscenes import box_room

from invrender.render.adjoint import backward
from invrender.render.features import Features
from invrender.render.renderer import Renderer, pixel_requests

SPP = 128


@pytest.fixture(scope="module")
def setup():
    scene = box_room(window=True, ks=0.3, ka=0.05, light=8.0, sky=2.0)
    camera = scene.cameras[0]
    requests = pixel_requests(camera)
    delta = np.random.default_rng(0).uniform(0.5, 1.5, (len(requests), 3)).astype(np.float32)
    features = Features.everything(max_bounces=3)
    return scene, camera, requests, delta, features, Renderer(scene, features)


def loss(scene, setup_, seed):
    _, camera, requests, delta, features, _ = setup_
    mean, _, _ = Renderer(scene, features).render_requests([camera], requests, SPP, seed)
    return float((delta * mean).astype(np.float64).sum())


def central_difference(setup_, name, index, h, seed):
    values = []
    for sign in (1, -1):
        scene = copy.deepcopy(setup_[0])
        getattr(scene.maps, name)[index] += sign * h
        values.append(loss(scene, setup_, seed))
    return (values[0] - values[1]) / (2 * h)


@pytest.mark.parametrize("name, index, h", [("ke", (0, 1, 0), 0.2), ("kw", (1, 0), 0.02)])
def test_linear_parameters_match_finite_differences_exactly(setup, name, index, h):
    """The loss is linear in an emitter's ke and in a window's kw (paths end there), so with
    common random numbers the central difference is exact up to float rounding."""
    gradient = backward(setup[5], [setup[1]], setup[2], setup[3], SPP, seed=3)[name][index]
    assert gradient == pytest.approx(central_difference(setup, name, index, h, seed=3), rel=1e-3)


def test_sky_gradient_matches_a_uniform_scaling_of_kg(setup):
    scene = setup[0]
    gradient = backward(setup[5], [setup[1]], setup[2], setup[3], SPP, seed=3)["kg"]
    values = []
    for factor in (1.01, 0.99):
        scaled = copy.deepcopy(scene)
        scaled.maps.kg *= factor
        values.append(loss(scaled, setup, seed=3))
    assert (gradient * scene.maps.kg).sum() == pytest.approx((values[0] - values[1]) / 0.02, rel=1e-3)


@pytest.mark.parametrize("name, index, h", [("kd", (0, 0, 1), 0.02), ("ks", (0, 0, 0), 0.02), ("ka", (0, 0), 0.005)])
def test_material_gradients_match_finite_differences_within_noise(setup, name, index, h):
    """kd, ks and ka also steer the sampling (mixture weights, the Beckmann lobe), which the
    adjoint holds fixed (MILO does not differentiate the pdf): both estimators are unbiased for
    the derivative of the expected image, so they agree in the mean over seeds."""
    seeds = range(20, 28)
    adjoint = np.array([backward(setup[5], [setup[1]], setup[2], setup[3], SPP, seed=s)[name][index] for s in seeds])
    finite = np.array([central_difference(setup, name, index, h, s) for s in seeds])
    error = np.sqrt(adjoint.var(ddof=1) / len(adjoint) + finite.var(ddof=1) / len(finite))
    assert abs(adjoint.mean() - finite.mean()) < 4 * error + 0.02 * abs(finite.mean()), (adjoint, finite)


def test_same_seed_same_bytes_different_seed_differs(setup):
    a = backward(setup[5], [setup[1]], setup[2], setup[3], 16, seed=1)
    b = backward(setup[5], [setup[1]], setup[2], setup[3], 16, seed=1)
    c = backward(setup[5], [setup[1]], setup[2], setup[3], 16, seed=2)
    for name in a:
        assert a[name].tobytes() == b[name].tobytes()
    assert any(not np.array_equal(a[name], c[name]) for name in a)
    assert all(np.isfinite(a[name]).all() for name in a)


def test_bucketed_float_accumulation_matches_fixed_point(setup):
    """MILO's buckets sum the same per-sample terms as the fixed-point mode, in float32 and in
    another order: the maps agree to float rounding, texel by texel."""
    fixed = backward(setup[5], [setup[1]], setup[2], setup[3], 16, seed=5)
    buckets = backward(setup[5], [setup[1]], setup[2], setup[3], 16, seed=5, accumulation="buckets")
    for name in fixed:
        scale = np.abs(fixed[name]).max()
        assert scale > 0, name
        np.testing.assert_allclose(buckets[name], fixed[name], rtol=0, atol=2e-4 * scale, err_msg=name)


def test_unknown_accumulation_is_refused(setup):
    with pytest.raises(ValueError, match="accumulation"):
        backward(setup[5], [setup[1]], setup[2], setup[3], 1, accumulation="float")


def test_only_the_wanted_maps_are_differentiated(setup):
    """maps=("kd",) compiles the other maps' additions out: kd is the same bytes as in a pass
    over every map (the same paths, the same additions to kd), and only kd comes back."""
    every = backward(setup[5], [setup[1]], setup[2], setup[3], 16, seed=7)
    kd_only = backward(setup[5], [setup[1]], setup[2], setup[3], 16, seed=7, maps=("kd",))
    assert list(kd_only) == ["kd"]
    assert np.abs(every["kd"]).max() > 0
    np.testing.assert_array_equal(kd_only["kd"], every["kd"])
    with pytest.raises(ValueError, match="maps"):
        backward(setup[5], [setup[1]], setup[2], setup[3], 1, maps=("albedo",))
