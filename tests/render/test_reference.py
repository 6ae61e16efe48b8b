"""The float64 reference itself (render/bsdf.py, sampling.py, rng.py): known answers, the
samplers against their PDFs (chi-square, tests/render/chi2.py), albedos, and robustness."""

import math

import numpy as np
import pytest
from chi2 import chi2_test, pdf_integral, pearson, sidak_threshold
from hypothesis import given, settings
from hypothesis import strategies as st

from invrender.render import bsdf, rng, sampling
from invrender.render.bsdf import dot, normalize
from invrender.scene import cubemap

# Sidak correction over the chi-square tests in this file that must accept (cosine 2,
# specular 5, environment 1, emitters 1, mixture 2).
CHI2_TESTS = 11
SIGNIFICANCE = 0.01
N_SAMPLES = 1_000_000
N_REJECT = 200_000  # the deliberately wrong PDFs are rejected with far fewer samples


def uniforms(n, seed, block=0):
    """(4, n) float64 uniforms from the reference Philox: one call per sample index."""
    return rng.uniform4(seed, np.arange(n), 0, 0, block).astype(np.float64).T


def frame(theta_n_deg, phi_n_deg, theta_o_deg, phi_o_deg=30.0):
    """A normal at polar/azimuth angles (world), and wo at theta_o from it."""
    t, p = np.radians(theta_n_deg), np.radians(phi_n_deg)
    n = np.array([np.sin(t) * np.cos(p), np.sin(t) * np.sin(p), np.cos(t)])
    to, po = np.radians(theta_o_deg), np.radians(phi_o_deg)
    wo = bsdf.to_world(n, np.array([np.sin(to) * np.cos(po), np.sin(to) * np.sin(po), np.cos(to)]))
    return n, wo


def assert_accepted(result):
    assert result.passed, result.message


def failed_below(n, wi):
    """A lobe sample below the surface is a failed sample (f = 0, PDF 0): NaN for chi2."""
    return np.where((dot(n, wi) > 0)[..., None], wi, np.nan)


# --------------------------------------------------------------------------------------------
# Philox-4x32-10


KAT = [  # Random123 tests/kat_vectors: counter, key, expected (philox4x32 10)
    ([0, 0, 0, 0], [0, 0], [0x6627E8D5, 0xE169C58D, 0xBC57AC4C, 0x9B00DBD8]),
    ([0xFFFFFFFF] * 4, [0xFFFFFFFF] * 2, [0x408F276D, 0x41C83B0E, 0xA20BC7C6, 0x6D5451FD]),
    (
        [0x243F6A88, 0x85A308D3, 0x13198A2E, 0x03707344],
        [0xA4093822, 0x299F31D0],
        [0xD16CFE09, 0x94FDCCEB, 0x5001E420, 0x24126EA1],
    ),
]


@pytest.mark.parametrize("counter,key,expected", KAT)
def test_philox_known_answers(counter, key, expected):
    got = rng.philox4x32(np.array(counter, np.uint32), np.array(key, np.uint32))
    assert got.dtype == np.uint32 and got.tolist() == expected


def test_philox_vectorised_matches_one_at_a_time():
    counters = np.array([c for c, _, _ in KAT], np.uint32)
    keys = np.array([k for _, k, _ in KAT], np.uint32)
    assert rng.philox4x32(counters, keys).tolist() == [e for _, _, e in KAT]


def test_uniform4_is_philox_of_seed_and_counter():
    seed = (0xA4093822 << 32) | 0x243F6A88  # key = (low, high)
    assert rng.seed_key(seed).tolist() == [0x243F6A88, 0xA4093822]
    ray, sample, bounce, block = 7, 3, 2, 1
    x = rng.philox4x32(np.array([ray, sample, bounce, block], np.uint32), rng.seed_key(seed))
    u = rng.uniform4(seed, ray, sample, bounce, block)
    assert u.dtype == np.float32 and u.shape == (4,)
    assert np.array_equal(u, ((x >> 8).astype(np.float64) * 2.0**-24).astype(np.float32))
    # extremes of the float conversion: 0 and the largest value below 1
    assert rng.to_unit_float(np.array([0, 0xFF, 0xFFFFFFFF], np.uint32)).tolist() == [0.0, 0.0, 1 - 2**-24]
    # a pure function, vectorised over counters, in [0, 1)
    many = rng.uniform4(seed, np.arange(1000), sample, bounce, block)
    assert many.shape == (1000, 4) and np.array_equal(many[ray], u)
    assert many.min() >= 0 and many.max() < 1 and abs(many.mean() - 0.5) < 0.02


