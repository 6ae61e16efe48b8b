"""OpenCL runtimes installed by pip, made visible to pyopencl's ICD loader.

pyopencl's bundled loader (ocl-icd) reads the ``.icd`` files of ``$OCL_ICD_VENDORS``, else of
``/etc/OpenCL/vendors``, plus the PoCL bundled beside it. Intel's CPU runtime from PyPI
(``intel-opencl-rt``) installs ``libintelocl.so`` into the environment's ``lib/`` (its libimf,
libsvml and libtbb beside it, found through the library's ``$ORIGIN`` run path), but the ``.icd``
files it ships name a build-time path, so the loader never finds it. Before the first platform
query, :func:`register` points ``OCL_ICD_VENDORS`` at a folder that holds the system's ``.icd``
files plus one naming each runtime installed in the environment. A user's own
``OCL_ICD_VENDORS`` is left as it is: that user chose which runtimes to load.
"""

from __future__ import annotations

import ctypes
import hashlib
import os
import sys
from pathlib import Path

SYSTEM_VENDORS = Path("/etc/OpenCL/vendors")
# Runtime libraries that pip puts in the environment's lib/ (not under site-packages).
PIP_RUNTIMES = {"intel-cpu.icd": "libintelocl.so"}
# Libraries of theirs loaded first, process-wide: pymeshlab bundles an older libtbb.so.12, and once
# it is loaded Intel's runtime fails to load ("undefined symbol ... get_thread_reference_vertex"),
# so its platform silently disappears. The newer TBB serves pymeshlab as well (the same ABI).
PRELOAD = ("libtbb.so.12",)


def pip_runtimes(prefix: Path | None = None) -> dict[str, Path]:
    """The runtime libraries installed in the environment: {icd file name: library path}."""
    lib = Path(prefix or sys.prefix) / "lib"
    return {icd: lib / name for icd, name in PIP_RUNTIMES.items() if (lib / name).is_file()}


def vendor_files(prefix: Path | None = None) -> dict[str, str]:
    """The .icd files the loader should read: the system's, and one per runtime pip installed."""
    files = {path.name: path.read_text() for path in sorted(SYSTEM_VENDORS.glob("*.icd")) if path.is_file()}
    files |= {icd: f"{library}\n" for icd, library in pip_runtimes(prefix).items()}
    return files


def preload(prefix: Path | None = None) -> None:
    lib = Path(prefix or sys.prefix) / "lib"
    for name in PRELOAD:
        if (lib / name).is_file():
            ctypes.CDLL(str(lib / name), mode=ctypes.RTLD_GLOBAL)


def register(cache: Path) -> Path | None:
    """Point the ICD loader at the system's and the environment's runtimes (a folder under
    ``cache``); None, changing nothing, when the user set OCL_ICD_VENDORS or pip installed none."""
    if not pip_runtimes():
        return None
    preload()
    if os.environ.get("OCL_ICD_VENDORS"):
        return None
    files = vendor_files()
    digest = hashlib.sha256(repr(sorted(files.items())).encode()).hexdigest()[:16]
    folder = cache / "opencl-vendors" / digest  # named by its contents: written once, never changed
    if not folder.is_dir():
        staging = folder.with_name(f"{digest}.tmp{os.getpid()}")
        staging.mkdir(parents=True, exist_ok=True)
        for name, text in files.items():
            (staging / name).write_text(text)
        try:
            staging.rename(folder)
        except OSError:  # another process wrote the same folder first
            for path in staging.iterdir():
                path.unlink()
            staging.rmdir()
    os.environ["OCL_ICD_VENDORS"] = str(folder)
    return folder
