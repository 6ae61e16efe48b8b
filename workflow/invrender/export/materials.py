"""The parameter maps as a UsdPreviewSurface material (specular workflow) with UsdUVTexture
textures, and back.

| UsdPreviewSurface input | from | texture | sourceColorSpace |
|---|---|---|---|
| diffuseColor | kd | textures/kd.exr (RGB float32) | raw |
| specularColor | ks | textures/ks.exr | raw |
| roughness | ka^(1/4) (roughness.py) | textures/roughness.exr (Y) | raw |
| emissiveColor | ke | textures/ke.exr | raw |
| useSpecularWorkflow | 1 | | |

Every texture is linear float32 EXR, so no tool applies an sRGB curve to it (the washed-out
textures users meet come from linear values in 8-bit files read as sRGB, or sRGB values read as
linear). `raw` says "use the values as they are", which is right for linear data; the importer
honours whatever a texture says, so an 8-bit PNG put in by another tool is decoded from sRGB
when it says `sRGB` (or `auto`, which means sRGB for 8-bit files) and read as stored when `raw`.

Beside the standard inputs the material keeps, as invrender: assets (schema.py), the exact ka
(textures/ka.exr) and the window map kw (textures/kw.exr), which UsdPreviewSurface cannot hold.
Textures are sampled by `st` (v up, our atlas convention: row = floor((1 - v) H)) and clamp at
the border, as our renderer does; renderers filter them, we take the nearest texel.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from pxr import Gf, Sdf, Usd, UsdShade

from ..scene.images import linear_to_srgb, read_image, srgb_to_linear, write_exr
from ..scene.types import Maps, SceneError
from . import schema
from .roughness import ka_from_roughness, roughness_from_ka

__all__ = [
    "TEXTURES",
    "write_textures",
    "author_material",
    "Source",
    "MaterialSources",
    "read_material",
    "evaluate",
    "texture_shape",
]

log = logging.getLogger(__name__)

TEXTURES = "textures"
# Standard input <- (texture file, UsdUVTexture output, Sdf type of the input).
STANDARD_INPUTS = {
    "diffuseColor": ("kd", "rgb", Sdf.ValueTypeNames.Color3f),
    "specularColor": ("ks", "rgb", Sdf.ValueTypeNames.Color3f),
    "roughness": ("roughness", "r", Sdf.ValueTypeNames.Float),
    "emissiveColor": ("ke", "rgb", Sdf.ValueTypeNames.Color3f),
}
EXACT_ASSETS = {schema.KA: "ka", schema.KW: "kw"}  # invrender: attribute <- texture file


def write_textures(maps: Maps, directory: Path) -> dict[str, str]:
    """Write the material's textures; return {name: path relative to the layer}."""
    images = {
        "kd": maps.kd,
        "ks": maps.ks,
        "ke": maps.ke,
        "roughness": roughness_from_ka(maps.ka),
        "ka": maps.ka,
        "kw": maps.kw,
    }
    files = {}
    for name, image in images.items():
        write_exr(directory / f"{name}.exr", image)
        files[name] = f"./{TEXTURES}/{name}.exr"
    return files


