"""log.csv of a training stage: one row per iteration, appended as the run goes.

Each stage names its columns; a float cell is written with six significant digits. A resumed run
first drops the rows after its checkpoint (the killed run's last iterations are computed again).
"""

from __future__ import annotations

import csv
from pathlib import Path

__all__ = ["TrainingLog"]


class TrainingLog:
    def __init__(self, path, columns, resume_from: int = 0):
        self.path, self.columns = Path(path), tuple(columns)
        kept = []
        if resume_from and self.path.exists():
            with open(self.path, newline="") as handle:
                kept = [row for row in csv.DictReader(handle) if int(row["iteration"]) <= resume_from]
        with open(self.path, "w", newline="") as handle:
            writer = csv.DictWriter(handle, self.columns)
            writer.writeheader()
            writer.writerows(kept)

    def append(self, row: dict) -> None:
        with open(self.path, "a", newline="") as handle:
            csv.DictWriter(handle, self.columns).writerow({key: _cell(row[key]) for key in self.columns})


def _cell(value):
    return f"{value:.6g}" if isinstance(value, float) else value
