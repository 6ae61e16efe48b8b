"""invrender.mitsuba and invrender.bench are tooling for the tests and benchmarks: no production
module (scene/, render/, the stages, export/, cli.py's imports at load) may import them, nor
Mitsuba itself, a test dependency."""

import ast
from pathlib import Path

import pytest

PACKAGE = Path(__file__).resolve().parents[2] / "workflow" / "invrender"
TOOLING = ("invrender.mitsuba", "invrender.bench")
FORBIDDEN = TOOLING + ("mitsuba", "drjit")


def imported_modules(path: Path) -> set[str]:
    """Absolute names of every module `path` imports, relative imports resolved."""
    parts = ["invrender", *path.relative_to(PACKAGE).with_suffix("").parts]
    package = parts if path.name == "__init__.py" else parts[:-1]
    package = package[:-1] if package[-1] == "__init__" else package
    names = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            names |= {alias.name for alias in node.names}
        elif isinstance(node, ast.ImportFrom):
            base = package[: len(package) - node.level + 1] if node.level else []
            module = ".".join(base + ([node.module] if node.module else []))
            names.add(module)
            names |= {f"{module}.{alias.name}" for alias in node.names}
    return names


def production_modules() -> list[Path]:
    tooling = {PACKAGE / "mitsuba", PACKAGE / "bench"}
    return [p for p in sorted(PACKAGE.rglob("*.py")) if not any(t in p.parents for t in tooling)]


def test_the_resolver_sees_relative_imports():
    names = imported_modules(PACKAGE / "bench" / "render.py")
    assert "invrender.bench.harness" in names and "invrender.mitsuba" in names


@pytest.mark.parametrize("path", production_modules(), ids=lambda p: str(p.relative_to(PACKAGE)))
def test_production_module_imports_no_tooling(path):
    bad = sorted(n for n in imported_modules(path) if any(n == f or n.startswith(f + ".") for f in FORBIDDEN))
    # cli.py dispatches `invrender bench` to bench/, imported inside its command only
    if path.name == "cli.py":
        bad = [n for n in bad if not n.startswith("invrender.bench")]
    assert not bad, f"{path.relative_to(PACKAGE)} imports {bad}"
