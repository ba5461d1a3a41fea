"""Bad input against bugs on the command line (issue 31, item 9): bad input is one line with exit code 2, an
exception from inside the package its traceback with exit code 1 (see mdsr_opt.core.errors)."""

from __future__ import annotations

from pathlib import Path

import pytest

from mdsr_opt.cli.main import main
from mdsr_opt.core.errors import InputError, InputTypeError, checking_input, exit_report

ROOT = Path(__file__).resolve().parents[1]
FINGER = ROOT / "tests" / "data" / "finger.toml"
QUIET_RUN = ("--serial", "--no-photos", "--no-figures", "--no-animations", "--no-prototype")


def _one_line(err: str) -> str:
    lines = err.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in err, err
    return lines[0]


def _bug_report(err: str, kind: str, words: str) -> None:
    assert "Traceback (most recent call last)" in err
    assert f"{kind}: {words}" in err
    assert "internal error" in err and "bug in mdsr_opt" in err


# ---------------------------------------------------------------------------------------------- mdsr run
@pytest.mark.parametrize("kind", [TypeError, ValueError, KeyError])
def test_a_bug_inside_mdsr_run_shows_its_traceback_and_exits_1(tmp_path, capsys, monkeypatch, kind):
    """A TypeError or ValueError raised while the scene runs is the package's bug, not the user's input."""
    def broken(*a, **k):
        raise kind("injected bug")

    monkeypatch.setattr("mdsr_opt.cli.run.write_scene", broken)
    assert main(["run", str(FINGER), "--out", str(tmp_path / "o"), *QUIET_RUN]) == 1
    err = capsys.readouterr().err
    _bug_report(err, kind.__name__, "'injected bug'" if kind is KeyError else "injected bug")
    assert "in broken" in err  # the traceback reaches the raising frame


def test_a_value_error_deep_in_a_solve_is_a_bug_with_its_traceback(tmp_path, capsys, monkeypatch):
    def broken(*a, **k):
        raise ValueError("operands could not be broadcast together")

    monkeypatch.setattr("mdsr_opt.mechanics.loadsteps.min_jacobian", broken)
    assert main(["run", str(FINGER), "--out", str(tmp_path / "o"), *QUIET_RUN]) == 1
    err = capsys.readouterr().err
    _bug_report(err, "ValueError", "operands could not be broadcast together")
    assert "loadsteps.py" in err


@pytest.mark.parametrize("args, words", [
    (["no_such_robot"], "unknown problem 'no_such_robot'"),
    ([str(FINGER), "--resolution", "huge"], "resolution must be one of"),
    ([str(FINGER), "--case", "nope"], "nope"),
    ([str(FINGER), str(FINGER)], "is named twice"),
])
def test_bad_input_to_mdsr_run_is_one_line_with_exit_2(tmp_path, capsys, args, words):
    assert main(["run", *args, "--out", str(tmp_path / "o"), *QUIET_RUN]) == 2
    line = _one_line(capsys.readouterr().err)
    assert line.startswith("mdsr run: error: ") and words in line
    assert not (tmp_path / "o").exists()


def test_a_scene_file_error_is_one_line_with_exit_2(tmp_path, capsys):
    bad = tmp_path / "bad.toml"
    bad.write_text(FINGER.read_text().replace("[body]", "[body]\nno_such_field = 1", 1))
    assert main(["run", str(bad), "--out", str(tmp_path / "o"), *QUIET_RUN]) == 2
    assert "no_such_field" in _one_line(capsys.readouterr().err)


# ---------------------------------------------------------------------------------------------- other commands
def test_mdsr_study_bad_input_is_one_line_and_a_bug_inside_is_a_traceback(tmp_path, capsys, monkeypatch):
    out = str(tmp_path / "s")
    assert main(["-q", "study", "quick", "--out", out, "--methods", "no_such_method"]) == 2
    assert "no_such_method" in _one_line(capsys.readouterr().err)
    assert main(["-q", "study", "no_such_study", "--out", out]) == 2
    _one_line(capsys.readouterr().err)

    def broken(*a, **k):
        raise TypeError("injected bug in the runs")

    monkeypatch.setattr("mdsr_opt.studies.study.run_all", broken)
    assert main(["-q", "study", "quick", "--out", out, "--resolutions", "30", "--methods", "ipopt",
                 "--problems", "strip-stretch"]) == 1
    _bug_report(capsys.readouterr().err, "TypeError", "injected bug in the runs")


def test_mdsr_demo_bad_input_is_one_line_and_a_bug_inside_is_a_traceback(tmp_path, capsys, monkeypatch):
    assert main(["demo", "--out", str(tmp_path / "d"), "--max-area", "-1"]) == 2
    assert "max_area must be > 0" in _one_line(capsys.readouterr().err)

    def broken(*a, **k):
        raise TypeError("injected bug in meshing")

    monkeypatch.setattr("mdsr_opt.body.mesh.Mesh.from_polygon", broken)
    assert main(["demo", "--out", str(tmp_path / "d")]) == 1
    _bug_report(capsys.readouterr().err, "TypeError", "injected bug in meshing")


def test_mdsr_photograph_bad_option_is_one_line(tmp_path, capsys):
    from mdsr_opt import Mesh
    from mdsr_opt.body.io import write_mesh

    mesh = Mesh.rectangle(3.0, 1.0, 6, 2)
    write_mesh(tmp_path / "states" / "a.vtu", mesh)
    assert main(["photograph", str(tmp_path / "states"), "--out", str(tmp_path / "img"), "--tilt", "45"]) == 2
    assert "tilt_deg must be <= 20 degrees" in _one_line(capsys.readouterr().err)
    assert main(["photograph", str(tmp_path / "nowhere"), "--out", str(tmp_path / "img")]) == 2
    _one_line(capsys.readouterr().err)
    assert not (tmp_path / "img").exists()


