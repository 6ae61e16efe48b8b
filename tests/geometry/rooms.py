"""Point clouds sampled from a known room box, shared by the geometry tests."""

import numpy as np

ROOM = np.array([4.0, 3.0, 5.0])


def sample_room(n, rng, room=ROOM):
    """n points uniformly on the box's six sides, with inward normals."""
    sides = [(axis, side) for axis in range(3) for side in (0, 1)]
    areas = np.array([np.prod(np.delete(room, axis)) for axis, _ in sides])
    which = rng.choice(len(sides), size=n, p=areas / areas.sum())
    points = rng.random((n, 3)) * room
    normals = np.zeros((n, 3))
    for k, (axis, side) in enumerate(sides):
        sel = which == k
        points[sel, axis] = side * room[axis]
        normals[sel, axis] = -1.0 if side else 1.0
    return points, normals
