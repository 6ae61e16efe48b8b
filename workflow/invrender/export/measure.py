"""What the USD export loses, measured on the two demo scenes: `python -m invrender.export.measure`.

Prints the tables docs/export.md quotes:

1. The round trip (export, import, render with the same seed) against the scene directory's own
   round trip (write_scene, load_scene): identical renders, or the difference instancing makes.
2. The standard view, part by part: the scene as a tool that knows only UsdPreviewSurface and
   UsdLux sees it (`import-usd --standard-only`), rendered by our renderer with the same seed.
3. The roughness mapping as a GGX renderer shows it: Mitsuba 3 (a test dependency) renders the room
   with our lobe (Beckmann, V-cavity) and with UsdPreviewSurface's (GGX, Smith) at r = ka^(1/4),
   everything else equal, sampled the same way (Beckmann half vectors), so the same seed gives
   correlated noise and the difference is the lobe's.

PSNR is taken with the reference's 99th percentile as the peak, and the noise floor (the same
scene, another seed) is printed beside it for scale.
"""

from __future__ import annotations

import argparse
import tempfile
from pathlib import Path

import numpy as np

from ..render.analysis import analyse
from ..render.renderer import Renderer
from ..scene.format import load_scene, write_scene
from ..scene.regions import classify_faces
from ..scene.types import Maps, Scene
from ..synthesize import make_duplicates, make_room
from . import export_usd, import_usd

__all__ = ["psnr", "main"]


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


def _row(label: str, reference, images, masks=None) -> str:
    masks = masks or [np.ones(r.shape[:2], bool) for r in reference]
    values = [psnr(a, b, m) for a, b, m in zip(reference, images, masks)]
    text = " / ".join("identical" if np.isinf(v) else f"{v:.1f}" for v in values)
    return f"| {label} | {text} |"


def _with_maps(scene: Scene, **maps) -> Scene:
    values = {name: getattr(scene.maps, name) for name in ("kd", "ks", "ka", "ke", "kw", "kg")} | maps
    return Scene(scene.mesh, Maps(**values), scene.cameras)


def round_trips(root: Path, spp: int) -> None:
    print("\n## Round trip: export, import, render with the same seed\n")
    print("| scene | PSNR per view, dB | max abs difference |")
    print("|---|---|---|")
    for name, make, options in (("room", make_room, {}), ("cans", make_duplicates, {}),
                                ("cans, --no-instancing", make_duplicates, {"instancing": False})):
        scene, metadata = make({})
        key = name.split(",")[0]
        write_scene(root / key, scene, metadata)
        write_scene(root / f"{key}_baseline", load_scene(root / key))
        baseline = load_scene(root / f"{key}_baseline")
        export_usd(root / key, root / f"{key}_usd", **options)
        import_usd(root / f"{key}_usd" / "scene.usda", root / f"{key}_back")
        back = load_scene(root / f"{key}_back")
        features = analyse(baseline)
        a, b = _render(baseline, features, spp, 1), _render(back, features, spp, 1)
        error = max(float(np.abs(x - y).max()) for x, y in zip(a, b))
        positions = float(np.abs(baseline.mesh.positions - back.mesh.positions).max())
        print(f"{_row(name, a, b)[:-1]}| {error:.3g} (positions: {positions:.3g} m) |")


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


def standard_view(root: Path, spp: int) -> None:
    print("\n## Standard view (import-usd --standard-only), the room, our renderer\n")
    original = load_scene(root / "room_baseline")
    import_usd(root / "room_usd" / "scene.usda", root / "room_standard", exact=False)
    standard = load_scene(root / "room_standard")
    features = analyse(original)
    reference = _render(original, features, spp, 1)
    print("| what differs | PSNR per view, dB |")
    print("|---|---|")
    print(_row("nothing, another seed (noise floor)", reference, _render(original, features, spp, 2)))
    print(_row("ka = roughness^4 (float32 rounding)", reference, _render(_with_maps(original, ka=standard.maps.ka), features, spp, 1)))
    lamps = _render(_with_maps(original, ke=standard.maps.ke), features, spp, 1)
    print(_row("lamps at their mean radiance (ke)", reference, lamps))
    print(_row("the same, pixels that see a lamp directly left out", reference, lamps, _not_seeing_lamps(original, features)))
    print(_row("cameras from the USD lens (float32)", reference,
               _render(Scene(original.mesh, original.maps, standard.cameras), features, spp, 1)))
    print(_row("all of the standard view", reference, _render(standard, features, spp, 1)))


