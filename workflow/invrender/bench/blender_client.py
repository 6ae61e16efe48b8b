"""Blender as a USD client: import an export with Blender's own importer, report what it made, and
render cameras with Cycles. Run by Blender's Python module (bpy) in its own interpreter, so that
Blender's state never enters the caller (tests/export/test_export_blender.py, bench/blender.py):

    python blender_client.py REQUEST.json OUT_DIR

REQUEST: {"usd": path, "width": W, "height": H, "points": [[x, y, z], ...] in the stage's frame,
"spp": n, "seed": s, "bounces": B, "renders": {name: {"camera": name, and the variant's switches:
"specular": false, "cycles_defaults": true, "f0_from_ks": true (see `apply_variant`)}}}.
OUT_DIR gets facts.json (meshes, lights, material, world, each camera's pixels of the points) and
<name>.exr per render: linear radiance, RGBA float32.

Only bpy and the standard library: this interpreter's numpy is not the project's (bpy 5.0.1
needs numpy < 2).
"""

import json
import sys
from array import array
from pathlib import Path

import bpy
from bpy_extras.object_utils import world_to_camera_view
from mathutils import Vector


def import_usd(path):
    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    scene.world = bpy.data.worlds.new("World")  # the importer puts the DomeLight into the scene's world
    result = bpy.ops.wm.usd_import(filepath=str(path))
    if result != {"FINISHED"}:
        raise RuntimeError(f"usd_import: {result}")
    return scene


