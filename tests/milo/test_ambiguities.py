"""The paper's ambiguity cases (MILO sections 3.3 and 4.3-4.4) on small closed rooms, trained
with the real stage (milo.stage.run) and scored on the atlas texels of each patch.

- Diffuse-emission (Fig. 3b, Fig. 12): a lamp in the ceiling over a white plate on the floor.
  Per texel the captures cannot tell kd E / pi from ke; the template can (a white plate lit
  unevenly is one material with one kd, not an emission gradient). The ablation of Fig. 12
  (`template: false`, two plain MLPs) explains part of the plate's light by emission.
- Colour bleeding (Fig. 15): a red and a white wall facing each other under one lamp; the white
  wall is lit red by its neighbour, and its recovered kd must not take the colour. The paper
  credits the light's radiance, fixed by enough views; the contrast here is training that cannot
  carry light from wall to wall (direct light only), which has to paint the red onto the kd.

Every setting the result depends on is passed explicitly (SETTINGS), so the tests do not follow
the presets' defaults. The numbers quoted were measured with the milo code that renders each
texel's most probable material and starts MLP 1 from the photographs' brightest texels (hard
materials and the warm start); without those (soft Eq. 7, no warm start) the template's plate
emits too (ke 0.04-0.09) and these tests fail. The rooms' walls are black, so all the light the cameras see comes from
the patches, and the captures need only the bounces training renders (SETTINGS' max_bounces).
"""

from __future__ import annotations

import time

import numpy as np
import pytest
import torch
from ambiguity_scenes import Patch, closed_room, pinhole_camera, ring_cameras, write_inputs

from invrender.milo import stage
from invrender.scene.snapshots import load_snapshot
from invrender.synthesize.room import Material

SETTINGS = {
    "iterations": 150,
    "rays": 4096,  # every pixel of the six 32 x 24 views, near enough
    "spp": 4,
    "max_bounces": 2,
    "materials": 4,  # Q: one lamp, one window, two normal materials (the rooms have 3 materials)
    "image_loss": "mse",
    "lr_mlp": 3e-3,
    "lr_template": 2.0,  # the losses are means (losses.py): the paper's 0.01 barely moves the template
    "decay_at": [0.7, 0.9],
    "seed": 0,
    "checkpoint_every": 1000,
    "snapshot_every": 1000,
}
LAMP_KE = 4.0
WHITE_KD = 0.8


@pytest.fixture(autouse=True, scope="module")
def one_torch_thread():
    """torch's OpenMP threads spin beside PoCL's on 2 cores: training ran 2-20 times slower
    (module scope: set before the module's fixtures train)."""
    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(threads)


def ceiling_cameras(count=6):
    """Six views around the room's middle, each seeing the ceiling and the floor."""
    ring = ring_cameras((0, 0.8, 0), (0, 0.8, 0), 1.0, count)
    return [pinhole_camera(c.name, c.center, (0, 0.7, 0), 32, 24, 110) for c in ring]


def train(fixture, root, **overrides):
    """(recovered maps, seconds) of the milo stage on `fixture`'s captures."""
    paths = write_inputs(fixture, root)
    start = time.perf_counter()
    settings = SETTINGS | overrides
    stage.run(paths["geometry"], paths["cameras"], paths["images"], root / "milo", "demo", settings, progress=False)
    maps = load_snapshot(root / "milo" / "maps.npz", fixture.texels.shape)[0]
    return maps, time.perf_counter() - start


def plate_means(fixture, maps, name):
    sel = fixture.part_texels(name)
    return {key: getattr(maps, key)[sel].mean(0) for key in ("kd", "ks", "ke", "kw")}


@pytest.fixture(scope="module")
def lamp_over_plate():
    return closed_room(
        (2.4, 1.6, 2.4),
        {
            "lamp": Patch("+y", (0, 0), (0.6, 0.6), Material(kd=0.0, ks=0.0, ke=LAMP_KE)),
            "white": Patch("-y", (0, 0), (1.4, 1.4), Material(kd=WHITE_KD, ks=0.0, ka=0.3)),
        },
        ceiling_cameras(),
    )


def test_diffuse_emission_ambiguity_is_resolved_by_the_template(lamp_over_plate, tmp_path):
    maps, seconds = train(lamp_over_plate, tmp_path)
    lamp, white = plate_means(lamp_over_plate, maps, "lamp"), plate_means(lamp_over_plate, maps, "white")
    print(f"template: {seconds:.1f} s; lamp ke {lamp['ke']}, white kd {white['kd']} ke {white['ke']} ks {white['ks']}")
    # The lamp is seen directly: its ke is the captured radiance (measured within 1 %).
    np.testing.assert_allclose(lamp["ke"], LAMP_KE, rtol=0.05)
    assert lamp["kd"].max() < 0.02
    # The plate reflects: no emission (measured 0: a normal material has ke = kw = 0) ...
    assert white["ke"].max() < 0.005 and white["kw"] < 0.005
    # ... and takes the plate's light as reflection: kd measured 0.40 0.42 0.46 after 150
    # iterations, 0.46-0.48 after 300 (truth 0.8). The tolerance is wide because the plate and the
    # black walls end on one normal material of the template (MLP 1 sends every normal texel to
    # one material, and the other never gets a gradient) and the detail texture, held back by its
    # L1 loss, makes up only part of the difference; it still excludes the ablation's 0.22.
    np.testing.assert_allclose(white["kd"], WHITE_KD, atol=0.45)
    assert white["kd"].mean() > 0.35


