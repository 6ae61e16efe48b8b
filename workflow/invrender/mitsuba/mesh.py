"""Triangles of our mesh as a Mitsuba `Mesh`: flat (face) normals, texcoords for our atlas."""

from __future__ import annotations

import mitsuba as mi
import numpy as np


def mesh_object(positions, faces, uvs, name: str, bsdf=None, emitter=None, v_up: bool = False):
    """A Mitsuba mesh with flat normals, unreferenced vertices dropped. Its texcoords are
    (u, 1 - v), so that Mitsuba's bitmaps read our atlas right (textures.py), or (u, v) with
    v_up=True (for the uv AOV). bsdf and emitter are dicts or loaded objects."""
    used, faces = np.unique(faces.ravel(), return_inverse=True)
    faces = faces.reshape(-1, 3).astype(np.uint32)
    positions = np.asarray(positions, np.float32)[used]
    uv = np.asarray(uvs, np.float32)[used].copy()
    if not v_up:
        uv[:, 1] = 1.0 - uv[:, 1]
    props = mi.Properties()
    props["face_normals"] = True
    if bsdf is not None:
        props["bsdf"] = bsdf if isinstance(bsdf, mi.Object) else mi.load_dict(bsdf)
    if emitter is not None:
        props["emitter"] = emitter if isinstance(emitter, mi.Object) else mi.load_dict(emitter)
    mesh = mi.Mesh(name, len(positions), len(faces), props=props, has_vertex_texcoords=True)
    params = mi.traverse(mesh)
    for key, values in (("vertex_positions", positions), ("faces", faces), ("vertex_texcoords", uv)):
        params[key] = type(params[key])(values.ravel())  # dynamic arrays in every variant
    params.update()
    return mesh
