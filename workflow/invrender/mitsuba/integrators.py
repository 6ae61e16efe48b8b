"""Mitsuba integrators that estimate what ours does: the same path length and Russian roulette."""

from __future__ import annotations


def rr_depth(max_bounces: int, roulette_depth: int = 0) -> int:
    """Mitsuba's rr_depth for our Features.roulette_depth (the same vertex: both decide after the
    BSDF sample of vertex rr_depth - 1, by the same rule); 0, no roulette: beyond the last bounce."""
    return int(roulette_depth) if roulette_depth else int(max_bounces) + 2


def path_integrator(max_bounces: int, roulette_depth: int = 0) -> dict:
    """Mitsuba's `path` for our B bounces: max_depth = B + 1, Russian roulette as ours."""
    return {
        "type": "path",
        "max_depth": int(max_bounces) + 1,
        "rr_depth": rr_depth(max_bounces, roulette_depth),
        "hide_emitters": False,
    }


def prb_integrator(max_bounces: int, roulette_depth: int = 0) -> dict:
    """Mitsuba's path replay backpropagation for B bounces: max_depth = B + 1, Russian roulette
    as ours (scene.rr_depth)."""
    return {"type": "prb", "max_depth": int(max_bounces) + 1, "rr_depth": rr_depth(max_bounces, roulette_depth)}
