"""The ``invrender:`` attributes the export writes beside the standard schemas.

Standard USD carries the look every tool sees (UsdGeom, UsdPreviewSurface, UsdLux, UsdGeom.Camera).
Some of a scene is not expressible there, or only up to rounding: Beckmann roughness, the window
map, COLMAP's distortion and exact double-precision poses, the original face and vertex order
(which the renderer's emitter sampling depends on). Those go into attributes named here, and the
importer uses each one only while the standard value it shadows is still the one the export
wrote: an edit made in another tool wins, an untouched stage comes back exactly.
"""

from __future__ import annotations

FORMAT = "invrender-usd"
VERSION = 1

# The layer's customLayerData: {"invrender": {"format": FORMAT, "version": VERSION}}.
LAYER_KEY = "invrender"

# Any prim made by the export: what it stands for ("surface", "light", "window", "instance").
ROLE = "invrender:role"

# Meshes (plain ones on the Mesh, instanced ones on the instanceable Xform): the scene's face
# index of each face and vertex index of each `st` value, and the scene's instance id.
FACE_INDICES = "invrender:faceIndices"
VERTEX_INDICES = "invrender:vertexIndices"
INSTANCE_ID = "invrender:instanceId"

# Materials: the exact Beckmann alpha^2 map, valid while `roughness` still reads the texture
# named by ROUGHNESS_SOURCE; the window map kw (no UsdPreviewSurface input is its equal).
KA = "invrender:ka"
ROUGHNESS_SOURCE = "invrender:roughnessSource"
KW = "invrender:kw"

# DomeLight: the kg cube map's size N (the lat-long texture is resampled back to 6 x N x N), and
# the exact cube map (stacked (6 N, N, 3)), valid while the texture file is still CUBE_SOURCE.
CUBE_SIZE = "invrender:cubeSize"
CUBE = "invrender:cube"
CUBE_SOURCE = "invrender:cubeSource"

# Cameras: the COLMAP camera exactly (model, parameters in COLMAP's order, image size, name,
# world-to-camera R and t), valid while the USD lens and transform are the ones it gives.
COLMAP_NAME = "invrender:colmap:name"
COLMAP_MODEL = "invrender:colmap:model"
COLMAP_PARAMS = "invrender:colmap:params"
COLMAP_SIZE = "invrender:colmap:size"
COLMAP_R = "invrender:colmap:R"
COLMAP_T = "invrender:colmap:t"

# v2 scenes (docs/scene-format.md): an object's Xform (role "object") keeps the object's name and
# sidedness, a material its material set's name (prim names must be identifiers; these need not).
OBJECT_NAME = "invrender:objectName"
EMISSION_SIDES = "invrender:emissionSides"
MATERIAL_SET = "invrender:materialSet"
