"""Settings that would silently turn a check off or move nothing are refused at the door (trial10):
``max_difference`` above 1 (5 read as 500 %), ``idle_contraction`` at or above ``a_max`` (every muscle idle,
explained as "the target must shorten the body"), a scene drag that turns one node about itself."""

from __future__ import annotations

import inspect

import numpy as np
import pytest

from mdsr_opt import Mesh, NeoHookean, load_scene
from mdsr_opt.cli.main import main
from mdsr_opt.scenes.reader import SceneFileError
from mdsr_opt.synthesis.acceptance import A_MAX, check_idle_contraction, check_max_difference
from mdsr_opt.synthesis.contractions import design_contractions
from mdsr_opt.synthesis.pipeline import design_pipeline
from conftest import STRIP_HEAD

STRIP = STRIP_HEAD
CASE = """[[cases]]
name = "bend"
anchors = "left"
drags = [{{ {drag} }}]
"""


def _scene(tmp_path, text):
    path = tmp_path / "strip.toml"
    path.write_text(STRIP + text)
    return path


@pytest.mark.parametrize("value", [5, 1.5, 100.0])
def test_a_max_difference_above_one_is_refused_as_a_percent(value):
    with pytest.raises(ValueError, match=rf"max_difference is a fraction of the body's size \(0.05 = 5 %\), got "
                                         rf"{value:g}: .* give {value / 100:g} for {value:g} %, or inf"):
        check_max_difference(value)
    assert check_max_difference(1.0) == 1.0 and check_max_difference(float("inf")) == float("inf")


def test_the_command_line_and_a_scene_file_refuse_it_too_and_write_nothing(tmp_path, capsys):
    path = _scene(tmp_path, CASE.format(drag='nodes = "right", by = [0, 1]'))
    out = tmp_path / "o"
    with pytest.raises(SystemExit) as stop:  # argparse's refusal of the flag: exit 2
        main(["run", str(path), "--out", str(out), "--max-difference", "5"])
    assert stop.value.code == 2
    assert "give 0.05 for 5 %" in capsys.readouterr().err and not out.exists()
    bad = _scene(tmp_path, CASE.format(drag='nodes = "right", by = [0, 1]') + "[acceptance]\nmax_difference = 3\n")
    with pytest.raises(SceneFileError, match=r"acceptance.max_difference is a fraction .* got 3"):
        load_scene(bad)


def test_an_idle_threshold_at_or_above_a_max_is_refused_everywhere(tmp_path):
    assert A_MAX == inspect.signature(design_contractions).parameters["a_max"].default  # one default
    with pytest.raises(ValueError, match=r"idle_contraction \(0.7\) must lie below a_max \(0.6\)"):
        check_idle_contraction(0.7, a_max=A_MAX)
    assert check_idle_contraction(0.5, a_max=A_MAX) == 0.5 and check_idle_contraction(0.0, a_max=0.0) == 0.0
    mesh = Mesh.rectangle(4.0, 1.0, 16, 4)
    P = mesh.points
    left, right = np.flatnonzero(P[:, 0] < 1e-9), np.flatnonzero(P[:, 0] > 4 - 1e-9)
    for kw, msg in (({"idle_contraction": 0.9}, r"\(0.9\) must lie below a_max \(0.6\)"),
                    ({"idle_contraction": 0.3, "a_max": 0.2}, r"\(0.3\) must lie below a_max \(0.2\)")):
        with pytest.raises(ValueError, match=msg):
            design_pipeline(mesh, NeoHookean(1.0, 0.3), left, (right, P[right] + [0, 1]), **kw)
    case = CASE.format(drag='nodes = "right", by = [0, 1]')
    with pytest.raises(SceneFileError, match=r"acceptance.idle_contraction \(0.7\) must lie below a_max \(0.6\)"):
        load_scene(_scene(tmp_path, case + "[acceptance]\nidle_contraction = 0.7\n"))
    with pytest.raises(SceneFileError, match=r"idle_contraction \(0.3\) must lie below a_max \(0.25\)"):
        load_scene(_scene(tmp_path, "[design]\na_max = 0.25\n" + case + "[acceptance]\nidle_contraction = 0.3\n"))
    assert load_scene(_scene(tmp_path, "[design]\na_max = 0.8\n" + case + "[acceptance]\nidle_contraction = 0.7\n"))


def test_a_drag_turning_one_node_about_itself_needs_about(tmp_path):
    with pytest.raises(SceneFileError, match=r"cases\[0\].drags\[0\].rotate: turns one node about itself, which "
                                             r"moves nothing: give about"):
        load_scene(_scene(tmp_path, CASE.format(drag="at = [4, 0.5], rotate = 30")))
    one = load_scene(_scene(tmp_path, CASE.format(drag="at = [4, 0.5], rotate = 90, about = [4, 0]"))).case("bend")
    np.testing.assert_allclose(one.drag_positions, [[3.5, 0.0]], atol=0.05)  # turned a quarter about (4, 0)
    many = load_scene(_scene(tmp_path, CASE.format(drag='nodes = "right", rotate = 30'))).case("bend")
    assert len(many.drag_nodes) > 1  # several nodes: about their centroid, as before


def test_leftovers_of_recheck10(tmp_path):
    """a numpy a_max is checked too; one node turned about itself with ``by`` is told to drop ``rotate``; a high
    (legal) idle threshold that leaves every muscle idle says to lower it, not only that the target must
    shorten the body."""
    from mdsr_opt import Muscle, solve_internal
    from mdsr_opt.synthesis.acceptance import design_active

    with pytest.raises(ValueError, match=r"must lie below a_max \(0.6\)"):
        check_idle_contraction(0.7, a_max=np.float32(0.6))
    with pytest.raises(SceneFileError, match=r"turns one node about itself, which moves nothing: give about \(the "
                                             r"point to turn it around\), or leave rotate out \(by alone moves it\)"):
        load_scene(_scene(tmp_path, CASE.format(drag="at = [4, 0.5], rotate = 30, by = [0, 1]")))
    mesh = Mesh.rectangle(4.0, 1.0, 16, 4)
    lower = Muscle(range(1, 16), name="lower")
    target = solve_internal(mesh, NeoHookean(1.0, 0.3), [lower], [0.15]).x
    res, kept, dropped = design_active(mesh, NeoHookean(1.0, 0.3), [lower], target, idle_contraction=0.2,
                                       a_max=0.3)
    assert not res.success and "every muscle is idle" in res.status and "lower it to keep these muscles" in res.status
