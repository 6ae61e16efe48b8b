"""Procedural furniture: parametric, seeded generators, several styles per category.

Each generator builds the piece in meters (+Y up, front towards +z) from closed boxes,
cylinders and frusta, one named part per material (legs, seat, top, shade, ...), then
unit-normalises it (asset.py). Every closed piece is wound outwards, so the union renders
without holes; pieces may touch or overlap (no booleans: a renderer needs only closed shells).

``furniture(category, variant)`` is deterministic: the variant picks a style (an armchair, a
round pedestal table, a bookcase) and seeds the dimensions within that style's real-world range.
``bundled()`` is the library's procedural part: ``VARIANTS`` of each category, named
``{category}_{a,b,c,d}``.
"""

from __future__ import annotations

import zlib

import numpy as np

from .asset import Asset, PartBuilder
from .primitives import Primitive, box, cylinder

__all__ = ["CATEGORIES", "VARIANTS", "furniture", "bundled", "variant_name"]

VARIANTS = 4
LETTERS = "abcdefghijklmnopqrstuvwxyz"


# ---------------------------------------------------------------- shapes, in meters


def block(cx, cz, width, depth, y0, y1) -> Primitive:
    """A box centred at (cx, cz) in the floor plane, from height y0 to y1."""
    return box([cx - width / 2, y0, cz - depth / 2], [cx + width / 2, y1, cz + depth / 2])


def slab(x0, x1, y0, y1, z0, z1) -> Primitive:
    return box([x0, y0, z0], [x1, y1, z1])


def frustum(cx, cz, r_bottom, r_top, y0, y1, segments=24) -> Primitive:
    """A closed truncated cone about +Y (a cylinder when the radii agree)."""
    can = cylinder(1.0, 1.0, segments)
    p = can.positions.copy()
    top = p[:, 1] > 0
    p[:, [0, 2]] *= np.where(top, r_top, r_bottom)[:, None]
    p[:, 1] = y0 + (p[:, 1] + 0.5) * (y1 - y0)
    p[:, 0] += cx
    p[:, 2] += cz
    return Primitive(p, can.faces, can.part)


def rod(cx, cz, radius, y0, y1, segments=12) -> Primitive:
    return frustum(cx, cz, radius, radius, y0, y1, segments)


def corners(half_x, half_z):
    return [(sx * half_x, sz * half_z) for sx in (-1, 1) for sz in (-1, 1)]


class Dims:
    """Seeded draws of dimensions: ``d(lo, hi)`` is uniform in [lo, hi)."""

    def __init__(self, seed: int):
        self.rng = np.random.default_rng(seed)

    def __call__(self, lo: float, hi: float) -> float:
        return float(self.rng.uniform(lo, hi))


# ---------------------------------------------------------------- categories


def chair(d: Dims, style: int) -> PartBuilder:
    """Styles: 0 solid back, 1 round legs + slatted back, 2 armchair, 3 tall slatted back."""
    w, dp, seat_y, seat_t, leg = d(0.42, 0.52), d(0.40, 0.50), d(0.42, 0.47), d(0.03, 0.06), d(0.03, 0.045)
    back_h = d(0.55, 0.7) if style == 3 else d(0.35, 0.5)
    b = PartBuilder()
    for cx, cz in corners(w / 2 - leg / 2 - 0.01, dp / 2 - leg / 2 - 0.01):
        b.add("legs", rod(cx, cz, leg / 2, 0, seat_y - seat_t) if style == 1 else block(cx, cz, leg, leg, 0, seat_y - seat_t))
    b.add("seat", block(0, 0, w, dp, seat_y - seat_t, seat_y))
    back_z = -dp / 2 + 0.01 + leg / 2
    top = seat_y + back_h
    for sx in (-1, 1):  # the back posts continue the back legs
        b.add("back", block(sx * (w / 2 - leg / 2 - 0.01), back_z, leg, leg, seat_y, top))
    inner = w - 2 * (leg + 0.01)
    if style in (0, 2):
        b.add("back", block(0, back_z, inner, 0.025, seat_y + 0.12, top))
    else:
        slats = 3 if style == 1 else 4
        for k in range(slats):
            y0 = seat_y + 0.12 + k * (back_h - 0.14) / slats
            b.add("back", block(0, back_z, inner, 0.02, y0, y0 + 0.05))
    if style == 2:
        arm_y = seat_y + d(0.2, 0.25)
        for sx in (-1, 1):
            x = sx * (w / 2 + 0.03)
            b.add("arms", block(x, 0, 0.05, dp, arm_y, arm_y + 0.03))
            b.add("arms", block(x, dp / 2 - 0.03, 0.04, 0.04, seat_y - seat_t, arm_y))
            b.add("arms", block(x, back_z, 0.04, 0.04, seat_y - seat_t, arm_y))
    return b