def author_material(stage: Usd.Stage, path: str, files: dict[str, str]) -> UsdShade.Material:
    """A UsdPreviewSurface material reading the textures `write_textures` wrote (module docstring)."""
    material = UsdShade.Material.Define(stage, path)
    reader = UsdShade.Shader.Define(stage, f"{path}/st")
    reader.CreateIdAttr("UsdPrimvarReader_float2")
    reader.CreateInput("varname", Sdf.ValueTypeNames.String).Set("st")
    st = reader.CreateOutput("result", Sdf.ValueTypeNames.Float2)
    surface = UsdShade.Shader.Define(stage, f"{path}/surface")
    surface.CreateIdAttr("UsdPreviewSurface")
    surface.CreateInput("useSpecularWorkflow", Sdf.ValueTypeNames.Int).Set(1)
    for input_name, (texture, output, value_type) in STANDARD_INPUTS.items():
        shader = UsdShade.Shader.Define(stage, f"{path}/{texture}")
        shader.CreateIdAttr("UsdUVTexture")
        shader.CreateInput("file", Sdf.ValueTypeNames.Asset).Set(files[texture])
        shader.CreateInput("sourceColorSpace", Sdf.ValueTypeNames.Token).Set("raw")
        shader.CreateInput("wrapS", Sdf.ValueTypeNames.Token).Set("clamp")
        shader.CreateInput("wrapT", Sdf.ValueTypeNames.Token).Set("clamp")
        shader.CreateInput("st", Sdf.ValueTypeNames.Float2).ConnectToSource(st)
        out = shader.CreateOutput(output, Sdf.ValueTypeNames.Float3 if output == "rgb" else Sdf.ValueTypeNames.Float)
        surface.CreateInput(input_name, value_type).ConnectToSource(out)
    material.CreateSurfaceOutput().ConnectToSource(surface.ConnectableAPI(), "surface")
    prim = material.GetPrim()
    prim.CreateAttribute(schema.ROUGHNESS_SOURCE, Sdf.ValueTypeNames.Asset, custom=True).Set(files["roughness"])
    for attribute, texture in EXACT_ASSETS.items():
        prim.CreateAttribute(attribute, Sdf.ValueTypeNames.Asset, custom=True).Set(files[texture])
    return material


# ---------------------------------------------------------------------------------------------
# Reading a material back: each map's source, then its values over the atlas
# ---------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class Source:
    """Where one input's values come from: a constant, or a texture channel (with the
    UsdUVTexture's colour space, scale and bias)."""

    constant: tuple | None = None
    file: str | None = None  # absolute path
    channels: str = "rgb"  # "rgb" or one of "r", "g", "b", "a"
    color_space: str = "raw"
    scale: tuple = (1.0, 1.0, 1.0, 1.0)
    bias: tuple = (0.0, 0.0, 0.0, 0.0)


@dataclass(frozen=True)
class MaterialSources:
    """The sources of a material's maps; `ka_from_roughness` when ka must come from `roughness`."""

    kd: Source
    ks: Source
    ka: Source
    ke: Source
    kw: Source
    ka_from_roughness: bool = False
    metallic: Source | None = None  # set when the material uses the metallic workflow
    ior: float = 1.5  # the metallic workflow's dielectric F0 = ((1 - ior) / (1 + ior))^2

    def key(self, name: str) -> tuple:
        """What decides map `name`: two materials with equal keys give it the same values."""
        if name == "kd":
            return (self.kd, self.metallic)
        if name == "ks":
            return (self.ks, self.kd, self.metallic, self.ior) if self.metallic else (self.ks,)
        if name == "ka":
            return (self.ka, self.ka_from_roughness)
        return (getattr(self, name),)


FALLBACKS = {
    "diffuseColor": (0.18, 0.18, 0.18),
    "specularColor": (0.0, 0.0, 0.0),
    "roughness": (0.5,),
    "emissiveColor": (0.0, 0.0, 0.0),
    "metallic": (0.0,),
    "ior": (1.5,),
}  # UsdPreviewSurface's defaults


def _asset_path(value, where: str) -> str:
    path = value.resolvedPath if isinstance(value, Sdf.AssetPath) else ""
    if not path:
        raise SceneError(where, "file", f"a texture that exists, got {getattr(value, 'path', value)!r}")
    return path


def _texture_source(shader: UsdShade.Shader, output: str, where: str) -> Source:
    if shader.GetIdAttr().Get() != "UsdUVTexture":
        raise SceneError(where, f"{shader.GetPath()} info:id", "UsdUVTexture (the only texture node read)")

    def get(name, default):
        value = shader.GetInput(name).Get() if shader.GetInput(name) else None
        return default if value is None else value

    file = _asset_path(get("file", None), f"{where} {shader.GetPath()}")
    return Source(
        file=file,
        channels=output,
        color_space=str(get("sourceColorSpace", "auto")),
        scale=tuple(get("scale", Gf.Vec4f(1, 1, 1, 1))),
        bias=tuple(get("bias", Gf.Vec4f(0, 0, 0, 0))),
    )


