"""Correct correspondences per pair of copies for one matcher, scored against the true poses:
what docs/duplicates.md's ASIFT table measures (not a test: a diagnostic, like diagnose_mapping).

    PYTHONPATH=$PWD/workflow python tests/duplicates/diagnose_pairs.py CAPTURE SEGMENTATION \
        [--matcher asift] [--crop-size 512]

CAPTURE: a synthesize-duplicates folder (images/, sparse/, ground_truth/); SEGMENTATION: the
segment stage's folder of the same photo (its `source` ids name the true copies). Per pair: the
matcher's matches (the stage's extract + match_pair), how many land within 2 px of where the
true poses send the point, and the same after a 1 px fundamental-matrix RANSAC (what survives a
geometric verification).
"""

import argparse
import itertools
import sys
from pathlib import Path

import cv2
import numpy as np

from invrender.duplicates import matching
from invrender.duplicates.crops import instance_boxes, make_crop
from invrender.scene.images import read_image, read_mask

sys.path.insert(0, str(Path(__file__).parent))
from diagnose_mapping import Truth  # noqa: E402


def verified(xy_a: np.ndarray, xy_b: np.ndarray, threshold_px: float = 1.0) -> np.ndarray:
    if len(xy_a) < 8:
        return np.zeros(len(xy_a), bool)
    _, inliers = cv2.findFundamentalMat(xy_a, xy_b, cv2.USAC_MAGSAC, threshold_px, 0.9999, 10000)
    return np.zeros(len(xy_a), bool) if inliers is None else inliers.ravel().astype(bool)


def main(capture, segmentation, matcher: str, crop_size: int) -> None:
    truth = Truth(capture, segmentation)
    image = read_image(Path(capture) / "images" / "view_000.exr")[:, :, :3]
    ids = read_mask(Path(segmentation) / "masks" / "view_000.png")
    crops = {k: make_crop(image, ids, k, box, crop_size) for k, box in sorted(instance_boxes(ids).items())}
    features = {k: matching.extract(c, matcher) for k, c in crops.items()}
    print("pair, matches, correct, verified, verified correct")
    for a, b in itertools.combinations(sorted(crops), 2):
        m = matching.match_pair(features[a], features[b], matcher)
        xy_a, xy_b = crops[a].to_full(m.xy_a), crops[b].to_full(m.xy_b)
        correct = truth.errors(a, b, xy_a, xy_b) < 2.0
        kept = verified(xy_a, xy_b)
        print((a, b), len(xy_a), int(correct.sum()), int(kept.sum()), int((kept & correct).sum()), flush=True)


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("capture")
    parser.add_argument("segmentation")
    parser.add_argument("--matcher", default="asift", choices=matching.MATCHERS)
    parser.add_argument("--crop-size", type=int, default=512)
    args = parser.parse_args()
    main(args.capture, args.segmentation, args.matcher, args.crop_size)
