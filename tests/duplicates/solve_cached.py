"""The stage's run() (`invrender duplicates solve`) with the rotation search's matches, and
optionally the track matches, loaded from caches instead of matched again: the search of box-20-hd's
190 pairs takes 1-4 hours on the shared machine, what comes after it minutes. Everything after the
matching is the stage's own code (docs/duplicates.md, "Sub-pixel tracks").

    PYTHONPATH=$PWD/workflow python tests/duplicates/solve_cached.py CAMERAS SEGMENTATION CROPS OUT \
        SEARCH DENSE [KEY=JSON ...]

SEARCH: {"pairs": {(a, b): (xy_a, xy_b)}, "report": [...]} pickled (stage.match_all's return), or
a duplicates.json (its pairs' angles only); DENSE: tracks.match_pairs's matches pickled as
diagnose_mapping.load_pairs reads them, or '-' to match them again; KEY=JSON: the stage's settings.
"""

import json
import logging
import pickle
import sys
from pathlib import Path

import numpy as np

from invrender.duplicates import stage, tracks

sys.path.insert(0, str(Path(__file__).parent))
from diagnose_mapping import load_pairs  # noqa: E402


def main(cameras, segmentation, crops, out, search, dense, *values):
    logging.basicConfig(level=logging.INFO, format="%(asctime)s %(name)s %(message)s")
    settings = stage.settings_from({k: json.loads(v) for k, v in (a.split("=", 1) for a in values)})
    if search.endswith(".pkl"):
        cached = pickle.loads(Path(search).read_bytes())
        pairs, report = cached["pairs"], cached["report"]
    else:
        report = [
            {k: r[k] for k in ("pair", "angle_deg", "matches")} for r in json.loads(Path(search).read_text())["pairs"]
        ]
        pairs = {tuple(r["pair"]): (np.zeros((0, 2)), np.zeros((0, 2))) for r in report}
    stage.match_all = lambda *args, **kwargs: (pairs, [dict(r) for r in report])
    stage.matching.CropFeatures.load = staticmethod(lambda path: None)  # the search is cached
    if dense != "-":
        found = load_pairs(dense)
        tracks.match_pairs = lambda features, angles: {p: found[p] for p in angles if p in found}
        tracks.detect = lambda crop, *args, **kwargs: None  # the cache holds the keypoints' matches
    segmentation = Path(segmentation)
    stage.run(cameras, segmentation / "masks/view_000.png", segmentation / "instances.json", crops, crops, out,
              settings, progress=False)  # fmt: skip


if __name__ == "__main__":
    main(*sys.argv[1:])
