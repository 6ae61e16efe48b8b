"""Crop pairs: the largest rectangle against brute force, the greedy disjoint crops, the trim of
slivers, and user pairs' errors."""

import numpy as np
import pytest

from invrender.room_materials.crops import Rect, crop_rectangles, largest_rectangle, user_pairs
from invrender.scene.types import SceneError


def _brute(mask):
    best = 0
    h, w = mask.shape
    for y0 in range(h):
        for x0 in range(w):
            for y1 in range(y0 + 1, h + 1):
                for x1 in range(x0 + 1, w + 1):
                    if mask[y0:y1, x0:x1].all():
                        best = max(best, (y1 - y0) * (x1 - x0))
    return best


@pytest.mark.parametrize("seed", range(6))
def test_largest_rectangle_is_the_brute_force_maximum(seed):
    rng = np.random.default_rng(seed)
    mask = rng.random((7, 9)) > 0.25
    r = largest_rectangle(mask)
    assert r.area == _brute(mask)
    assert r.cut(mask).all()


def test_crops_are_disjoint_inside_and_trimmed():
    mask = np.zeros((120, 200), bool)
    mask[10:90, 20:100] = True  # an 80 x 80 square
    mask[100:118, 10:190] = True  # a sliver, 18 high: too thin for min_side 24
    mask[20:70, 120:190] = True  # 50 x 70
    rects = crop_rectangles(mask, count=3, min_side=24, erosion=0)
    assert [r.area for r in rects] == sorted((r.area for r in rects), reverse=True)
    assert rects[0] == Rect(20, 10, 80, 80)
    assert rects[1] == Rect(120, 20, 70, 50)
    assert len(rects) == 2
    taken = np.zeros_like(mask, int)
    for r in rects:
        assert r.cut(mask).all()
        taken[r.y : r.y + r.h, r.x : r.x + r.w] += 1
    assert taken.max() == 1
    long = np.zeros((40, 250), bool)
    long[5:35, :] = True
    (r,) = crop_rectangles(long, count=1, min_side=8, erosion=0)
    assert r.h == 30 and r.w == 75 and r.x == (250 - 75) // 2  # at most 2.5 times as long as high


def test_user_pairs():
    (pair,) = user_pairs([{"part": "floor", "photo": [4, 5, 20, 10]}], ["floor"], (64, 48))
    assert pair.photo == pair.render == Rect(4, 5, 20, 10) and pair.source == "user"
    with pytest.raises(SceneError, match="material parts"):
        user_pairs([{"part": "sofa", "photo": [0, 0, 10, 10]}], ["floor"], (64, 48))
    with pytest.raises(SceneError, match="inside the 64 x 48"):
        user_pairs([{"part": "floor", "photo": [60, 0, 10, 10]}], ["floor"], (64, 48))
