"""Draw docs/demo.png, the README's picture, from a demo run's results: the room's capture (a view
held out of training), the scene MILO recovered rendered from that view, and two edits of it (a
ball inserted, a lamp-ball inserted), each beside the truth through the same edit.

    .venv/bin/snakemake --cores 2            # the demo, results/ in the working directory
    .venv/bin/python docs/demo_strip.py [--results results] [--out docs/demo.png]

The panels are the PNG previews the stages write (render, edit), shown as they are.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.image as mpimg  # noqa: E402
import matplotlib.pyplot as plt  # noqa: E402

DOCS = Path(__file__).resolve().parent
# (title, path under results/room, path of the truth beside it or None)
PANELS = (
    ("capture (view 5, held out)", "capture/images/view_005.png", None),
    ("recovered scene, same view", "renders/view_005.png", None),
    ("edit: a ball inserted", "edits/ball/view_005.png", "edits/ball/view_005_truth.png"),
    ("edit: a lamp-ball inserted", "edits/lamp_ball/view_005.png", "edits/lamp_ball/view_005_truth.png"),
)


def draw(results: Path, out: Path) -> None:
    room = results / "room"
    figure, axes = plt.subplots(2, len(PANELS), figsize=(3.0 * len(PANELS), 4.8))
    for column, (title, ours, truth) in enumerate(PANELS):
        for row, (path, label) in enumerate(((ours, "recovered"), (truth, "truth, same edit"))):
            axis = axes[row, column]
            axis.axis("off")
            if path is None:
                continue
            axis.imshow(mpimg.imread(room / path), interpolation="nearest")
            axis.set_title(title if row == 0 else label, fontsize=9)
    axes[1, 0].text(0.5, 0.5, "the demo room:\n12 views of 96 x 72,\nMILO-Net trained on 10", ha="center",
                    va="center", fontsize=9, transform=axes[1, 0].transAxes)  # fmt: skip
    figure.tight_layout()
    figure.savefig(out, dpi=110)
    plt.close(figure)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--results", type=Path, default=Path("results"))
    parser.add_argument("--out", type=Path, default=DOCS / "demo.png")
    args = parser.parse_args()
    draw(args.results, args.out)
    print(args.out)


if __name__ == "__main__":
    main()
