"""Device choice, kernel assembly and the on-disk program cache."""

import pyopencl as cl
import pytest

from invrender.render import program as prog
from invrender.render.device import DeviceError, choose_device, context_and_queue, describe
from invrender.render.features import Features


def test_device_by_name_and_a_clear_error_for_an_unknown_one():
    preferred = describe(choose_device(None))
    platform = preferred.split(" / ")[0]
    assert describe(choose_device(platform.lower())) == preferred  # a name's part, any case
    with pytest.raises(DeviceError, match=r"no OpenCL device matches 'no-such-gpu'; available: .*Portable"):
        choose_device("no-such-gpu")


def test_every_kernel_file_names_itself_for_compiler_messages():
    for path in sorted(prog.KERNEL_DIR.glob("*.[ch]*")):
        first = path.read_text().splitlines()[0]
        assert first == f'#line 2 "{path.name}"', path


def test_compiler_errors_point_at_the_header_that_has_them(tmp_path, monkeypatch):
    (tmp_path / "good.h").write_text('#line 2 "good.h"\ninline int one(void) { return 1; }\n')
    (tmp_path / "bad.h").write_text('#line 2 "bad.h"\n\ninline int two(void) { return undefined_name; }\n')
    (tmp_path / "entry.cl").write_text(
        '#line 2 "entry.cl"\n#include "good.h"\n#include "bad.h"\n'
        "kernel void k(global int* x) { x[0] = one() + two(); }\n"
    )
    source = prog.assemble_source("entry.cl", tmp_path)
    assert source.count('#line 2 "good.h"') == 1
    context, _ = context_and_queue(None)
    with pytest.raises(cl.RuntimeError, match=r"bad\.h:3"):
        cl.Program(context, source).build()


def test_code_after_an_inlined_header_keeps_its_own_file_and_line(tmp_path):
    (tmp_path / "a.h").write_text('#line 2 "a.h"\n#include "b.h"\ninline int one(void) { return two() - 1; }\n')
    (tmp_path / "b.h").write_text('#line 2 "b.h"\ninline int two(void) { return 2; }\n')
    (tmp_path / "entry.cl").write_text(
        '#line 2 "entry.cl"\n#include "a.h"\n#include "b.h"\n\n'
        "kernel void k(global int* x) { x[0] = one() + undefined_name; }\n"
    )
    context, _ = context_and_queue(None)
    with pytest.raises(cl.RuntimeError, match=r"entry\.cl:5"):
        cl.Program(context, prog.assemble_source("entry.cl", tmp_path)).build()


def test_every_header_includes_what_it_uses():
    """Each header builds on its own, with every feature on: an entry kernel includes only the
    headers it calls, and no list of all of them is kept anywhere."""
    from invrender.render.adjoint import LAYOUT_DEFINES

    context, _ = context_and_queue(None)
    flags = list(Features.everything(max_bounces=2).defines() + LAYOUT_DEFINES)
    headers = sorted(path.name for path in prog.KERNEL_DIR.glob("*.h"))
    assert len(headers) >= 11
    for name in headers:
        source = prog.assemble_source(name) + "\nkernel void nothing(global int* x) { x[0] = 0; }\n"
        cl.Program(context, source).build(options=flags)


def test_binaries_are_cached_by_source_flags_and_device(tmp_path, monkeypatch):
    monkeypatch.setenv("INVRENDER_CACHE", str(tmp_path))
    context, _ = context_and_queue(None)
    prog._build_cached.cache_clear()
    flags_a = Features.everything(max_bounces=2).defines()
    flags_b = Features.everything(max_bounces=3).defines()
    prog.build_program(context, "render.cl", flags_a)
    prog.build_program(context, "render.cl", flags_b)
    cached = sorted((tmp_path / "kernels").glob("*.bin"))
    assert len(cached) == 2  # one per flag set
    # A corrupt cache entry is rebuilt, not trusted.
    for path in cached:
        path.write_bytes(b"not a binary")
    prog._build_cached.cache_clear()
    program = prog.build_program(context, "render.cl", flags_a)
    assert cl.Kernel(program, "render_rays")
    assert any(p.stat().st_size > 1000 for p in (tmp_path / "kernels").glob("*.bin"))
    prog._build_cached.cache_clear()
