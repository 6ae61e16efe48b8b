"""The kernels' four sampling strategies and their mixture: chi-square goodness of fit of the
sampled directions against the kernel's own density, the density's integral over the sphere,
and the density's value against the float64 reference (render/sampling.py)."""

import numpy as np
import pytest
from chi2 import chi2_test
from probe import KernelProbe
from testscenes import quad

from invrender.render import bsdf as bsdf_ref
from invrender.render import sampling as ref
from invrender.render.features import Features
from invrender.render.scene_buffers import emitted_power
from invrender.scene import cubemap
from invrender.scene.types import Maps, Mesh, Scene

X = np.array([0.0, 0.0, 0.0])  # the shading point, on the floor
N = np.array([0.0, 1.0, 0.0])
WO = np.array([0.6, 0.8, 0.0])
CASES = 9  # chi-square tests in this file, for the Sidak correction


def sky_with_sun(n=8):
    """A cube map with a gradient sky, a dark ground and one bright sun texel."""
    faces, s, t = np.meshgrid(np.arange(6), (np.arange(n) + 0.5) / n, (np.arange(n) + 0.5) / n, indexing="ij")
    d = cubemap.cube_to_direction(faces, s.transpose(0, 2, 1), t.transpose(0, 2, 1))
    up = d[..., 1]
    kg = np.where(up[..., None] > 0, np.array([0.4, 0.6, 1.0]) * (0.5 + up[..., None]), 0.05)
    kg[2, n // 2, n // 3] = 20.0  # sun on the +Y face
    return kg.astype(np.float32)


def sampling_scene(kd, ks, ka, one_sided=False):
    """A floor (texel 0: the material under test) and emitters above it (texel 1: ke > 0), two of
    them one above the other so the density must sum over every hit, and one tilted. With
    one_sided, the low lamp emits only downwards (its front, towards X) and a fifth lamp, facing
    up, only upwards: X sees its back, so every sample on it is spent."""
    floor = quad((0, 0, 0), (0, 0, 1), (1, 0, 0))  # front face +Y
    lamp_low = quad((0.2, 1.0, 0.1), (0.3, 0, 0), (0, 0, 0.3))  # faces -Y
    lamp_high = quad((0.3, 2.0, 0.0), (0.5, 0, 0), (0, 0, 0.4))
    tilted = quad((-1.0, 1.5, -0.5), (0.3, 0.3, 0), (0, 0, 0.3))
    parts = [floor, lamp_low, lamp_high, tilted] + (
        [quad((0.5, 1.2, -0.6), (0, 0, 0.3), (0.3, 0, 0))] if one_sided else []
    )
    positions = np.concatenate([p for p, _, _ in parts])
    faces = np.concatenate([f + 4 * i for i, (_, f, _) in enumerate(parts)]).astype(np.int32)
    uvs = np.concatenate([np.full((4, 2), [0.25, 0.75])] + [np.full((4, 2), [0.75, 0.75])] * (len(parts) - 1))
    maps = Maps.uniform(size=(2, 2), kd=0, ks=0, ka=ka, kg=0, cube=8)
    maps.kd[0, 0], maps.ks[0, 0] = kd, ks
    maps.ke[0, 1] = [5.0, 4.0, 3.0]
    maps.kg[:] = sky_with_sun()
    flags = np.repeat([False, True, False, False, True], 2)[: len(faces)] if one_sided else None
    return Scene(Mesh(positions, faces, uvs.astype(np.float32), one_sided=flags), maps)


def reference_distributions(scene):
    mesh = scene.mesh
    v = mesh.positions[mesh.faces].astype(np.float64)
    power = emitted_power(mesh, scene.maps)
    emitting = power > 0
    one_sided = mesh.one_sided[emitting] if mesh.one_sided is not None else None
    return ref.EnvironmentDistribution(scene.maps.kg), ref.EmitterDistribution(
        v[emitting, 0], v[emitting, 1], v[emitting, 2], power[emitting], one_sided
    )


def run_chi2(probe, n_samples=400_000, seed=0, res=(20, 40), sub=16):
    rng = np.random.default_rng(seed)

    def sample_fn(n):
        u = rng.uniform(0, 1, (n, 4)).astype(np.float32)
        wi, _, _, _ = probe.mixture(
            0,
            np.broadcast_to(X, (n, 3)),
            np.broadcast_to(N, (n, 3)),
            np.broadcast_to(WO / np.linalg.norm(WO), (n, 3)),
            u,
        )
        wi = wi.astype(np.float64)
        wi[np.all(wi == 0, axis=1)] = np.nan  # spent samples
        return wi

    def pdf_fn(dirs):
        return probe.mixture_pdf(0, X, N, WO / np.linalg.norm(WO), dirs).astype(np.float64)

    return chi2_test(sample_fn, pdf_fn, n_samples=n_samples, res=res, sub=sub, test_count=CASES)


# Integration nodes per cell side: densities with texel and triangle edges, or a sharp lobe,
# inside a cell need dense nodes, else the integration error alone rejects a right sampler.
NODES = {"environment": 64, "emitters": 64, "mixture": 128}
STRATEGIES = {
    # name: (kd, ks, ka, w_env, w_emit)
    "diffuse": (0.7, 0.0, 0.1, 0.0, 0.0),
    "specular_rough": (0.0, 0.5, 0.3, 0.0, 0.0),
    "specular_sharp": (0.0, 0.5, 0.01, 0.0, 0.0),
    "environment": (0.5, 0.0, 0.1, 1.0, 0.0),
    "emitters": (0.5, 0.0, 0.1, 0.0, 1.0),
    "mixture": (0.5, 0.3, 0.05, 0.25, 0.25),
    "emitters_one_sided": (0.5, 0.0, 0.1, 0.0, 1.0),
}


@pytest.mark.parametrize("name", STRATEGIES)
def test_chi_square_of_each_strategy_and_the_mixture(name):
    kd, ks, ka, w_env, w_emit = STRATEGIES[name]
    scene = sampling_scene(kd, ks, ka, one_sided=name.endswith("one_sided"))
    probe = KernelProbe(Features.everything(), scene, w_env=w_env, w_emit=w_emit)
    result = run_chi2(probe, sub=NODES.get(name.removesuffix("_one_sided"), 16))
    assert result, result.message
    # the density integrates to the probability that a sample is not spent
    assert abs(result.integral - result.valid_fraction) < 2e-3, result.message
    if scene.mesh.one_sided is not None:  # spent: the samples on the lamp X sees from behind
        behind = emitted_power(scene.mesh, scene.maps)[-2:].sum() / emitted_power(scene.mesh, scene.maps).sum()
        assert abs(1 - result.valid_fraction - behind) < 3e-3, (result.valid_fraction, behind)


@pytest.mark.parametrize("one_sided", [False, True], ids=["two-sided", "one-sided"])
def test_chi_square_of_the_light_sample_of_next_event_estimation(one_sided):
    """The light sample (kernels/nee.h) against its segment density: strategy 3 or 4 by w_env :
    w_emit, kept only where the ray's first hit is what strategy 4 aimed at (the low lamp hides
    part of the high one), above the surface, and not the back of a one-sided lamp. Every such
    loss is a failure cell of its own, so the density must integrate to exactly the rest."""
    scene = sampling_scene(0.5, 0.3, 0.05, one_sided=one_sided)
    probe = KernelProbe(Features.everything(), scene, w_env=0.3, w_emit=0.7)
    x = X + 1e-4 * N  # off the floor, as the integrator offsets its origins
    wo = WO / np.linalg.norm(WO)
    rng = np.random.default_rng(3)

    def sample_fn(n):
        d, found = probe.light(0, x, N, wo, rng.uniform(0, 1, (n, 4)).astype(np.float32))
        d = d.astype(np.float64)
        d[~found] = np.nan
        return d

    result = chi2_test(
        sample_fn,
        lambda d: probe.light_pdf(x, N, d).astype(np.float64),
        n_samples=400_000,
        res=(20, 40),
        sub=64,
        test_count=CASES,
    )
    assert result, result.message
    assert abs(result.integral - result.valid_fraction) < 2e-3, result.message
    assert 0.05 < 1 - result.valid_fraction < 0.9, result.valid_fraction  # the failure cells are there


def test_chi_square_rejects_a_wrong_density():
    """The same machinery must fail a density that forgets the cube-face Jacobian."""
    probe = KernelProbe(Features.everything(), sampling_scene(0.5, 0.0, 0.1), w_env=1.0, w_emit=0.0)
    env = ref.EnvironmentDistribution(sky_with_sun())
    rng = np.random.default_rng(1)
    sample = lambda n: probe.mixture(
        0,
        np.broadcast_to(X, (n, 3)),
        np.broadcast_to(N, (n, 3)),
        np.broadcast_to(WO / np.linalg.norm(WO), (n, 3)),
        rng.uniform(0, 1, (n, 4)).astype(np.float32),
    )[0].astype(np.float64)

    def no_jacobian(d):
        face, s, t = cubemap.direction_to_cube(d)
        row, col = cubemap.cube_texel(s, t, env.n)
        return env.prob[(face * env.n + row) * env.n + col] / (4.0 * np.pi / (6 * env.n**2))

    assert not chi2_test(sample, no_jacobian, n_samples=200_000)


@pytest.mark.parametrize("name", ["mixture", "emitters", "environment", "emitters_one_sided"])
def test_mixture_density_matches_reference(name):
    kd, ks, ka, w_env, w_emit = STRATEGIES[name]
    scene = sampling_scene(kd, ks, ka, one_sided=name.endswith("one_sided"))
    probe = KernelProbe(Features.everything(), scene, w_env=w_env, w_emit=w_emit)
    env, emitters = reference_distributions(scene)
    rng = np.random.default_rng(2)
    u = rng.uniform(0, 1, (20000, 4)).astype(np.float32)
    wo = WO / np.linalg.norm(WO)
    bx = lambda v: np.broadcast_to(v, (len(u), 3))
    wi, pdf, f, parts = probe.mixture(0, bx(X), bx(N), bx(wo), u)
    ok = np.any(wi != 0, axis=1)
    wi64 = wi[ok].astype(np.float64)
    weights = ref.mixture_weights(np.full(3, kd), np.full(3, ks), w_env, w_emit)
    want = ref.mixture_pdf(weights, N, wo, wi64, ka, env, emitters, X)
    rel = np.abs(pdf[ok] - want) / want
    assert np.quantile(rel, 0.999) < 1e-3 and rel.max() < 1e-2, (rel.max(), np.quantile(rel, 0.999))


@pytest.mark.parametrize("theta_deg", [0.0, 45.0, 80.0, 88.0])
@pytest.mark.parametrize("ks,ka", [(0.04, 0.3), (0.5, 0.02), (1.0, 1e-4)])
def test_kernel_albedo_matches_the_numerical_integral(theta_deg, ks, ka):
    """E[f cos / p_mix] over the kernel's own mixture samples is the directional albedo; it must
    match the float64 quadrature (render/bsdf.directional_albedo) within its standard error.
    This exercises f, the sampler and the density together, at grazing angles too, where the
    model reflects more than kd + ks (see docs/renderer.md)."""
    kd = 0.5
    scene = sampling_scene(kd, ks, ka)
    probe = KernelProbe(Features.everything(), scene, w_env=0.0, w_emit=0.0)
    theta = np.radians(theta_deg)
    wo = np.array([np.sin(theta), np.cos(theta), 0.0])
    count = 1_000_000
    u = np.random.default_rng(5).uniform(0, 1, (count, 4)).astype(np.float32)
    bx = lambda v: np.broadcast_to(v, (count, 3))
    wi, pdf, f, _ = probe.mixture(0, bx(X), bx(N), bx(wo), u)
    weight = np.where((pdf > 0)[:, None], f / np.where(pdf > 0, pdf, 1)[:, None], 0.0).astype(np.float64)
    estimate, stderr = weight.mean(0), weight.std(0) / np.sqrt(count)
    want = bsdf_ref.directional_albedo(theta, np.full(3, kd), np.full(3, ks), ka)
    assert np.all(np.abs(estimate - want) < 5 * stderr + 1e-4), (estimate, want, stderr)
