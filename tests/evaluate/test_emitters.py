"""Lamp-by-lamp emitted power (evaluate/emitters.py) on hand-made surfaces with known answers."""

import numpy as np

from invrender.evaluate.emitters import emitter_powers, lamp_labels


def _ceiling(n: int = 40) -> np.ndarray:
    """(n n, 3) points 0.1 m apart on a plane: the corresponded surface points."""
    x, z = np.meshgrid(np.arange(n) * 0.1, np.arange(n) * 0.1)
    return np.stack([x.ravel(), np.full(n * n, 2.5), z.ravel()], -1)


def _patch(points, x0, z0, size=0.3):
    return (np.abs(points[:, 0] - x0) < size / 2) & (np.abs(points[:, 2] - z0) < size / 2)


def test_two_lamps_are_told_apart_and_each_scored_by_the_power_near_it():
    points = _ceiling()
    true = np.zeros((len(points), 3))
    lamp_a, lamp_b = _patch(points, 1.0, 1.0), _patch(points, 3.0, 3.0)
    true[lamp_a], true[lamp_b] = 10.0, 5.0
    labels = lamp_labels(points, true.sum(-1) > 0, 0.1)
    assert len(set(labels[lamp_a])) == 1 and len(set(labels[lamp_b])) == 1 and labels[lamp_a][0] != labels[lamp_b][0]
    recovered = np.zeros_like(true)
    shifted = _patch(points, 1.1, 1.0)  # lamp A recovered one texel over, at 90 % of its radiance
    recovered[shifted] = 9.0
    recovered[_patch(points, 0.5, 3.5, 0.1)] = 1.0  # a glow far from both lamps
    result = emitter_powers(recovered, true, points)
    ratios = {round(r["center"][0], 1): r["ratio"] for r in result["lamps"]}
    np.testing.assert_allclose(ratios[1.0], 0.9 * shifted.sum() / lamp_a.sum())
    assert ratios[3.0] == 0.0  # lamp B was not found
    assert result["worst_ratio_error"] == 1.0
    np.testing.assert_allclose(result["stray_share"], 3.0 / true.sum())


def test_no_truth_emission_gives_none():
    points = _ceiling(5)
    assert emitter_powers(np.ones((25, 3)), np.zeros((25, 3)), points) is None
