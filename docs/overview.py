"""Draw docs/overview.png, the README's picture: for each mode, what a capture holds, the scene
recovered from it and the edits made on that scene, with the asset and material libraries the
room mode retrieves from (docs/assets/library.png, docs/materials-thumbnails.png).

    .venv/bin/python docs/overview.py [--out docs/overview.png]

A diagram, not a render: it draws boxes and text with matplotlib and cuts tiles out of the two
library sheets, so it runs in a second and needs no OpenCL device. Run it again after changing
what a mode recovers or edits (the text is below).
"""

from __future__ import annotations

import argparse
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.image as mpimg  # noqa: E402
import matplotlib.pyplot as plt  # noqa: E402
from matplotlib.patches import FancyArrowPatch, FancyBboxPatch  # noqa: E402

DOCS = Path(__file__).resolve().parent
STEPS = ("1  capture", "2  recovered scene", "3  an edit")
# mode: (capture, recovered scene, edits), as config/README.md and docs/edit.md describe them
MODES = {
    "multiview (MILO)": (
        "photographs from posed cameras\n(COLMAP or transforms.json)\nand a mesh or point cloud",
        "the mesh unwrapped, with six maps\nMILO-Net predicts: diffuse, specular,\nroughness, emission, windows, sky",
        "lamps off, a sphere inserted,\na camera nobody stood at;\nrendered and exported as USD",
    ),
    "duplicates (Structure from\nDuplicates)": (
        "one photograph of identical\nobjects (and their masks,\nif another tool made them)",
        "one shared mesh and material,\na pose per copy, the floor\nthey stand on and the sky",
        "a new sky, an object inserted,\nanother camera; USD with\nnative instancing of the copies",
    ),
    "room (PSDR-Room)": (
        "one photograph of a room,\nits depth map and a panoptic\nsegmentation",
        "the room's box, furniture from\nthe asset library, a material\nper part, the lights",
        "relight, insert an object,\nrepaint a region, a new view",
    ),
}
# tiles of the library sheets shown beside the room mode's recovered scene: (file, rows, columns)
# of its grid, and the tiles taken (row, column)
LIBRARIES = (
    ("assets/library.png", 9, 4, ((0, 0), (6, 1), (7, 0))),
    ("materials-thumbnails.png", 2, 5, ((0, 3), (0, 4), (1, 2))),
)


def tiles(name: str, rows: int, columns: int, which) -> list:
    image = mpimg.imread(DOCS / name)
    h, w = image.shape[0] / rows, image.shape[1] / columns
    return [image[int(r * h) : int((r + 1) * h), int(c * w) : int((c + 1) * w)] for r, c in which]


def draw(out: Path) -> None:
    fig = plt.figure(figsize=(12.0, 6.0), dpi=100)
    fig.patch.set_facecolor("white")
    ax = fig.add_axes((0, 0, 1, 1))
    ax.set_xlim(0, 12)
    ax.set_ylim(0, 6)
    ax.axis("off")
    left, width, gap = 2.35, 2.75, 0.45
    for k, step in enumerate(STEPS):
        ax.text(left + k * (width + gap) + width / 2, 5.65, step, ha="center", va="center", fontsize=13, weight="bold")
    for j, (mode, texts) in enumerate(MODES.items()):
        y = 4.05 - j * 1.75
        ax.text(0.15, y + 0.55, mode.replace(" (", "\n("), ha="left", va="center", fontsize=10.5, weight="bold")
        for k, text in enumerate(texts):
            x = left + k * (width + gap)
            box = FancyBboxPatch(
                (x, y),
                width,
                1.25,
                boxstyle="round,pad=0.02,rounding_size=0.08",
                fc=("#eef3fa", "#f3f7ee", "#faf1ea")[k],
            )
            box.set_edgecolor("#777777")
            ax.add_patch(box)
            ax.text(x + 0.12, y + 0.62, text, ha="left", va="center", fontsize=9.5, linespacing=1.35)
            if k < 2:
                arrow = FancyArrowPatch(
                    (x + width + 0.04, y + 0.62),
                    (x + width + gap - 0.04, y + 0.62),
                    arrowstyle="-|>",
                    mutation_scale=14,
                )
                ax.add_patch(arrow)
    # the libraries the room mode retrieves from, under its recovered scene
    x0, size = left + width + gap + 0.05, 0.42
    pictures = [tile for library in LIBRARIES for tile in tiles(*library)]
    for i, picture in enumerate(pictures):
        inset = fig.add_axes(((x0 + i * (size + 0.04)) / 12, 0.07 / 6, size / 12, size / 6))
        inset.imshow(picture)
        inset.axis("off")
    ax.text(
        x0 + len(pictures) * (size + 0.04) + 0.05,
        0.07 + size / 2,
        "from the asset and\nmaterial libraries",
        ha="left",
        va="center",
        fontsize=8.5,
        color="#555555",
    )
    fig.savefig(out, dpi=100, facecolor="white")
    plt.close(fig)


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--out", type=Path, default=DOCS / "overview.png")
    draw(parser.parse_args(argv).out)


if __name__ == "__main__":
    main()
