"""tracks.py: one fixed set of keypoints per copy, matched at a given turn.

The copies are test_matching's textured crop and the same crop turned by OpenCV about its centre
(independent of matching.py's warp), so every pixel's true correspondence is known; what is
tested is that the matches are right at the true turn and that every match lands on its copies'
own fixed keypoints, so that three copies share points (tracks of three)."""

import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).parent))
from test_matching import true_xy_a, turned_crop  # noqa: E402

from invrender.duplicates import tracks  # noqa: E402
from invrender.duplicates.matching import rotate_points  # noqa: E402

TURNS = {1: 0.0, 2: 110.0, 3: 200.0}  # instance id: its turn (degrees, counter-clockwise on screen)


@pytest.fixture(scope="module")
def features():
    return {i: tracks.detect(turned_crop(t, i), max_keypoints=512) for i, t in TURNS.items()}


@pytest.fixture(scope="module")
def pairs(features):
    # the angle that turns b onto a is b's turn minus a's (test_matching: a = R(theta) b)
    angles = {(a, b): TURNS[b] - TURNS[a] for a, b in [(1, 2), (1, 3), (2, 3)]}
    return tracks.match_pairs(features, angles)


def test_matches_at_the_true_turn_are_the_true_correspondences(pairs):
    """Right to XFeat's repeatability: each copy's keypoints are detected on its own pixels, and
    the same corner is found about 2 px apart in the crop and its turned copy (median 2.3 px here;
    the search's matches at the exact turn see the same image twice and agree to 0.0 px)."""
    for (a, b), (xy_a, xy_b) in pairs.items():
        # b's points taken back to the upright crop, then into a's turn
        upright = true_xy_a(xy_b, TURNS[b])
        truth = rotate_points(upright, -TURNS[a], (80, 80), (80, 80))
        error = np.linalg.norm(xy_a - truth, axis=1)
        assert len(error) >= 40, (a, b, len(error))
        assert np.median(error) < 3.0 and np.mean(error < 4.5) >= 0.9, (a, b, np.percentile(error, [50, 90]))


def test_every_match_lands_on_its_copies_fixed_keypoints(features, pairs):
    for (a, b), (xy_a, xy_b) in pairs.items():
        for i, xy in ((a, xy_a), (b, xy_b)):
            own = {tuple(p) for p in features[i].crop.to_full(features[i].keypoints)}
            assert all(tuple(p) in own for p in xy), (a, b, i)


def test_three_copies_share_points(pairs):
    """A keypoint of copy 2 matched to copy 1 and to copy 3 is one point seen three times: the
    two pairs name it by the same coordinates, so COLMAP chains them into a track of three."""
    via_1 = {tuple(p) for p in pairs[1, 2][1]}
    via_3 = {tuple(p) for p in pairs[2, 3][0]}
    assert len(via_1 & via_3) >= 20, len(via_1 & via_3)


def _off(angle, truth):
    return abs((angle - truth + 180.0) % 360.0 - 180.0)


@pytest.fixture(scope="module")
def curves(features):
    return tracks.search_angles(features, [(1, 2), (1, 3), (2, 3)])


def test_the_search_on_fixed_keypoints_peaks_at_the_true_turn(curves):
    """Mutual nearest neighbours of the copies' own descriptors, per angle: the count's peak is
    within one and a half steps (12 degrees) of the true turn (copy 2: 120 for 110), and well above
    the angles half a turn away."""
    for (a, b), (grid, counts) in curves.items():
        truth = TURNS[b] - TURNS[a]
        peak = grid[int(np.argmax(counts))]
        assert _off(peak, truth) <= 1.5 * tracks.SEARCH_STEP_DEG, (a, b, peak, truth)
        far = counts[[_off(g, truth) > 90 for g in grid]]
        assert counts.max() >= 5 * max(1, far.max()), (a, b, counts.max(), far.max())


def test_rematch_keeps_the_angle_with_more_matches(features, curves):
    """Given a crop search that chose the wrong half-turn, rematch matches at the fixed keypoints'
    peak as well and keeps it: its matches are the true correspondences."""
    wrong = {(a, b): TURNS[b] - TURNS[a] + 180.0 for a, b in curves}
    found, chosen = tracks.rematch(features, wrong, curves)
    for (a, b), angle in chosen.items():
        assert _off(angle, TURNS[b] - TURNS[a]) <= 1.5 * tracks.SEARCH_STEP_DEG, (a, b, angle)
        xy_a, xy_b = found[a, b]
        truth = rotate_points(true_xy_a(xy_b, TURNS[b]), -TURNS[a], (80, 80), (80, 80))
        assert np.median(np.linalg.norm(xy_a - truth, axis=1)) < 3.0, (a, b)
