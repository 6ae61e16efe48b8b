"""invrender: inverse rendering of real spaces by Monte Carlo inverse path tracing."""

__version__ = "0.1.0"

# Before anything in the process asks OpenCL for its platforms (the ICD loader reads its vendors
# once): the runtimes pip installed, made visible to it (render/runtimes.py).
from .render import runtimes as _runtimes  # noqa: E402
from .render.cache import cache_root as _cache_root  # noqa: E402

_runtimes.register(_cache_root())
