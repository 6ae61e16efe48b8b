"""The slurm profile's per-rule resources from Snakemake's `benchmark:` records.

    python workflow/profiles/slurm/resources.py results [more results dirs ...]

reads every results/<scene>/benchmarks/<rule>.tsv (and <rule>/<wildcards>.tsv of the per-instance
rules), takes each rule's worst case over scenes and runs, and prints `set-resources:` for
workflow/profiles/slurm/config.yaml. The headroom, because a cluster's limits kill a job that
exceeds them and the records come from the demo's small scenes on a busy 2-core machine:

- mem_mb: twice the largest max_rss, rounded up to 500 MB, at least 1000 MB (one Python process
  importing the stack is some 200-500 MB before it reads anything);
- runtime (minutes): ten times the longest wall time, rounded up, at least 5 (SLURM counts whole
  minutes; a queue's backfill favours short, honest limits);
- cpus_per_task: the largest cpu_time / s, rounded up (the parallelism the stage used; PoCL and
  torch use what the allocation gives, so 2 on a 2-core machine means "more would help").

Rules whose runtime follows the config (milo_train: common.smk, milo_runtime) get no runtime.
Re-run this on the benchmarks of your own captures and paste its output into the profile,
leaving out the localrules (the Snakefile's: they run on the login node).
"""

from __future__ import annotations

import csv
import math
import sys
from pathlib import Path

# Each rule writes results/{scene}/benchmarks/<rule>.tsv, or <rule>/<wildcards>.tsv per instance.
RUNTIME_FROM_CONFIG = {"milo_train"}
MEM_STEP_MB = 500
MIN_MEM_MB = 1000
MIN_RUNTIME_MIN = 5
TIME_FACTOR = 10
MEM_FACTOR = 2


def records(results_dirs) -> dict[str, list[dict[str, float]]]:
    """{rule: [{s, max_rss, cpu_time}, ...]} over every benchmark file under the results dirs."""
    found: dict[str, list[dict[str, float]]] = {}
    for results in map(Path, results_dirs):
        for tsv in sorted(results.glob("*/benchmarks/**/*.tsv")):
            benchmarks = next(p for p in tsv.parents if p.name == "benchmarks")
            parts = tsv.relative_to(benchmarks).parts
            rule = parts[0] if len(parts) > 1 else tsv.stem
            with tsv.open() as f:
                for row in csv.DictReader(f, delimiter="\t"):
                    values = {key: row[key] for key in ("s", "max_rss", "cpu_time")}
                    if "NA" in values.values():
                        continue
                    found.setdefault(rule, []).append({k: float(v) for k, v in values.items()})
    return found


def resources(rows: list[dict[str, float]], rule: str) -> dict[str, int]:
    """One rule's request from its records, with the headroom in the module's docstring."""
    rss = max(row["max_rss"] for row in rows)
    seconds = max(row["s"] for row in rows)
    parallel = max(row["cpu_time"] / row["s"] for row in rows if row["s"] > 0)
    request = {"mem_mb": max(MIN_MEM_MB, math.ceil(MEM_FACTOR * rss / MEM_STEP_MB) * MEM_STEP_MB)}
    if rule not in RUNTIME_FROM_CONFIG:
        request["runtime"] = max(MIN_RUNTIME_MIN, math.ceil(TIME_FACTOR * seconds / 60))
    request["cpus_per_task"] = max(1, math.ceil(parallel - 0.05))  # 1.02 cores is one core
    return request


def main(argv: list[str]) -> int:
    if not argv:
        print(__doc__, file=sys.stderr)
        return 2
    found = records(argv)
    print("set-resources:")
    for rule in sorted(found):
        rows = found[rule]
        request = resources(rows, rule)
        worst = f"max_rss {max(r['max_rss'] for r in rows):.0f} MB, s {max(r['s'] for r in rows):.1f}"
        print(f"  {rule}:  # {len(rows)} record{'s' if len(rows) > 1 else ''}: {worst}")
        for key, value in request.items():
            print(f"    {key}: {value}")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
