"""Host and kernels agree on the scene arguments: the host's list is read from
kernels/scene_data.h, and the compiled entry kernels report the same names, types and address
spaces (clGetKernelArgInfo, which needs -cl-kernel-arg-info)."""

import shutil

import numpy as np
import pyopencl as cl
import pytest
from testscenes import box_room

from invrender.render import program as prog
from invrender.render.adjoint import LAYOUT_DEFINES
from invrender.render.device import context_and_queue
from invrender.render.features import Features
from invrender.render.renderer import Renderer
from invrender.render.scene_buffers import SCENE_ARGS, SceneArg, read_scene_data
from invrender.scene.types import Maps

ENTRIES = {
    "render.cl": ("render_rays", "primary_aovs"),
    "adjoint.cl": ("adjoint_rays",),
    "probe.cl": ("probe_mixture", "probe_mixture_pdf", "probe_intersect", "probe_light", "probe_light_pdf"),
}
FLAGS = Features.everything(max_bounces=2).defines() + LAYOUT_DEFINES + ("-cl-kernel-arg-info",)
GLOBAL, PRIVATE = cl.kernel_arg_address_qualifier.GLOBAL, cl.kernel_arg_address_qualifier.PRIVATE


def built(entry: str, kernel_dir=prog.KERNEL_DIR, flags=FLAGS) -> cl.Program:
    context, _ = context_and_queue(None)
    # no binary cache: a program made from a cached binary has no argument info on Intel's runtime
    return cl.Program(context, prog.assemble_source(entry, kernel_dir)).build(options=list(flags), cache_dir=False)


def kernel_arguments(kernel: cl.Kernel) -> list[tuple[str, str, int]]:
    info = cl.kernel_arg_info
    return [
        (
            kernel.get_arg_info(i, info.NAME),
            kernel.get_arg_info(i, info.TYPE_NAME),
            kernel.get_arg_info(i, info.ADDRESS_QUALIFIER),
        )
        for i in range(kernel.get_info(cl.kernel_info.NUM_ARGS))
    ]


def expected(args: tuple[SceneArg, ...]) -> list[tuple[str, str, int]]:
    return [(a.name, a.cl_type + "*" if a.buffer else a.cl_type, GLOBAL if a.buffer else PRIVATE) for a in args]


def test_every_entry_kernel_takes_the_scene_arguments_the_host_reads_from_the_header():
    assert len(SCENE_ARGS) == 26 and SCENE_ARGS[0] == SceneArg("tri_v", "float4", True)
    for entry, kernels in ENTRIES.items():
        program = built(entry)
        for name in kernels:
            got = kernel_arguments(cl.Kernel(program, name))
            assert got[: len(SCENE_ARGS)] == expected(SCENE_ARGS), (entry, name)
    # The FIXED_PROPOSAL hook appends one buffer after the list.
    got = kernel_arguments(cl.Kernel(built("render.cl", flags=FLAGS + ("-D FIXED_PROPOSAL",)), "render_rays"))
    assert got[len(SCENE_ARGS)] == ("proposal_material", "float4*", GLOBAL)


def test_the_renderer_passes_one_value_of_the_headers_kind_per_argument():
    scene = box_room(size=(4, 3))
    for proposal in (None, Maps.uniform(size=scene.maps.atlas_shape, kd=0.3, cube=4)):
        renderer = Renderer(scene, Features.everything(max_bounces=1), proposal=proposal)
        assert len(renderer.scene_args) == len(SCENE_ARGS) + (proposal is not None)
        for arg, value in zip(SCENE_ARGS, renderer.scene_args):
            if arg.buffer:
                assert isinstance(value, cl.Buffer), arg
            else:
                assert value.dtype == np.dtype({"int": np.int32, "float": np.float32}[arg.cl_type]), arg
    bad = renderer.host
    bad.em_cdf = bad.em_cdf.astype(np.float64)  # the kernel would read garbage: refused
    with pytest.raises(ValueError, match=r"HostScene\.em_cdf: expected float elements"):
        bad.upload(renderer.context, 0.25, 0.25)


def altered_kernels(tmp_path, edit) -> tuple:
    """A copy of kernels/ whose scene_data.h is edited."""
    kernel_dir = tmp_path / "kernels"
    shutil.copytree(prog.KERNEL_DIR, kernel_dir)
    header = kernel_dir / "scene_data.h"
    header.write_text(edit(header.read_text()))
    return kernel_dir, header


def test_a_reordered_list_is_caught_and_followed(tmp_path):
    """Swapping two buffers of one type leaves every signature valid: only the names tell."""
    lines = (prog.KERNEL_DIR / "scene_data.h").read_text().splitlines(keepends=True)
    i, j = (
        next(k for k, line in enumerate(lines) if f"BUFFER(float, {name})" in line) for name in ("env_cdf", "env_pmf")
    )
    lines[i], lines[j] = lines[j], lines[i]
    kernel_dir, header = altered_kernels(tmp_path, lambda _: "".join(lines))
    got = kernel_arguments(cl.Kernel(built("render.cl", kernel_dir), "render_rays"))[: len(SCENE_ARGS)]
    assert got != expected(SCENE_ARGS)  # the shipped host list no longer agrees ...
    assert got == expected(read_scene_data(header))  # ... and the host reads the new order


@pytest.mark.parametrize(
    "old, new, message",
    [
        ("BUFFER(float2, tri_uv) NEXT", "BUFFER(float2, tri_uv) NEXT BUFFER(int, x) NEXT", "expected `"),
        ("BUFFER(int, tri_id) NEXT", "BUFFER(int, tri_id)", "NEXT and a backslash go together"),
        ("BUFFER(float, env_pmf)", "BUFFER(double, env_pmf)", "type 'double'"),
        ("BUFFER(float, env_pmf)", "BUFFER(float, env_cdf)", "env_cdf listed twice"),
        ("SCENE_DATA(BUFFER, VALUE, NEXT)", "SCENE_DATA(ARRAY, VALUE, NEXT)", "expected one line starting"),
    ],
)
def test_the_host_refuses_a_list_of_another_form(tmp_path, old, new, message):
    """Loudly, naming the line, rather than passing the kernels what it guessed."""
    text = (prog.KERNEL_DIR / "scene_data.h").read_text()
    line = text[: text.index(old)].count("\n") + 1
    _, header = altered_kernels(tmp_path, lambda t: t.replace(old, new))
    where = "" if old.startswith("SCENE_DATA") else f":{line}"  # a missing start has no line
    with pytest.raises(ValueError, match=rf"scene_data\.h{where}: {message}"):
        read_scene_data(header)


def test_the_gradient_layout_comes_from_the_host():
    """adjoint.cl keeps no copy of the map order or channel layout: without the host's defines
    it does not build, and says why."""
    with pytest.raises(cl.RuntimeError, match="LAYOUT_DEFINES"):
        built("adjoint.cl", flags=Features.everything(max_bounces=2).defines())
