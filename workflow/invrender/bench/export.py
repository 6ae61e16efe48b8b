"""`invrender bench export`: what the USD export loses, measured on the demo's room and the
duplicates generator's default scene (six cans).

Three tables (docs/export.md quotes them), printed and written under ``--out`` (``export.json``,
one CSV per table, ``export_table.md``):

1. **Round trip**: export, import, render with the same seed, against the scene directory's own
   round trip (write_scene, load_scene): identical renders, or the difference instancing makes.
2. **Standard view**, part by part: the scene as a tool that knows only UsdPreviewSurface and
   UsdLux sees it (`import-usd --standard-only`), rendered by our renderer with the same seed.
3. **The roughness mapping in a GGX renderer**: Mitsuba 3 renders the room with our lobe
   (Beckmann, V-cavity; the `milo` plugin) and with UsdPreviewSurface's (GGX, Smith) at
   r = ka^(1/4) (the `usd_preview_lobe` plugin, invrender/mitsuba/usd_preview.py), everything
   else equal, sampled the same way, so the same seed gives correlated noise and the difference
   is the lobe's. Without libLLVM (scalar_rgb, the plugins called per sample) on fewer views.

PSNR is taken with the reference's 99th percentile as the peak, and the noise floor (the same
scene, another seed) is printed beside it for scale.
"""

from __future__ import annotations

import logging
import tempfile
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from ..export import export_usd, import_usd
from ..render.analysis import analyse
from ..render.renderer import Renderer
from ..scene.format import load_scene, write_scene
from ..scene.regions import classify_faces
from ..scene.types import Maps, Scene
from ..synthesize import make_duplicates, make_room
from .harness import run_report, start_run, write_report

log = logging.getLogger("invrender.bench")


@dataclass(frozen=True)
class Settings:
    mode: str
    spp: int = 256  # our renders
    mitsuba_spp: int = 256
    mitsuba_views: int | None = None  # the room's first N views in Mitsuba (None: all 6)
    room_config: tuple = ()  # overrides of the demo room's config, as (key, value) pairs


FULL = Settings("full")
QUICK = Settings(
    "quick", spp=2, mitsuba_spp=1, mitsuba_views=1, room_config=(("cameras", {"count": 2, "width": 32, "height": 24}),)
)


def scalar_settings(settings: Settings) -> Settings:
    """scalar_rgb calls the Python BSDF plugins per sample (~40x slower than llvm): one view."""
    return replace(settings, mitsuba_views=1)


def psnr(reference: np.ndarray, image: np.ndarray, mask: np.ndarray | None = None) -> float:
    """PSNR in dB, the peak being the whole reference's 99th percentile (an HDR image has no
    natural peak: this one ignores the sun and the lamps), the error over the `mask`ed pixels."""
    peak = float(np.percentile(reference, 99))
    mask = np.ones(reference.shape[:2], bool) if mask is None else mask
    mse = float(np.mean((np.asarray(image, np.float64)[mask] - reference[mask]) ** 2))
    return float("inf") if mse == 0 else 10.0 * np.log10(peak**2 / mse)


def _render(scene: Scene, features, spp: int, seed: int) -> list[np.ndarray]:
    renderer = Renderer(scene, features)
    return [renderer.render(c, spp=spp, seed=seed, aovs=False)["radiance"] for c in scene.cameras]


def _row(what: str, reference, images, masks=None) -> dict:
    """One table row: PSNR of each view against the reference, as numbers and as text."""
    masks = masks or [np.ones(r.shape[:2], bool) for r in reference]
    values = [psnr(a, b, m) for a, b, m in zip(reference, images, masks)]
    text = " / ".join("identical" if np.isinf(v) else f"{v:.1f}" for v in values)
    return {"what": what, "psnr_db": text, "psnr_per_view": [None if np.isinf(v) else v for v in values]}


def _with_maps(scene: Scene, **maps) -> Scene:
    values = {name: getattr(scene.maps, name) for name in ("kd", "ks", "ka", "ke", "kw", "kg")} | maps
    return Scene(scene.mesh, Maps(**values), scene.cameras)


def round_trips(root: Path, spp: int, room_config: dict) -> list[dict]:
    rows = []
    for name, make, config, options in (
        ("room", make_room, room_config, {}),
        ("cans", make_duplicates, {}, {}),
        ("cans, --no-instancing", make_duplicates, {}, {"instancing": False}),
    ):
        scene, metadata = make(dict(config))
        key = name.split(",")[0]
        write_scene(root / key, scene, metadata)
        write_scene(root / f"{key}_baseline", load_scene(root / key))
        baseline = load_scene(root / f"{key}_baseline")
        export_usd(root / key, root / f"{key}_usd", **options)
        import_usd(root / f"{key}_usd" / "scene.usda", root / f"{key}_back")
        back = load_scene(root / f"{key}_back")
        features = analyse(baseline)
        a, b = _render(baseline, features, spp, 1), _render(back, features, spp, 1)
        rows.append(
            _row(name, a, b)
            | {
                "max_abs_diff": max(float(np.abs(x - y).max()) for x, y in zip(a, b)),
                "positions_max_diff_m": float(np.abs(baseline.mesh.positions - back.mesh.positions).max()),
            }
        )
    return rows


