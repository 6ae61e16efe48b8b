"""Whole renders against closed forms, hard cases, determinism, and the feature analysis."""

import numpy as np
import pytest
from testscenes import box_room, hard_room, inside_sphere, look_at_camera, sphere_in_sky

from invrender.render.analysis import AnalysisSettings, analyse_scene
from invrender.render.features import Features
from invrender.render.renderer import Renderer, pixel_requests

DIFFUSE_ONLY = dict(
    specular=False, emission=True, emitter_sampling=True, environment=False, window=False, env_sampling=False
)


def interior(mask, steps=1):
    """Pixels whose 4-neighbourhood is in the mask too (no partially covered pixels)."""
    m = mask.copy()
    for _ in range(steps):
        m[1:-1, 1:-1] &= mask[:-2, 1:-1] & mask[2:, 1:-1] & mask[1:-1, :-2] & mask[1:-1, 2:]
        m[[0, -1], :] = False
        m[:, [0, -1]] = False
    return m


def assert_within_noise(a, b, z_max=5.5):
    """Every pixel of two independent renders agrees within z_max combined standard errors."""
    z = (a["radiance"] - b["radiance"]) / np.sqrt(a["variance"] + b["variance"] + 1e-12)
    assert np.abs(z).max() < z_max, f"max |z| = {np.abs(z).max():.2f}"


@pytest.mark.parametrize("kd", [0.5, 1.0])
@pytest.mark.parametrize("everything", [False, True])
def test_diffuse_sphere_under_uniform_sky_is_kd_times_sky(kd, everything):
    """A convex object never sees itself: one bounce is exact. kd = 1 is the white furnace, which
    also holds with every feature compiled in, since ks = 0 is exactly Lambertian (F90 clamp)."""
    scene = sphere_in_sky(kd=kd, sky=1.0)
    features = Features.everything(max_bounces=2) if everything else analyse_scene(scene)[0]
    out = Renderer(scene, features).render(scene.cameras[0], spp=512, seed=3)
    inside = interior(out["instance_id"] == 1)
    values, se = out["radiance"][inside], np.sqrt(out["variance"][inside])
    assert inside.sum() > 100
    assert abs(values.mean() / kd - 1) < 2e-3, values.mean()
    assert np.all(np.abs(values - kd) < 5.5 * se + 1e-6)
    assert out["dropped"] == 0


@pytest.mark.parametrize("bounces", [1, 3, 10])
@pytest.mark.parametrize("nee", [True, False], ids=["nee", "mixture"])
@pytest.mark.parametrize("roulette_depth", [0, 2], ids=["all", "roulette"])
def test_emitting_enclosure_has_geometric_series_radiance(bounces, nee, roulette_depth):
    """The closed form holds for both estimators, with and without Russian roulette (which must
    stay unbiased: 1/q on every survivor)."""
    kd, ke = 0.6, 1.0
    scene = inside_sphere(kd=kd, ke=ke)
    features = Features(**(DIFFUSE_ONLY | {"max_bounces": bounces, "nee": nee, "roulette_depth": roulette_depth}))
    out = Renderer(scene, features).render(scene.cameras[0], spp=256, seed=1)
    expected = ke * (1 - kd ** (bounces + 1)) / (1 - kd)
    assert abs(out["radiance"].mean() / expected - 1) < 2e-3
    z = (out["radiance"] - expected) / np.sqrt(out["variance"] + 1e-12)
    assert np.abs(z).max() < 5.5


def test_same_seed_same_bytes_and_batches_match_full_images():
    scene = box_room(ks=0.3, ka=0.02, window=True)
    renderer = Renderer(scene, Features.everything(max_bounces=4))
    cam = scene.cameras[0]
    a = renderer.render(cam, spp=8, seed=7, aovs=False)["radiance"]
    b = renderer.render(cam, spp=8, seed=7, aovs=False)["radiance"]
    c = renderer.render(cam, spp=8, seed=8, aovs=False)["radiance"]
    assert a.tobytes() == b.tobytes()
    assert np.abs(a - c).max() > 0
    requests = pixel_requests(cam)
    pick = np.random.default_rng(0).permutation(len(requests))[:100]
    mean, _, _ = renderer.render_requests([cam], requests[pick], spp=8, seed=7)
    assert np.array_equal(mean, a.reshape(-1, 3)[pick])


