"""invrender scenes in Mitsuba 3, the reference renderer of the tests and benchmarks.

Tooling, not part of the workflow: only tests/ and bench/ import this package (mitsuba is a test
dependency). One concept per module, as Mitsuba's own plugins:

- llvm.py: which libLLVM drjit loads (imported first: it sets DRJIT_LIBLLVM_PATH);
- variant.py: DEFAULT_VARIANT (llvm_ad_rgb if usable, else scalar_rgb), `set_variant`, which
  registers the plugins below;
- milo.py: the `milo` BSDF plugin, our material model;
- usd_preview.py: the `usd_preview_lobe` BSDF plugin, milo with UsdPreviewSurface's GGX lobe;
- camera.py: the `invrender_camera` sensor plugin and `sensor_dict` for COLMAP cameras;
- textures.py: parameter maps as `bitmap` textures; mesh.py: our triangles as a Mitsuba mesh;
- envmap.py: the kg cube map as a lat-long `envmap`;
- scene.py: `scene_to_mitsuba` (and its Lambertian `scene_to_mitsuba_diffuse`), `render_mitsuba`,
  `render_aovs`, and what Mitsuba cannot express;
- diffuse.py: Mitsuba's `diffuse` BSDF on our kd atlas, for gradients;
- integrators.py: `path` and `prb` with our path length and Russian roulette.

Conventions measured on mitsuba 3.9.1 are in each module; tests/mitsuba/ checks them.
"""

from . import llvm  # noqa: F401, I001 - first: sets DRJIT_LIBLLVM_PATH before mitsuba is imported
from .camera import camera_to_world, sensor_dict
from .diffuse import diffuse_bsdf, kd_parameter
from .envmap import cube_to_latlong, default_envmap_size, envmap_directions
from .integrators import path_integrator, prb_integrator, rr_depth
from .llvm import llvm_available
from .mesh import mesh_object
from .milo import KA_MIN, milo_bsdf
from .scene import (
    lambertian_faces,
    render_aovs,
    render_mitsuba,
    scene_to_mitsuba,
    scene_to_mitsuba_diffuse,
)
from .textures import bitmap_texture
from .variant import DEFAULT_VARIANT, set_variant

__all__ = [
    "DEFAULT_VARIANT",
    "KA_MIN",
    "bitmap_texture",
    "camera_to_world",
    "cube_to_latlong",
    "default_envmap_size",
    "diffuse_bsdf",
    "envmap_directions",
    "kd_parameter",
    "lambertian_faces",
    "llvm_available",
    "mesh_object",
    "milo_bsdf",
    "path_integrator",
    "prb_integrator",
    "rr_depth",
    "render_aovs",
    "render_mitsuba",
    "scene_to_mitsuba",
    "scene_to_mitsuba_diffuse",
    "sensor_dict",
    "set_variant",
]
