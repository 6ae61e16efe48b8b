"""The recovered emission against the truth's, in total and lamp by lamp.

Each lamp is a connected patch of the truth's emitting surface (its corresponded points within
a few texel spacings of each other); every recovered emitting point counts towards the lamp
nearest to it, so a lamp recovered a little larger or smaller than it is, or shifted by a texel,
is still scored by the power it gives the room. Emission far from every lamp is counted apart
("stray"): a glow on a wall is not a lamp's power.
"""

from __future__ import annotations

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components
from scipy.spatial import cKDTree

from ..scene.neighbours import point_spacing

LINK_SPACINGS = 3.0  # truth emitting points this many texel spacings apart belong to one lamp
NEAR_SPACINGS = 10.0  # recovered emission within this many texel spacings of a lamp is that lamp's
EMITTING = 1e-3  # ke (summed over RGB) above which a point emits


def emitted_power_ratio(recovered_ke, true_ke) -> float | None:
    """The surface's emission, recovered over true (summed over the corresponded texels, which
    sample the surface evenly, and the RGB channels); None where the truth emits nothing."""
    true_total = float(np.sum(true_ke))
    return float(np.sum(recovered_ke)) / true_total if true_total > 0 else None


def lamp_labels(points: np.ndarray, emitting: np.ndarray, spacing: float) -> np.ndarray:
    """(n,) int: each emitting point's lamp (0, 1, ...), -1 for points that do not emit."""
    labels = np.full(len(points), -1)
    at = np.flatnonzero(emitting)
    if not len(at):
        return labels
    pairs = cKDTree(points[at]).query_pairs(LINK_SPACINGS * spacing, output_type="ndarray")
    graph = coo_matrix((np.ones(len(pairs)), (pairs[:, 0], pairs[:, 1])), shape=(len(at), len(at)))
    labels[at] = connected_components(graph, directed=False)[1]
    return labels


def emitter_powers(recovered_ke, true_ke, points) -> dict | None:
    """Per lamp: its centre, true power and recovered power (summed ke, the points sampling the
    surface evenly) and their ratio; the largest |ratio - 1| over the lamps, and the stray
    recovered emission's share of the truth's total. None where the truth emits nothing."""
    recovered, true = np.asarray(recovered_ke).sum(-1), np.asarray(true_ke).sum(-1)
    spacing = point_spacing(points)
    labels = lamp_labels(points, true > EMITTING, spacing)
    if labels.max() < 0:
        return None
    lamps = np.flatnonzero(labels >= 0)
    distance, nearest = cKDTree(points[lamps]).query(points)
    owner = np.where(distance <= NEAR_SPACINGS * spacing, labels[lamps][nearest], -1)
    rows = []
    for lamp in range(labels.max() + 1):
        own = labels == lamp
        true_power, recovered_power = float(true[own].sum()), float(recovered[owner == lamp].sum())
        rows.append(
            {
                "center": points[own].mean(0).round(3).tolist(),
                "true_power": true_power,
                "recovered_power": recovered_power,
                "ratio": recovered_power / true_power,
            }
        )
    return {
        "lamps": rows,
        "worst_ratio_error": max(abs(r["ratio"] - 1.0) for r in rows),
        "stray_share": float(recovered[owner < 0].sum() / true.sum()),
    }
