"""Texture importance sampling (MILO section 3.5): strategy 4 also draws directions towards
texels by an importance map. The estimate's expectation must not change (the mixture's density
counts every sampled triangle), only its variance."""

import numpy as np
from testscenes import box_room

from invrender.render.features import Features
from invrender.render.renderer import Renderer


def test_importance_keeps_the_mean_and_samples_the_lit_walls():
    scene = box_room(window=True, ks=0.3, ka=0.05)
    camera = scene.cameras[0]
    features = Features(one_sided=False, max_bounces=3)
    importance = np.random.default_rng(0).uniform(0.5, 2.0, scene.maps.atlas_shape)
    plain = Renderer(scene, features)
    sampled = Renderer(scene, features, importance=importance)
    assert sampled.host.num_emitters > plain.host.num_emitters  # the walls joined the lamps
    a = plain.render(camera, spp=512, seed=1, aovs=False)
    b = sampled.render(camera, spp=512, seed=2, aovs=False)
    difference = a["radiance"].mean() - b["radiance"].mean()
    error = np.sqrt(a["variance"].sum() + b["variance"].sum()) / a["radiance"].size
    assert abs(difference) < 4 * error, (difference, error)
    assert abs(difference) < 0.01 * a["radiance"].mean()
    # per block, too: a wrong density shows where the importance is uneven
    za = (a["radiance"] - b["radiance"]) / np.sqrt(a["variance"] + b["variance"] + 1e-12)
    assert np.abs(za.mean()) < 0.1