def table(d: Dims, style: int) -> tuple[PartBuilder, int]:
    """Styles: 0 rectangular with an apron, 1 rectangular on round legs, 2 square, 3 round on a
    pedestal. Returns the parts and the symmetry (2, 4 or 0)."""
    h, top_t = d(0.72, 0.77), d(0.03, 0.05)
    b = PartBuilder()
    if style == 3:
        radius = d(0.4, 0.6)
        b.add("top", rod(0, 0, radius, h - top_t, h, 32))
        b.add("legs", rod(0, 0, d(0.04, 0.07), 0.03, h - top_t, 16))
        b.add("legs", rod(0, 0, d(0.22, 0.3), 0, 0.03, 24))
        return b, 0
    w = d(0.8, 0.95) if style == 2 else d(1.2, 1.8)
    dp = w if style == 2 else d(0.7, 0.95)
    leg = d(0.04, 0.07)
    b.add("top", block(0, 0, w, dp, h - top_t, h))
    for cx, cz in corners(w / 2 - leg / 2 - 0.04, dp / 2 - leg / 2 - 0.04):
        b.add("legs", rod(cx, cz, leg / 2, 0, h - top_t) if style == 1 else block(cx, cz, leg, leg, 0, h - top_t))
    if style in (0, 2):
        apron = 0.08
        b.add("legs", block(0, 0, w - 2 * 0.04 - leg, dp - 2 * 0.04 - leg, h - top_t - apron, h - top_t))
    return b, 4 if style == 2 else 2


def drawer_stack(b: PartBuilder, cx, width, depth, y0, y1, front_z, drawers: int) -> None:
    """A pedestal with drawer fronts and handles on its +z face."""
    b.add("frame", slab(cx - width / 2, cx + width / 2, y0, y1, front_z - depth, front_z))
    gap = 0.006
    step = (y1 - y0 - 0.05) / drawers
    for k in range(drawers):
        lo = y0 + 0.05 + k * step
        b.add("drawers", slab(cx - width / 2 + gap, cx + width / 2 - gap, lo + gap, lo + step - gap, front_z, front_z + 0.018))
        mid = lo + 0.65 * step
        b.add("handles", slab(cx - 0.05, cx + 0.05, mid - 0.008, mid + 0.008, front_z + 0.018, front_z + 0.04))