# --------------------------------------------------------------------------------------------
# frames and cube maps


def test_branchless_onb_is_orthonormal_and_right_handed():
    gen = np.random.default_rng(0)
    n = normalize(gen.normal(size=(1000, 3)))
    n = np.concatenate([n, [[0, 0, 1], [0, 0, -1], [0.6, 0.8, -0.0], [1, 0, 0], [0, 1e-9, -1]]])
    n = normalize(n)
    b1, b2 = bsdf.branchless_onb(n)
    for a, b in [(b1, b2), (b1, n), (b2, n)]:
        assert np.abs(dot(a, b)).max() < 1e-12
    for a in (b1, b2):
        assert np.abs(np.linalg.norm(a, axis=-1) - 1).max() < 1e-12
    assert np.abs(np.cross(b1, b2) - n).max() < 1e-12
    for i in (0, 1000, 1001, 1002):  # the scalar form the kernel mirrors gives the same numbers
        s1, s2 = bsdf.branchless_onb_scalar(*n[i])
        assert np.allclose(s1, b1[i], atol=0, rtol=1e-15) and np.allclose(s2, b2[i], atol=0, rtol=1e-15)
    v = gen.normal(size=(1000, 3))
    assert np.allclose(bsdf.to_world(n[:1000], bsdf.to_local(n[:1000], v)), v)


# --------------------------------------------------------------------------------------------
# the material


def random_frames(gen, count):
    n = normalize(gen.normal(size=(count, 3)))
    lo, li = gen.normal(size=(2, count, 3))
    lo[:, 2], li[:, 2] = np.abs(lo[:, 2]), np.abs(li[:, 2])  # above the surface
    lo, li = normalize(lo), normalize(li)
    return n, bsdf.to_world(n, lo), bsdf.to_world(n, li)


def test_bsdf_is_lambertian_without_ks_and_zero_below():
    gen = np.random.default_rng(2)
    n, wo, wi = random_frames(gen, 5000)
    kd = gen.uniform(size=(5000, 3))
    ka = 10 ** gen.uniform(-6, 0, 5000)
    f = bsdf.milo_bsdf_cos(n, wo, wi, kd, np.zeros(3), ka)
    assert np.array_equal(f, kd * (dot(n, wi) / np.pi)[:, None])  # exactly: F = 0 with the clamp
    assert not np.array_equal(bsdf.milo_bsdf_cos(n, wo, wi, kd, np.zeros(3), ka, f90_clamp=False), f)
    ks = gen.uniform(size=(5000, 3))
    assert np.all(bsdf.milo_bsdf_cos(n, -wo, wi, kd, ks, ka) == 0)
    assert np.all(bsdf.milo_bsdf_cos(n, wo, -wi, kd, ks, ka) == 0)


def test_bsdf_is_reciprocal_and_matches_the_formula():
    gen = np.random.default_rng(3)
    n, wo, wi = random_frames(gen, 5000)
    kd, ks = gen.uniform(size=(2, 5000, 3))
    ka = 10 ** gen.uniform(-3, 0, 5000)
    ci, co = dot(n, wi), dot(n, wo)
    f_io = bsdf.milo_bsdf_cos(n, wo, wi, kd, ks, ka) / ci[:, None]
    f_oi = bsdf.milo_bsdf_cos(n, wi, wo, kd, ks, ka) / co[:, None]
    assert np.allclose(f_io, f_oi, rtol=1e-10, atol=0)
    # MILO Eq. 3 written out naively (D via cos^2, 4 ci co denominator), F90 clamp
    h = normalize(wi + wo)
    ch = dot(n, h)
    d = np.exp((ch**2 - 1) / (ka * ch**2)) / (np.pi * ka * ch**4)
    g = np.minimum(1, np.minimum(2 * ch * co / dot(wo, h), 2 * ch * ci / dot(wi, h)))
    fr = ks + (np.minimum(1, 50 * ks) - ks) * ((1 - dot(wi, h)) ** 5)[:, None]
    naive = kd / np.pi + (d * g / (4 * ci * co))[:, None] * fr
    assert np.allclose(f_io, naive, rtol=1e-8, atol=0)


