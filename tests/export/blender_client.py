"""Blender as a USD client: import an export with Blender's own importer, report what it made, and
render one camera with Cycles. Run by Blender's Python module (bpy) in its own interpreter, so
that Blender's state never enters pytest (test_export_blender.py starts it):

    python blender_client.py REQUEST.json OUT_DIR

REQUEST: {"usd": path, "camera": name, "width": W, "height": H, "points": [[x, y, z], ...] in
the stage's frame, "spp": n, "seed": s, "bounces": B, "renders": {name: {"specular": bool}}}.
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
    return {"file": Path(bpy.path.abspath(image.filepath)).name, "size": list(image.size),
            "colorspace": image.colorspace_settings.name, "mean": rgb}


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
    for name in ("Base Color", "Specular Tint", "Roughness", "Emission Color", "Emission Strength", "IOR",
                 "Specular IOR Level", "Metallic"):
        socket = principled.inputs[name]
        value = socket.default_value
        inputs[name] = {"texture": _linked_image(socket),
                        "value": list(value) if hasattr(value, "__len__") else float(value)}
    return {"inputs": inputs, "distribution": principled.distribution}


def world_facts(world):
    nodes = world.node_tree.nodes
    background = next(n for n in nodes if n.bl_idname == "ShaderNodeBackground")
    return {"texture": _linked_image(background.inputs["Color"]),
            "strength": background.inputs["Strength"].default_value}


def scene_facts(scene, request):
    meshes, lights, cameras, materials = {}, [], {}, {}
    for obj in scene.objects:
        if obj.type == "MESH":
            meshes[obj.name] = {"vertices": len(obj.data.vertices), "faces": len(obj.data.polygons),
                                "triangles": sum(len(p.vertices) - 2 for p in obj.data.polygons),
                                "materials": [s.material.name for s in obj.material_slots if s.material]}
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
    return {"meshes": meshes, "lights": lights, "materials": materials, "world": world_facts(scene.world),
            "camera_pixels": pixels, "blender": bpy.app.version_string}


def configure_cycles(scene, request):
    """Cycles set to our renderer's model of light transport: B scattering events of every kind, no
    clamping, no glossy filter, no denoiser, one sample per pixel area (box filter), linear output."""
    scene.render.engine = "CYCLES"
    cycles = scene.cycles
    cycles.device = "CPU"
    cycles.samples = request["spp"]
    cycles.seed = request["seed"]
    cycles.use_adaptive_sampling = False
    cycles.use_denoising = False
    bounces = request["bounces"]
    cycles.max_bounces = cycles.diffuse_bounces = cycles.glossy_bounces = cycles.transmission_bounces = bounces
    cycles.sample_clamp_direct = cycles.sample_clamp_indirect = 0.0  # Cycles' default clamps indirect at 10
    cycles.blur_glossy = 0.0
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
    scene.camera = scene.objects[request["camera"]]


_IMPORTED_LEVEL = {}  # each Principled BSDF's Specular IOR Level as the importer set it


def set_specular(enabled):
    """Specular IOR Level 0 removes the Principled BSDF's specular layer (and with it the dimming of
    the diffuse beneath it): the diffuse-only model, comparable with our renderer's Lambertian one."""
    for material in bpy.data.materials:
        for node in material.node_tree.nodes if material.node_tree else ():
            if node.bl_idname == "ShaderNodeBsdfPrincipled":
                level = node.inputs["Specular IOR Level"]
                imported = _IMPORTED_LEVEL.setdefault((material.name, node.name), level.default_value)
                level.default_value = imported if enabled else 0.0


def main(request_path, out_dir):
    request = json.loads(Path(request_path).read_text())
    out_dir = Path(out_dir)
    scene = import_usd(request["usd"])
    facts = scene_facts(scene, request)
    configure_cycles(scene, request)
    for name, render in request["renders"].items():
        set_specular(render.get("specular", True))
        scene.render.filepath = str(out_dir / f"{name}.exr")
        bpy.ops.render.render(write_still=True)
    (out_dir / "facts.json").write_text(json.dumps(facts, indent=1))


if __name__ == "__main__":
    main(*sys.argv[1:3])
