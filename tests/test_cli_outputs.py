"""No stage deletes or overwrites anything outside its own output path (issue 10, defect 1:
`--out f.txt` replaced the file with a directory). Every stage verb runs with --out inside a
directory of sentinels, then with --out on an existing file and on a directory it did not write;
every sentinel, and every input, keeps its bytes and its modification time."""

import pytest
from stage_runs import STAGES, args, build_inputs

from invrender.cli import main
from invrender.scene.atomic import MARKER


@pytest.fixture(scope="module")
def inputs(tmp_path_factory):
    return build_inputs(tmp_path_factory.mktemp("inputs"))


def snapshot(root):
    """Every file under root: its bytes and mtime; every directory: its entries."""
    return {
        p: (p.read_bytes(), p.stat().st_mtime_ns) if p.is_file() else sorted(q.name for q in p.iterdir())
        for p in [root, *root.rglob("*")]
    }


def sentinels(folder):
    folder.mkdir()
    (folder / "file.txt").write_text("data\n")  # `echo data > f.txt`
    (folder / "foreign").mkdir()
    (folder / "foreign" / "notes.txt").write_text("mine\n")
    (folder / "other_stage").mkdir()  # another stage's output
    (folder / "other_stage" / MARKER).write_text("not-this-stage\n")
    (folder / "other_stage" / "result.exr").write_bytes(b"\x76\x2f\x31\x01")
    (folder / "out.tmp-1a2b3c4d").mkdir()  # a temporary of older versions: not ours to judge
    (folder / ".out.tmp-looks-alike").write_text("keep\n")  # hidden, but not our temporary's form
    (folder / ".out.tmp-00000000-1-0123abcd").write_text("keep\n")  # another host's pid 1


@pytest.mark.parametrize("stage", STAGES)
def test_a_stage_touches_nothing_but_its_output(stage, inputs, tmp_path, capsys):
    folder = tmp_path / "work"
    sentinels(folder)
    before = snapshot(folder) | snapshot(inputs)
    for target in ("file.txt", "foreign", "other_stage"):
        capsys.readouterr()
        assert main(args(stage, inputs, folder / target)) == 2, target
        message = capsys.readouterr().err.strip().splitlines()[-1]
        assert f"{folder / target}: output: expected a new path" in message, message
        assert snapshot(folder) | snapshot(inputs) == before, target
    out = folder / ("features.json" if stage == "features" else "out")
    for _ in range(2):  # a new output, then its replacement
        assert main(args(stage, inputs, out)) == 0
        after = snapshot(folder) | snapshot(inputs)
        assert after.pop(folder) == sorted(before[folder] + [out.name])
        assert {p: v for p, v in after.items() if out not in (p, *p.parents)} == {
            p: v for p, v in before.items() if p != folder
        }
    assert (
        out.is_file()
        if stage == "features"
        else (out / MARKER).read_text()
        == {"synthesize": "capture", "render": "renders", "import": "scene", "import-usd": "scene"}.get(stage, stage)
        + "\n"
    )