def ggx_in_mitsuba(root: Path, spp: int) -> None:
    print("\n## The roughness mapping in a GGX renderer: Mitsuba 3, the room\n")
    try:
        from ..render import mitsuba_bridge as mb
    except ImportError as exc:  # mitsuba is a test dependency
        print(f"(skipped: {exc})")
        return
    import drjit as dr
    import mitsuba as mi

    scene = load_scene(root / "room_baseline")
    bounces = analyse(scene).max_bounces
    variant = mb.DEFAULT_VARIANT
    mb.set_variant(variant)
    milo = mb._registered[variant]["milo"]

    class UsdPreviewLobe(milo):
        """Our BSDF with UsdPreviewSurface's specular lobe: GGX D and separable Smith G at
        alpha = r^2 = sqrt(ka); sampled and weighted as ours (Beckmann half vectors), so the
        estimate is unbiased and its noise follows ours."""

        def _eval_pdf(self, si, wo, active):
            _, pdf = milo._eval_pdf(self, si, wo, active)  # the density sample() draws from
            view, light = self._local(si, wo)
            kd, ks, ka, _ = self._params(si, active)
            ci, co = light.z, view.z
            valid = active & (ci > 0) & (co > 0)
            h = dr.normalize(light + view)
            c2 = dr.square(h.z)
            d = ka / (dr.pi * dr.square(c2 * (ka - 1.0) + 1.0))  # GGX with alpha^2 = ka
            g1 = lambda c: 2.0 / (1.0 + dr.sqrt(1.0 + ka * (1.0 - dr.square(c)) / dr.square(c)))
            wih = dr.dot(light, h)
            f90 = dr.minimum(1.0, 50.0 * ks)
            fresnel = ks + (f90 - ks) * dr.power(dr.maximum(1.0 - wih, 0.0), 5)
            value = kd * (ci * dr.inv_pi) + fresnel * (d * g1(ci) * g1(co) / (4.0 * co))
            return dr.select(valid, value, 0.0), pdf

    mi.register_bsdf("usd_preview_lobe", lambda props: UsdPreviewLobe(props))
    original_bsdf = mb.milo_bsdf

    def render(lobe: str, seed: int) -> list[np.ndarray]:
        mb.milo_bsdf = lambda *a: original_bsdf(*a) | {"type": lobe}
        try:
            return [mb.render_mitsuba(scene, c, bounces, spp, variant, seed) for c in scene.cameras]
        finally:
            mb.milo_bsdf = original_bsdf

    reference = render("milo", 1)
    print(f"({variant}, {spp} spp, {bounces} bounces)\n")
    print("| what differs | PSNR per view, dB |")
    print("|---|---|")
    print(_row("nothing, another seed (noise floor)", reference, render("milo", 2)))
    ggx = render("usd_preview_lobe", 1)
    print(_row("GGX + Smith at r = ka^(1/4) instead of Beckmann + V-cavity", reference, ggx))
    change = " / ".join(f"{100 * (b.mean() / a.mean() - 1):+.1f} %" for a, b in zip(reference, ggx))
    print(f"| the same: mean image brightness, GGX over ours | {change} |")


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(prog="python -m invrender.export.measure", description=__doc__.split("\n")[0])
    parser.add_argument("--spp", type=int, default=64, help="samples per pixel of our renders")
    parser.add_argument("--mitsuba-spp", type=int, default=64, help="samples per pixel of the Mitsuba renders")
    parser.add_argument("--skip-mitsuba", action="store_true", help="only our renderer's tables")
    args = parser.parse_args(argv)
    with tempfile.TemporaryDirectory() as tmp:
        root = Path(tmp)
        round_trips(root, args.spp)
        standard_view(root, args.spp)
        if not args.skip_mitsuba:
            ggx_in_mitsuba(root, args.mitsuba_spp)


if __name__ == "__main__":
    main()