def test_hard_cases_never_give_nan_or_inf():
    """Mirror-sharp lobes (ka = 1e-6) with ks = 1, emission 1e6, degenerate triangles, grazing
    views, a camera inside a box, rays escaping to the sky."""
    grazing = look_at_camera((-1.9, 0.001, 1.4), (1.9, 0.0, -1.4), width=24, height=16, fov_x_deg=40)
    in_table = look_at_camera((-0.8, 0.4, -0.3), (0, 0.4, 0), width=16, height=12)
    for scene in (hard_room(), hard_room(open_top=True)):
        cams = scene.cameras = scene.cameras + [grazing, in_table]
        renderer = Renderer(scene, Features.everything(max_bounces=10))
        for cam in cams:
            out = renderer.render(cam, spp=16, seed=2)
            assert out["dropped"] == 0
            assert np.isfinite(out["radiance"]).all() and np.isfinite(out["variance"]).all()
            assert (out["radiance"] >= 0).all()


def test_features_of_an_all_diffuse_room_without_windows():
    scene = box_room()
    features, evidence = analyse_scene(scene)
    bounces = features.max_bounces
    roulette = AnalysisSettings().roulette_depth if bounces > AnalysisSettings().roulette_depth else 0
    assert features == Features(**(DIFFUSE_ONLY | {"max_bounces": bounces, "roulette_depth": roulette}))
    assert evidence["strategy_weights"] is None  # one light strategy: nothing to choose
    lit_outside = box_room()
    lit_outside.maps.kg[:] = 1.0  # a sky, but the closed room hides it: no environment code
    features, evidence = analyse_scene(lit_outside)
    assert evidence["rays_can_escape"] is False and not features.environment
    open_room = box_room(window=True)
    open_room.mesh.faces = open_room.mesh.faces[2:]  # no floor
    assert analyse_scene(open_room)[1]["rays_can_escape"] is True
    window_room = box_room(window=True, ks=0.3)
    f2, _ = analyse_scene(window_room)
    assert f2.specular and f2.window and f2.environment and f2.env_sampling


def test_specialised_kernel_converges_to_the_all_features_image():
    scene = box_room()
    specialised = analyse_scene(scene)[0]
    everything = Features.everything(max_bounces=specialised.max_bounces)
    a = Renderer(scene, specialised).render(scene.cameras[0], spp=256, seed=1, aovs=False)
    b = Renderer(scene, everything).render(scene.cameras[0], spp=256, seed=2, aovs=False)
    assert_within_noise(a, b)
    ratio = a["radiance"].mean() / b["radiance"].mean()
    assert abs(ratio - 1) < 0.01, (ratio, specialised, a["dropped"], b["dropped"])


@pytest.mark.parametrize("fraction", [0.05, 0.01])
def test_chosen_bounce_count_meets_the_configured_fraction(fraction):
    """The energy bound picks B; the measured energy beyond B (10 bounces as the truth, with
    identical random numbers for the shared bounces) is below the fraction."""
    scene = box_room(kd=(0.5, 0.5, 0.5))
    features, evidence = analyse_scene(scene, AnalysisSettings(bounce_fraction=fraction))
    assert evidence["tail_bound"] <= fraction and 1 <= features.max_bounces < 10
    cam = scene.cameras[0]
    short = Renderer(scene, features).render(cam, spp=128, seed=4, aovs=False)["radiance"]
    full = Renderer(scene, Features(**(DIFFUSE_ONLY | {"max_bounces": 10}))).render(cam, spp=128, seed=4, aovs=False)[
        "radiance"
    ]
    measured = (full - short).sum() / full.sum()
    assert 0 <= measured < fraction, (features.max_bounces, measured)
