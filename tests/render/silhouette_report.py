"""The numbers docs/renderer.md ("Geometric gradients") quotes: agreement of the gradients with
finite differences over all 9 parameters of each test case, and the time per pass at three
image sizes. Not a test (it takes minutes); run it as

    PYTHONPATH=$PWD/workflow python tests/render/silhouette_report.py [agreement] [time]
"""

import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import test_silhouette as T  # noqa: E402

from invrender.render.silhouette import PosedScene, kernels  # noqa: E402
from invrender.scene.cameras import pinhole_camera  # noqa: E402

ROOM_POSE = [0.5, 1.5, 1.5, 0.0, 0.2, 0.0, np.log(4.0), np.log(3.0), np.log(5.0)]
OCCLUSION = [[0.25, 0.1, -0.6, 0.0, 0.4, 0.0, -0.4, -0.4, -0.4], [-0.1, 0.0, 0.8, 0.0, -0.3, 0.0, 0.2, 0.2, 0.2]]


def room_camera(width, height):
    return pinhole_camera("c", (0.3, 1.4, 0.5), (1.0, 1.2, 3.0), width, height, 70.0)


def agreement():
    every = lambda parts: [(i, j) for i in range(parts) for j in range(9)]
    cases = {
        "box with label edges": (
            [T.box_part(labels_by_axis=[0, 0, 1, 1, 0, 0])],
            [T.BOX_POSE],
            T.camera(),
            2,
            every(1),
        ),
        "box in front of another": ([T.box_part(0), T.box_part(0)], OCCLUSION, T.camera(), 1, every(2)),
        "room box from inside": ([T.room_part()], [ROOM_POSE], room_camera(T.W, T.H), 3, every(1)),
    }
    for name, args in cases.items():
        g, fd, se = T.check_against_fd(*args)
        z, rel = (g - fd) / se, np.abs(g - fd) / np.abs(fd)
        print(
            f"{name}: {len(g)} derivatives, max |z| {np.abs(z).max():.2f}, median relative difference "
            f"{100 * np.median(rel):.2f} % (max {100 * rel.max():.2f} %)"
        )


def timing(spp=16):
    rng = np.random.default_rng(0)
    parts = [T.room_part()] + [T.box_part(3) for _ in range(10)]
    params = [ROOM_POSE] + [
        [rng.uniform(-1, 2), 0.3, rng.uniform(1.5, 3.5), 0, rng.uniform(0, 3), 0, np.log(0.4), np.log(0.6), np.log(0.5)]
        for _ in parts[1:]
    ]
    k = kernels()
    for width, height in ((160, 120), (320, 240), (640, 480)):
        cam, samples = room_camera(width, height), 64 * spp * (width + height)
        for _ in range(2):  # the first builds the program
            t0 = time.perf_counter()
            posed = PosedScene(parts, np.array(params), cam)
            dev = k.upload(posed)
            t1 = time.perf_counter()
            k.forward(posed, dev, 4, spp, 0)
            t2 = time.perf_counter()
            k.interior(posed, dev, spp, 0, np.ones((height, width)))
            t3 = time.perf_counter()
            k.boundary(posed, dev, samples, 1, np.ones((4, height, width)), np.ones((height, width)))
            t4 = time.perf_counter()
        print(
            f"{width} x {height}, spp {spp}: pose + BVH + upload {t1 - t0:.2f} s, forward {t2 - t1:.2f} s, "
            f"interior {t3 - t2:.2f} s, boundary {t4 - t3:.2f} s ({samples} edge samples)"
        )


if __name__ == "__main__":
    wanted = set(sys.argv[1:]) or {"agreement", "time"}
    if "agreement" in wanted:
        agreement()
    if "time" in wanted:
        timing()
