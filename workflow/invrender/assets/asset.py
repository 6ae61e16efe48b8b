"""An asset: one piece of furniture as a triangle mesh with named parts, unit-normalised.

Unit-normalised (docs/assets.md, ROOM_API.md): standing on y = 0, the footprint's bounding box
centred at the origin in x and z, the largest extent 1. Its front (a chair's seat, a cabinet's
doors, a sofa's cushions) faces +z, so a yaw of 0 places it facing +z in the room.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .primitives import Primitive, concatenate

__all__ = ["Asset", "PartBuilder", "normalised"]


@dataclass(frozen=True, eq=False)
class Asset:
    name: str  # unique in a library: "chair_a", "user/chairs/eames"
    category: str  # "chair", "table", ... (procedural) or the user's folder or file name
    mesh: Primitive  # unit-normalised; mesh.part indexes part_names
    part_names: tuple[str, ...]  # material ids: "legs", "seat", "shade", ...
    nominal_size: float  # meters: the real object's largest extent (the unit mesh's scale)
    # Rotations about +Y that map the shape onto itself, for the azimuth's ambiguity: 1 none,
    # 2 half turns (a rectangular table), 4 quarter turns (a square one), 0 any (a round lamp).
    symmetry: int = 1
    emissive_parts: tuple[str, ...] = ()  # parts that emit (a lamp's shade)
    source: str = "procedural"  # "procedural" or the file it was read from

    @property
    def extent(self) -> np.ndarray:
        """(3,) the unit mesh's bounding-box size, the largest entry 1."""
        p = self.mesh.positions
        return p.max(axis=0) - p.min(axis=0)

    def part_faces(self, part_name: str) -> np.ndarray:
        """Indices of the faces of one part."""
        return np.flatnonzero(self.mesh.part == self.part_names.index(part_name))


def normalised(mesh: Primitive) -> tuple[Primitive, float]:
    """The mesh moved onto y = 0 with its footprint centred at the origin and scaled to a
    largest extent of 1; and that extent before scaling (its size in the mesh's units)."""
    p = np.asarray(mesh.positions, np.float64)
    lo, hi = p.min(axis=0), p.max(axis=0)
    size = float((hi - lo).max())
    if not np.isfinite(size) or size <= 0:
        raise ValueError(f"normalised: a mesh with extent {hi - lo} has no size")
    offset = np.array([0.5 * (lo[0] + hi[0]), lo[1], 0.5 * (lo[2] + hi[2])])
    return Primitive((p - offset) / size, mesh.faces, mesh.part), size


class PartBuilder:
    """Collects primitives under part names (the part id is the name's order of first use)."""

    def __init__(self):
        self.names: list[str] = []
        self.pieces: list[Primitive] = []

    def add(self, part_name: str, piece: Primitive) -> None:
        if part_name not in self.names:
            self.names.append(part_name)
        pid = self.names.index(part_name)
        self.pieces.append(Primitive(piece.positions, piece.faces, np.full(len(piece.faces), pid, np.int32)))

    def asset(self, name: str, category: str, symmetry: int = 1, emissive_parts=()) -> Asset:
        mesh, size = normalised(concatenate(self.pieces))
        return Asset(name, category, mesh, tuple(self.names), size, symmetry, tuple(emissive_parts))