@pytest.mark.parametrize("ka", [1e-6, 1e-3, 0.1, 1.0])
def test_beckmann_d_matches_its_sampler(ka):
    # D (n.h) d(omega_h) = du1 du2 under the sampler's map tan^2 = -ka ln(1 - u1), phi = 2 pi u2:
    # pointwise, D cos sin (dtheta/du1) 2 pi = 1 (so D is normalised and the sampler exact)
    u = (np.arange(1, 10_000) - 0.5) / 10_000
    t2 = -ka * np.log1p(-u)
    ct = 1 / np.sqrt(1 + t2)
    st = np.sqrt(t2) * ct
    h = np.stack([st, np.zeros_like(st), ct], -1)
    dtheta_du = ka / (2 * np.sqrt(t2) * (1 - u) * (1 + t2))
    assert np.allclose(bsdf.beckmann_d([0, 0, 1], h, ka) * ct * st * dtheta_du * 2 * np.pi, 1.0, rtol=1e-9)
    hs = bsdf.sample_beckmann_h([0, 0, 1], ka, u, 0.3)
    assert np.allclose(hs[:, 2], ct, rtol=1e-12)


def test_fresnel_clamp():
    assert np.allclose(bsdf.f90([0, 0.01, 0.02, 0.5]), [0, 0.5, 1, 1])
    assert np.allclose(bsdf.f90([0, 0.01], clamp=False), [1, 1])
    ks = np.array([0.0, 0.01, 0.04])
    assert np.allclose(bsdf.fresnel_schlick(ks, 1.0), ks)  # F(normal incidence) = ks
    assert np.allclose(bsdf.fresnel_schlick(ks, 0.0), [0, 0.5, 1])


# --------------------------------------------------------------------------------------------
# directional albedo


def test_albedo_without_the_clamp_reproduces_the_design_numbers():
    # docs/renderer.md, "Material model": kd = 1, ks = 0, ka = 0.1, F90 = 1: 1.00 at normal incidence,
    # about 1.28 at 85 degrees
    a = bsdf.directional_albedo(np.radians([0.0, 85.0]), 1.0, 0.0, 0.1, f90_clamp=False)[:, 0]
    assert a[0] == pytest.approx(1.0, abs=1e-4)
    assert a[1] == pytest.approx(1.28, abs=0.005)


def test_albedo_with_the_clamp_and_no_ks_is_exactly_kd():
    theta = np.radians(np.linspace(0, 90, 91))
    kd = np.array([1.0, 0.5, 0.25])
    for ka in (1e-6, 0.01, 0.1, 1.0):
        assert np.array_equal(bsdf.directional_albedo(theta, kd, 0.0, ka), np.broadcast_to(kd, (91, 3)))


def test_white_furnace_diffuse_lobe():
    # kd = 1, ks = 0: every cosine-sampled path weight f cos / p is exactly 1
    gen = np.random.default_rng(4)
    n, wo, _ = random_frames(gen, 1)
    u1, u2, _, _ = uniforms(100_000, seed=11)
    wi = bsdf.sample_cosine(n, u1, u2)
    weight = bsdf.milo_bsdf_cos(n, wo, wi, np.ones(3), np.zeros(3), 0.1) / bsdf.pdf_cosine(n, wi)[:, None]
    assert np.abs(weight - 1).max() < 1e-12


@pytest.mark.parametrize("ka", [1e-3, 0.01, 0.3, 1.0])
def test_albedo_quadrature_converged(ka):
    theta = np.radians([0, 30, 60, 80, 85, 88, 89.5, 90])
    a = np.array(bsdf.specular_albedo_terms(theta, ka))
    b = np.array(bsdf.specular_albedo_terms(theta, ka, 512, 32))
    assert np.abs(a - b).max() < 1e-4