def test_plain_mlps_explain_the_lit_plate_by_emission(lamp_over_plate, tmp_path):
    """Fig. 12's ablation: the same captures, no template; the plate comes out partly emitting:
    ke measured 0.070 (0.06 after 100 iterations, 0.077 after 300) with kd 0.22, where its
    captured radiance is 0.113 on average (0.035-0.169 across it): about 60 % of the light it
    sends is taken for emission, which would stay on when the lamp is switched off."""
    maps, seconds = train(lamp_over_plate, tmp_path, template=False)
    white = plate_means(lamp_over_plate, maps, "white")
    print(f"plain MLPs: {seconds:.1f} s; white kd {white['kd']} ke {white['ke']}")
    assert white["ke"].mean() > 0.03
    assert white["kd"].mean() < 0.35


# Fig. 15: a red wall facing a white one 0.8 m away, a lamp in the ceiling between them. The white
# wall is lit red by its neighbour (its captured red/green ratio is above 1); its kd must not be.
WALL_KD = {"red": (0.7, 0.1, 0.1), "white": (0.7, 0.7, 0.7)}
BLEEDING = {"materials": 6, "max_bounces": 3}  # Q: lamp, window, black, red, white and one spare


@pytest.fixture(scope="module")
def facing_walls():
    eyes = [(x, 0.8, z) for z in (-0.85, 0.85) for x in (-0.21, 0.0, 0.21)]
    cameras = [pinhole_camera(f"view_{k:03d}.exr", eye, (0, 0.75, 0), 32, 24, 110) for k, eye in enumerate(eyes)]
    return closed_room(
        (0.8, 1.6, 2.0),
        {
            "lamp": Patch("+y", (0, 0), (0.6, 0.4), Material(kd=0.0, ks=0.0, ke=LAMP_KE)),
            "red": Patch("-x", (0.8, 0), (1.2, 1.4), Material(kd=WALL_KD["red"], ks=0.0, ka=0.3)),
            "white": Patch("+x", (0.8, 0), (1.2, 1.4), Material(kd=WALL_KD["white"], ks=0.0, ka=0.3)),
        },
        cameras,
    )


def red_over_green(fixture, maps, name):
    kd = plate_means(fixture, maps, name)["kd"]
    return kd[0] / kd[1], kd


@pytest.fixture(scope="module")
def facing_walls_trained(facing_walls, tmp_path_factory):
    """(maps, seconds): the milo stage on the facing walls, shared by both tests below."""
    return train(facing_walls, tmp_path_factory.mktemp("bleeding"), **BLEEDING)


def test_facing_walls_come_out_without_colour_bleeding(facing_walls, facing_walls_trained):
    maps, seconds = facing_walls_trained
    white, white_kd = red_over_green(facing_walls, maps, "white")
    red, red_kd = red_over_green(facing_walls, maps, "red")
    print(f"{seconds:.1f} s; white kd {white_kd} (r/g {white:.3f}), red kd {red_kd} (r/g {red:.3f})")
    # Truth r/g: 1 on the white wall. Measured 1.22 after 150 iterations: the template's random
    # starting colours are not gone yet (the wall's kd 0.60 0.49 0.51, truth 0.7).
    assert abs(white - 1.0) < 0.3
    # The red wall stays red (truth r/g 7; measured 3.3: its green and blue 0.15 for 0.1).
    assert red > 2.5


def test_colour_bleeds_when_training_ignores_inter_reflection(facing_walls, facing_walls_trained, tmp_path):
    """The same captures trained with direct light only (max_bounces 1): the red light the white
    wall receives from its neighbour can only be explained by a pinker kd (r/g measured 1.49,
    against 1.22 with the inter-reflection modelled)."""
    white = red_over_green(facing_walls, facing_walls_trained[0], "white")[0]
    maps, seconds = train(facing_walls, tmp_path, **(BLEEDING | {"max_bounces": 1}))
    direct, direct_kd = red_over_green(facing_walls, maps, "white")
    print(f"direct light only: {seconds:.1f} s; white kd {direct_kd} (r/g {direct:.3f}, {white:.3f} modelled)")
    assert direct > white + 0.1
