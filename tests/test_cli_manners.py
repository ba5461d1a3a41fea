"""mdsr run's words: --no-photos does not speak of photographs, --resolution -5 gets the API's message, a
finished output folder keeps no lock file (new-user trial defects 12-14)."""

from __future__ import annotations

import json

import pytest

from mdsr_opt import get_problem
from mdsr_opt.cli.main import main
from mdsr_opt.scenes.rundir import LOCK_NAME

STRIP = {"name": "strip", "body": {"outline": [[0, 0], [4, 0], [4, 1], [0, 1]], "resolution": 60},
         "regions": {"base": {"box": [-1, -1, 0, 2]}, "end": {"box": [4, -1, 5, 2]}},
         "cases": [{"name": "bend", "anchors": "base", "drags": [{"nodes": "end", "by": [-0.8, 1.2]}]}]}


def test_no_photos_says_nothing_of_photographs_and_leaves_no_lock(tmp_path, capsys):
    strip, out = tmp_path / "strip.json", tmp_path / "out"
    strip.write_text(json.dumps(STRIP))
    assert main(["run", str(strip), "--out", str(out), "--no-photos", "--no-figures", "--serial"]) == 0
    last = capsys.readouterr().out.strip().splitlines()[-1]
    assert last.startswith("1/1 case(s) succeeded") and last.endswith(f"results in {out}"), last
    assert "SYNTHETIC" not in last
    assert not (out / LOCK_NAME).exists()


@pytest.mark.parametrize("count", ["-5", "5", "0", "+3"])
def test_a_small_node_count_gets_the_same_message_from_the_cli_and_the_api(tmp_path, capsys, count):
    try:  # argparse's own check (a count in digits) exits; the scene's returns 2
        code = main(["run", "gecko", f"--resolution={count}", "--out", str(tmp_path / "o")])
    except SystemExit as exc:
        code = exc.code
    assert code == 2
    err = capsys.readouterr().err
    want = f"resolution must be at least 20 nodes, got {int(count)}"
    assert want in err, err
    assert "must be one of" not in err
    with pytest.raises(ValueError, match=want):
        get_problem("gecko", resolution=int(count))
    with pytest.raises(ValueError, match="must be one of 'coarse', 'medium', 'fine' or a node count, got 'huge'"):
        get_problem("gecko", resolution="huge")


def test_photograph_names_the_case_folders_of_a_run_folder(tmp_path, capsys):
    """README (c): `mdsr photograph out/gecko` found "no state files": it now names the case folders holding
    them (their files share names, so they are not merged)."""
    import numpy as np

    from mdsr_opt import Mesh
    from mdsr_opt.body.io import write_mesh

    mesh = Mesh.rectangle(4.0, 1.0, 8, 2)
    for case in ("bend", "curl"):
        (tmp_path / "run" / case).mkdir(parents=True)
        write_mesh(tmp_path / "run" / case / "driven.vtu", mesh, np.asarray(mesh.points))
    assert main(["photograph", str(tmp_path / "run"), "--out", str(tmp_path / "img")]) == 2
    err = capsys.readouterr().err
    assert f"no state files (.vtk, .vtu, .xdmf, .msh) in {tmp_path / 'run'} itself" in err
    assert "give one of its folders that hold some: bend, curl" in err
    assert not (tmp_path / "img").exists()
    assert main(["photograph", str(tmp_path / "run" / "bend"), "--out", str(tmp_path / "img")]) == 0
    assert (tmp_path / "img" / "driven.png").is_file()


@pytest.mark.parametrize("how", ["script", "stdin"])
def test_main_called_from_an_unguarded_script_or_stdin_runs_once_without_a_pool(tmp_path, how):
    """A pool's workers run the main script again as they start (and cannot run standard input at all): main()
    called from such a script keeps mdsr run's jobs in its own process (trial9 #6: a broken pool reported as a
    bug from stdin, a nested run in every worker from a script without a main guard)."""
    import os
    import subprocess
    import sys
    from pathlib import Path

    code = ("import os\n"
            "from mdsr_opt.cli.main import main\n"
            "print('START', os.getpid(), flush=True)\n"
            "print('CODE', main(['-q', 'run', 'one_muscle', '--resolution', 'coarse', '--case', 'a30',\n"
            "                    '--no-photos', '--no-animations', '--out', 'out']), flush=True)\n")
    env = dict(os.environ, PYTHONPATH=str(Path(__file__).resolve().parents[1]), OPENBLAS_NUM_THREADS="1")
    if how == "script":
        (tmp_path / "go.py").write_text(code)
        proc = subprocess.run([sys.executable, "go.py"], cwd=tmp_path, env=env, capture_output=True, text=True,
                              timeout=300)
    else:
        proc = subprocess.run([sys.executable, "-"], input=code, cwd=tmp_path, env=env, capture_output=True,
                              text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr[-2000:]
    assert proc.stdout.count("START") == 1 and "CODE 0" in proc.stdout, (proc.stdout[-2000:], proc.stderr[-2000:])
    assert "internal error" not in proc.stderr and "BrokenProcessPool" not in proc.stderr, proc.stderr[-2000:]
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted(["out"] + (["go.py"] if how == "script" else []))
    assert (tmp_path / "out" / "a30" / "design.png").is_file()
