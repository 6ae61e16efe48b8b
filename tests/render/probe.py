"""Runs the probe kernels (kernels/probe.cl): single device functions, case by case."""

from __future__ import annotations

import numpy as np
import pyopencl as cl

from invrender.render.device import context_and_queue
from invrender.render.features import Features
from invrender.render.program import build_program
from invrender.render.scene_buffers import HostScene, pack_cameras


def as4(v) -> np.ndarray:
    v = np.asarray(v, np.float32)
    out = np.zeros((*v.shape[:-1], 4), np.float32)
    out[..., : v.shape[-1]] = v
    return np.ascontiguousarray(out.reshape(-1, 4))


class KernelProbe:
    def __init__(self, features: Features = Features.everything(), scene=None, w_env=0.25, w_emit=0.25):
        self.context, self.queue = context_and_queue(None)
        self.program = build_program(self.context, "probe.cl", features.defines())
        self.scene_args = None
        self.kernels = {}
        if scene is not None:
            host = HostScene.pack(scene.mesh, scene.maps)
            self.host = host
            self.scene_args = host.upload(self.context, w_env, w_emit)

    def _in(self, array):
        return cl.Buffer(
            self.context, cl.mem_flags.READ_ONLY | cl.mem_flags.COPY_HOST_PTR, hostbuf=np.ascontiguousarray(array)
        )

    def _run(self, name, n, inputs, outputs, scene=False):
        bufs = [cl.Buffer(self.context, cl.mem_flags.WRITE_ONLY, max(o.nbytes, 16)) for o in outputs]
        args = (list(self.scene_args) if scene else []) + list(inputs) + bufs
        if name not in self.kernels:
            self.kernels[name] = cl.Kernel(self.program, name)
        self.kernels[name](self.queue, (n,), None, *args)
        for host, buf in zip(outputs, bufs):
            cl.enqueue_copy(self.queue, host, buf)
        return outputs

    def bsdf(self, n, wo, wi, kd, ks, ka):
        """(f cos (N, 3), pdf_cosine (N,), pdf_specular (N,)) in float32."""
        count = len(n)
        mats = np.zeros((count, 3, 4), np.float32)
        mats[:, 0, :3], mats[:, 0, 3] = kd, ka
        mats[:, 1, :3] = ks
        f, pdfs = self._run(
            "probe_bsdf",
            count,
            [self._in(mats), self._in(as4(n)), self._in(as4(wo)), self._in(as4(wi))],
            [np.zeros((count, 4), np.float32), np.zeros((count, 2), np.float32)],
        )
        return f[:, :3], pdfs[:, 0], pdfs[:, 1]

    def lobe_samples(self, n, wo, ka, u):
        count = len(n)
        cos_s, spec_s = self._run(
            "probe_lobe_samples",
            count,
            [self._in(as4(n)), self._in(as4(wo)), self._in(np.asarray(ka, np.float32)), self._in(as4(u))],
            [np.zeros((count, 4), np.float32), np.zeros((count, 4), np.float32)],
        )
        return cos_s[:, :3], spec_s[:, :3]

    def rng(self, seed, counters):
        counters = np.ascontiguousarray(counters, np.uint32)
        (out,) = self._run(
            "probe_rng",
            len(counters),
            [np.uint64(seed), self._in(counters)],
            [np.zeros((len(counters), 4), np.float32)],
        )
        return out

    def _cases(self, count, texel, *vectors):
        """Input buffers for `count` cases: the texel (None: none) and 3-vectors, each broadcast."""
        texels = [] if texel is None else [self._in(np.broadcast_to(np.asarray(texel, np.int32), (count,)).copy())]
        return texels + [self._in(as4(np.broadcast_to(np.asarray(v, np.float32), (count, 3)))) for v in vectors]

    def mixture(self, texel, x, n, wo, u):
        """Sampled wi (N, 3), its mixture pdf (N,), f cos (N, 3), strategy pdfs (N, 4)."""
        count = len(x)
        wi, parts, f = self._run(
            "probe_mixture",
            count,
            [*self._cases(count, texel, x, n, wo), self._in(as4(u))],
            [np.zeros((count, 4), np.float32) for _ in range(3)],
            scene=True,
        )
        return wi[:, :3], wi[:, 3], f[:, :3], parts

    def mixture_pdf(self, texel, x, n, wo, wi):
        count = len(wi)
        (pdf,) = self._run(
            "probe_mixture_pdf",
            count,
            [*self._cases(count, texel, x, n, wo), self._in(as4(wi))],
            [np.zeros(count, np.float32)],
            scene=True,
        )
        return pdf

    def light(self, texel, x, n, wo, u):
        """Next-event estimation's light samples: directions (N, 3) and whether each found a
        segment (N,) (kernels/nee.h)."""
        count = len(u)
        (out,) = self._run(
            "probe_light",
            count,
            [*self._cases(count, texel, x, n, wo), self._in(as4(u))],
            [np.zeros((count, 4), np.float32)],
            scene=True,
        )
        return out[:, :3], out[:, 3] > 0

    def light_pdf(self, x, n, directions):
        count = len(directions)
        (pdf,) = self._run(
            "probe_light_pdf",
            count,
            [*self._cases(count, None, x, n), self._in(as4(directions))],
            [np.zeros(count, np.float32)],
            scene=True,
        )
        return pdf

    def intersect(self, origins, directions):
        """(t, b1, b2, original triangle or -1) per ray."""
        count = len(origins)
        (out,) = self._run(
            "probe_intersect",
            count,
            [self._in(as4(origins)), self._in(as4(directions))],
            [np.zeros((count, 4), np.float32)],
            scene=True,
        )
        return out

    def offset(self, p, n):
        (out,) = self._run(
            "probe_offset", len(p), [self._in(as4(p)), self._in(as4(n))], [np.zeros((len(p), 4), np.float32)]
        )
        return out[:, :3]

    def camera_directions(self, camera, pixels):
        pixels = np.ascontiguousarray(pixels, np.float32)
        (out,) = self._run(
            "probe_camera",
            len(pixels),
            [self._in(pack_cameras([camera])), self._in(pixels)],
            [np.zeros((len(pixels), 4), np.float32)],
        )
        return out[:, :3]
