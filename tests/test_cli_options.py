"""The command line's options mean one thing wherever they are given: -v/-q after the subcommand too,
``mdsr run --quiet`` is ``mdsr -q run``, and ``--vector-format`` alone asks for vector figures."""

from __future__ import annotations

import json
import logging

import pytest

from mdsr_opt.cli.main import main


@pytest.fixture
def mdsr_logger():
    logger = logging.getLogger("mdsr_opt")
    yield logger
    logger.setLevel(logging.NOTSET)
    for h in [h for h in logger.handlers if getattr(h, "_mdsr_cli", False)]:
        logger.removeHandler(h)


def _cli_format(logger) -> str:
    (handler,) = [h for h in logger.handlers if getattr(h, "_mdsr_cli", False)]
    return handler.formatter._fmt


@pytest.mark.parametrize("before, after", [(["-v"], []), ([], ["-v"]), ([], ["--verbose"])])
def test_verbose_before_or_after_the_subcommand_is_the_same(mdsr_logger, capsys, before, after):
    assert main([*before, "list", *after]) == 0
    assert mdsr_logger.level == logging.INFO and "%(name)s" in _cli_format(mdsr_logger)


def test_verbosity_counts_add_up_and_quiet_after_the_subcommand_is_the_global_quiet(mdsr_logger, capsys):
    assert main(["list", "-vv"]) == 0
    assert mdsr_logger.level == logging.DEBUG
    assert main(["-v", "list", "-v"]) == 0
    assert mdsr_logger.level == logging.DEBUG
    assert main(["list"]) == 0
    assert mdsr_logger.level == logging.INFO and "%(name)s" not in _cli_format(mdsr_logger)
    assert main(["list", "-q"]) == 0
    assert mdsr_logger.level == logging.WARNING


def test_run_quiet_is_the_global_quiet(mdsr_logger, capsys, tmp_path):
    """``mdsr run ... --quiet`` had a meaning of its own (progress lines dropped, the library's log kept)."""
    assert main(["run", str(tmp_path / "no_such_scene.toml"), "--out", str(tmp_path / "o"), "--quiet"]) == 2
    assert mdsr_logger.level == logging.WARNING
    assert "no_such_scene" in capsys.readouterr().err


_FIGURE_SCRIPT = """
import os

OUTPUTS = ("a.png",)


def run_figure(out, resolution="medium", log=print{signature}):
    import matplotlib.pyplot as plt
    from mdsr_opt.plot.common import save_figure

    save_figure(plt.figure(), os.path.join(out, "a.png"), close=True{call})
    return 0
"""


def test_vector_format_alone_asks_for_vector_figures(tmp_path, capsys, monkeypatch):
    """``--vector-format svg`` without ``--vector`` wrote no SVG and said nothing; now it implies --vector
    (and a script that writes no vector figures refuses it at the door, as it refuses --vector)."""
    lib = tmp_path / "lib"
    lib.mkdir()
    (lib / "takes.py").write_text(_FIGURE_SCRIPT.format(signature=", vector=None", call=", vector=vector"))
    (lib / "plain.py").write_text(_FIGURE_SCRIPT.format(signature="", call=""))
    monkeypatch.setenv("MDSR_PROBLEMS", str(lib))
    assert main(["run", "takes", "--out", str(tmp_path / "t"), "--vector-format", "svg"]) == 0
    assert "<svg" in (tmp_path / "t" / "a.svg").read_text()
    assert json.loads((tmp_path / "t" / ".mdsr-run.json").read_text())["files"] == ["a.png", "a.svg"]
    assert main(["run", "takes", "--out", str(tmp_path / "n")]) == 0  # neither option: PNG only
    assert sorted(p.name for p in (tmp_path / "n").iterdir() if not p.name.startswith(".")) == ["a.png"]
    assert main(["run", "plain", "--out", str(tmp_path / "p"), "--vector-format", "pdf"]) == 2
    assert "writes no vector figures" in capsys.readouterr().err and not (tmp_path / "p").exists()


@pytest.mark.parametrize("extra, said", [
    (["--no-figures", "--vector"], "--vector writes the figures as vector files too: it cannot go with --no-figures"),
    (["--vector-format", "svg", "--no-figures"], "--vector-format writes the figures as vector files too"),
    (["--no-photos", "--photo-size", "300x300"], "--photo-size sets the size of the synthetic photographs"),
])
def test_options_that_contradict_each_other_are_refused_at_the_door(tmp_path, capsys, extra, said):
    """A new user's trial: ``--no-figures --vector`` and ``--no-photos --photo-size`` ran and silently ignored
    one of the two; now exit 2 with one line, and no folder."""
    out = tmp_path / "o"
    assert main(["run", "one_muscle", "--out", str(out), *extra]) == 2
    err = capsys.readouterr().err
    assert said in err and "Traceback" not in err and not out.exists()


@pytest.mark.parametrize("columns", [80, 120])
def test_the_progress_bar_keeps_its_bar_in_the_terminals_width(monkeypatch, columns):
    """In an 80-column terminal the current stage beside the bar (up to 48 characters, then the rate) left
    the bar one column; the stage is now shortened to the width, the bar keeps at least 10 columns."""
    from mdsr_opt.core import progress

    monkeypatch.setattr(progress, "_terminal_width", lambda: columns)
    with progress.Progress(12, "mdsr run", enabled=True, stream=None, unit="stage") as log:
        stage = "[plate_mm 1/2 curl] design (flattened, cable): commanded a = [0.265], achieved [0.265]"
        log(stage)
        log.advance(5)
        shown = log._bar.format_dict
        line = log._bar.format_meter(**dict(shown, ncols=columns))
    bar = line.split("|")[1]
    assert len(line) <= columns and len(bar) >= progress.MIN_BAR, line
    assert "[plate_mm 1/2 curl] des" in line and line.endswith("...]"), line


@pytest.mark.parametrize("name, said", [("gait", "[s] gait: not made (no layout)"),
                                        ("wave", "[s] gait wave: not made (no layout)")])
def test_the_log_names_a_gait_once(monkeypatch, tmp_path, name, said):
    """A gait with the default name "gait" was logged as "gait gait: ..."."""
    from types import SimpleNamespace

    import numpy as np

    from mdsr_opt.synthesis import poses
    from mdsr_opt.scenes.gaitrun import run_gait
    from mdsr_opt.synthesis.gait import Gait

    def no_layout(*args, **kwargs):
        raise ValueError("no layout")

    monkeypatch.setattr(poses, "design_poses", no_layout)
    runs = {c: SimpleNamespace(setup=SimpleNamespace(target=np.zeros((3, 2)), muscles=()), design=None)
            for c in ("a", "b")}
    from mdsr_opt import Mesh

    mesh = Mesh.rectangle(1.0, 1.0, 2, 2)  # the fixtures' default wall is a fraction of the body's size
    scene = SimpleNamespace(name="s", gait=Gait(name, ("a", "b")), mesh=mesh, material=None, routing_options={},
                            design_options={}, units=None)
    lines = []
    info = run_gait(scene, tmp_path, runs, log=lines.append)
    assert lines == [said] and info["success"] is False
