"""Warnings on the command line: shown under -q (the README: -q prints warnings, errors and results), and
each as one clean line, in the command's process and in its pool's workers (no file path, no source line)."""

from __future__ import annotations

import os
import subprocess
import sys
import warnings
from pathlib import Path

from conftest import outline_finger
from mdsr_opt.cli.main import main
from mdsr_opt.core.progress import Progress, is_loud

ROOT = Path(__file__).resolve().parents[1]


def test_quiet_run_still_prints_the_fabrication_warning(tmp_path, capsys):
    """finger.toml with its muscle moved onto the outline: mdsr -q run printed no FabricationWarning at all."""
    scene = outline_finger(tmp_path)
    code = main(["-q", "run", str(scene), "--out", str(tmp_path / "o"), "--case", "contract", "--serial",
                 "--no-photos", "--no-figures", "--no-animations", "--no-prototype", "--resolution", "coarse"])
    assert code == 0
    out = capsys.readouterr().out.splitlines()
    warned = [line for line in out if "FabricationWarning" in line]
    assert len(warned) == 1 and warned[0].startswith("[finger 1/1 contract] ") and "runs on the outline" in warned[0]
    assert not any(line.startswith("[finger") and "design (flattened" in line for line in out)  # progress: gone


def test_loud_messages_are_told_from_progress():
    assert is_loud("[gecko 1/2 bend] FabricationWarning: two ropes cross")
    assert is_loud("[gecko 1/2 bend] warning: MuscleWarning: saturated") and is_loud("warning: x")
    assert is_loud("[finger 1/2 bend] FAILED: target solve failed") and is_loud("error: no")
    assert not is_loud("[finger 1/2 bend] design (flattened, cable): verified")
    assert not is_loud("[finger] 3 warnings were fixed by routing")
    said = []

    class Out:
        def write(self, s):
            said.append(s)

        def flush(self):
            pass

    p = Progress(0, "t", enabled=False, stream=Out(), quiet=True)
    p("[a 1/1 b] target by external driving: ok")
    p("[a 1/1 b] FabricationWarning: runs on the outline")
    assert "".join(said) == "[a 1/1 b] FabricationWarning: runs on the outline\n"


def test_a_python_warning_in_a_command_is_one_line_even_under_quiet(tmp_path, capsys, monkeypatch):
    from mdsr_opt.synthesis.fabrication import FabricationWarning

    def work(out, max_area, contraction, log):
        warnings.warn("ropes too close:\nNOT mouldable", FabricationWarning)
        return {"success": True}

    monkeypatch.setattr("mdsr_opt.cli.demo._write_demo", work)
    before = warnings.showwarning
    assert main(["-q", "demo", "--out", str(tmp_path / "d")]) == 0
    err = capsys.readouterr().err.strip().splitlines()
    assert err == ["warning: FabricationWarning: ropes too close: NOT mouldable"]
    assert warnings.showwarning is before  # the display is as it was after the command


def test_a_pool_workers_warning_is_one_line():
    """A worker (set up as the run's pool sets it up) shows its warnings without path or source line."""
    code = ("import warnings\nfrom mdsr_opt.core import jobs\n"
            "jobs._prepare_worker(jobs.worker_environment(), (), None)\n"
            "warnings.warn('two ropes cross\\nin one layer', UserWarning)\n")
    env = {**os.environ, "PYTHONPATH": str(ROOT), "OPENBLAS_NUM_THREADS": "1"}
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=ROOT, env=env,
                          timeout=60)
    assert done.returncode == 0, done.stderr
    assert done.stderr.strip().splitlines() == ["warning: UserWarning: two ropes cross in one layer"]
