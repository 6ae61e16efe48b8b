"""The synthesize stage through the CLI: a generator config it cannot build is one line, exit 2."""

from invrender.cli import main


def test_an_impossible_generator_config_is_one_line_and_writes_nothing(tmp_path, capsys):
    config = tmp_path / "room.yaml"
    config.write_text("window: {wall: roof}\n")
    out = tmp_path / "capture"
    assert main(["synthesize", "room", "--out", str(out), "--config", str(config), "--spp", "1"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "config.window.wall" in err[0] and "roof" in err[0], err
    assert not out.exists()
