"""`python -m invrender.materials thumbnails OUT.png` draws the library's contact sheet;
`python -m invrender.materials match CROP` retrieves a material for a photo crop, searches its
transform and fits its parameters, and prints the result as JSON."""

from __future__ import annotations

import argparse
import json
import sys

from ..scene.images import read_image
from ..scene.types import SceneError
from .fit import fit
from .gram import load_network
from .library import PRESETS, preset
from .retrieval import retrieve
from .thumbnails import write_contact_sheet


def _thumbnails(args) -> dict:
    height, width = write_contact_sheet(args.out, size=args.size, columns=args.columns)
    return {"out": str(args.out), "height": height, "width": width}


def _match(args) -> dict:
    crop = read_image(args.crop)
    if crop.shape[2] != 3:
        raise SceneError(args.crop, "channels", f"an RGB crop, got {crop.shape[2]} channel(s)")
    net = load_network(args.weights)
    presets = PRESETS
    if args.presets:
        try:
            presets = [preset(name) for name in args.presets.split(",")]
        except KeyError as error:
            raise SceneError("--presets", "name", str(error.args[0])) from None
    matches = retrieve(crop, presets, net=net)
    best = matches[0]
    result = fit(best.preset.type, best.preset.params(), best.transform, crop, steps=args.steps, net=net)
    return {
        "ranking": [
            {
                "preset": m.preset.name,
                "material": m.preset.material,
                "distance": m.distance,
                "transform": m.transform.as_dict(),
            }
            for m in matches[: args.top]
        ],
        "material": best.preset.material,
        "params": result.values(),
        "transform": result.transform.as_dict(),
        "loss": {
            "initial": result.losses[0] if result.losses else None,
            "final": result.losses[-1] if result.losses else None,
        },
        "seconds": result.seconds,
    }


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(prog="python -m invrender.materials", description=__doc__)
    sub = parser.add_subparsers(dest="command", required=True)
    thumbs = sub.add_parser("thumbnails", help="the library's contact sheet as a PNG")
    thumbs.add_argument("out")
    thumbs.add_argument("--size", type=int, default=128, help="swatch size in pixels")
    thumbs.add_argument("--columns", type=int, default=5)
    thumbs.set_defaults(run=_thumbnails)
    match = sub.add_parser("match", help="retrieve, place and fit a material for a photo crop")
    match.add_argument("crop", help="an RGB crop of a planar surface (PNG/JPEG sRGB or EXR linear)")
    match.add_argument("--steps", type=int, default=80, help="Adam steps of the parameter fit")
    match.add_argument("--top", type=int, default=5, help="how many ranked presets to print")
    match.add_argument("--weights", help="a state dict of the Gram network or of torchvision's VGG19")
    match.add_argument("--presets", help="comma-separated preset names to choose among (default: the whole library)")
    match.set_defaults(run=_match)
    args = parser.parse_args(argv)
    try:
        print(json.dumps(args.run(args), indent=1))
    except SceneError as error:
        print(f"error: {error}", file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":
    sys.exit(main())
