"""Which tests leave the fast tier for their time: tests/slow_tests.txt, made from a run's
``--durations=0`` report. A test whose setup, call and teardown took THRESHOLD seconds or more
there is listed (tests/conftest.py marks it `slow`); so is every test of FULL_SUITE_ONLY files
without saying so. Regenerate after adding slow tests:

    .venv/bin/python -m pytest -n 2 --durations=0 > durations.log
    .venv/bin/python tests/tiers.py durations.log
"""

from __future__ import annotations

import re
import sys
from collections import defaultdict
from pathlib import Path

THRESHOLD = 3.0  # seconds, on two cores under the load of a shared machine (about 2.5x a quiet one)
LIST = Path(__file__).with_name("slow_tests.txt")
LINE = re.compile(r"^(\d+\.\d+)s (?:setup|call|teardown)\s+(tests/\S+)$")


def durations(report: str) -> dict[str, float]:
    """Each test's seconds (setup, call and teardown added) in a --durations report."""
    seconds: dict[str, float] = defaultdict(float)
    for line in report.splitlines():
        found = LINE.match(line.strip())
        if found:
            seconds[found.group(2)] += float(found.group(1))
    return dict(seconds)


def slow_tests(seconds: dict[str, float], full_suite_only: tuple[str, ...]) -> list[str]:
    return sorted(test for test, s in seconds.items() if s >= THRESHOLD and not test.startswith(full_suite_only))


def main(path: str) -> None:
    from conftest import FULL_SUITE_ONLY

    listed = slow_tests(durations(Path(path).read_text()), tuple(f"tests/{p}" for p in FULL_SUITE_ONLY))
    header = f"# Tests out of the fast tier for their time (>= {THRESHOLD:g} s): written by tests/tiers.py\n"
    LIST.write_text(header + "".join(f"{test}\n" for test in listed))
    print(f"{LIST}: {len(listed)} tests")


if __name__ == "__main__":
    sys.path.insert(0, str(Path(__file__).parent))
    main(sys.argv[1])
