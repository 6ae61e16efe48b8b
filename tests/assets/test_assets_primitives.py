"""assets.primitives: orientation (counter-clockwise fronts outwards), watertightness, labels."""

from collections import Counter

import numpy as np
import pytest

from invrender.assets.primitives import (
    BOX_SIDES,
    axis_grid,
    box,
    cylinder,
    face_normals,
    grid_quad,
    quad,
    signed_volume,
    subdivide_breaks,
)


def directed_edges(faces):
    return Counter((int(a), int(b)) for f in faces for a, b in ((f[0], f[1]), (f[1], f[2]), (f[2], f[0])))


def assert_closed_and_consistent(faces):
    """Every directed edge appears once and its reverse once: closed, consistently wound."""
    edges = directed_edges(faces)
    assert max(edges.values()) == 1
    assert all((b, a) in edges for a, b in edges)


def test_box_is_closed_and_faces_outwards():
    lo, hi = np.array([-1.0, 0.0, 0.5]), np.array([1.0, 0.7, 1.3])
    b = box(lo, hi, cell=0.3)
    assert_closed_and_consistent(b.faces)
    assert signed_volume(b.positions, b.faces) == pytest.approx(np.prod(hi - lo))
    centroids = b.positions[b.faces].mean(1)
    assert np.all(np.einsum("ij,ij->i", face_normals(b.positions, b.faces), centroids - (lo + hi) / 2) > 0)
    # Part labels name the side: its normal is that axis direction.
    for side, name in enumerate(BOX_SIDES):
        axis = np.zeros(3)
        axis["xyz".index(name[1])] = 1 if name[0] == "+" else -1
        np.testing.assert_allclose(
            face_normals(b.positions, b.faces[b.part == side]), np.tile(axis, ((b.part == side).sum(), 1)), atol=1e-12
        )


def test_box_can_leave_sides_out():
    full, open_box = box([0, 0, 0], [1, 1, 1]), box([0, 0, 0], [1, 1, 1], omit=("-y", "+x"))
    assert len(open_box.faces) == len(full.faces) - 4
    assert not np.isin([BOX_SIDES.index("-y"), BOX_SIDES.index("+x")], open_box.part).any()


def test_cylinder_is_closed_and_faces_outwards():
    r, h, n = 0.4, 1.2, 20
    c = cylinder(r, h, n, rings=3)
    assert_closed_and_consistent(c.faces)
    prism = 0.5 * n * r * r * np.sin(2 * np.pi / n) * h
    assert signed_volume(c.positions, c.faces) == pytest.approx(prism)
    normals = face_normals(c.positions, c.faces)
    centroids = c.positions[c.faces].mean(1)
    side = c.part == 0
    radial = centroids[side] * [1, 0, 1]
    assert np.all(np.einsum("ij,ij->i", normals[side], radial) > 0)
    assert np.all(normals[c.part == 1][:, 1] > 0.999) and np.all(normals[c.part == 2][:, 1] < -0.999)
    assert c.positions[:, 1].min() == pytest.approx(-h / 2) and c.positions[:, 1].max() == pytest.approx(h / 2)


def test_quads_face_along_edge_u_cross_edge_v():
    g = grid_quad([0, 0, 0], [2, 0, 0], [0, 0, -1], nu=4, nv=3)
    assert len(g.faces) == 24
    np.testing.assert_allclose(face_normals(g.positions, g.faces), np.tile([0, 1, 0], (24, 1)), atol=1e-12)
    q = quad([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]])
    np.testing.assert_allclose(face_normals(q.positions, q.faces), [[0, 0, 1], [0, 0, 1]])


@pytest.mark.parametrize("axis", [0, 1, 2])
@pytest.mark.parametrize("facing", [1, -1])
def test_axis_grid_faces_and_holes(axis, facing):
    label = lambda a, b: np.where((a > 1) & (a < 2) & (b > 1) & (b < 2), -1, 0)  # one hole
    g = axis_grid(axis, 0.5, facing, [0, 1, 2, 3], [0, 1, 2, 3], label=label)
    assert len(g.faces) == 2 * 8
    expected = np.zeros(3)
    expected[axis] = facing
    np.testing.assert_allclose(face_normals(g.positions, g.faces), np.tile(expected, (16, 1)), atol=1e-12)
    assert np.all(g.positions[:, axis] == 0.5)


def test_breaks_include_hole_edges_without_slivers():
    b = subdivide_breaks(-2, 2, 0.25, extra=[-0.8, 0.8])
    assert b[0] == -2 and b[-1] == 2 and -0.8 in b and 0.8 in b
    # A regular break next to a hole edge is dropped: cells between 0.3 and 1.3 of the nominal size.
    assert np.diff(b).min() >= 0.3 * 0.25 - 1e-12 and np.diff(b).max() <= 1.3 * 0.25 + 1e-12