def desk(d: Dims, style: int) -> PartBuilder:
    """Styles: 0 pedestal right + panel leg, 1 pedestal left + two legs, 2 two pedestals,
    3 four legs, a drawer under the top and a modesty panel."""
    w, dp, h, top_t = d(1.1, 1.6), d(0.55, 0.75), d(0.72, 0.76), d(0.025, 0.04)
    b = PartBuilder()
    b.add("top", block(0, 0, w, dp, h - top_t, h))
    ped_w, front = d(0.38, 0.45), dp / 2 - 0.03
    leg = 0.05
    side = {0: (1,), 1: (-1,), 2: (-1, 1), 3: ()}[style]
    for sx in side:
        drawer_stack(b, sx * (w / 2 - ped_w / 2 - 0.01), ped_w, dp - 0.06, 0, h - top_t, front, 3)
    if style == 0:
        b.add("frame", slab(-w / 2 + 0.01, -w / 2 + 0.04, 0, h - top_t, -dp / 2 + 0.03, front))
    if style == 1:
        for cz in (-dp / 2 + 0.05, front - 0.03):
            b.add("frame", block(w / 2 - 0.05, cz, leg, leg, 0, h - top_t))
    if style == 3:
        for cx, cz in corners(w / 2 - 0.05, dp / 2 - 0.05):
            b.add("frame", block(cx, cz, leg, leg, 0, h - top_t))
        drawer_stack(b, 0, 0.6, dp - 0.1, h - top_t - 0.14, h - top_t, front - 0.02, 1)
    if style != 2:  # the modesty panel at the back, between the supports
        b.add("frame", slab(-w / 2 + 0.05, w / 2 - 0.05, h - top_t - d(0.3, 0.4), h - top_t, -dp / 2 + 0.04, -dp / 2 + 0.06))
    return b


def cabinet(d: Dims, style: int) -> PartBuilder:
    """Styles: 0 low sideboard, 1 tall wardrobe, 2 bedside cabinet, 3 medium cupboard. A plinth
    recessed at the front, a top overhanging at the front and sides, doors with handles."""
    w, h = {0: (d(1.0, 1.4), d(0.7, 0.9)), 1: (d(0.8, 1.1), d(1.8, 2.0)), 2: (d(0.45, 0.55), d(0.5, 0.6)),
            3: (d(0.7, 0.9), d(1.0, 1.3))}[style]
    dp = d(0.35, 0.45) if style == 2 else d(0.45, 0.6)
    plinth, top_t = d(0.06, 0.1), 0.025
    b = PartBuilder()
    b.add("body", slab(-w / 2 + 0.02, w / 2 - 0.02, 0, plinth, -dp / 2, dp / 2 - 0.05))
    b.add("body", slab(-w / 2, w / 2, plinth, h - top_t, -dp / 2, dp / 2))
    b.add("body", slab(-w / 2 - 0.02, w / 2 + 0.02, h - top_t, h, -dp / 2, dp / 2 + 0.03))
    doors = 1 if w < 0.7 else 2
    door_w = (w - 0.01) / doors
    for k in range(doors):
        x0 = -w / 2 + 0.005 + k * door_w
        b.add("doors", slab(x0 + 0.003, x0 + door_w - 0.003, plinth + 0.01, h - top_t - 0.01, dp / 2, dp / 2 + 0.018))
        hx = x0 + (door_w - 0.06 if k == 0 and doors == 2 or doors == 1 else 0.06)
        hy = plinth + 0.55 * (h - top_t - plinth) if style != 1 else 1.0
        b.add("handles", slab(hx - 0.01, hx + 0.01, hy - 0.06, hy + 0.06, dp / 2 + 0.018, dp / 2 + 0.04))
    return b


def shelf(d: Dims, style: int) -> PartBuilder:
    """An open bookcase: two sides, top, bottom on a plinth, a back panel, evenly spaced
    shelves. Styles: 0 tall, 1 tall and wide, 2 low and wide, 3 narrow."""
    w, h = {0: (d(0.7, 0.9), d(1.7, 2.0)), 1: (d(1.0, 1.2), d(1.8, 2.0)), 2: (d(1.2, 1.6), d(0.75, 1.0)),
            3: (d(0.4, 0.5), d(1.2, 1.6))}[style]
    dp, t, plinth = d(0.26, 0.4), d(0.018, 0.026), d(0.05, 0.08)
    b = PartBuilder()
    for sx in (-1, 1):
        b.add("frame", slab(sx * w / 2 - (t if sx > 0 else 0), sx * w / 2 + (t if sx < 0 else 0), 0, h, -dp / 2, dp / 2))
    b.add("frame", slab(-w / 2 + t, w / 2 - t, h - t, h, -dp / 2, dp / 2))
    b.add("frame", slab(-w / 2 + t, w / 2 - t, 0, plinth + t, -dp / 2, dp / 2 - 0.015))
    b.add("back", slab(-w / 2 + t, w / 2 - t, plinth + t, h - t, -dp / 2, -dp / 2 + 0.008))
    count = max(1, int(round((h - plinth) / 0.35)) - 1)
    for k in range(1, count + 1):
        y = plinth + t + k * (h - t - plinth - t) / (count + 1)
        b.add("shelves", slab(-w / 2 + t, w / 2 - t, y - t / 2, y + t / 2, -dp / 2 + 0.008, dp / 2 - 0.01))
    return b