def _input_source(surface: UsdShade.Shader, name: str, where: str) -> Source:
    """The source of a UsdPreviewSurface input: a connected UsdUVTexture, else its value or fallback."""
    surface_input = surface.GetInput(name)
    if surface_input:
        for attribute in surface_input.GetValueProducingAttributes():
            kind = UsdShade.Utils.GetType(attribute.GetName())
            if kind == UsdShade.AttributeType.Output:
                output = UsdShade.Utils.GetBaseNameAndType(attribute.GetName())[0]
                return _texture_source(UsdShade.Shader(attribute.GetPrim()), output, where)
            value = attribute.Get()
            if value is not None:
                return Source(constant=tuple(np.atleast_1d(np.asarray(value, np.float64)).tolist()))
    return Source(constant=FALLBACKS[name])


def _exact_source(prim: Usd.Prim, attribute: str) -> Source | None:
    attr = prim.GetAttribute(attribute)
    value = attr.Get() if attr and attr.HasAuthoredValue() else None
    if not isinstance(value, Sdf.AssetPath) or not value.resolvedPath:
        return None
    return Source(file=value.resolvedPath, channels="r")


def read_material(material: UsdShade.Material | None, where: str, exact: bool = True) -> MaterialSources:
    """The sources of a bound material's maps (UsdPreviewSurface, either workflow). ka comes from the
    exact invrender: map while `roughness` still reads the texture the export wrote, else from r^4;
    kw from its invrender: map, else 0. Without a material: UsdPreviewSurface's fallbacks."""
    surface = None
    if material:
        shader = material.ComputeSurfaceSource()[0]
        if shader and shader.GetIdAttr().Get() == "UsdPreviewSurface":
            surface = shader
        elif shader:
            log.warning(
                "%s: surface shader %s is not a UsdPreviewSurface: its fallbacks are used",
                where,
                shader.GetIdAttr().Get(),
            )
    if surface is None:
        return MaterialSources(
            *(Source(constant=FALLBACKS[n]) for n in ("diffuseColor", "specularColor")),
            Source(constant=FALLBACKS["roughness"]),
            Source(constant=FALLBACKS["emissiveColor"]),
            Source(constant=(0.0,)),
            ka_from_roughness=True,
        )
    sources = {name: _input_source(surface, name, where) for name in STANDARD_INPUTS}
    prim = material.GetPrim()
    exact_ka = _exact_source(prim, schema.KA) if exact else None
    roughness_file = _exact_source(prim, schema.ROUGHNESS_SOURCE)
    untouched = roughness_file is not None and sources["roughness"] == Source(file=roughness_file.file, channels="r")
    kw = (_exact_source(prim, schema.KW) if exact else None) or Source(constant=(0.0,))
    workflow = surface.GetInput("useSpecularWorkflow")
    specular = bool(workflow.Get()) if workflow and workflow.Get() is not None else False
    metallic = None if specular else _input_source(surface, "metallic", where)
    ior = _input_source(surface, "ior", where).constant if not specular else None
    workflow = {"metallic": metallic, "ior": float(ior[0]) if ior else 1.5}
    if exact_ka is not None and untouched:
        return MaterialSources(
            sources["diffuseColor"], sources["specularColor"], exact_ka, sources["emissiveColor"], kw, **workflow
        )
    return MaterialSources(
        sources["diffuseColor"],
        sources["specularColor"],
        sources["roughness"],
        sources["emissiveColor"],
        kw,
        ka_from_roughness=True,
        **workflow,
    )


def _read_texture(path: str, color_space: str) -> np.ndarray:
    """A texture's linear values as the UsdUVTexture would give them (8-bit files are sRGB unless raw)."""
    image = read_image(path)  # EXR as stored, PNG / JPEG decoded from sRGB
    eight_bit = Path(path).suffix.lower() not in (".exr", ".hdr")
    if eight_bit and color_space == "raw":
        return linear_to_srgb(image).astype(np.float32)  # undo the decoding: the stored values / 255
    if not eight_bit and color_space == "sRGB":
        return srgb_to_linear(image).astype(np.float32)
    return image


