"""One-sided emitters (Mesh.one_sided, FEATURE_ONE_SIDED): a ceiling panel 2 cm below the
ceiling, facing down, rendered against Mitsuba 3, whose `area` emitter is one-sided, from the
room and from inside the gap, where only the back of the panel faces the ceiling; and the
adjoint's ke derivative there against an exact finite difference."""

import copy

import mitsuba as mi
import numpy as np
import pytest
from testscenes import box_room, look_at_camera

import invrender.mitsuba as mb  # noqa: I001 - first: it points drjit at a usable libLLVM
from invrender.render.adjoint import backward
from invrender.render.analysis import analyse_scene
from invrender.render.features import Features
from invrender.render.renderer import Renderer, pixel_requests

BOUNCES = 3
SPP = 1024
PASSES = 8  # independent Mitsuba renders: their spread gives Mitsuba's per-pixel standard error
CEILING = 2.6
LIGHT_PART = 6  # box_room's light quad: faces 12 and 13, vertices 24..27


def panel_room(one_sided: bool = True):
    """box_room with its 1.0 x 0.8 m light (ke = 8, black behind) 2 cm below the ceiling and two
    cameras: the room's, and one inside the gap looking up at the ceiling behind the panel."""
    scene = box_room(size=(24, 18))
    scene.mesh.positions[4 * LIGHT_PART : 4 * LIGHT_PART + 4, 1] = CEILING - 0.02
    if one_sided:
        scene.mesh.one_sided = np.isin(np.arange(len(scene.mesh.faces)), [2 * LIGHT_PART, 2 * LIGHT_PART + 1])
    gap = look_at_camera(
        (0.3, CEILING - 0.01, 0.2), (0.3, CEILING + 1.0, 0.5), width=12, height=9, fov_x_deg=60, name="gap"
    )
    scene.cameras.append(gap)
    return scene


def mitsuba_mean_and_variance(scene, camera, spp):
    loaded = mi.load_dict(mb.scene_to_mitsuba_diffuse(scene, camera, BOUNCES, spp // PASSES), parallel=False)
    passes = np.stack([np.array(mi.render(loaded, spp=spp // PASSES, seed=2000 + k))[..., :3] for k in range(PASSES)])
    return passes.mean(0), passes.var(0, ddof=1) / PASSES


def test_the_analysis_compiles_sidedness_in_only_for_one_sided_emitters():
    assert analyse_scene(panel_room(True))[0].one_sided
    assert not analyse_scene(panel_room(False))[0].one_sided
    flipped = panel_room(True)
    flipped.mesh.one_sided = ~flipped.mesh.one_sided  # one-sided walls, a two-sided lamp
    assert not analyse_scene(flipped)[0].one_sided


def test_a_one_sided_panel_renders_like_mitsubas_area_emitter_and_leaves_the_ceiling_behind_it_dark():
    one_sided, two_sided = panel_room(True), panel_room(False)
    ours = Renderer(one_sided, Features.everything(max_bounces=BOUNCES))
    before = Renderer(two_sided, Features.everything(max_bounces=BOUNCES))
    for camera in one_sided.cameras:
        # In the gap, light is a rare event (paths that leave it at a grazing angle): more samples
        # there, so that both renderers see enough of them (its 108 pixels cost little).
        spp = SPP * (16 if camera.name == "gap" else 1)
        mine = ours.render(camera, spp=spp, seed=5, aovs=False)
        theirs, theirs_var = mitsuba_mean_and_variance(one_sided, camera, spp)
        # In the gap light is a rare event: Mitsuba's passes may all see none, and their spread
        # then says 0. Its noise is at least ours (both trace the same paths, one-sample NEE aside).
        theirs_var = np.maximum(theirs_var, mine["variance"])
        z = (mine["radiance"] - theirs) / np.sqrt(mine["variance"] + theirs_var + 1e-10)
        assert np.abs(z).max() < 6.0, f"{camera.name}: max |z| {np.abs(z).max():.2f}"
        # The image means, within 5 of their standard errors (in the gap, light is rare).
        z_mean = (mine["radiance"].mean() - theirs.mean()) / np.sqrt(mine["variance"].sum() + theirs_var.sum()) * z.size
        assert abs(z_mean) < 5.0, f"{camera.name}: means {mine['radiance'].mean():.4g} vs {theirs.mean():.4g}"
        two = before.render(camera, spp=SPP, seed=5, aovs=False)["radiance"]
        print(
            f"{camera.name}: one-sided {mine['radiance'].mean():.4g}, Mitsuba {theirs.mean():.4g} (z {z_mean:.2f}), "
            f"two-sided {two.mean():.4g}"
        )
        if camera.name != "gap":
            assert abs(mine["radiance"].mean() / theirs.mean() - 1) < 0.02, camera.name
        else:
            # Two-sided, the back of the panel lights the ceiling 2 cm above it: kd ke F with
            # the point-to-rectangle form factor F ~ 0.97; one-sided, only light that finds its
            # way into the gap from the room does, some hundred times less.
            assert two.mean() > 50 * theirs.mean() and two.mean() > 0.8 * np.mean(one_sided.maps.kd[0, 0]) * 8.0


def test_the_adjoint_leaves_the_back_of_a_one_sided_panel_out():
    """The loss is linear in the panel's ke: with common random numbers the central difference is
    exact, and from inside the gap it sees almost none of the light a two-sided panel would
    give, so an adjoint that counted the back would be off by orders of magnitude."""
    scene = panel_room(True)
    camera = scene.cameras[1]
    requests = pixel_requests(camera)
    delta = np.random.default_rng(0).uniform(0.5, 1.5, (len(requests), 3)).astype(np.float32)
    features = Features.everything(max_bounces=BOUNCES)

    def loss(maps_scene):
        mean, _, _ = Renderer(maps_scene, features).render_requests([camera], requests, 256, 3)
        return float((delta * mean).astype(np.float64).sum())

    values = []
    for sign in (1, -1):
        changed = copy.deepcopy(scene)
        changed.maps.ke[0, 1] += sign * 0.2
        values.append(loss(changed))
    gradient = backward(Renderer(scene, features), [camera], requests, delta, 256, seed=3)["ke"][0, 1]
    assert gradient.sum() == pytest.approx((values[0] - values[1]) / 0.4, rel=1e-3)  # all three channels moved
    two_sided = backward(Renderer(panel_room(False), features), [camera], requests, delta, 256, seed=3)["ke"][0, 1]
    assert 0 < gradient.sum() < 0.02 * two_sided.sum()
