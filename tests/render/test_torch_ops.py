"""The renderer as a torch operation, and a tiny inverse-rendering run that recovers a known
diffuse albedo and a light's emission from renders of a synthetic scene."""

import copy

import numpy as np
import torch
from testscenes import box_room, look_at_camera

from invrender.render.adjoint import backward, backward_seed
from invrender.render.batches import ray_batch
from invrender.render.features import Features
from invrender.render.renderer import Renderer
from invrender.render.torch_ops import MAP_ORDER, render_rays

FEATURES = Features.only(max_bounces=3, emission=True, emitter_sampling=True)


def scene_with_two_views():
    scene = box_room(kd=(0.6, 0.5, 0.4), light=8.0)
    # a second view looks up at the ceiling light: seen directly, its emission is not
    # confused with the walls' albedo (MILO's diffuse-emission ambiguity)
    scene.cameras.append(look_at_camera((0.3, 1.0, 0.9), (0.5, 2.6, 0.0), width=32, height=24, fov_x_deg=70, name="up"))
    return scene


def as_tensors(maps):
    return {name: torch.tensor(getattr(maps, name)) for name in MAP_ORDER}


def test_forward_is_the_render_and_backward_is_the_adjoint():
    scene = scene_with_two_views()
    renderer = Renderer(copy.deepcopy(scene), FEATURES)
    requests = ray_batch(scene.cameras, 500, seed=0, iteration=3)
    maps = {name: t.requires_grad_() for name, t in as_tensors(scene.maps).items()}
    out = render_rays(maps, renderer, scene.cameras, requests, 8, 5)
    mean, _, _ = Renderer(scene, FEATURES).render_requests(scene.cameras, requests, 8, 5)
    assert np.array_equal(out.detach().numpy(), mean)
    weights = torch.rand(out.shape, generator=torch.Generator().manual_seed(0))
    (out * weights).sum().backward()
    want = backward(renderer, scene.cameras, requests, weights.numpy(), 8, backward_seed(5))
    for name in MAP_ORDER:
        assert np.allclose(maps[name].grad.numpy(), want[name], rtol=1e-6, atol=1e-9), name
    assert maps["kd"].grad.abs().sum() > 0 and maps["ke"].grad.abs().sum() > 0


def test_batches_are_reproducible_and_keep_pixel_ray_ids():
    cameras = scene_with_two_views().cameras
    a, b = ray_batch(cameras, 300, 1, 7), ray_batch(cameras, 300, 1, 7)
    assert np.array_equal(a, b) and not np.array_equal(a, ray_batch(cameras, 300, 1, 8))
    width = cameras[0].width
    first = a[a[:, 0] == 0]
    assert np.array_equal(first[:, 3], first[:, 2] * width + first[:, 1])
    assert len(np.unique(a[:, 3])) == 300


def test_tiny_optimisation_recovers_albedo_and_emission():
    truth = scene_with_two_views()
    cameras = truth.cameras
    requests = ray_batch(cameras, sum(c.width * c.height for c in cameras), seed=0, iteration=0)
    target = torch.from_numpy(Renderer(truth, FEATURES).render_requests(cameras, requests, 2048, 99)[0])
    start = copy.deepcopy(truth)
    start.maps.kd[0, 0], start.maps.ke[0, 1] = 0.3, 3.0
    renderer = Renderer(copy.deepcopy(start), FEATURES)
    fixed = as_tensors(start.maps)
    albedo = torch.tensor([0.3, 0.3, 0.3], requires_grad=True)
    emission = torch.tensor([3.0, 3.0, 3.0], requires_grad=True)
    optimiser = torch.optim.Adam([{"params": [albedo], "lr": 0.02}, {"params": [emission], "lr": 0.3}])
    schedule = torch.optim.lr_scheduler.MultiStepLR(optimiser, milestones=[80, 120], gamma=0.3)

    def maps_of(kd_value, ke_value):
        kd, ke = fixed["kd"].clone(), fixed["ke"].clone()
        kd[0, 0], ke[0, 1] = kd_value, ke_value
        return dict(fixed, kd=kd, ke=ke)

    def clean_loss():  # at many samples, so the comparison is of the maps, not of the noise
        with torch.no_grad():
            out = render_rays(maps_of(albedo, emission), renderer, cameras, requests, 256, 12345)
        return float(((out - target) ** 2).mean())

    first = clean_loss()
    for iteration in range(160):
        out = render_rays(maps_of(albedo, emission), renderer, cameras, requests, 16, iteration)
        loss = ((out - target) ** 2).mean()
        optimiser.zero_grad()
        loss.backward()
        optimiser.step()
        schedule.step()
        with torch.no_grad():
            albedo.clamp_(0.01, 1.0)
            emission.clamp_(0.0, 100.0)
    last = clean_loss()
    assert first / last > 100, (first, last)
    assert np.allclose(albedo.detach().numpy(), [0.6, 0.5, 0.4], rtol=0.02), albedo
    assert np.allclose(emission.detach().numpy(), 8.0, rtol=0.02), emission
