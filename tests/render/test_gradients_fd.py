"""Every map's gradient against central finite differences with common random numbers, on a
small room with diffuse, glossy, emitting and window texels, at 1, 3 and 10 bounces (the
gradients issue's first acceptance check).

The loss is linear in the image, sum_pixels delta . L, with fixed random weights delta: any image
loss back-propagates to such weights (MILO's Eq. 5 gives delta = 2 (L - T) / n), so this checks
the adjoint for all of them. Per map, the gradient is summed over a block of texels and compared
with the central difference of the loss when the whole block moves by +-h. The adjoint with
seed s traces the forward render's paths with seed s, so each seed gives a pair.

Two checks, because kd, ks and ka also steer the sampling, which the adjoint holds fixed:

- Path for path: with the proposal held at the unperturbed maps (Renderer's `proposal`, the
  FIXED_PROPOSAL hook) the perturbed renders are importance-sampled estimates along the same
  paths (the environment and emitter sampling tables, built from kg and ke, stay put too), so
  their central difference is the derivative of exactly what the adjoint differentiates. Every
  seed must agree within 2 %: this pins the chain rule of every map.
- In the mean, the issue's criterion: ordinary renders (the perturbation moves the sampled
  directions and switches strategies), so finite differences are noisy and heavy tailed; the
  mean over seeds must agree within 2 % or within 4 of the finite differences' own standard
  errors, whichever is larger. This is the check that detached sampling is unbiased.
"""

import copy

import numpy as np
import pytest
from testscenes import ROOM_TILES, textured_room, tile_texels

from invrender.render.adjoint import backward
from invrender.render.features import Features
from invrender.render.renderer import Renderer, pixel_requests

SPP = 32
SEEDS = range(8)


def tile(name: str) -> tuple:
    return tile_texels(ROOM_TILES[name])


def inner_block(name: str) -> tuple:
    rows, cols = tile(name)
    return slice(rows.start + 1, rows.start + 3), slice(cols.start + 1, cols.start + 3)


# map: (texels moved together, step), each on the texel kind where it matters
ALONG_PATHS = {
    "kd": (inner_block("floor"), 0.01),
    "ks": (inner_block("table"), 0.01),
    "ka": (inner_block("table"), 0.0003),
    "ke": (inner_block("light"), 0.5),
    "kw": (inner_block("window"), 0.02),
    "kg": ((0, slice(1, 3), slice(1, 3)), 0.1),
}  # kg: the +X face, the sky the window shows
# ordinary renders: whole tiles and larger steps, against the finite differences' heavy tails;
# "kd-black": the light's texels, kd = ks = 0, where only a forward difference stays in range
IN_THE_MEAN = {
    "kd": (tile("floor"), 0.05),
    "ks": (tile("table"), 0.1),
    "ka": (tile("table"), 0.003),
    "kd-black": (tile("light"), 0.05),
}


@pytest.fixture(scope="module")
def room():
    scene = textured_room()
    camera = scene.cameras[0]
    requests = pixel_requests(camera)
    delta = np.random.default_rng(1).uniform(0.5, 1.5, (len(requests), 3)).astype(np.float32)
    return scene, camera, requests, delta


@pytest.fixture(scope="module", params=[1, 3, 10], ids=lambda b: f"B{b}")
def gradients(request, room):
    """Adjoint gradients of every map for each seed at one bounce count."""
    features = Features.everything(max_bounces=request.param)
    scene, camera, requests, delta = room
    renderer = Renderer(scene, features)
    return features, [backward(renderer, [camera], requests, delta, SPP, seed=s) for s in SEEDS]


def loss(scene, room_, features, seed, proposal=None) -> float:
    _, camera, requests, delta = room_
    mean, _, dropped = Renderer(scene, features, proposal=proposal).render_requests([camera], requests, SPP, seed)
    assert dropped == 0
    return float((delta.astype(np.float64) * mean).sum())


def finite_difference(room_, features, name, index, h, seed, fixed_proposal=False, signs=(1, -1)) -> float:
    values = []
    for sign in signs:
        scene = copy.deepcopy(room_[0])
        getattr(scene.maps, name)[index] += sign * h
        values.append(loss(scene, room_, features, seed, room_[0].maps if fixed_proposal else None))
    return (values[0] - values[1]) / ((signs[0] - signs[1]) * h)


@pytest.mark.parametrize("name", list(ALONG_PATHS))
def test_every_seed_matches_the_derivative_along_its_paths(room, gradients, name):
    features, per_seed = gradients
    index, h = ALONG_PATHS[name]
    adjoint = np.array([g[name][index].sum() for g in per_seed])
    finite = np.array([finite_difference(room, features, name, index, h, s, fixed_proposal=True) for s in SEEDS])
    assert np.all(np.abs(finite) > 0), (name, finite)
    np.testing.assert_allclose(adjoint, finite, rtol=0.02, err_msg=name)


@pytest.mark.parametrize("case", list(IN_THE_MEAN))
def test_detached_sampling_is_unbiased_in_the_mean(room, gradients, case):
    """kd-black: a texel that reflects nothing ends the forward path, yet d(f cos)/d kd = cos / pi
    there; the adjoint's recorded path goes on for it (kernels/integrator.h)."""
    features, per_seed = gradients
    index, h = IN_THE_MEAN[case]
    name, black = case.split("-")[0], case.endswith("black")
    adjoint = np.array([g[name][index].sum() for g in per_seed])
    signs = (1, 0) if black else (1, -1)
    finite = np.array([finite_difference(room, features, name, index, h, s, signs=signs) for s in SEEDS])
    noise = finite.std(ddof=1) / np.sqrt(len(SEEDS))
    tolerance = max(0.02 * abs(finite.mean()), 4 * noise)
    assert abs(adjoint.mean() - finite.mean()) <= tolerance, (name, adjoint.mean(), finite.mean(), noise)