def test_problem_scripts_tell_bad_input_from_bugs(tmp_path, capsys, monkeypatch):
    from mdsr_opt.scenes import runscene
    from mdsr_opt.scenes.scenefile import load_scene

    def build(resolution="medium"):
        return load_scene(FINGER, resolution)

    assert runscene.run_main(build, ["--out", str(tmp_path / "o"), "--resolution", "huge"]) == 2
    assert "resolution must be one of" in _one_line(capsys.readouterr().err)

    def broken(*a, **k):
        raise TypeError("injected bug in the run")

    monkeypatch.setattr(runscene, "run_scene", broken)
    assert runscene.run_main(build, ["--out", str(tmp_path / "o"), "--resolution", "coarse"]) == 1
    _bug_report(capsys.readouterr().err, "TypeError", "injected bug in the run")


# ---------------------------------------------------------------------------------------------- the classes
def test_checking_input_marks_value_and_type_errors_as_input_errors():
    with pytest.raises(InputError, match="could not convert") as info:
        with checking_input():
            float("many")
    assert isinstance(info.value.__cause__, ValueError) and not isinstance(info.value.__cause__, InputError)
    with pytest.raises(InputTypeError, match="must be a number") as tinfo:
        with checking_input():
            raise TypeError("x must be a number")
    assert isinstance(tinfo.value, TypeError) and isinstance(tinfo.value, ValueError)  # callers' excepts hold
    same = InputError("already marked")
    with pytest.raises(InputError) as kept:
        with checking_input():
            raise same
    assert kept.value is same
    with pytest.raises(KeyError):  # other exceptions pass unchanged
        with checking_input():
            raise KeyError("k")


def test_exit_report_for_input_os_errors_and_bugs():
    assert exit_report("mdsr x", InputError("bad --y")) == (2, "mdsr x: error: bad --y")
    assert exit_report("mdsr x", FileNotFoundError(2, "No such file or directory", "/no/file")) == \
        (2, "mdsr x: error: No such file or directory: /no/file")
    try:
        raise ValueError("deep")
    except ValueError as exc:
        code, text = exit_report("mdsr x", exc)
    assert code == 1 and text.startswith("Traceback (most recent call last)") and "ValueError: deep" in text


def test_the_package_input_errors_are_input_errors():
    from mdsr_opt.scenes.reader import SceneFileError
    from mdsr_opt.scenes.rundir import FolderBusy, OutputFolderError
    from mdsr_opt.scenes.scene import UnknownName

    for cls in (SceneFileError, OutputFolderError, FolderBusy, UnknownName):
        assert issubclass(cls, InputError) and issubclass(cls, ValueError), cls
    assert issubclass(UnknownName, KeyError)


# ------------------------------------------------------------------- limits found inside: checked at the door
def test_mdsr_demo_too_fine_a_mesh_is_refused_at_the_door(tmp_path, capsys, monkeypatch):
    """A --max-area whose mesh would exceed Mesh.from_polygon's triangle limit: one line, exit 2, before meshing
    and before any folder is made (it was an 'internal error' from inside meshing, with an empty folder)."""
    monkeypatch.setattr("mdsr_opt.body.mesh.Mesh.from_polygon", lambda *a, **k: pytest.fail("meshing started"))
    assert main(["demo", "--out", str(tmp_path / "d"), "--max-area", "1e-7"]) == 2
    line = _one_line(capsys.readouterr().err)
    assert "max_area 1e-07 would make about 6.22e+07 triangles" in line and "at least 3.1e-06" in line
    assert not (tmp_path / "d").exists()


def test_demo_mesh_size_door_agrees_with_the_mesher():
    """The demo's door refuses exactly what Mesh.from_polygon would refuse (its limit, scaled down)."""
    from mdsr_opt import Mesh
    from mdsr_opt.cli.demo import check_demo_mesh_size, finger_outline

    with pytest.raises(ValueError, match="more than the limit max_triangles=1000"):
        Mesh.from_polygon(finger_outline(), max_area=4.0 * 1.6 / 1500, max_triangles=1000)
    check_demo_mesh_size(1e-5)  # about 6.2e5 triangles: allowed
    with pytest.raises(InputError, match="would make about"):
        check_demo_mesh_size(2e-6)


def test_mdsr_study_fidelity_bad_tolerance_is_one_line(tmp_path, capsys, monkeypatch):
    monkeypatch.setattr("mdsr_opt.studies.fidelity._run_fidelity", lambda *a, **k: pytest.fail("runs started"))
    assert main(["study", "fidelity", "--out", str(tmp_path / "f"), "--tol", "0.01,-1"]) == 2
    assert "tolerances must be positive numbers, got -1.0" in _one_line(capsys.readouterr().err)
    assert not (tmp_path / "f").exists()


@pytest.mark.parametrize("study, option", [("quick", ["--tol", "0.1"]), ("quick", ["--scenes", "gecko"]),
                                           ("fidelity", ["--methods", "ipopt"]), ("recommend", ["--problems", "x"]),
                                           ("fidelity", ["--timeout", "5"]), ("speed", ["--stroke-tol", "0.1"])])
def test_mdsr_study_refuses_an_option_the_study_would_ignore(tmp_path, capsys, study, option):
    assert main(["study", study, "--out", str(tmp_path / "s"), *option]) == 2
    line = _one_line(capsys.readouterr().err)
    assert f"{option[0]} does not apply to the {study} study" in line
    assert not (tmp_path / "s").exists()
