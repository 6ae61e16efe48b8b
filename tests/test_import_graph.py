"""The package's layers, checked on every module's imports (function-level ones included):

- scene/ (formats) imports nothing else of invrender;
- render/ (the renderer library) imports scene/ and itself;
- assets/ (the asset library: furniture meshes and their retrieval) imports scene/, render/ and itself;
- a stage package imports the libraries and itself, never another stage;
- tooling (bench/, mitsuba/, cli.py) may import anything, and nothing but tooling imports it.

docs/architecture.md explains the layers; a new arrow fails here."""

import ast
from pathlib import Path

import pytest

PACKAGE = Path(__file__).resolve().parents[1] / "workflow" / "invrender"
LIBRARIES = {"scene": {"scene"}, "render": {"scene", "render"}, "assets": {"scene", "render", "assets"}}
TOOLING = {"bench", "mitsuba", "cli", "__init__", "__main__"}
TEST_ONLY = {"mitsuba", "drjit"}  # the reference renderer: tests and benchmarks only


def top_level_units() -> set[str]:
    return {
        p.stem if p.is_file() else p.name
        for p in PACKAGE.iterdir()
        if (p.is_dir() and (p / "__init__.py").exists()) or (p.is_file() and p.suffix == ".py")
    }


def unit_of(path: Path) -> str:
    return path.relative_to(PACKAGE).parts[0].removesuffix(".py")


def invrender_imports(path: Path, source: str | None = None) -> set[str]:
    """The top-level units of invrender that a module imports, relative or absolute."""
    tree = ast.parse(source if source is not None else path.read_text(encoding="utf-8"))
    package = path.relative_to(PACKAGE).parent.parts
    found = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            names = [alias.name.split(".") for alias in node.names]
        elif isinstance(node, ast.ImportFrom):
            if node.level == 0:
                names = [(node.module or "").split(".")]
            else:
                base = list(package[: len(package) - node.level + 1])
                module = base + (node.module.split(".") if node.module else [])
                names = [["invrender", *module]] if module else [["invrender", alias.name] for alias in node.names]
        else:
            continue
        found |= {parts[1] for parts in names if parts[0] == "invrender" and len(parts) > 1}
        found |= {f"{parts[0]} (a test and benchmark dependency)" for parts in names if parts[0] in TEST_ONLY}
        if isinstance(node, ast.ImportFrom) and node.level and not node.module and len(package) == node.level - 1:
            found |= {alias.name for alias in node.names}
    return found


def allowed(unit: str, stages: set[str]) -> set[str] | None:
    """What `unit` may import (None: anything)."""
    if unit in TOOLING:
        return None
    if unit in LIBRARIES:
        return LIBRARIES[unit]
    assert unit in stages, unit
    return set(LIBRARIES) | {unit}


def violations(modules) -> list[str]:
    stages = top_level_units() - set(LIBRARIES) - TOOLING
    found = []
    for path, source in modules:
        unit = unit_of(path)
        allowed_for = allowed(unit, stages)
        if allowed_for is None:
            continue
        for target in sorted(invrender_imports(path, source) - allowed_for):
            found.append(f"{path.relative_to(PACKAGE)} ({unit}) imports {target}")
    return found


def all_modules():
    return [(path, None) for path in sorted(PACKAGE.rglob("*.py"))]


def test_no_layer_imports_what_it_must_not():
    assert violations(all_modules()) == []


def test_every_stage_is_a_package_with_stage_run():
    stages = top_level_units() - set(LIBRARIES) - TOOLING
    assert {"synthesize", "cameras", "geometry", "gradients", "features", "renders", "export"} <= stages
    for stage in stages:
        tree = ast.parse((PACKAGE / stage / "stage.py").read_text(encoding="utf-8"))
        names = {n.name for n in tree.body if isinstance(n, ast.FunctionDef)}
        names |= {t.id for n in tree.body if isinstance(n, ast.Assign) for t in n.targets if isinstance(t, ast.Name)}
        assert "run" in names, f"{stage}/stage.py has no run"


@pytest.mark.parametrize(
    "unit, source, arrow",
    [
        ("render", "from ..geometry import stage\n", "imports geometry"),  # library -> stage
        ("scene", "def f():\n    from ..render.renderer import Renderer\n", "imports render"),  # lazy import
        ("gradients", "from invrender.features.stage import run\n", "imports features"),  # stage -> stage
        ("export", "from ..bench import harness\n", "imports bench"),  # production -> tooling
        ("render", "import mitsuba as mi\n", "imports mitsuba (a test"),  # production -> reference renderer
    ],
)
def test_a_new_arrow_is_caught(unit, source, arrow):
    path = PACKAGE / unit / "new_module.py"
    (found,) = violations([(path, source)])
    assert arrow in found
