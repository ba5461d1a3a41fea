"""The design made again without its idle muscles, when its optimiser stops short (trial10: Nelder-Mead at its
evaluation cap with contact, at the same difference), is the answer when verified and no farther from the
target than the design with them; otherwise the idle muscles are kept and that is said: a MuscleWarning, and in
``mdsr run`` a note and the verdict's "idle ... kept" (it used to be only in the status)."""

from __future__ import annotations

import dataclasses
import types

import numpy as np
import pytest

import mdsr_opt.synthesis.contractions as contractions
from mdsr_opt import Mesh, Muscle, NeoHookean, solve_internal
from mdsr_opt.scenes.verdict import design_verdict
from mdsr_opt.synthesis.acceptance import IDLE_RTOL, design_active
from mdsr_opt.synthesis.results import MuscleWarning

MAT = NeoHookean(1.0, 0.3)


def _layout():
    mesh = Mesh.rectangle(4.0, 1.0, 16, 4)
    lower, upper = Muscle(range(1, 16), name="lower"), Muscle(range(69, 84), name="upper")
    target = solve_internal(mesh, MAT, [lower], [0.15]).x  # the upper muscle's path lengthens: idle
    return mesh, [lower, upper], target


def _short_second(monkeypatch, difference: float | None = None):
    """design_contractions whose design of one muscle stops short of success (as at an evaluation cap), ending
    at ``difference`` (default: where it ended)."""
    real = contractions.design_contractions

    def design(mesh, material, muscles, target, **kw):
        res = real(mesh, material, muscles, target, **kw)
        if len(muscles) == 1:
            res = dataclasses.replace(res, success=False, status="optimiser: maximum number of evaluations",
                                      difference=res.difference if difference is None else difference)
        return res

    monkeypatch.setattr(contractions, "design_contractions", design)


def _reject_one_muscle_redesigns(monkeypatch):
    """design_contractions whose designs of a single muscle are rejected (as a redesign without an idle one
    may be)."""
    real = contractions.design_contractions

    def one_muscle_rejected(mesh, material, muscles, target, **kw):
        res = real(mesh, material, muscles, target, **kw)
        if len(muscles) == 1:
            res = dataclasses.replace(res, success=False, status="rejected (test)")
        return res

    monkeypatch.setattr(contractions, "design_contractions", one_muscle_rejected)


def test_a_redesign_stopped_short_but_verified_and_as_near_is_the_answer(monkeypatch):
    mesh, mus, target = _layout()
    with_idle, _, _ = design_active(mesh, MAT, mus, target, idle_contraction=0.0)
    _short_second(monkeypatch)
    res, kept, dropped = design_active(mesh, MAT, mus, target)
    assert [m.name for m in kept] == ["lower"] and [d.name for d in dropped] == ["upper"]
    assert res.success and res.verification.passed
    assert res.difference <= with_idle.difference * (1 + IDLE_RTOL) + 1e-12
    assert "a success all the same: verified" in res.status and "optimiser: maximum" in res.status


def test_a_redesign_that_ends_farther_keeps_the_idle_muscle_and_warns(monkeypatch):
    mesh, mus, target = _layout()
    with_idle, _, _ = design_active(mesh, MAT, mus, target, idle_contraction=0.0)
    _short_second(monkeypatch, difference=with_idle.difference * (1 + 10 * IDLE_RTOL))
    with pytest.warns(MuscleWarning, match=r"idle muscle\(s\) upper kept in the layout .* the design without "
                                           r"them failed \(optimiser: maximum"):
        res, kept, dropped = design_active(mesh, MAT, mus, target)
    assert res.success and [m.name for m in kept] == ["lower", "upper"] and dropped == ()
    assert "idle muscle(s) upper kept" in res.status


def test_the_verdict_names_idle_muscles_kept():
    case = types.SimpleNamespace(success=True, message="", saturated=["M2"], dropped=[], idle_kept=["M1"],
                                 fabrication=[], photo=None)
    assert design_verdict(case) == "ok (saturated M2; idle M1 kept)"


def test_mdsr_run_notes_an_idle_muscle_kept(monkeypatch, tmp_path):
    from pathlib import Path

    from mdsr_opt.scenes.runner import run_case
    from mdsr_opt.scenes.scenefile import load_scene

    finger = Path(__file__).resolve().parent / "data" / "finger.toml"
    lower = '[[muscles]]\nname = "lower"\npath = [[0.3, 0.3], [3.3, 0.3]]\n\n[routing]'
    text = finger.read_text().replace("[routing]", lower, 1).replace("contractions = [0.3]", "contractions = [0.3, 0]")
    (tmp_path / "f.toml").write_text(text)
    scene = load_scene(tmp_path / "f.toml")  # before the patch: the file's keys are checked against the signature
    _reject_one_muscle_redesigns(monkeypatch)
    rep = run_case(scene, "bend", photo=False).report
    assert rep.success and rep.idle_kept == ["lower"] and rep.dropped == []  # the tip turned up: lower idle
    assert any(n.startswith("design: idle lower kept") for n in rep.notes)
    assert design_verdict(rep).startswith("ok (idle lower kept")


def test_the_page_says_an_idle_muscle_kept(monkeypatch):
    """recheck10 A: when the design without the idle rope fails, the page's summary names the rope kept (it said
    nothing: no field, and the status shown only on failure)."""
    from mdsr_opt.author.session import Session

    s = Session.from_outline([[0, 0], [4, 0], [4, 1], [0, 1]], resolution=120)
    X = s.mesh.points
    left, right = np.flatnonzero(X[:, 0] < 1e-9), np.flatnonzero(X[:, 0] > 4 - 1e-9)
    c, si = np.cos(np.pi / 3), np.sin(np.pi / 3)
    s.set_fixed(left, right, (X[right] - [0, 0.5]) @ np.array([[c, si], [-si, c]]) + [0, 0.5])
    assert s.settle().success
    bottom = [int(i) for i in np.argsort(X[:, 0]) if X[i, 1] < 1e-9]
    top = [int(i) for i in np.argsort(X[:, 0]) if X[i, 1] > 1 - 1e-9]
    s.muscles = (Muscle(bottom[1:-1], name="bottom"), Muscle(top[1:-1], name="top"))
    s.routed_target = s.target.copy()
    _reject_one_muscle_redesigns(monkeypatch)
    out = s.run_design()
    assert out["success"] and out["idle_kept"] == ["bottom"] and out["dropped"] == []