@pytest.mark.parametrize("ka,theta_deg", [(0.1, 40.0), (0.5, 75.0), (1.0, 85.0)])
def test_albedo_quadrature_against_a_direct_hemisphere_grid(ka, theta_deg):
    # independent of the sampler's change of variables: Gauss-Legendre in (cos theta_i, phi_i)
    ci, wc = bsdf.gauss_legendre01(600)
    phi = (np.arange(1200) + 0.5) * 2 * np.pi / 1200
    si = np.sqrt(1 - ci**2)
    wi = np.stack(np.broadcast_arrays(si[:, None] * np.cos(phi), si[:, None] * np.sin(phi), ci[:, None]), -1)
    t = np.radians(theta_deg)
    wo = np.array([np.sin(t), 0, np.cos(t)])
    ks = np.array([0.04, 0.5, 1.0])
    f = bsdf.milo_bsdf_cos([0, 0, 1], wo, wi, 0.0, ks, ka)
    grid = np.einsum("i,ijc->c", wc, f) * (2 * np.pi / 1200)
    assert np.allclose(grid, bsdf.directional_albedo(t, 0.0, ks, ka), atol=1e-3, rtol=0)


@pytest.mark.parametrize(
    "ka,theta_deg,clamp", [(1e-3, 60.0, True), (0.01, 85.0, True), (0.1, 85.0, False), (0.8, 30.0, True)]
)
def test_albedo_quadrature_against_monte_carlo(ka, theta_deg, clamp):
    # the model's albedo estimated with the reference importance sampler (cosine + Beckmann)
    count = 400_000
    u0, u1, u2, _ = uniforms(count, seed=12)
    n, wo = frame(20.0, 70.0, theta_deg)
    kd, ks = np.array([0.3, 0.0, 1.0]), np.array([0.04, 0.0, 0.7])
    weights = np.array([0.5, 0.5, 0, 0])
    wi, _ = sampling.sample_mixture(weights, n, wo, ka, np.stack([u0, u1, u2, u2], -1))
    p = sampling.mixture_pdf(weights, n, wo, wi, ka)
    f = bsdf.milo_bsdf_cos(n, wo, wi, kd, ks, ka, f90_clamp=clamp)
    est = np.where((p > 0)[:, None], f / np.where(p > 0, p, 1)[:, None], 0.0)
    mean, err = est.mean(0), est.std(0) / np.sqrt(count)
    want = bsdf.directional_albedo(np.radians(theta_deg), kd, ks, ka, f90_clamp=clamp)
    assert np.all(np.abs(mean - want) < 4 * err + 1e-3), (mean, want, err)


def test_max_albedo_is_an_upper_bound():
    t = bsdf.albedo_bound_tables()
    # off the table's nodes: geometric midpoints in ka (every other one), midpoints in theta
    ka = np.sqrt(t["ka"][:-1] * t["ka"][1:])[::2]
    theta = np.concatenate([0.5 * (t["theta"][:-1] + t["theta"][1:]), [0.5 * np.pi]])
    a1, a2 = bsdf.specular_albedo_terms(theta[None, :], ka[:, None])
    ks = np.array([0.0, 0.003, 0.011, 0.019, 0.021, 0.037, 0.12, 0.55, 0.97, 1.0, 1.3])
    for clamp in (True, False):
        f90 = bsdf.f90(ks, clamp)
        true_max = (ks[None, :, None] * a1[:, None] + f90[None, :, None] * a2[:, None]).max(-1)
        kd = np.array([0.0, 0.5, 1.0])
        bound = bsdf.max_albedo(kd, np.broadcast_to(ks[:, None], (len(ks), 3))[None], ka[:, None], f90_clamp=clamp)
        assert bound.shape == (len(ka), len(ks), 3)
        excess = true_max[..., None] + kd - bound
        assert excess.max() <= 0, excess.max()
        assert (bound - true_max[..., None] - kd)[:, :10].max() < 0.06  # and not loose (ks <= 1)
    # Lambertian texels: exactly kd (plus the margin)
    assert np.allclose(
        bsdf.max_albedo(np.full((5, 3), 0.7), np.zeros((5, 3)), np.full(5, 0.2)), 0.7 + bsdf.ALBEDO_BOUND_MARGIN
    )


# --------------------------------------------------------------------------------------------
# chi-square tests of the samplers


