"""What each step of adjust.py does to COLMAP's poses of the copies (docs/duplicates.md, "Sub-pixel
tracks, the planar flip and one bundle adjustment"): the stage's mapping of cached matches, then
the steps of stage._subpixel_rounds one by one, the rotation error against the truth after each.

    PYTHONPATH=$PWD/workflow python tests/duplicates/diagnose_adjust.py CAPTURE SEGMENTATION PAIRS.pkl CAMERAS [ROUNDS]

CAPTURE, SEGMENTATION and PAIRS.pkl as for diagnose_mapping.py (the track matches: tracks.match_pairs
pickled as {"pairs": ...} or {"keypoints": ..., "matches": ...}); CAMERAS: the cameras stage's
folder of the capture (the photograph the patches are taken from).
"""

import logging
import sys
from pathlib import Path

import numpy as np

from invrender.duplicates import adjust, mapping, stage

sys.path.insert(0, str(Path(__file__).parent))
from diagnose_mapping import Truth, load_pairs  # noqa: E402


def main(capture, segmentation, pairs_path, cameras, rounds="3", workdir="/tmp/diagnose_adjust"):
    logging.basicConfig(level=logging.WARNING)
    truth = Truth(capture, segmentation)
    camera, photo = stage.load_photo(cameras)
    ids = stage.load_ids(Path(segmentation) / "masks/view_000.png", camera)
    names = {mapping.image_name(i): i for i in truth.T_cam}
    reg = mapping.register(workdir, truth.K, camera.width, camera.height, sorted(truth.T_cam),
                           load_pairs(pairs_path), max_error_px=2.0)  # fmt: skip
    model = reg.reconstruction

    def show(tag):
        e = truth.rotation_errors(adjust.poses_by_instance(model, names))
        print(f"{tag}: {len(e)} of {len(truth.T_cam)}, mean {e.mean():.3f} median {np.median(e):.3f} "
              f"max {e.max():.3f} deg; {model.num_points3D()} points, reprojection "
              f"{model.compute_mean_reprojection_error():.3f} px", flush=True)  # fmt: skip

    show("COLMAP")
    adjust.bundle_adjust(model, 4.0)
    show("bundle adjustment (4 px, Cauchy)")
    print("flipped:", adjust.resolve_flips(model, ids, truth.K, names))
    adjust.bundle_adjust(model, 2.0)
    show("planar flips, bundle adjustment (2 px)")
    model = mapping.retriangulate(model, workdir)
    adjust.bundle_adjust(model, 4.0)
    show("every verified match triangulated, bundle adjustment")
    gray = adjust.gray_image(photo)
    for k in range(int(rounds)):
        stats = adjust.align_tracks(model, gray, truth.K)
        adjust.bundle_adjust(model, 2.0)
        again = adjust.resolve_flips(model, ids, truth.K, names)
        if again:
            adjust.bundle_adjust(model, 2.0)
        show(f"sub-pixel round {k} ({stats.moved} of {stats.observations} moved, flipped {again})")


if __name__ == "__main__":
    main(*sys.argv[1:])
