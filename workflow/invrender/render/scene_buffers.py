"""A Scene packed into the device buffers the kernels read (SceneData in kernels/scene_data.h).

Triangles are stored in BVH leaf order; the emitting triangles get a BVH of their own for the
all-hits density of sampling strategy 4; the cube map gets its sampling distribution. The
kernels' list of scene arguments is read from kernels/scene_data.h, so the order in which the
host passes them is the header's.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, fields, replace
from pathlib import Path

import numpy as np
import pyopencl as cl

from ..scene.cubemap import cube_texel_solid_angles
from ..scene.types import Camera, Maps, Mesh
from .bvh import WideBVH, build_bvh, leaf_blocks, triangle_vertices
from .program import KERNEL_DIR

LUMINANCE = np.array([0.2126, 0.7152, 0.0722])

# kernels/camera.h CameraData: 24 four-byte fields, no padding on any OpenCL device.
CAMERA_DTYPE = np.dtype(
    [
        ("R", "<f4", 9),
        ("C", "<f4", 3),
        ("f", "<f4", 2),
        ("c", "<f4", 2),
        ("k", "<f4", 4),
        ("width", "<i4"),
        ("height", "<i4"),
        ("distorted", "<i4"),
        ("pad", "<i4"),
    ]
)


@dataclass(frozen=True)
class SceneArg:
    """One entry of SCENE_DATA in kernels/scene_data.h."""

    name: str
    cl_type: str  # OpenCL type of the scalar, or of a buffer's elements
    buffer: bool  # a read-only global buffer (BUFFER) or a scalar passed by value (VALUE)


# numpy kind, item size and elements per value of each OpenCL type the list may use.
CL_TYPES = {
    "float": ("f", 4, 1),
    "float2": ("f", 4, 2),
    "float4": ("f", 4, 4),
    "float8": ("f", 4, 8),
    "int": ("i", 4, 1),
    "int8": ("i", 4, 8),
    "uchar": ("u", 1, 1),
}
_SCENE_DATA_START = "#define SCENE_DATA(BUFFER, VALUE, NEXT)"
_SCENE_DATA_ENTRY = re.compile(r"^\s+(BUFFER|VALUE)\((\w+), (\w+)\)( NEXT)?\s*(/\*[^*]*\*/)?\s*(\\)?$")


def read_scene_data(path: Path = KERNEL_DIR / "scene_data.h") -> tuple[SceneArg, ...]:
    """The SCENE_DATA list of kernels/scene_data.h, in order. Strict: the macro's first line as
    written there, then one `BUFFER(type, name) NEXT` or `VALUE(type, name) NEXT` per line, each
    continued with a backslash, the last without NEXT or backslash. Any other form is an error
    rather than a guess, since a misread list would pass the kernels the wrong buffers."""
    lines = Path(path).read_text().splitlines()
    where = lambda number: f"{path}:{number}"
    starts = [i for i, line in enumerate(lines) if line.startswith(_SCENE_DATA_START)]
    if len(starts) != 1 or not lines[starts[0]].rstrip().endswith("\\"):
        raise ValueError(f"{path}: expected one line starting {_SCENE_DATA_START!r} and ending in a backslash")
    args, number = [], starts[0] + 1
    while True:
        if number >= len(lines):
            raise ValueError(f"{where(number)}: SCENE_DATA does not end")
        match = _SCENE_DATA_ENTRY.match(lines[number])
        number += 1
        if not match:
            raise ValueError(
                f"{where(number)}: expected `    BUFFER(type, name) NEXT /* ... */ \\` or VALUE, "
                f"got {lines[number - 1]!r}"
            )
        kind, cl_type, name, has_next, _, continued = match.groups()
        if cl_type not in CL_TYPES:
            raise ValueError(f"{where(number)}: type {cl_type!r}: expected one of {sorted(CL_TYPES)}")
        if bool(has_next) != bool(continued):
            raise ValueError(f"{where(number)}: NEXT and a backslash go together (every entry but the last)")
        if name in {arg.name for arg in args}:
            raise ValueError(f"{where(number)}: {name} listed twice")
        args.append(SceneArg(name, cl_type, kind == "BUFFER"))
        if not continued:
            return tuple(args)


def pack_cameras(cameras: list[Camera]) -> np.ndarray:
    packed = np.zeros(len(cameras), CAMERA_DTYPE)
    for record, cam in zip(packed, cameras):
        record["R"] = np.asarray(cam.R, np.float64).ravel()
        record["C"] = cam.center  # in float64, then rounded once
        record["f"] = cam.focal
        record["c"] = cam.principal_point
        record["k"] = cam.distortion
        record["width"], record["height"] = cam.width, cam.height
        record["distorted"] = int(np.any(cam.distortion != 0))
    return packed


def pack_material(maps: Maps) -> np.ndarray:
    """Three float4 per texel: [kd, ka], [ks, kw], [ke, 0] (Material in kernels/common.h)."""
    h, w = maps.atlas_shape
    packed = np.zeros((h * w, 3, 4), np.float32)
    packed[:, 0, :3] = maps.kd.reshape(-1, 3)
    packed[:, 0, 3] = maps.ka.reshape(-1)
    packed[:, 1, :3] = maps.ks.reshape(-1, 3)
    packed[:, 1, 3] = maps.kw.reshape(-1)
    packed[:, 2, :3] = maps.ke.reshape(-1, 3)
    return packed


def atlas_lookup(image: np.ndarray, uv: np.ndarray) -> np.ndarray:
    """Nearest texel, as kernels/textures.h: column floor(u W), row floor((1 - v) H)."""
    h, w = image.shape[:2]
    col = np.clip(np.floor(uv[..., 0] * w).astype(np.int64), 0, w - 1)
    row = np.clip(np.floor((1.0 - uv[..., 1]) * h).astype(np.int64), 0, h - 1)
    return image[row, col]


def _barycentric_grid(levels: int = 8) -> np.ndarray:
    """Centroids of the levels^2 congruent sub-triangles: an even cover of a triangle."""
    points = []
    for i in range(levels):
        for j in range(levels - i):
            points.append(((i + 1 / 3) / levels, (j + 1 / 3) / levels))
            if i + j < levels - 1:
                points.append(((i + 2 / 3) / levels, (j + 2 / 3) / levels))
    b = np.array(points)
    return np.column_stack([1 - b.sum(1), b])


def emitted_power(mesh: Mesh, maps: Maps) -> np.ndarray:
    """area x mean luminance of ke over each triangle (sampling strategy 4's weights)."""
    return surface_power(mesh, maps.ke @ LUMINANCE)


def surface_power(mesh: Mesh, luminance: np.ndarray) -> np.ndarray:
    """area x mean of an (H, W) atlas map over each triangle.

    Only triangles whose UV box holds a positive texel are looked up (a summed-area table
    answers that in O(1) per triangle): in a room almost none emit, and looking up all of a
    million-triangle mesh was most of the time it took to pack it."""
    h, w = luminance.shape
    positive = luminance > 0
    power = np.zeros(len(mesh.faces))
    if not positive.any():
        return power
    table = np.pad(positive.cumsum(0).cumsum(1), ((1, 0), (1, 0)))
    uv = mesh.uvs[mesh.faces].astype(np.float64)  # (F, 3, 2)
    col = np.clip(np.floor(uv[..., 0] * w).astype(np.int64), 0, w - 1)
    row = np.clip(np.floor((1.0 - uv[..., 1]) * h).astype(np.int64), 0, h - 1)
    r0, r1, c0, c1 = row.min(1), row.max(1) + 1, col.min(1), col.max(1) + 1
    candidates = np.flatnonzero(table[r1, c1] - table[r0, c1] - table[r1, c0] + table[r0, c0] > 0)
    faces = mesh.faces[candidates]
    v0, v1, v2 = (mesh.positions[faces[:, k]].astype(np.float64) for k in range(3))
    area = 0.5 * np.linalg.norm(np.cross(v1 - v0, v2 - v0), axis=1)
    points = np.einsum("pk,fkc->fpc", _barycentric_grid(), uv[candidates])
    values = atlas_lookup(luminance, points)
    power[candidates] = area * values.mean(axis=1)
    return np.where(np.isfinite(power), power, 0.0)


def one_sided_faces(mesh: Mesh) -> np.ndarray:
    """(F,) bool: the faces that emit only on their front side (Mesh.one_sided; none if None)."""
    if mesh.one_sided is None:
        return np.zeros(len(mesh.faces), bool)
    flags = np.asarray(mesh.one_sided)
    if flags.shape != (len(mesh.faces),) or flags.dtype != bool:
        raise ValueError(f"Mesh.one_sided: expected ({len(mesh.faces)},) bool, got {flags.dtype} {flags.shape}")
    return flags


def environment_distribution(kg: np.ndarray) -> tuple[np.ndarray, np.ndarray, bool]:
    """P(texel) ~ luminance x solid angle over the 6 N N cube texels, its inclusive CDF, and
    whether the sky is black (then the distribution is uniform and must get weight 0)."""
    n = kg.shape[1]
    solid_angle = np.broadcast_to(cube_texel_solid_angles(n), (6, n, n))
    weight = np.maximum(((kg.reshape(6, n, n, 3) @ LUMINANCE) * solid_angle).ravel(), 0.0)
    black = not weight.sum() > 0
    if black:  # any valid density over all 6 N N texels will do: it gets weight 0
        weight = solid_angle.ravel()
    pmf = weight / weight.sum()
    cdf = np.cumsum(pmf)
    cdf[-1] = 1.0
    return pmf.astype(np.float32), cdf.astype(np.float32), black


def _empty_bvh() -> WideBVH:
    bounds = np.empty((1, 6, 8), np.float32)
    bounds[:, :3], bounds[:, 3:] = np.inf, -np.inf
    children = np.zeros((1, 2, 8), np.int32)
    children[:, 1] = -1
    return WideBVH(bounds, children, np.zeros(0, np.int32))


def _as_float4(points: np.ndarray) -> np.ndarray:
    out = np.zeros((len(points), 4), np.float32)
    out[:, :3] = points
    return out


@dataclass
class HostScene:
    """Everything the kernels read, as numpy arrays: a field per SCENE_DATA entry of
    kernels/scene_data.h but the strategy weights (see upload), and what the host keeps."""

    tri_v: np.ndarray
    tri_uv: np.ndarray
    tri_id: np.ndarray
    tri_instance: np.ndarray
    tri_one_sided: np.ndarray
    bvh_bounds: np.ndarray
    bvh_children: np.ndarray
    bvh_leaves: np.ndarray
    material: np.ndarray
    atlas_w: int
    atlas_h: int
    kg: np.ndarray
    cube_n: int
    env_cdf: np.ndarray
    env_pmf: np.ndarray
    em_v: np.ndarray
    em_cdf: np.ndarray
    em_pdf_area: np.ndarray
    num_emitters: int
    em_bounds: np.ndarray
    em_children: np.ndarray
    em_one_sided: np.ndarray
    em_slot: np.ndarray
    tri_light_pdf: np.ndarray
    bvh: WideBVH
    env_black: bool

    @classmethod
    def pack(
        cls, mesh: Mesh, maps: Maps, bvh: WideBVH | None = None, importance: np.ndarray | None = None
    ) -> HostScene:
        """`importance`: an (H, W) luminance map that strategy 4 samples besides the emitters
        (MILO's texture importance sampling: the captured images' brightness projected onto the
        atlas, so directions towards brightly lit walls are drawn as often as towards lamps). The
        strategy's density stays exact: pdf_emitter sums every sampled triangle along a ray."""
        v0, v1, v2 = triangle_vertices(mesh.positions, mesh.faces)
        bvh = bvh or build_bvh(v0, v1, v2)
        order = bvh.tri_order
        tri_v = _as_float4(np.stack([v0[order], v1[order], v2[order]], axis=1).reshape(-1, 3))
        tri_uv = mesh.uvs[mesh.faces[order]].reshape(-1, 2).astype(np.float32)
        instances = mesh.instance_ids if mesh.instance_ids is not None else np.zeros(len(mesh.faces), np.int32)
        one_sided = one_sided_faces(mesh).astype(np.uint8)

        power = emitted_power(mesh, maps)
        if importance is not None:
            power = power + surface_power(mesh, np.asarray(importance, np.float64))
        emitters = np.flatnonzero(power > 0)
        # pdf_emitter tests the emitter BVH's triangles one at a time: small leaves.
        em_bvh = build_bvh(v0[emitters], v1[emitters], v2[emitters], min_leaf=4) if len(emitters) else _empty_bvh()
        em_order = emitters[em_bvh.tri_order]  # emitter-BVH slot -> original triangle
        em_area = 0.5 * np.linalg.norm(np.cross(v1[em_order] - v0[em_order], v2[em_order] - v0[em_order]), axis=1)
        em_pmf = power[em_order] / max(power[em_order].sum(), 1e-300)
        em_cdf = np.cumsum(em_pmf)
        if len(em_cdf):
            em_cdf[-1] = 1.0
        em_pdf_area = (em_pmf / np.maximum(em_area, 1e-30)).astype(np.float32)
        slot_of = np.argsort(order)  # original triangle -> leaf slot
        tri_light_pdf = np.zeros(len(order), np.float32)
        tri_light_pdf[slot_of[em_order]] = em_pdf_area
        env_pmf, env_cdf, env_black = environment_distribution(maps.kg)
        h, w = maps.atlas_shape
        bvh_children, bvh_leaves = leaf_blocks(bvh, v0, v1, v2)
        return cls(
            tri_v=tri_v,
            tri_uv=tri_uv,
            tri_id=order.astype(np.int32),
            tri_instance=instances[order].astype(np.int32),
            tri_one_sided=one_sided[order],
            bvh_bounds=bvh.bounds,
            bvh_children=bvh_children,
            bvh_leaves=bvh_leaves,
            material=pack_material(maps),
            atlas_w=w,
            atlas_h=h,
            kg=_as_float4(maps.kg.reshape(-1, 3)),
            cube_n=maps.kg.shape[1],
            env_cdf=env_cdf,
            env_pmf=env_pmf,
            em_v=_as_float4(np.stack([v0[em_order], v1[em_order], v2[em_order]], 1).reshape(-1, 3)),
            em_cdf=em_cdf.astype(np.float32),
            em_pdf_area=em_pdf_area,
            num_emitters=len(em_order),
            em_bounds=em_bvh.bounds,
            em_children=em_bvh.children,
            em_one_sided=one_sided[em_order],
            em_slot=slot_of[em_order].astype(np.int32),
            tri_light_pdf=tri_light_pdf,
            bvh=bvh,
            env_black=env_black,
        )

    def strategy_weights(self, w_env: float, w_emit: float) -> tuple[np.float32, np.float32]:
        """The kernel arguments w_env, w_emit: a strategy with nothing to sample gets weight 0,
        so its share goes to the BSDF lobes instead of to directions it cannot draw."""
        return np.float32(0.0 if self.env_black else w_env), np.float32(w_emit if self.num_emitters > 0 else 0.0)

    def sampling_from(self, proposal: HostScene) -> HostScene:
        """This scene with the environment and emitter sampling tables of `proposal`."""
        return replace(self, **{name: getattr(proposal, name) for name in SAMPLING_ARGS})

    def upload(self, context: cl.Context, w_env: float, w_emit: float, reuse: dict | None = None) -> list:
        """Kernel arguments in SCENE_DATA order (kernels/scene_data.h): buffers as cl.Buffer,
        scalars as the header's type; w_env and w_emit as strategy_weights gives them. `reuse`
        maps argument names to buffers already on the device (the geometry, when only the maps
        changed)."""
        weights = dict(zip(("w_env", "w_emit"), self.strategy_weights(w_env, w_emit)))
        args = []
        for arg in SCENE_ARGS:
            value = weights[arg.name] if arg.name in weights else getattr(self, arg.name)
            if reuse and arg.name in reuse:
                args.append(reuse[arg.name])
            elif arg.buffer:
                data = np.ascontiguousarray(_checked_buffer(arg, value))
                data = data if data.size else np.zeros(4, data.dtype)  # OpenCL has no empty buffers
                args.append(cl.Buffer(context, cl.mem_flags.READ_ONLY | cl.mem_flags.COPY_HOST_PTR, hostbuf=data))
            else:
                args.append(np.dtype(f"{CL_TYPES[arg.cl_type][0]}{CL_TYPES[arg.cl_type][1]}").type(value))
        return args


def _checked_buffer(arg: SceneArg, value) -> np.ndarray:
    """`value` if its elements are the header's type: vector types as the last axis."""
    kind, size, width = CL_TYPES[arg.cl_type]
    fits = (
        isinstance(value, np.ndarray)
        and value.dtype.kind == kind
        and value.dtype.itemsize == size
        and (value.shape[-1:] == (width,) if width > 1 else value.ndim == 1)
    )
    if not fits:
        got = f"{value.dtype} {value.shape}" if isinstance(value, np.ndarray) else type(value).__name__
        raise ValueError(f"HostScene.{arg.name}: expected {arg.cl_type} elements (kernels/scene_data.h), got {got}")
    return value


# The kernels' scene arguments, in order: read from the header the kernels are built from.
SCENE_ARGS = read_scene_data()
SCENE_ARG_ORDER = tuple(arg.name for arg in SCENE_ARGS)
_missing = set(SCENE_ARG_ORDER) - {f.name for f in fields(HostScene)} - {"w_env", "w_emit"}
if _missing:
    raise ImportError(f"kernels/scene_data.h lists {sorted(_missing)}, which HostScene does not pack")

# Arguments that depend on the mesh only: new maps for the same mesh leave them as they are.
GEOMETRY_ARGS = (
    "tri_v",
    "tri_uv",
    "tri_id",
    "tri_instance",
    "tri_one_sided",
    "bvh_bounds",
    "bvh_children",
    "bvh_leaves",
)

# Arguments that say how directions are sampled (strategies 3 and 4), built from kg and ke.
SAMPLING_ARGS = (
    "env_cdf",
    "env_pmf",
    "env_black",
    "em_v",
    "em_cdf",
    "em_pdf_area",
    "num_emitters",
    "em_bounds",
    "em_children",
    "em_one_sided",
    "em_slot",
    "tri_light_pdf",
)