def texture_shape(source: Source) -> tuple[int, int] | None:
    if source.file is None:
        return None
    return _read_texture_cached(source.file, source.color_space).shape[:2]


_CACHE: dict = {}  # materials share textures: read each once per import


def _read_texture_cached(path: str, color_space: str) -> np.ndarray:
    stat = Path(path).stat()
    key = (path, stat.st_mtime_ns, stat.st_size, color_space)  # a rewritten file is read again
    if key not in _CACHE:
        if len(_CACHE) >= 16:
            _CACHE.clear()
        _CACHE[key] = _read_texture(path, color_space)
    return _CACHE[key]


CHANNEL = {"r": 0, "g": 1, "b": 2, "a": 3}


def evaluate(source: Source, shape: tuple[int, int], channels: int) -> np.ndarray:
    """A source's values at the centre of every texel of an (H, W) atlas: (H, W, channels)."""
    h, w = shape
    if source.constant is not None:
        value = np.asarray(source.constant, np.float32)
        value = np.resize(value, channels) if value.size != channels else value
        return np.broadcast_to(value, (h, w, channels)).copy()
    image = _read_texture_cached(source.file, source.color_space)
    if image.shape[:2] != (h, w):  # nearest texel of the texture at each atlas texel's centre
        rows = np.minimum((np.arange(h) + 0.5) / h * image.shape[0], image.shape[0] - 1).astype(np.int64)
        cols = np.minimum((np.arange(w) + 0.5) / w * image.shape[1], image.shape[1] - 1).astype(np.int64)
        image = image[rows][:, cols]
    if image.shape[2] == 1:
        image = np.repeat(image, 3, axis=2)  # a one-channel file reads as grey
    if source.channels == "rgb":
        values, lanes = image[..., :3], slice(0, 3)
    else:
        k = min(CHANNEL[source.channels], image.shape[2] - 1)
        values, lanes = image[..., k : k + 1], slice(CHANNEL[source.channels], CHANNEL[source.channels] + 1)
    scale, bias = np.asarray(source.scale, np.float32)[lanes], np.asarray(source.bias, np.float32)[lanes]
    if np.any(scale != 1) or np.any(bias != 0):
        values = values * scale + bias
    if values.shape[2] != channels:
        values = np.repeat(values[..., :1], channels, axis=2) if values.shape[2] == 1 else values[..., :channels]
    return np.ascontiguousarray(values, np.float32)


def evaluate_maps(sources: MaterialSources, shape: tuple[int, int]) -> dict[str, np.ndarray]:
    """kd, ks, ka, ke, kw over the atlas from a material's sources. The metallic workflow is
    turned into ours: kd = base (1 - metallic), ks = F0 (1 - metallic) + base metallic with the
    dielectric F0 = ((1 - ior) / (1 + ior))^2 (0.04 at UsdPreviewSurface's default ior 1.5)."""
    kd = evaluate(sources.kd, shape, 3)
    ks = evaluate(sources.ks, shape, 3)
    if sources.metallic is not None:
        metallic = np.clip(evaluate(sources.metallic, shape, 1), 0.0, 1.0)
        f0 = ((1.0 - sources.ior) / (1.0 + sources.ior)) ** 2
        ks = f0 * (1.0 - metallic) + kd * metallic
        kd = kd * (1.0 - metallic)
    ka = evaluate(sources.ka, shape, 1)[..., 0]
    ka = ka_from_roughness(ka) if sources.ka_from_roughness else ka
    maps = {
        "kd": kd,
        "ks": ks,
        "ka": ka,
        "ke": evaluate(sources.ke, shape, 3),
        "kw": evaluate(sources.kw, shape, 1)[..., 0],
    }
    return {name: np.ascontiguousarray(values, np.float32) for name, values in maps.items()}
