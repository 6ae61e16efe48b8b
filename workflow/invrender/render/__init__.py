"""The OpenCL path tracer for MILO's scene model: host code over the kernels in kernels/."""

from .features import Features


def __getattr__(name):
    # The renderer pulls in pyopencl; import it on first use so `invrender --help` stays fast.
    if name == "Renderer":
        from .renderer import Renderer

        return Renderer
    raise AttributeError(name)


__all__ = ["Features", "Renderer"]
