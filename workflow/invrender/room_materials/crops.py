"""Crop pairs (PSDR-Room section 4.4): for a material part, the rectangles of largest area inside
the intersection of its photo mask (the panoptic segment it shows in) and its rendered mask (the
assembled scene's part, from the triangle-id AOV at the photo's camera). The same window cut from
the photo and from the render is a pair; the Gram loss compares the two without needing pixel
alignment, and a rectangle, unlike a masked region, needs no case-dependent erosion (the paper).

Users may give their own pairs (the paper's section 5, "semi-auto"): a part and a window in the
photo and one in the render, which need not be the same.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from ..scene.types import SceneError

__all__ = ["Rect", "CropPair", "largest_rectangle", "crop_rectangles", "user_pairs"]

# The rectangle search runs on masks reduced to at most this width (a block counts only when
# every pixel in it is inside): the search is O(H W) in Python, and the largest rectangles of a
# room photo are tens of pixels on a side, far above a block's 4 pixels at 1024 wide.
SEARCH_WIDTH = 256
MAX_ASPECT = 2.5  # a crop's longer side over its shorter, at most


@dataclass(frozen=True)
class Rect:
    """Pixels [x, x + w) x [y, y + h) of the photo, arrays indexed [y, x]."""

    x: int
    y: int
    w: int
    h: int

    @property
    def area(self) -> int:
        return self.w * self.h

    def cut(self, image: np.ndarray) -> np.ndarray:
        return image[self.y : self.y + self.h, self.x : self.x + self.w]

    def to_json(self) -> list[int]:
        return [self.x, self.y, self.w, self.h]


@dataclass(frozen=True)
class CropPair:
    part: str
    photo: Rect  # the window in the photo
    render: Rect  # the window in the render (the same one unless a user says otherwise)
    source: str = "auto"  # "auto" or "user"

    def to_json(self) -> dict:
        return {
            "part": self.part,
            "photo": self.photo.to_json(),
            "render": self.render.to_json(),
            "source": self.source,
        }


def largest_rectangle(mask: np.ndarray) -> Rect | None:
    """The axis-aligned rectangle of most pixels, all True (the histogram-stack method: each row's
    run lengths upwards are a histogram whose largest rectangle is found in one pass)."""
    mask = np.asarray(mask, bool)
    h, w = mask.shape
    heights = np.zeros(w + 1, np.int64)  # a zero sentinel at the end empties the stack
    best = (0, None)
    for row in range(h):
        heights[:w] = np.where(mask[row], heights[:w] + 1, 0)
        if not heights[:w].any():
            continue
        stack: list[int] = []
        for col in range(w + 1):
            while stack and heights[stack[-1]] >= heights[col]:
                top = stack.pop()
                left = stack[-1] + 1 if stack else 0
                area = int(heights[top]) * (col - left)
                if area > best[0]:
                    best = (area, Rect(left, row - int(heights[top]) + 1, col - left, int(heights[top])))
            stack.append(col)
    return best[1]


def _trim(r: Rect, aspect: float) -> Rect:
    """The rectangle's middle, at most ``aspect`` times as long as it is wide: a texture
    descriptor of a sliver (a strip of floor along a wall) sees few periods one way."""
    if r.w > aspect * r.h:
        w = max(1, int(aspect * r.h))
        return Rect(r.x + (r.w - w) // 2, r.y, w, r.h)
    if r.h > aspect * r.w:
        h = max(1, int(aspect * r.w))
        return Rect(r.x, r.y + (r.h - h) // 2, r.w, h)
    return r


def _blocks(mask: np.ndarray, factor: int) -> np.ndarray:
    """True where a whole factor x factor block is inside the mask."""
    if factor == 1:
        return mask
    h, w = (mask.shape[0] // factor) * factor, (mask.shape[1] // factor) * factor
    m = mask[:h, :w].reshape(h // factor, factor, w // factor, factor)
    return m.all(axis=(1, 3))


def crop_rectangles(
    mask: np.ndarray, count: int = 3, min_side: int = 16, min_fraction: float = 0.25, erosion: int = 1
) -> list[Rect]:
    """Up to ``count`` disjoint rectangles inside ``mask``, largest first: the largest, then the
    largest of what is left, while a rectangle has both sides of at least ``min_side`` pixels and
    at least ``min_fraction`` of the first one's area. The mask is eroded by ``erosion`` pixels
    first (a border pixel mixes two surfaces)."""
    mask = np.asarray(mask, bool)
    if erosion > 0 and mask.any():
        mask = cv2.erode(mask.astype(np.uint8), np.ones((2 * erosion + 1,) * 2, np.uint8)).astype(bool)
    factor = max(1, -(-mask.shape[1] // SEARCH_WIDTH))
    small = _blocks(mask, factor).copy()
    rects: list[Rect] = []
    while len(rects) < count:
        r = largest_rectangle(small)
        if r is None:
            break
        r = _trim(r, MAX_ASPECT)
        full = Rect(r.x * factor, r.y * factor, r.w * factor, r.h * factor)
        if min(full.w, full.h) < min_side or (rects and full.area < min_fraction * rects[0].area):
            break
        rects.append(full)
        small[r.y : r.y + r.h, r.x : r.x + r.w] = False
    return rects


def _rect(value, where: str, size: tuple[int, int]) -> Rect:
    """A user's [x, y, w, h] inside an image of ``size`` = (W, H)."""
    try:
        x, y, w, h = (int(v) for v in value)
    except (TypeError, ValueError):
        raise SceneError("config", where, f"[x, y, width, height] in pixels, got {value!r}") from None
    if w < 8 or h < 8 or x < 0 or y < 0 or x + w > size[0] or y + h > size[1]:
        raise SceneError(
            "config", where, f"a window of at least 8 x 8 pixels inside the {size[0]} x {size[1]} photo, got {value!r}"
        )
    return Rect(x, y, w, h)


def user_pairs(entries, parts, size: tuple[int, int]) -> list[CropPair]:
    """The config's crop pairs: [{"part": name, "photo": [x, y, w, h], "render": [x, y, w, h]
    (default the photo's window)}], ``parts`` the part names there are."""
    out = []
    for k, entry in enumerate(entries or ()):
        where = f"room_materials.crops[{k}]"
        if not isinstance(entry, dict) or "part" not in entry or "photo" not in entry:
            raise SceneError("config", where, f"{{part, photo: [x, y, w, h], render (optional)}}, got {entry!r}")
        if entry["part"] not in parts:
            raise SceneError(
                "config", f"{where}.part", f"one of the scene's material parts {sorted(parts)}, got {entry['part']!r}"
            )
        photo = _rect(entry["photo"], f"{where}.photo", size)
        render = _rect(entry.get("render", entry["photo"]), f"{where}.render", size)
        out.append(CropPair(entry["part"], photo, render, "user"))
    return out