def test_chi2_machinery_pooling_and_sidak():
    assert sidak_threshold(0.01, 1) == pytest.approx(0.01)
    assert sidak_threshold(0.01, 10) == pytest.approx(1 - 0.99**0.1)
    stat, dof, _ = pearson([10, 12, 0, 3, 1], [10, 11, 1, 2, 1], min_expected=5)
    # three small cells pooled (expected 4 < 5), the pool merged into the smallest other cell
    assert dof == 1 and stat == pytest.approx(1 / 11)
    # a sampler leaving its PDF's support is rejected outright
    sphere = lambda k: normalize(np.random.default_rng(7).normal(size=(k, 3)))
    upper = lambda d: np.where(d[:, 2] > 0, 1 / (2 * np.pi), 0.0)
    res = chi2_test(sphere, upper, 10_000)
    assert not res.passed and "PDF is 0" in res.message
    uniform = lambda d: np.full(len(d), 1 / (4 * np.pi))
    assert pdf_integral(uniform) == pytest.approx(1.0, rel=1e-12)


@pytest.mark.parametrize("theta_n", [0.0, 120.0])
def test_chi2_cosine(theta_n):
    n, _ = frame(theta_n, 40.0, 0.0)
    sample = lambda k: bsdf.sample_cosine(n, *uniforms(k, seed=21)[:2])
    res = chi2_test(
        sample, lambda d: bsdf.pdf_cosine(n, d), N_SAMPLES, significance=SIGNIFICANCE, test_count=CHI2_TESTS
    )
    assert_accepted(res)
    assert res.integral == pytest.approx(1.0, abs=1e-3) and res.valid_fraction == 1.0


@pytest.mark.parametrize(
    "ka,theta_n,theta_o", [(0.01, 30.0, 40.0), (0.1, 0.0, 10.0), (0.1, 100.0, 80.0), (0.8, 60.0, 0.0), (0.8, 0.0, 85.0)]
)
def test_chi2_specular(ka, theta_n, theta_o):
    n, wo = frame(theta_n, 200.0, theta_o)
    sample = lambda k: failed_below(n, bsdf.sample_specular(n, wo, ka, *uniforms(k, seed=22)[:2]))
    pdf = lambda d: bsdf.pdf_specular(n, wo, d, ka)
    res = chi2_test(sample, pdf, N_SAMPLES, significance=SIGNIFICANCE, test_count=CHI2_TESTS)
    assert_accepted(res)
    # integral = success probability of the sampler (5 sigma + quadrature)
    tol = 5 * math.sqrt(0.25 / N_SAMPLES) + 2e-3
    assert res.integral == pytest.approx(res.valid_fraction, abs=tol)


def sky_with_sun(n=8, sun=(4, 2, 5), sun_gain=60.0):
    gen = np.random.default_rng(5)
    kg = gen.uniform(0.05, 1.0, size=(6, n, n, 3))
    kg[1] *= 0.0  # a black face: never sampled
    kg[sun] = sun_gain * np.array([1.0, 0.9, 0.7])
    return kg


def test_chi2_environment():
    env = sampling.EnvironmentDistribution(sky_with_sun())
    assert 0.1 < env.texel_probability.max() < 0.5  # the sun is a good share of the samples
    sample = lambda k: env.sample(*uniforms(k, seed=23)[:3])
    res = chi2_test(sample, env.pdf, N_SAMPLES, significance=SIGNIFICANCE, test_count=CHI2_TESTS)
    assert_accepted(res)
    assert res.integral == pytest.approx(1.0, abs=1e-4)
    d = sample(200_000)
    assert np.all(cubemap.direction_to_cube(d)[0] != 1)  # zero-probability texels never drawn


def test_environment_all_black_falls_back_to_uniform():
    env = sampling.EnvironmentDistribution(np.zeros((6, 4, 4, 3)))
    assert env.black
    assert pdf_integral(env.pdf) == pytest.approx(1.0, abs=1e-4)
    assert np.allclose(env.texel_probability.sum(axis=(1, 2)), 1 / 6)  # P = solid angle / 4 pi


def emitter_set():
    """Two quads stacked above the origin (so rays cross both), a triangle to the side and one
    below: (v0, v1, v2, power)."""

    def quad(c, sx, sy):  # two triangles in the plane z = c[2]
        corner = lambda i, j: [c[0] + i * sx, c[1] + j * sy, c[2]]
        return [(corner(-1, -1), corner(1, -1), corner(1, 1)), (corner(-1, -1), corner(1, 1), corner(-1, 1))]

    tris = quad([0.1, 0.0, 1.0], 0.6, 0.4) + quad([0.3, 0.1, 2.0], 0.9, 0.9)
    tris += [
        ([2.0, -0.5, 0.0], [2.0, 0.5, 0.2], [2.2, 0.0, 1.0]),
        ([-0.5, -0.5, -1.5], [0.5, -0.5, -1.5], [0.0, 0.7, -1.2]),
    ]
    v = np.array(tris, dtype=np.float64)
    return v[:, 0], v[:, 1], v[:, 2], np.array([1.0, 1.0, 3.0, 3.0, 2.0, 0.5])