def bed(d: Dims, style: int) -> PartBuilder:
    """Styles: 0 single, 1 double, 2 king, 3 double with a footboard. The headboard is at -z."""
    w = {0: d(0.9, 1.0), 1: d(1.4, 1.6), 2: d(1.8, 2.0), 3: d(1.4, 1.6)}[style]
    length, leg_h, frame_top, mat_top = d(2.0, 2.1), d(0.06, 0.12), d(0.3, 0.36), d(0.5, 0.58)
    head_h, board_t = d(0.85, 1.15), 0.06
    b = PartBuilder()
    for cx, cz in corners(w / 2 - 0.04, length / 2 - 0.04):
        b.add("frame", block(cx, cz, 0.06, 0.06, 0, leg_h))
    b.add("frame", block(0, 0, w, length, leg_h, frame_top))
    b.add("mattress", block(0, 0.01, w - 0.04, length - 0.04, frame_top, mat_top))
    b.add("headboard", slab(-w / 2 - 0.02, w / 2 + 0.02, 0, head_h, -length / 2 - board_t, -length / 2))
    if style == 3:
        b.add("headboard", slab(-w / 2 - 0.02, w / 2 + 0.02, 0, d(0.5, 0.6), length / 2, length / 2 + board_t))
    pillows = 1 if w < 1.2 else 2
    pw = (w - 0.12) / pillows
    for k in range(pillows):
        cx = -w / 2 + 0.06 + (k + 0.5) * pw
        b.add("pillows", block(cx, -length / 2 + 0.25, pw - 0.06, 0.35, mat_top, mat_top + 0.12))
    return b


def sofa(d: Dims, style: int) -> PartBuilder:
    """Styles: 0 two-seat, 1 three-seat, 2 armchair, 3 armless three-seat. The back is at -z."""
    w = {0: d(1.5, 1.8), 1: d(2.0, 2.4), 2: d(0.8, 1.0), 3: d(1.8, 2.2)}[style]
    dp, leg_h, base_top, seat_top = d(0.8, 0.95), d(0.06, 0.12), d(0.28, 0.33), d(0.42, 0.47)
    back_t, back_top, arm_w, arm_top = d(0.15, 0.22), d(0.78, 0.92), d(0.1, 0.2), d(0.55, 0.66)
    arms = style != 3
    b = PartBuilder()
    for cx, cz in corners(w / 2 - 0.06, dp / 2 - 0.06):
        b.add("legs", block(cx, cz, 0.05, 0.05, 0, leg_h))
    b.add("frame", block(0, 0, w, dp, leg_h, base_top))
    b.add("frame", slab(-w / 2, w / 2, base_top, back_top, -dp / 2, -dp / 2 + back_t))
    inner = w / 2 - (arm_w if arms else 0)
    if arms:
        for sx in (-1, 1):
            b.add("frame", slab(sx * w / 2 - (arm_w if sx > 0 else 0), sx * w / 2 + (arm_w if sx < 0 else 0), base_top, arm_top, -dp / 2, dp / 2))
    seats = {0: 2, 1: 3, 2: 1, 3: 3}[style]
    cw = 2 * inner / seats
    for k in range(seats):
        x0 = -inner + k * cw
        b.add("cushions", slab(x0 + 0.005, x0 + cw - 0.005, base_top, seat_top, -dp / 2 + back_t, dp / 2))
    return b


