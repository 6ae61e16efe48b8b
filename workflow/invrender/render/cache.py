"""Where invrender keeps what it can make again: kernel binaries, device verdicts, the folder of
OpenCL runtimes the ICD loader reads. ``$INVRENDER_CACHE`` moves it."""

from __future__ import annotations

import os
from pathlib import Path


def cache_root() -> Path:
    return Path(os.environ.get("INVRENDER_CACHE") or Path.home() / ".cache" / "invrender")
