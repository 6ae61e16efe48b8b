"""Screened Poisson reconstruction of a noisy, holey point cloud of a known closed room box.

The fixture is sampled here: a 4 x 3 x 5 m box (a room, normals pointing inwards as seen from
inside), Gaussian position noise of 0.5% of its largest side (2.5 cm), and four spherical holes of
25 cm radius on walls, floor and ceiling (10x the mean point spacing).
"""

import time

import numpy as np
import pymeshlab
import pytest
from rooms import ROOM, sample_room
from scipy.spatial import cKDTree

from invrender.geometry.clean import mean_point_spacing, reconstruct

HOLES = np.array([[2.0, 1.5, 0.0], [0.0, 1.0, 2.5], [4.0, 2.0, 4.0], [1.0, 3.0, 1.0]])
HOLE_RADIUS = 0.25


def sample_surface(positions, faces, n, rng):
    corners = np.asarray(positions, np.float64)[faces]
    area = 0.5 * np.linalg.norm(np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0]), axis=1)
    tri = rng.choice(len(faces), size=n, p=area / area.sum())
    u = rng.random((n, 2))
    flip = u.sum(1) > 1
    u[flip] = 1 - u[flip]
    c = corners[tri]
    return c[:, 0] + u[:, :1] * (c[:, 1] - c[:, 0]) + u[:, 1:] * (c[:, 2] - c[:, 0])


def chamfer(a, b):
    """Symmetric mean nearest-neighbour distance between two dense samples."""
    return 0.5 * (cKDTree(b).query(a)[0].mean() + cKDTree(a).query(b)[0].mean())


def edge_use(faces):
    """How many faces use each undirected edge."""
    edges = np.sort(np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]]), axis=1)
    _, counts = np.unique(edges, axis=0, return_counts=True)
    return counts


def cloud_set(points, normals):
    ms = pymeshlab.MeshSet()
    ms.add_mesh(pymeshlab.Mesh(vertex_matrix=points, v_normals_matrix=normals))
    return ms


@pytest.fixture(scope="module")
def holey_room():
    rng = np.random.default_rng(1)
    clean, normals = sample_room(40_000, rng)
    keep = np.all(np.linalg.norm(clean[:, None] - HOLES[None], axis=2) > HOLE_RADIUS, axis=1)
    noisy = clean + rng.normal(scale=0.005 * ROOM.max(), size=clean.shape)
    ms = cloud_set(noisy[keep], normals[keep])
    start = time.perf_counter()
    report = reconstruct(ms, depth=8, threads=1)
    seconds = time.perf_counter() - start
    mesh = ms.current_mesh()
    return dict(
        positions=mesh.vertex_matrix(), faces=mesh.face_matrix(), report=report, seconds=seconds, points=int(keep.sum())
    )


def test_reconstruction_is_watertight_enough(holey_room):
    """Watertight enough: under 1% of edges are boundary edges (used by one face) and no edge is
    used by more than two faces. Poisson closes the 25 cm holes; trimming must not reopen them."""
    use = edge_use(holey_room["faces"])
    boundary = (use == 1).mean()
    print(
        f"\n{holey_room['points']} points -> {len(holey_room['faces'])} faces in {holey_room['seconds']:.1f} s; "
        f"boundary edges {100 * boundary:.3f}% of {len(use)}, non-manifold {(use > 2).sum()}"
    )
    assert boundary < 0.01
    assert (use > 2).sum() == 0


def test_reconstruction_is_close_to_the_room(holey_room):
    """Symmetric mean Chamfer distance under 0.5% of the room's diagonal (7.07 m: 3.5 cm), on
    200k samples of each surface; and each hole is covered by the surface."""
    rng = np.random.default_rng(2)
    truth, _ = sample_room(200_000, rng)
    surface = sample_surface(holey_room["positions"], holey_room["faces"], 200_000, rng)
    diagonal = float(np.linalg.norm(ROOM))
    distance = chamfer(truth, surface)
    print(f"\nChamfer {distance * 100:.2f} cm = {100 * distance / diagonal:.3f}% of the diagonal")
    assert distance < 0.005 * diagonal
    near_hole = cKDTree(surface).query(HOLES)[0]
    print(f"surface to hole centres: {np.round(near_hole * 100, 1)} cm")
    assert near_hole.max() < 0.1  # an open hole would leave its centre ~25 cm from the surface


def test_trim_distance_is_ten_point_spacings(holey_room):
    report = holey_room["report"]
    assert report["trim_distance_m"] == pytest.approx(10 * report["mean_point_spacing_m"])
    # 40k points over 94 m^2, 2.5 cm noise: the nearest-neighbour spacing is a few centimetres
    assert 0.02 < report["mean_point_spacing_m"] < 0.06


def test_missing_ceiling_is_trimmed_not_a_blob():
    """A room scanned without its ceiling: untrimmed, Poisson closes the top with a dome that
    rises about a meter above the walls; trimmed, nothing is farther than the trim distance from the
    points, so the walls end within about that distance above their top (2.9 m)."""
    rng = np.random.default_rng(3)
    points, normals = sample_room(30_000, rng)
    points += rng.normal(scale=0.01, size=points.shape)
    keep = points[:, 1] < 2.9
    ms = cloud_set(points[keep], normals[keep])
    report = reconstruct(ms, depth=7, threads=1)
    top = float(ms.current_mesh().vertex_matrix()[:, 1].max())
    trimmed = report["removed"]["trimmed_far_from_points"]["faces"]
    print(
        f"\ntrimmed {trimmed} of {report['poisson_faces']} faces; top of the surface {top:.2f} m, "
        f"trim distance {report['trim_distance_m']:.2f} m"
    )
    assert trimmed > 0
    assert top < 2.9 + 1.2 * report["trim_distance_m"]


def test_mean_point_spacing_of_a_grid():
    """A 1 cm grid: every point's nearest neighbour is 1 cm away."""
    g = np.stack(np.meshgrid(np.arange(100), np.arange(100), indexing="ij"), -1).reshape(-1, 2) * 0.01
    points = np.column_stack([g, np.zeros(len(g))])
    assert mean_point_spacing(points, chunk=1000) == pytest.approx(0.01, rel=1e-6)
