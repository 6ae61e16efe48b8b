"""The forward renderer: a Scene, its features and a device in; radiance and AOVs out."""

from __future__ import annotations

import numpy as np
import pyopencl as cl
from tqdm import tqdm

from ..scene.types import Camera, Maps, Scene
from .device import context_and_queue
from .features import Features
from .program import build_program
from .scene_buffers import GEOMETRY_ARGS, SCENE_ARG_ORDER, HostScene, pack_cameras, pack_material

LOCAL_SIZE = 64
SAMPLES_PER_LAUNCH = 2_000_000  # path samples per kernel launch: keeps launches short on GPUs


def pixel_requests(camera: Camera, camera_index: int = 0, ray_offset: int = 0) -> np.ndarray:
    """int4 (camera, x, y, ray id) for every pixel, row by row; ray id = ray_offset + y W + x."""
    ys, xs = np.mgrid[0 : camera.height, 0 : camera.width]
    ids = ray_offset + ys * camera.width + xs
    return np.stack([np.full_like(xs, camera_index), xs, ys, ids], -1).reshape(-1, 4).astype(np.int32)


class Renderer:
    """Renders a scene with kernels built for exactly the given features (render/analysis.py
    decides them; the renderer never does).

    w_env and w_emit, the weights of the environment and emitter strategies, are the features'
    (Features.w_env, w_emit) unless given; they apply only when the strategy is compiled in. `proposal`, a test
    hook, gives other maps to sample paths from (FIXED_PROPOSAL in kernels/scene_data.h): the
    renders are then importance-sampled estimates of `scene` with a proposal that stays put.
    """

    def __init__(
        self,
        scene: Scene,
        features: Features,
        device: str | None = None,
        w_env: float | None = None,
        w_emit: float | None = None,
        host_scene: HostScene | None = None,
        proposal: Maps | None = None,
        importance: np.ndarray | None = None,
    ):
        if not isinstance(features, Features):
            raise TypeError(
                f"Renderer: features: expected a Features (render/analysis.analyse decides them), "
                f"got {type(features).__name__}"
            )
        self.scene, self.features = scene, features
        self.w_env = features.w_env if w_env is None else w_env
        self.w_emit = features.w_emit if w_emit is None else w_emit
        self.context, self.queue = context_and_queue(device)
        self.importance = importance  # HostScene.pack: texels strategy 4 samples besides the emitters
        self.host = host_scene or HostScene.pack(scene.mesh, scene.maps, importance=importance)
        if proposal is not None:  # every sampling decision from the proposal: BSDF lobes and tables
            self.host = self.host.sampling_from(HostScene.pack(scene.mesh, proposal, bvh=self.host.bvh))
        self.proposal = None if proposal is None else self._buffer(pack_material(proposal))
        self.defines = features.defines() + (() if proposal is None else ("-D FIXED_PROPOSAL",))
        self.scene_args = self._scene_args()
        program = build_program(self.context, "render.cl", self.defines)
        self.render_kernel = cl.Kernel(program, "render_rays")
        self.aov_kernel = cl.Kernel(program, "primary_aovs")

    def set_maps(self, maps) -> None:
        """New parameter maps for the same mesh (an optimiser's step): the BVH and the geometry
        buffers stay on the device; the material, sky and both sampling distributions are packed
        and uploaded again."""
        self.scene.maps = maps
        on_device = {name: self.scene_args[SCENE_ARG_ORDER.index(name)] for name in GEOMETRY_ARGS}
        self.host = HostScene.pack(self.scene.mesh, maps, bvh=self.host.bvh, importance=self.importance)
        self.scene_args = self._scene_args(reuse=on_device)

    def _scene_args(self, reuse: dict | None = None) -> list:
        """SCENE_PARAMS in kernels/scene_data.h: the scene's arguments, then the proposal material
        under the FIXED_PROPOSAL hook."""
        args = self.host.upload(self.context, self.w_env, self.w_emit, reuse)
        return args + ([] if self.proposal is None else [self.proposal])

    # --- buffers -------------------------------------------------------------------------
    def _buffer(self, array: np.ndarray) -> cl.Buffer:
        return cl.Buffer(
            self.context, cl.mem_flags.READ_ONLY | cl.mem_flags.COPY_HOST_PTR, hostbuf=np.ascontiguousarray(array)
        )

    def _zeros(self, shape, dtype=np.float32) -> tuple[np.ndarray, cl.Buffer]:
        host = np.zeros(shape, dtype)
        return host, cl.Buffer(self.context, cl.mem_flags.READ_WRITE | cl.mem_flags.COPY_HOST_PTR, hostbuf=host)

    def _global_size(self, n: int) -> tuple[int]:
        return (max(LOCAL_SIZE, -(-n // LOCAL_SIZE) * LOCAL_SIZE),)

    def request_buffers(self, cameras: list[Camera], requests: np.ndarray) -> tuple[cl.Buffer, cl.Buffer]:
        return self._buffer(pack_cameras(cameras)), self._buffer(requests.astype(np.int32))

    def sample_launches(
        self,
        kernel: cl.Kernel,
        n: int,
        spp: int,
        seed: int,
        head: tuple,
        tail: tuple,
        desc: str = "render",
        progress: bool = False,
    ) -> None:
        """Run a per-request kernel over samples [0, spp) in launches of at most
        SAMPLES_PER_LAUNCH paths: kernel(scene args, *head, seed, start, count, *tail)."""
        per_launch = max(1, min(spp, SAMPLES_PER_LAUNCH // max(n, 1)))
        for start in tqdm(range(0, spp, per_launch), desc=desc, unit="launch", disable=not progress, leave=False):
            count = min(per_launch, spp - start)
            kernel(
                self.queue,
                self._global_size(n),
                (LOCAL_SIZE,),
                *self.scene_args,
                *head,
                np.uint64(seed),
                np.uint32(start),
                np.uint32(count),
                *tail,
            )
            # One launch at a time: the progress bar tells the truth, and a signal (Ctrl-C,
            # SIGTERM) is handled within a launch instead of after the whole queue drains.
            self.queue.finish()

    def ray_offset(self, camera: Camera) -> int:
        """Ray ids continue across the scene's cameras, so no two pixels share random numbers."""
        offset = 0
        for cam in self.scene.cameras:
            if cam.name == camera.name:
                return offset
            offset += cam.width * cam.height
        return 0

    # --- rendering -----------------------------------------------------------------------
    def render_requests(
        self, cameras: list[Camera], requests: np.ndarray, spp: int, seed: int = 0, progress: bool = False
    ) -> tuple[np.ndarray, np.ndarray, int]:
        """Mean radiance (n, 3), the variance of that mean (n, 3), and the count of samples that
        were dropped (non-finite radiance) or whose path ended on a density or weight that was not
        a positive finite number: 0 unless something is wrong. For int4 requests
        (camera, x, y, ray id)."""
        n = len(requests)
        cams, reqs = self.request_buffers(cameras, requests)
        accum, accum_buf = self._zeros((n, 4))
        accum_sq, accum_sq_buf = self._zeros((n, 4))
        shift, shift_buf = self._zeros((n, 4))
        self.sample_launches(
            self.render_kernel,
            n,
            spp,
            seed,
            (cams, reqs, np.int32(n)),
            (accum_buf, accum_sq_buf, shift_buf),
            progress=progress,
        )
        for host, buf in ((accum, accum_buf), (accum_sq, accum_sq_buf), (shift, shift_buf)):
            cl.enqueue_copy(self.queue, host, buf)
        dropped = int(accum[:, 3].sum() + accum_sq[:, 3].sum())
        kept = np.maximum(spp - accum[:, 3:4], 1).astype(np.float64)
        offset = accum[:, :3] / kept  # the mean's distance from the shift (render.cl)
        mean = shift[:, :3] + offset
        variance = np.maximum(accum_sq[:, :3] / kept - offset**2, 0) / kept
        return mean.astype(np.float32), variance.astype(np.float32), dropped

    def aovs(self, cameras: list[Camera], requests: np.ndarray) -> dict[str, np.ndarray]:
        n = len(requests)
        cams, reqs = self.request_buffers(cameras, requests)
        out = {
            "depth": self._zeros(n),
            "normal": self._zeros((n, 4)),
            "uv": self._zeros((n, 2)),
            "instance_id": self._zeros(n, np.int32),
            "triangle_id": self._zeros(n, np.int32),
        }
        self.aov_kernel(
            self.queue,
            self._global_size(n),
            (LOCAL_SIZE,),
            *self.scene_args,
            cams,
            reqs,
            np.int32(n),
            *(buf for _, buf in out.values()),
        )
        for host, buf in out.values():
            cl.enqueue_copy(self.queue, host, buf)
        result = {name: host for name, (host, _) in out.items()}
        result["normal"] = result["normal"][:, :3]
        return result

    def render(
        self, camera: Camera, spp: int = 64, seed: int = 0, aovs: bool = True, progress: bool = False
    ) -> dict[str, np.ndarray]:
        """One image: 'radiance' (H, W, 3), 'variance' of each pixel's mean, and with aovs
        'depth', 'normal', 'uv', 'instance_id', 'triangle_id' (H, W, ...)."""
        requests = pixel_requests(camera, 0, self.ray_offset(camera))
        mean, variance, dropped = self.render_requests([camera], requests, spp, seed, progress)
        shape = (camera.height, camera.width)
        out = {"radiance": mean.reshape(*shape, 3), "variance": variance.reshape(*shape, 3), "dropped": dropped}
        if aovs:
            for name, value in self.aovs([camera], requests).items():
                out[name] = value.reshape(*shape, *value.shape[1:])
        return out