def test_chi2_emitters_all_hits():
    em = sampling.EmitterDistribution(*emitter_set())
    x = np.zeros(3)
    sample = lambda k: em.sample(x, *uniforms(k, seed=24)[:3])
    res = chi2_test(sample, lambda d: em.pdf(x, d), N_SAMPLES, significance=SIGNIFICANCE, test_count=CHI2_TESTS)
    assert_accepted(res)
    assert res.integral == pytest.approx(1.0, abs=2e-3)


def first_hit_only_pdf(em, x, d):
    """The WRONG emitter PDF: only the nearest crossed triangle counts."""
    best_s, best_p = np.full(len(d), np.inf), np.zeros(len(d))
    for t in range(len(em.prob)):
        single = sampling.EmitterDistribution(em.v0[t : t + 1], em.v1[t : t + 1], em.v2[t : t + 1], [1.0])
        p = single.pdf(x, d)
        s = dot(em.normal[t], em.v0[t] - x) / np.where(dot(em.normal[t], d) != 0, dot(em.normal[t], d), 1)
        nearer = (p > 0) & (s < best_s)
        best_s = np.where(nearer, s, best_s)
        best_p = np.where(nearer, em.prob[t] * p, best_p)
    return best_p


def test_chi2_rejects_wrong_pdfs():
    # must be able to fail: each density below is wrong in one documented way
    em = sampling.EmitterDistribution(*emitter_set())
    x = np.zeros(3)
    res = chi2_test(lambda k: em.sample(x, *uniforms(k, seed=25)[:3]), lambda d: first_hit_only_pdf(em, x, d), N_REJECT)
    assert not res.passed, res.message
    assert res.integral < 0.95  # the hidden triangles' share is missing

    env = sampling.EnvironmentDistribution(sky_with_sun())

    def no_jacobian(d):  # P / (2/N)^2 without the gnomonic factor (1 + u^2 + v^2)^(3/2)
        _, s_, t_ = cubemap.direction_to_cube(d)
        return env.pdf(d) / (1 + (2 * s_ - 1) ** 2 + (2 * t_ - 1) ** 2) ** 1.5

    res = chi2_test(lambda k: env.sample(*uniforms(k, seed=26)[:3]), no_jacobian, N_REJECT)
    assert not res.passed, res.message

    n, wo = frame(30.0, 0.0, 50.0)
    ka = 0.3

    # Beckmann PDF of h used as a PDF of wi (missing d(omega_h)/d(omega_i) = 1 / (4 wo.h))
    def no_jac_spec(d):
        h = normalize(d + wo)
        return np.where(dot(n, d) > 0, bsdf.beckmann_d(n, h, ka) * dot(n, h), 0)

    res = chi2_test(
        lambda k: failed_below(n, bsdf.sample_specular(n, wo, ka, *uniforms(k, seed=27)[:2])), no_jac_spec, N_REJECT
    )
    assert not res.passed, res.message


@pytest.mark.parametrize(
    "kd,ks,ka,theta_n,theta_o",
    [
        ([0.6, 0.5, 0.4], [0.04, 0.04, 0.04], 0.05, 10.0, 50.0),
        ([0.05, 0.05, 0.05], [0.9, 0.8, 0.7], 0.01, 160.0, 70.0),
    ],
)
def test_chi2_mixture(kd, ks, ka, theta_n, theta_o):
    n, wo = frame(theta_n, 300.0, theta_o)
    env = sampling.EnvironmentDistribution(sky_with_sun())
    em = sampling.EmitterDistribution(*emitter_set())
    x = np.zeros(3)
    w = sampling.mixture_weights(kd, ks, 0.25, 0.25)
    assert w.sum() == pytest.approx(1.0) and w[1] > 0 and w[0] > 0

    def sample(k):
        u = uniforms(k, seed=28).T
        wi, strategy = sampling.sample_mixture(w, n, wo, ka, u, env, em, x)
        spent = (strategy == 1) & (dot(n, wi) <= 0)  # a specular sample below the surface
        return np.where(spent[:, None], np.nan, wi)

    pdf = lambda d: sampling.mixture_pdf(w, n, wo, d, ka, env, em, x)
    res = chi2_test(sample, pdf, N_SAMPLES, significance=SIGNIFICANCE, test_count=CHI2_TESTS)
    assert_accepted(res)


