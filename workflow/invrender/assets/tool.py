"""`invrender assets sheet|accuracy`: the library's contact sheet, and retrieval's accuracy on it
(docs/assets.md reports the numbers this prints)."""

from __future__ import annotations

import json
import logging
import time

from ..scene.atomic import atomic_path
from .accuracy import measure
from .library import library
from .sheet import write_contact_sheet

log = logging.getLogger(__name__)


def run(what: str, out=None, user_dirs=(), shots: int = 5, seed: int = 0, cache_dir=None) -> dict | None:
    assets = library(user_dirs)
    if what == "sheet":
        write_contact_sheet(out or "assets.png", assets)
        log.info("wrote %s: %d assets", out or "assets.png", len(assets))
        return None
    results = {}
    # The asset in the library; not (its siblings must give the category); the world's up not
    # given (no centring of off-centre objects); the query damaged as a photo's would be.
    for mode, leave_one_out, know_up, damage in (
        ("library", False, True, False),
        ("leave_one_out", True, True, False),
        ("library_without_up", False, False, False),
        ("library_damaged", False, True, True),
    ):
        start = time.perf_counter()
        found = measure(assets, shots, seed, leave_one_out, cache_dir, know_up, damage)
        found["seconds"] = round(time.perf_counter() - start, 1)
        results[mode] = found
        log.info(
            "%s: %d queries, category top-1 %.3f top-3 %.3f, asset top-1 %.3f, "
            "azimuth median error %s deg, within 30 deg %s (%.1f s)",
            mode,
            found["queries"],
            found["category_top1"],
            found["category_top3"],
            found["asset_top1"],
            None if found["azimuth_error_median_deg"] is None else round(found["azimuth_error_median_deg"], 1),
            None if found["azimuth_within_30deg"] is None else round(found["azimuth_within_30deg"], 3),
            found["seconds"],
        )
    if out:
        with atomic_path(out) as tmp:
            tmp.write_text(json.dumps(results, indent=1))
    return results