def _image_facts(image):
    pixels = array("f", bytes(4 * len(image.pixels)))
    image.pixels.foreach_get(pixels)
    channels = image.channels
    rgb = [sum(pixels[c::channels]) / (len(pixels) // channels) for c in range(min(channels, 3))]
    return {
        "file": Path(bpy.path.abspath(image.filepath)).name,
        "size": list(image.size),
        "colorspace": image.colorspace_settings.name,
        "mean": rgb,
    }


def _linked_image(socket):
    """The image texture feeding a socket, through Separate Color nodes (one channel)."""
    while socket.is_linked:
        node = socket.links[0].from_node
        if node.bl_idname in ("ShaderNodeTexImage", "ShaderNodeTexEnvironment"):
            return _image_facts(node.image) | {"interpolation": node.interpolation}
        if not node.inputs:
            return None
        socket = node.inputs[0]
    return None


def material_facts(material):
    principled = next(n for n in material.node_tree.nodes if n.bl_idname == "ShaderNodeBsdfPrincipled")
    inputs = {}
    for name in (
        "Base Color",
        "Specular Tint",
        "Roughness",
        "Emission Color",
        "Emission Strength",
        "IOR",
        "Specular IOR Level",
        "Metallic",
    ):
        socket = principled.inputs[name]
        value = socket.default_value
        inputs[name] = {
            "texture": _linked_image(socket),
            "value": list(value) if hasattr(value, "__len__") else float(value),
        }
    return {"inputs": inputs, "distribution": principled.distribution}


def world_facts(world):
    nodes = world.node_tree.nodes
    background = next(n for n in nodes if n.bl_idname == "ShaderNodeBackground")
    return {
        "texture": _linked_image(background.inputs["Color"]),
        "strength": background.inputs["Strength"].default_value,
    }


def scene_facts(scene, request):
    meshes, lights, cameras, materials = {}, [], {}, {}
    for obj in scene.objects:
        if obj.type == "MESH":
            meshes[obj.name] = {
                "vertices": len(obj.data.vertices),
                "faces": len(obj.data.polygons),
                "triangles": sum(len(p.vertices) - 2 for p in obj.data.polygons),
                "materials": [s.material.name for s in obj.material_slots if s.material],
            }
            for slot in obj.material_slots:
                if slot.material and slot.material.name not in materials:
                    materials[slot.material.name] = material_facts(slot.material)
        elif obj.type == "LIGHT":
            lights.append(obj.name)
        elif obj.type == "CAMERA":
            cameras[obj.name] = obj
    # The points are in the stage's frame; the importer turns the stage (Y up) into Blender's Z up
    # by the root's transform, which every mesh inherits: a mesh's matrix_world maps its points
    # (stored in the stage's frame) into Blender's world.
    to_blender = scene.objects["room"].matrix_world
    scene.render.resolution_x, scene.render.resolution_y = request["width"], request["height"]
    scene.render.resolution_percentage = 100
    pixels = {}
    for name, camera in cameras.items():
        uv = []
        for p in request["points"]:
            ndc = world_to_camera_view(scene, camera, to_blender @ Vector(p))  # (0, 0) bottom left
            uv.append([ndc.x * request["width"], (1.0 - ndc.y) * request["height"]])
        pixels[name] = uv
    return {
        "meshes": meshes,
        "lights": lights,
        "materials": materials,
        "world": world_facts(scene.world),
        "camera_pixels": pixels,
        "blender": bpy.app.version_string,
    }


def configure_cycles(scene, request):
    """Cycles sampling as ours does: a fixed sample count, no denoiser, one pixel's area per sample
    (box filter), linear EXR output. The view transform (Standard, no look, exposure 0, gamma 1)
    applies to display and 8-bit output only; the EXR holds scene-linear radiance either way."""
    scene.render.engine = "CYCLES"
    cycles = scene.cycles
    cycles.device = "CPU"
    cycles.samples = request["spp"]
    cycles.seed = request["seed"]
    cycles.use_adaptive_sampling = False
    cycles.use_denoising = False
    cycles.pixel_filter_type = "BOX"
    cycles.filter_width = 1.0
    scene.view_settings.view_transform = "Standard"
    scene.view_settings.look = "None"
    scene.view_settings.exposure = 0.0
    scene.view_settings.gamma = 1.0
    scene.render.image_settings.file_format = "OPEN_EXR"
    scene.render.image_settings.color_depth = "32"
    scene.render.threads_mode = "FIXED"
    scene.render.threads = 2


LIGHT_PATHS = (
    "max_bounces",
    "diffuse_bounces",
    "glossy_bounces",
    "transmission_bounces",
    "sample_clamp_direct",
    "sample_clamp_indirect",
    "blur_glossy",
)


def set_light_paths(cycles, bounces, defaults=False):
    """B scattering events of every kind, no clamping, no glossy filter (our renderer's light
    transport); or, with `defaults`, what a new Cycles scene has (12 bounces but 4 diffuse and 4
    glossy, indirect samples clamped at 10, glossy filter 1)."""
    if defaults:
        for name in LIGHT_PATHS:
            setattr(cycles, name, type(cycles).bl_rna.properties[name].default)
        return
    cycles.max_bounces = cycles.diffuse_bounces = cycles.glossy_bounces = cycles.transmission_bounces = bounces
    cycles.sample_clamp_direct = cycles.sample_clamp_indirect = 0.0
    cycles.blur_glossy = 0.0


def _principled_nodes():
    for material in bpy.data.materials:
        for node in material.node_tree.nodes if material.node_tree else ():
            if node.bl_idname == "ShaderNodeBsdfPrincipled":
                yield material.node_tree, node


_IMPORTED = {}  # each Principled BSDF's inputs as the importer set them: (value, linked socket)


def _restore(tree, node, name):
    value, source = _IMPORTED.setdefault(
        (tree.name, node.name, name),
        (
            node.inputs[name].default_value
            if not hasattr(node.inputs[name].default_value, "__len__")
            else tuple(node.inputs[name].default_value),
            node.inputs[name].links[0].from_socket if node.inputs[name].is_linked else None,
        ),
    )
    for link in list(node.inputs[name].links):
        tree.links.remove(link)
    node.inputs[name].default_value = value
    if source is not None:
        tree.links.new(source, node.inputs[name])
    return source


def _ior_from_f0(tree, f0):
    """Nodes computing the dielectric IOR whose normal-incidence Fresnel is f0 (grey):
    (1 + sqrt f0) / (1 - sqrt f0)."""
    nodes = tree.nodes
    grey = nodes.new("ShaderNodeRGBToBW")
    tree.links.new(f0, grey.inputs[0])
    root = nodes.new("ShaderNodeMath")
    root.operation = "SQRT"
    tree.links.new(grey.outputs[0], root.inputs[0])
    plus, minus, ratio = (nodes.new("ShaderNodeMath") for _ in range(3))
    plus.operation, minus.operation, ratio.operation = "ADD", "SUBTRACT", "DIVIDE"
    plus.inputs[0].default_value = minus.inputs[0].default_value = 1.0
    tree.links.new(root.outputs[0], plus.inputs[1])
    tree.links.new(root.outputs[0], minus.inputs[1])
    tree.links.new(plus.outputs[0], ratio.inputs[0])
    tree.links.new(minus.outputs[0], ratio.inputs[1])
    return ratio.outputs[0]


def apply_variant(render):
    """The material as imported, changed by the variant's switches:
    - specular false: Specular IOR Level 0 removes the Principled BSDF's specular layer (and with it
      the dimming of the diffuse beneath it): the diffuse-only model, comparable with our
      renderer's Lambertian one;
    - f0_from_ks true: what the importer would make if it read specularColor as UsdPreviewSurface
      defines it (the reflectance at normal incidence, white at grazing): IOR from ks's grey
      value, Specular Tint white, instead of Specular Tint = ks at IOR 1.5 (F0 = 0.04 ks)."""
    for tree, node in _principled_nodes():
        _restore(tree, node, "Specular IOR Level")
        _restore(tree, node, "IOR")
        ks = _restore(tree, node, "Specular Tint")
        if not render.get("specular", True):
            node.inputs["Specular IOR Level"].default_value = 0.0
        if render.get("f0_from_ks") and ks is not None:
            tree.links.remove(node.inputs["Specular Tint"].links[0])
            node.inputs["Specular Tint"].default_value = (1.0, 1.0, 1.0, 1.0)
            tree.links.new(_ior_from_f0(tree, ks), node.inputs["IOR"])


def main(request_path, out_dir):
    request = json.loads(Path(request_path).read_text())
    out_dir = Path(out_dir)
    scene = import_usd(request["usd"])
    facts = scene_facts(scene, request)
    configure_cycles(scene, request)
    for name, render in request["renders"].items():
        apply_variant(render)
        set_light_paths(scene.cycles, request["bounces"], render.get("cycles_defaults", False))
        scene.camera = scene.objects[render["camera"]]
        scene.render.filepath = str(out_dir / f"{name}.exr")
        bpy.ops.render.render(write_still=True)
    (out_dir / "facts.json").write_text(json.dumps(facts, indent=1, allow_nan=False))


if __name__ == "__main__":
    main(*sys.argv[1:3])