def _not_seeing_lamps(scene: Scene, features) -> list[np.ndarray]:
    """Pixels whose camera ray does not hit an emitting face first: there a tool that keeps the
    texture for camera rays (materialSyncMode independent) and ours with uniform lamps differ
    only by the light the lamps cast."""
    emitter = classify_faces(scene)["emitter"]
    renderer = Renderer(scene, features)
    masks = []
    for camera in scene.cameras:
        triangle = renderer.render(camera, spp=1, seed=0)["triangle_id"]
        masks.append(~((triangle >= 0) & emitter[np.maximum(triangle, 0)]))
    return masks


def standard_view(root: Path, spp: int) -> list[dict]:
    """The room as `import-usd --standard-only` gives it, part by part (needs round_trips' files)."""
    original = load_scene(root / "room_baseline")
    import_usd(root / "room_usd" / "scene.usda", root / "room_standard", exact=False)
    standard = load_scene(root / "room_standard")
    features = analyse(original)
    reference = _render(original, features, spp, 1)
    lamps = _render(_with_maps(original, ke=standard.maps.ke), features, spp, 1)
    return [
        _row("nothing, another seed (noise floor)", reference, _render(original, features, spp, 2)),
        _row(
            "ka = roughness^4 (float32 rounding)",
            reference,
            _render(_with_maps(original, ka=standard.maps.ka), features, spp, 1),
        ),
        _row("lamps at their mean radiance (ke)", reference, lamps),
        _row(
            "the same, pixels that see a lamp directly left out",
            reference,
            lamps,
            _not_seeing_lamps(original, features),
        ),
        _row(
            "cameras from the USD lens (float32)",
            reference,
            _render(Scene(original.mesh, original.maps, standard.cameras), features, spp, 1),
        ),
        _row("all of the standard view", reference, _render(standard, features, spp, 1)),
    ]


def ggx_in_mitsuba(root: Path, spp: int, variant: str, views: int | None) -> list[dict]:
    """Our lobe against UsdPreviewSurface's, both in Mitsuba, on the room's first `views` views."""
    from .. import mitsuba as mb

    scene = load_scene(root / "room_baseline")
    bounces = analyse(scene).max_bounces
    cameras = scene.cameras[:views]
    maps = scene.maps

    def render(lobe: str, seed: int) -> list[np.ndarray]:
        bsdf = mb.milo_bsdf(maps.kd, maps.ks, maps.ka) | {"type": lobe}
        return [mb.render_mitsuba(scene, c, bounces, spp, variant, seed, bsdf=bsdf) for c in cameras]

    reference, ggx = render("milo", 1), render("usd_preview_lobe", 1)
    change = " / ".join(f"{100 * (b.mean() / a.mean() - 1):+.1f} %" for a, b in zip(reference, ggx))
    return [
        _row("nothing, another seed (noise floor)", reference, render("milo", 2)),
        _row("GGX + Smith at r = ka^(1/4) instead of Beckmann + V-cavity", reference, ggx),
        {"what": "the same: mean image brightness, GGX over ours", "psnr_db": change},
    ]


TABLES = {
    "round_trip": (
        "Round trip: export, import, render with the same seed",
        [
            ("what", "scene", "s"),
            ("psnr_db", "PSNR per view, dB", "s"),
            ("max_abs_diff", "max abs difference", ".3g"),
            ("positions_max_diff_m", "positions [m]", ".3g"),
        ],
    ),
    "standard_view": (
        "Standard view (import-usd --standard-only), the room, our renderer",
        [("what", "what differs", "s"), ("psnr_db", "PSNR per view, dB", "s")],
    ),
    "ggx": (
        "The roughness mapping in a GGX renderer: Mitsuba 3, the room",
        [("what", "what differs", "s"), ("psnr_db", "PSNR per view, dB", "s")],
    ),
}


def run(quick: bool = False, out="docs/benchmarks", device: str | None = None) -> dict:
    """The three tables; `device` is not used (our renders take the default device)."""
    settings, out, variant, notes, started, load_start = start_run(
        "export", QUICK if quick else FULL, out, scalar_settings
    )
    with tempfile.TemporaryDirectory() as tmp:
        root = Path(tmp)
        results = {"round_trip": round_trips(root, settings.spp, dict(settings.room_config))}
        results["standard_view"] = standard_view(root, settings.spp)
        results["ggx"] = ggx_in_mitsuba(root, settings.mitsuba_spp, variant, settings.mitsuba_views)
    report = run_report("export", settings, variant, notes, started, load_start, device, results)
    views = "all" if settings.mitsuba_views is None else settings.mitsuba_views
    title = (
        f"# invrender bench export ({settings.mode}; our renders {settings.spp} spp; Mitsuba {variant} "
        f"{settings.mitsuba_spp} spp, {views} room views; {report['seconds']:.0f} s)"
    )
    write_report(out, "export", title, report, TABLES, tuple(TABLES))
    return report