def test_mixture_weights_and_strategy_choice():
    kd = [[1, 1, 1], [0, 0, 0], [0, 0, 0]]
    ks = [[1, 1, 1], [0.5, 0.5, 0.5], [0, 0, 0]]
    w = sampling.mixture_weights(kd, ks, 0.25, 0.25)
    assert np.allclose(w, [[0.25, 0.25, 0.25, 0.25], [0, 0.5, 0.25, 0.25], [0.5, 0, 0.25, 0.25]])
    assert np.allclose(sampling.mixture_weights([1, 0, 0], [0, 0, 1], 0, 0), [0.2126 / 0.2848, 0.0722 / 0.2848, 0, 0])
    u0 = np.linspace(0, 1 - 2**-24, 10001)
    for weights in ([0.5, 0, 0.5, 0], [0, 0.3, 0.7, 0], [0, 0, 0, 1], [0.1, 0.2, 0.3, 0.4]):
        k = sampling.choose_strategy(np.array(weights), u0)
        assert np.all(np.array(weights)[k] > 0)
        assert np.allclose(np.bincount(k, minlength=4) / len(u0), weights, atol=1e-3)


# --------------------------------------------------------------------------------------------
# robustness


# Vector components are 0 or at least 1e-30 in magnitude (directions come from float32 data).
# With float64 denormal components a cosine can be 1e-311, and f cos = D F G / (4 co) ~ 1 / co
# along the mirror direction at grazing (the model's genuine singularity) then exceeds 1e308.
COMPONENT = st.floats(-1, 1).map(lambda c: c if abs(c) >= 1e-30 else 0.0)
UNIT = st.tuples(*[COMPONENT] * 3).filter(lambda v: np.linalg.norm(v) > 1e-6)
U = st.floats(0, 1, exclude_max=True)
RGB = st.tuples(*[st.floats(0, 1)] * 3)
KA = st.one_of(st.floats(1e-6, 1), st.sampled_from([1e-6, 1e-5, 1.0]))
_ENV = sampling.EnvironmentDistribution(sky_with_sun(n=4, sun=(2, 1, 3)))
_EM = sampling.EmitterDistribution(*emitter_set())


@settings(max_examples=300, deadline=None)
@given(
    n=UNIT,
    wo=UNIT,
    wi=UNIT,
    kd=RGB,
    ks=RGB,
    ka=KA,
    u=st.tuples(U, U, U, U),
    clamp=st.booleans(),
    mirror=st.booleans(),
    x=st.tuples(*[st.floats(-3, 3)] * 3),
)
def test_property_no_nan_or_inf(n, wo, wi, kd, ks, ka, u, clamp, mirror, x):
    n, wo, wi = normalize(np.array(n)), normalize(np.array(wo)), normalize(np.array(wi))
    if mirror:  # the exact mirror direction: the top of the specular peak
        wi = bsdf.reflect(wo, n)
    samples = [
        bsdf.sample_cosine(n, u[0], u[1]),
        bsdf.sample_specular(n, wo, ka, u[0], u[1]),
        _ENV.sample(u[1], u[2], u[3]),
        _EM.sample(np.array(x), u[1], u[2], u[3]),
    ]
    for s in samples:
        assert np.all(np.isfinite(s)) and (np.linalg.norm(s) == 0 or abs(np.linalg.norm(s) - 1) < 1e-9)
    for v in [wi] + samples:
        f = bsdf.milo_bsdf_cos(n, wo, v, kd, ks, ka, f90_clamp=clamp)
        pdfs = [bsdf.pdf_cosine(n, v), bsdf.pdf_specular(n, wo, v, ka), _ENV.pdf(v), _EM.pdf(np.array(x), v)]
        assert np.all(np.isfinite(f)) and np.all(f >= 0)
        assert all(np.isfinite(p) and p >= 0 for p in pdfs)
    w = sampling.mixture_weights(kd, ks)
    assert np.all(np.isfinite(w)) and w.sum() == pytest.approx(1.0)
