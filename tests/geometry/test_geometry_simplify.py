"""Quadric simplification lands within 5% of the target face count, and keeps smaller meshes."""

import time

import numpy as np
import pymeshlab
import pytest

from invrender.geometry.clean import simplify


@pytest.fixture(scope="module")
def dense_torus():
    """A 100,000-face torus (1 m / 0.35 m radii) with 2 mm vertex noise, so that the collapse
    has real choices to make."""
    ms = pymeshlab.MeshSet()
    ms.create_torus(hradius=1.0, vradius=0.35, hsubdiv=250, vsubdiv=200)
    mesh = ms.current_mesh()
    rng = np.random.default_rng(0)
    positions = mesh.vertex_matrix() + rng.normal(scale=0.002, size=(mesh.vertex_number(), 3))
    return positions, mesh.face_matrix()


@pytest.mark.parametrize("target", [20_000, 5_000])
def test_simplify_lands_within_five_percent(dense_torus, target):
    positions, faces = dense_torus
    assert len(faces) == 100_000
    ms = pymeshlab.MeshSet()
    ms.add_mesh(pymeshlab.Mesh(positions, faces))
    start = time.perf_counter()
    report = simplify(ms, target)
    seconds = time.perf_counter() - start
    got = ms.current_mesh().face_number()
    print(f"\n100000 -> {got} faces (target {target}) in {seconds:.2f} s, {report['passes']} pass(es)")
    assert abs(got - target) <= 0.05 * target
    assert report == {"target_faces": target, "faces_before": 100_000, "faces_after": got, "passes": report["passes"]}
    topology = ms.get_topological_measures()
    assert topology["genus"] == 1 and topology["boundary_edges"] == 0  # still a closed torus
    # the surface stays on the torus: every vertex within 1 cm of the tube's surface
    v = ms.current_mesh().vertex_matrix()
    ring = np.hypot(v[:, 0], v[:, 1]) if np.ptp(v[:, 2]) < np.ptp(v[:, 1]) else np.hypot(v[:, 0], v[:, 2])
    axis = v[:, 2] if np.ptp(v[:, 2]) < np.ptp(v[:, 1]) else v[:, 1]
    tube = np.abs(np.hypot(ring - 1.0, axis) - 0.35)
    assert tube.max() < 0.01


def test_simplify_keeps_a_mesh_below_the_target(caplog):
    ms = pymeshlab.MeshSet()
    ms.create_sphere(subdiv=3)  # 1280 faces
    before = ms.current_mesh().face_matrix().copy()
    with caplog.at_level("INFO"):
        report = simplify(ms, 5000)
    assert report["faces_after"] == report["faces_before"] == 1280 and report["passes"] == 0
    assert np.array_equal(ms.current_mesh().face_matrix(), before)
    assert "kept as is" in caplog.text
