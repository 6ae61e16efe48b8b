"""Kernel programs: sources assembled from kernels/, built with the scene's feature defines, and
program binaries cached on disk by (source hash, build flags, device)."""

from __future__ import annotations

import hashlib
import os
import re
import warnings
from functools import lru_cache
from pathlib import Path

import pyopencl as cl

from .cache import cache_root

KERNEL_DIR = Path(__file__).resolve().parents[3] / "kernels"
_INCLUDE = re.compile(r'^\s*#include\s+"([^"]+)"\s*$')


def assemble_source(entry: str, kernel_dir: Path = KERNEL_DIR) -> str:
    """Inline the local #include "x.h" lines, each file once (the headers have include guards
    and include what they use), as the compiler would. Every file starts with its own #line
    directive and the text after an inlined header gets its includer's back, so compiler
    errors name the right file and line; the whole text (hence its hash, the binary cache's
    key) covers every header the program depends on."""
    seen: set[str] = set()

    def expand(name: str) -> str:
        if name in seen:
            return ""
        seen.add(name)
        lines = (kernel_dir / name).read_text().splitlines(keepends=True)
        out = []
        for number, line in enumerate(lines, start=1):
            match = _INCLUDE.match(line)
            if not match:
                out.append(line)
            elif match.group(1) in seen:
                out.append("\n")  # already inlined: a blank line keeps the numbering
            else:
                out.append(expand(match.group(1)))
                out.append(f'#line {number + 1} "{name}"\n')
        return "".join(out)

    return expand(entry)


def cache_dir() -> Path:
    return cache_root() / "kernels"


def _cache_key(source: str, options: tuple[str, ...], device: cl.Device) -> str:
    identity = "\n".join(
        [source, " ".join(options), device.name, device.driver_version, device.platform.version, cl.VERSION_TEXT]
    )
    return hashlib.sha256(identity.encode()).hexdigest()


def build_program(context: cl.Context, entry: str, options: tuple[str, ...] = ()) -> cl.Program:
    return _build_cached(context, entry, tuple(options))


def build(program: cl.Program, options: tuple[str, ...]) -> cl.Program:
    """program.build(options), without pyopencl's warning for a successful build that logged
    something: Intel's runtime logs its vectoriser's remarks for every kernel. A failed build
    still raises, with the log."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", cl.CompilerWarning)
        return program.build(options=list(options))


@lru_cache(maxsize=64)
def _build_cached(context: cl.Context, entry: str, options: tuple[str, ...]) -> cl.Program:
    device = context.devices[0]
    source = assemble_source(entry)
    path = cache_dir() / f"{_cache_key(source, options, device)}.bin"
    if path.exists():
        try:
            return build(cl.Program(context, [device], [path.read_bytes()]), options)
        except cl.Error:
            path.unlink(missing_ok=True)  # stale or corrupt binary: rebuild below
    program = build(cl.Program(context, source), options)
    binary = program.get_info(cl.program_info.BINARIES)[0]
    path.parent.mkdir(parents=True, exist_ok=True)
    temporary = path.with_suffix(f".tmp{os.getpid()}")
    temporary.write_bytes(binary)
    temporary.replace(path)  # atomic: a concurrent reader never sees half a binary
    return program
