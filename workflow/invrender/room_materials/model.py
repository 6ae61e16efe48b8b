"""The scene the material and light stage optimises: the assembled room's mesh and atlas, its
material parts (faces, the photo segments they show in, how their surface is laid out for a
procedural material) and its lights (faces), and the map writes that carry gradients.

Every part's material is a library material (invrender.materials; a homogeneous one is `plain`)
evaluated at its texels' surface coordinates (meters over `meters_per_unit`, along a plane for
the room box's surfaces, box mapping for objects), written into the atlas at the part's covered
texels and copied into the gutter around them (the renderer's nearest-texel lookup reads the
gutter at chart edges). The adjoint's map gradient (render/adjoint.py) comes back the same way:
a gutter texel's gradient is its source texel's, then a part's texel gradients go through the
torch evaluation to the material's parameters.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field

import numpy as np
import torch

from ..materials.bake import _surface_uv
from ..materials.base import Material, Transform
from ..materials.library import material as library_material
from ..scene.atlas import rasterize_atlas
from ..scene.types import Camera, Maps, Scene

__all__ = ["Part", "Light", "PartMaterial", "RoomModel", "crop_camera"]

GUTTER = 2  # texels a chart's values are copied into the gutter (the synthetic rooms bake with 2)


@dataclass
class Part:
    """One material part: the faces of the scene's mesh it covers, the photo segment ids it
    shows in, and its surface layout (`plane` = (origin, u axis, v axis) in meters, or None for
    box mapping)."""

    name: str
    faces: np.ndarray
    segments: tuple[int, ...]
    plane: tuple | None = None


@dataclass
class Light:
    """One light: its emitting faces and its RGB radiance."""

    name: str
    faces: np.ndarray
    radiance: np.ndarray
    kind: str = "light"


@dataclass
class PartMaterial:
    """A part's material: a library material type, its parameters (tensors), the transform and
    the surface length one material UV unit spans."""

    kind: str
    params: dict
    transform: Transform = field(default_factory=Transform)
    meters_per_unit: float = 1.0
    preset: str | None = None

    @property
    def material(self) -> Material:
        return library_material(self.kind)

    def to_json(self) -> dict:
        p = self.material.complete(self.params)
        values = {k: np.round(np.asarray(v.detach(), np.float64), 6).tolist() for k, v in p.items()}
        return {
            "kind": self.kind,
            "preset": self.preset,
            "params": values,
            "transform": {**self.transform.as_dict(), "scale": float(self.transform.scale)},
            "meters_per_unit": round(float(self.meters_per_unit), 6),
        }


def _sources(covered: np.ndarray, iterations: int) -> np.ndarray:
    """Per texel, the flat index of the covered texel it copies (itself if covered, a covered
    8-neighbour's source for up to ``iterations`` rings of gutter, else -1)."""
    h, w = covered.shape
    src = np.where(covered.ravel(), np.arange(h * w), -1).reshape(h, w)
    for _ in range(iterations):
        grown = src.copy()
        for dr in (-1, 0, 1):
            for dc in (-1, 0, 1):
                if dr == dc == 0:
                    continue
                dst = (slice(max(dr, 0), h + min(dr, 0)), slice(max(dc, 0), w + min(dc, 0)))
                s = (slice(max(-dr, 0), h + min(-dr, 0)), slice(max(-dc, 0), w + min(-dc, 0)))
                take = (grown[dst] < 0) & (src[s] >= 0)
                grown[dst][take] = src[s][take]
        src = grown
    return src.ravel()


class RoomModel:
    """The scene, its parts and lights, and where each part's and light's texels are."""

    def __init__(self, scene: Scene, parts: list[Part], lights: list[Light]):
        self.scene, self.parts, self.lights = scene, parts, lights
        h, w = scene.maps.kd.shape[:2]
        self.texels = rasterize_atlas(scene.mesh, h, w)
        nf = len(scene.mesh.faces)
        self.face_part = np.full(nf, -1, np.int64)
        for i, part in enumerate(parts):
            self.face_part[np.asarray(part.faces, np.int64)] = i
        self.face_light = np.full(nf, -1, np.int64)
        for j, light in enumerate(lights):
            self.face_light[np.asarray(light.faces, np.int64)] = j
        source = _sources(self.texels.mask, GUTTER)
        tri = self.texels.triangle.ravel()
        self.gutter = np.flatnonzero((source >= 0) & ~self.texels.mask.ravel())
        self.gutter_source = source[self.gutter]
        covered = np.flatnonzero(self.texels.mask.ravel())
        position = self.texels.position.reshape(-1, 3)
        normal = self.texels.normal.reshape(-1, 3)
        self.part_texels, self.part_xy = [], []
        for i, part in enumerate(parts):
            idx = covered[self.face_part[tri[covered]] == i]
            self.part_texels.append(idx)
            self.part_xy.append(
                _surface_uv(position[idx].astype(np.float64), normal[idx].astype(np.float64), part.plane)
            )
        self.light_texels = [covered[self.face_light[tri[covered]] == j] for j in range(len(lights))]
        self._values: dict = {}

    # --- maps -----------------------------------------------------------------------------
    def evaluate(self, i: int, mat: PartMaterial, footprint: float = 0.0):
        """kd (n, 3), ks (n,), ka (n,) of part i's texels under its material (torch)."""
        uv = torch.from_numpy((self.part_xy[i] / mat.meters_per_unit).astype(np.float32))
        return mat.material.evaluate(uv, mat.params, mat.transform, footprint)

    @staticmethod
    def _key(mat: PartMaterial) -> tuple:
        params = tuple(
            (k, tuple(np.ravel(np.asarray(torch.as_tensor(v).detach(), np.float64))))
            for k, v in sorted(mat.params.items())
        )
        t = mat.transform
        return (mat.kind, float(t.scale), t.rotation_deg, tuple(t.offset), mat.meters_per_unit, params)

    def values(self, i: int, mat: PartMaterial):
        """Part i's (kd, ks, ka) as numpy, evaluated once per distinct material: a procedural
        part's noise over a wall's texels takes seconds, and a light solve or a render asks for
        the same values many times (measured on the living room: 274 of 652 s were re-evaluations)."""
        key = self._key(mat)
        cached = self._values.get(i)
        if cached is None or cached[0] != key:
            with torch.no_grad():
                cached = (key, tuple(t.numpy() for t in self.evaluate(i, mat)))
            self._values[i] = cached
        return cached[1]

    def prime(self, i: int, mat: PartMaterial, values) -> None:
        """Put values already evaluated for part i's material in the cache."""
        self._values[i] = (self._key(mat), values)

    def maps(self, materials: list[PartMaterial], radiance=None, only_light: int | None = None) -> Maps:
        """The scene's maps with every part's material and every light's radiance written
        (``only_light``: that light at unit radiance, the others dark: one term of the linear
        transport)."""
        m = self.scene.maps
        out = dataclasses.replace(m, **{f.name: getattr(m, f.name).copy() for f in dataclasses.fields(m)})
        kd, ks, ka = (getattr(out, n).reshape(len(self.texels.mask.ravel()), -1) for n in ("kd", "ks", "ka"))
        for i, mat in enumerate(materials):
            d, s, a = self.values(i, mat)
            idx = self.part_texels[i]
            kd[idx], ks[idx], ka[idx, 0] = d, s[:, None], a
        for arr in (kd, ks, ka):
            arr[self.gutter] = arr[self.gutter_source]
        return self.with_lights(out, radiance, only_light)

    def with_lights(self, maps: Maps, radiance=None, only_light: int | None = None) -> Maps:
        """``maps`` with ke replaced by the lights' (a copy of ke only: a light render changes
        no material, and evaluating the procedural parts again for each light was most of a
        light solve's time)."""
        ke = np.zeros_like(maps.ke)
        flat = ke.reshape(-1, 3)
        radiance = [light.radiance for light in self.lights] if radiance is None else radiance
        for j, idx in enumerate(self.light_texels):
            if only_light is None:
                flat[idx] = np.asarray(radiance[j])
            elif j == only_light:
                flat[idx] = 1.0
        flat[self.gutter] = flat[self.gutter_source]
        return dataclasses.replace(maps, ke=ke)

    def gather(self, grad_map: np.ndarray) -> list[np.ndarray]:
        """A map's gradient (H, W, C) back to each part's texels: gutter texels' gradients added
        to their sources' (the write copied the source there)."""
        g = np.array(grad_map, np.float64).reshape(len(self.texels.mask.ravel()), -1)
        np.add.at(g, self.gutter_source, g[self.gutter])
        return [g[idx] for idx in self.part_texels]

    def light_gather(self, grad_ke: np.ndarray) -> np.ndarray:
        """d Loss / d radiance of each light (K, 3) from the gradient of the ke map."""
        g = np.array(grad_ke, np.float64).reshape(len(self.texels.mask.ravel()), -1)
        np.add.at(g, self.gutter_source, g[self.gutter])
        return np.stack([g[idx].sum(0) for idx in self.light_texels]) if self.lights else np.zeros((0, 3))

    # --- pixels -----------------------------------------------------------------------------
    def light_ids(self, triangle_id: np.ndarray) -> np.ndarray:
        """The light index of each pixel from a triangle-id AOV (-1: no light)."""
        tri = np.asarray(triangle_id, np.int64)
        out = np.full(tri.shape, -1, np.int64)
        hit = (tri >= 0) & (tri < len(self.face_light))
        out[hit] = self.face_light[tri[hit]]
        return out

    def part_ids(self, triangle_id: np.ndarray) -> np.ndarray:
        """The part index of each pixel from a triangle-id AOV (-1: no part, a light or nothing)."""
        tri = np.asarray(triangle_id, np.int64)
        out = np.full(tri.shape, -1, np.int64)
        hit = (tri >= 0) & (tri < len(self.face_part))
        out[hit] = self.face_part[tri[hit]]
        return out


MIN_CROP = 32  # the Gram network's five poolings need at least 2 x 2 features after the fourth


def crop_camera(camera: Camera, rect, max_size: int, name: str) -> Camera:
    """A camera that sees exactly the photo's window ``rect`` (x, y, w, h), at most ``max_size``
    pixels on its longer side (a crop is compared at the Gram network's working size) and at
    least MIN_CROP on its shorter (crops are at most 2.5 times as long as wide, crops.py)."""
    k = max_size / max(rect.w, rect.h)
    k = max(k, MIN_CROP / min(rect.w, rect.h))
    w, h = max(8, round(rect.w * k)), max(8, round(rect.h * k))
    sx, sy = w / rect.w, h / rect.h
    fx, fy, cx, cy = np.asarray(camera.params, float)[:4]
    params = np.array([fx * sx, fy * sy, (cx - rect.x) * sx, (cy - rect.y) * sy])
    return Camera(name, "PINHOLE", w, h, params, camera.R, camera.t)


def from_room_scene(scene, labels: dict, assets: dict) -> tuple[list[Part], list[Light]]:
    """The parts and lights of a scene from scene/room_scene.assemble_room, by its metadata:
    each box surface one part (plane layout, the photo segments of its class); each object's
    asset part one part (box mapping, the object's segment), except a lamp's emissive parts,
    which are a light; each light quad a light (its radiance read from the maps)."""
    from ..scene.atlas import texel_index

    meta = scene.metadata
    parts, lights = [], []
    start = 0
    by_class: dict[str, list[int]] = {}
    for sid, (cls, _) in (labels or {}).items():
        by_class.setdefault(cls, []).append(int(sid))
    for obj, inst in zip(scene.objects, meta["instances"]):
        n = len(obj.mesh.faces)
        faces = np.arange(start, start + n)
        name, kind = inst["name"], inst["kind"]
        if kind == "box":
            s = meta["surfaces"][name]
            plane = (np.asarray(s["origin"]), np.asarray(s["u_axis"]), np.asarray(s["v_axis"]))
            parts.append(Part(name, faces, tuple(by_class.get(inst["class"], ())), plane))
        elif kind == "object":
            asset = assets.get(inst.get("asset"))
            emissive = set(asset.emissive_parts) if asset is not None and inst["class"] == "lamp" else set()
            segment = () if inst.get("segment") is None else (int(inst["segment"]),)
            for part_name, (a, b) in meta["parts"].get(name, {}).items():
                idx = start + np.arange(a, b)
                if part_name in emissive:
                    lights.append(Light(f"{name}.{part_name}", idx, _radiance(scene, idx, texel_index), "lamp"))
                else:
                    parts.append(Part(f"{name}.{part_name}", idx, segment, None))
        else:
            lights.append(Light(name, faces, _radiance(scene, faces, texel_index), inst["class"]))
        start += n
    return parts, lights


def _radiance(scene, faces, texel_index) -> np.ndarray:
    """ke at the first face's centroid in UV (a light's set is constant)."""
    uv = scene.mesh.uvs[scene.mesh.faces[faces[0]]].mean(0)
    row, col = texel_index(uv, scene.maps.ke.shape)
    return np.asarray(scene.maps.ke[row, col], np.float64).copy()
