"""In-memory scene types shared by every stage.

Arrays are numpy, float32 unless said otherwise. See docs/renderer.md for the conventions
(texture orientation, cube map layout, camera axes).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

ATLAS_MAPS = ("kd", "ks", "ka", "ke", "kw")
MAP_CHANNELS = {"kd": 3, "ks": 3, "ka": 1, "ke": 3, "kw": 1}
# All six maps, in the one order every list of them uses: scene files, the torch operation's
# arguments, the adjoint kernel's per-map scales and its atlas gradient channels (render/adjoint.py).
MAP_NAMES = (*ATLAS_MAPS, "kg")


class SceneError(ValueError):
    """Bad input: names the file, the field and what was expected, in one message."""

    def __init__(self, file, field: str, expected: str):
        self.file, self.field, self.expected = str(file), field, expected
        super().__init__(f"{file}: {field}: expected {expected}")

    def __reduce__(self):  # survives pickling (scene/isolate.py sends it from a child process)
        return type(self), (self.file, self.field, self.expected)


def require_positive(file, field: str, value, minimum: int = 1) -> int:
    """A count the user gave (samples per pixel, a batch size) as an int >= minimum, or the
    SceneError that names it: 0 or a negative count would write a black image or zero gradients."""
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < minimum:
        raise SceneError(file, field, f"an integer of at least {minimum}, got {value!r}")
    return int(value)


@dataclass
class Mesh:
    positions: np.ndarray  # (V, 3) float32, meters, +Y up
    faces: np.ndarray  # (F, 3) int32, counter-clockwise seen from the front
    uvs: np.ndarray  # (V, 2) float32 atlas coordinates in [0, 1], v up
    instance_ids: np.ndarray | None = None  # (F,) int32, 0 = no instance
    one_sided: np.ndarray | None = (
        None  # (F,) bool: emits only on its front (counter-clockwise) side; None = all two-sided
    )

    @property
    def triangle_count(self) -> int:
        return len(self.faces)


@dataclass
class Atlas:
    """MILO's five atlas maps of one material set, all of one (H, W)."""

    kd: np.ndarray  # (H, W, 3) diffuse albedo
    ks: np.ndarray  # (H, W, 3) specular albedo (reflectance at normal incidence)
    ka: np.ndarray  # (H, W) Beckmann alpha^2
    ke: np.ndarray  # (H, W, 3) emitted radiance
    kw: np.ndarray  # (H, W) window map in [0, 1]

    @property
    def atlas_shape(self) -> tuple[int, int]:
        return self.kd.shape[:2]

    @classmethod
    def uniform(cls, size=(64, 64), kd=0.5, ks=0.0, ka=0.1, ke=0.0, kw=0.0):
        h, w = size
        rgb = lambda value: np.broadcast_to(np.asarray(value, np.float32), (h, w, 3)).copy()
        one = lambda value: np.full((h, w), value, np.float32)
        return cls(kd=rgb(kd), ks=rgb(ks), ka=one(ka), ke=rgb(ke), kw=one(kw))


@dataclass
class Maps(Atlas):
    """MILO's six parameter maps: the atlas maps and kg, a (6, N, N, 3) cube map."""

    kg: np.ndarray  # (6, N, N, 3) outdoor radiance by direction

    @classmethod
    def uniform(cls, size=(64, 64), kd=0.5, ks=0.0, ka=0.1, ke=0.0, kw=0.0, kg=0.0, cube=8):
        atlas = Atlas.uniform(size, kd, ks, ka, ke, kw)
        kg_map = np.broadcast_to(np.asarray(kg, np.float32), (6, cube, cube, 3)).copy()
        return cls(**{name: getattr(atlas, name) for name in ATLAS_MAPS}, kg=kg_map)

    @property
    def atlas(self) -> Atlas:
        return Atlas(**{name: getattr(self, name) for name in ATLAS_MAPS})


@dataclass
class Camera:
    """A COLMAP camera with its pose: x_cam = R @ x_world + t, OpenCV axes."""

    name: str
    model: str  # PINHOLE, SIMPLE_PINHOLE or OPENCV
    width: int
    height: int
    params: np.ndarray  # COLMAP's parameter order for the model
    R: np.ndarray  # (3, 3) float64 world-to-camera rotation
    t: np.ndarray  # (3,) float64

    @property
    def focal(self) -> tuple[float, float]:
        p = self.params
        return (p[0], p[0]) if self.model == "SIMPLE_PINHOLE" else (p[0], p[1])

    @property
    def principal_point(self) -> tuple[float, float]:
        p = self.params
        return (p[1], p[2]) if self.model == "SIMPLE_PINHOLE" else (p[2], p[3])

    @property
    def distortion(self) -> np.ndarray:
        """OpenCV (k1, k2, p1, p2); zeros for the pinhole models."""
        return np.asarray(self.params[4:8] if self.model == "OPENCV" else np.zeros(4), np.float64)

    @property
    def center(self) -> np.ndarray:
        return -self.R.T @ self.t

    def world_to_camera(self) -> np.ndarray:
        m = np.eye(4)
        m[:3, :3], m[:3, 3] = self.R, self.t
        return m


EMISSION_SIDES = ("two", "one")  # an object's emission: from both sides (captured meshes), or its front only


@dataclass
class SceneObject:
    """One placement of a mesh in a v2 scene (docs/scene-format.md).

    The mesh is in the object's own frame with UVs in its material set's own atlas; `transform`
    takes it to the world. Objects that share a Mesh (the same Python object) and a material set
    are instances of one object: their texels are the same texels.
    """

    name: str
    mesh: Mesh
    material: str  # a key of the scene's material sets
    transform: np.ndarray = field(default_factory=lambda: np.eye(4))  # (4, 4) float64 object-to-world
    instance_id: int | None = None  # every face's instance id; None: the mesh's own (v1 scenes)
    emission_sides: str = "two"


@dataclass
class Scene:
    """What the renderer reads: one world-space mesh and one atlas (`mesh`, `maps`).

    A v2 scene (`objects` non-empty) also keeps its objects and the `packing` (scene/packing.py)
    that laid their material sets into `maps` and flattened them into `mesh`; its per-set maps
    are `packing.unpack_atlas(maps)`.
    """

    mesh: Mesh
    maps: Maps
    cameras: list[Camera] = field(default_factory=list)
    path: Path | None = None  # the scene directory it was loaded from, if any
    objects: list[SceneObject] = field(default_factory=list)
    packing: object | None = None  # scene.packing.Packing of a v2 scene

    @property
    def version(self) -> int:
        return 2 if self.objects else 1