def lamp(d: Dims, style: int) -> tuple[PartBuilder, int]:
    """A floor lamp: base, pole, emissive shade. Styles: 0 conical shade, 1 drum shade, 2 tall
    narrow shade, 3 square base and shade. Returns the parts and the symmetry (0 or 4)."""
    height, shade_h = d(1.35, 1.65), d(0.25, 0.35)
    b = PartBuilder()
    pole_top = height - 0.6 * shade_h
    if style == 3:
        base, shade = d(0.25, 0.32), d(0.3, 0.4)
        b.add("base", block(0, 0, base, base, 0, 0.03))
        b.add("pole", block(0, 0, 0.025, 0.025, 0.03, pole_top))
        b.add("shade", block(0, 0, shade, shade, height - shade_h, height))
        return b, 4
    b.add("base", rod(0, 0, d(0.12, 0.18), 0, d(0.02, 0.035), 24))
    b.add("pole", rod(0, 0, d(0.01, 0.015), 0.02, pole_top, 8))
    r_bottom = {0: d(0.2, 0.26), 1: d(0.18, 0.24), 2: d(0.11, 0.14)}[style]
    r_top = {0: 0.55 * r_bottom, 1: r_bottom, 2: 0.9 * r_bottom}[style]
    if style == 2:
        shade_h *= 1.6
    b.add("shade", frustum(0, 0, r_bottom, r_top, height - shade_h, height, 32))
    return b, 0


def generic_box(d: Dims, style: int) -> tuple[PartBuilder, int]:
    """The fallback: a closed box. Styles: 0 cube-like, 1 low and wide, 2 tall and narrow, 3 long."""
    w, h, dp = {0: (d(0.4, 0.6), d(0.4, 0.6), d(0.4, 0.6)), 1: (d(0.8, 1.2), d(0.25, 0.4), d(0.5, 0.7)),
                2: (d(0.3, 0.45), d(0.9, 1.3), d(0.3, 0.45)), 3: (d(1.2, 1.8), d(0.4, 0.6), d(0.3, 0.45))}[style]
    b = PartBuilder()
    b.add("body", block(0, 0, w, dp, 0, h))
    return b, 4 if abs(w - dp) < 0.02 * max(w, dp) else 2


# Each category's builder returns its parts, or (parts, symmetry) where the shape has one.
BUILDERS = {
    "chair": chair,
    "table": table,
    "desk": desk,
    "cabinet": cabinet,
    "shelf": shelf,
    "bed": bed,
    "sofa": sofa,
    "lamp": lamp,
    "box": generic_box,
}
CATEGORIES = tuple(BUILDERS)
EMISSIVE = {"lamp": ("shade",)}


def variant_name(category: str, variant: int) -> str:
    return f"{category}_{LETTERS[variant]}"


def furniture(category: str, variant: int = 0, seed: int | None = None) -> Asset:
    """One procedural asset. The style is ``variant % 4``; the dimensions are drawn from a
    generator seeded by ``seed`` (default: a hash of the name, so every run builds the same
    library)."""
    if category not in BUILDERS:
        raise ValueError(f"furniture: unknown category {category!r}; one of {', '.join(CATEGORIES)}")
    name = variant_name(category, variant)
    seed = zlib.crc32(name.encode()) if seed is None else seed
    built = BUILDERS[category](Dims(seed), variant % 4)
    parts, symmetry = built if isinstance(built, tuple) else (built, 1)
    return parts.asset(name, category, symmetry, EMISSIVE.get(category, ()))


def bundled(variants: int = VARIANTS, categories=CATEGORIES) -> list[Asset]:
    """``variants`` procedural assets of each category."""
    return [furniture(category, v) for category in categories for v in range(variants)]
