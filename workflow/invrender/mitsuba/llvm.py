"""Which libLLVM drjit's LLVM backend loads (it needs >= 16; Debian 12 ships 14 and 15).

Imported first by the package (`__init__.py`): drjit reads DRJIT_LIBLLVM_PATH when its LLVM
backend starts, so the variable has to be set before mitsuba is imported. Without a usable
libLLVM, `llvm_ad_rgb` is unusable and the package falls back to `scalar_rgb` (variant.py).
"""

from __future__ import annotations

import glob
import os
import re


def find_libllvm() -> str | None:
    """The newest system libLLVM >= 16 (drjit's LLVM backend fails on Debian's 14 and 15)."""
    best, best_version = None, 0
    for path in glob.glob("/usr/lib/*/libLLVM*.so*") + glob.glob("/usr/lib/libLLVM*.so*"):
        match = re.search(r"libLLVM[-.]?(?:so\.)?(\d+)", os.path.basename(path))
        if match and int(match.group(1)) >= 16 and int(match.group(1)) > best_version:
            best, best_version = path, int(match.group(1))
    return best


def llvm_available() -> bool:
    """Whether drjit's LLVM backend has a library it works with (FACTS.md: >= 16 on Debian)."""
    path = os.environ.get("DRJIT_LIBLLVM_PATH")
    return bool(path) and os.path.exists(path)


if "DRJIT_LIBLLVM_PATH" not in os.environ and (_libllvm := find_libllvm()):
    os.environ["DRJIT_LIBLLVM_PATH"] = _libllvm
