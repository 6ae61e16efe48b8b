"""assets.furniture: every bundled asset is unit-normalised, closed and outward-wound, with its
named parts used, built the same on every call, and different across variants."""

import numpy as np
import pytest

from invrender.assets.furniture import CATEGORIES, VARIANTS, bundled, furniture
from invrender.assets.primitives import signed_volume

LIBRARY = bundled()


def directed_edges(faces):
    return np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]])


def test_the_library_has_every_category_in_every_style():
    assert [a.name for a in LIBRARY[:VARIANTS]] == ["chair_a", "chair_b", "chair_c", "chair_d"]
    assert {a.category for a in LIBRARY} == set(CATEGORIES)
    assert len({a.name for a in LIBRARY}) == len(LIBRARY) == VARIANTS * len(CATEGORIES)
    assert {"chair", "table", "desk", "cabinet", "shelf", "bed", "sofa", "lamp", "box"} <= set(CATEGORIES)


@pytest.mark.parametrize("asset", LIBRARY, ids=lambda a: a.name)
def test_unit_normalised_closed_and_outward(asset):
    p, f = asset.mesh.positions, asset.mesh.faces
    lo, hi = p.min(axis=0), p.max(axis=0)
    assert lo[1] == pytest.approx(0, abs=1e-12)  # on the floor
    assert lo[0] + hi[0] == pytest.approx(0, abs=1e-12) and lo[2] + hi[2] == pytest.approx(0, abs=1e-12)
    assert (hi - lo).max() == pytest.approx(1, abs=1e-12)
    # Closed and consistently wound: each directed edge once, and its reverse once.
    edges = directed_edges(f)
    assert len({tuple(e) for e in edges.tolist()}) == len(edges)
    assert {tuple(e) for e in edges.tolist()} == {tuple(e) for e in edges[:, ::-1].tolist()}
    assert signed_volume(p, f) > 0  # fronts outwards
    # Every part is used, every face has a part; the nominal size is a piece of furniture's.
    assert sorted(np.unique(asset.mesh.part).tolist()) == list(range(len(asset.part_names)))
    assert 0.4 < asset.nominal_size < 2.5


def test_the_lamp_shade_emits_and_its_faces_are_found():
    lamp = furniture("lamp", 0)
    assert lamp.emissive_parts == ("shade",)
    shade = lamp.mesh.positions[lamp.mesh.faces[lamp.part_faces("shade")]]
    assert shade[..., 1].max() == pytest.approx(1.0)  # the shade is the lamp's top
    assert shade[..., 1].min() > 0.6


def test_seeded_and_varied():
    a, b = furniture("chair", 1), furniture("chair", 1)
    np.testing.assert_array_equal(a.mesh.positions, b.mesh.positions)
    c = furniture("chair", 1, seed=7)
    assert a.mesh.positions.shape == c.mesh.positions.shape  # the style fixes the topology
    assert not np.allclose(a.mesh.positions, c.mesh.positions)  # the seed the dimensions
    # A chair faces +z: its back is at -z.
    back = a.mesh.positions[a.mesh.faces[a.part_faces("back")]]
    assert back[..., 2].mean() < a.mesh.positions[:, 2].mean() - 0.1


def test_unknown_category():
    with pytest.raises(ValueError, match="unknown category 'stool'"):
        furniture("stool")
