"""The installed product: the wheel, the command line's conventions, the plot module's manners, the extras."""

from __future__ import annotations

import argparse
import ast
import importlib
import inspect
import io
import logging
import os
import shutil
import site
import subprocess
import sys
import zipfile
from pathlib import Path

import pytest

import mdsr_opt
from mdsr_opt.cli.main import build_parser, main

ROOT = Path(__file__).resolve().parents[1]
try:  # Python 3.11+
    import tomllib
except ModuleNotFoundError:  # pragma: no cover
    import tomli as tomllib


def _clean_env(**extra) -> dict:
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "MDSR_PROBLEMS", "MPLBACKEND")}
    env.update(extra)
    return env


def _setuptools_at_least(major: int) -> bool:
    try:
        import setuptools
    except ImportError:
        return False
    return int(setuptools.__version__.split(".")[0]) >= major


# ---------------------------------------------------------------------------------------------- the wheel
def test_wheel_installs_the_library_outside_the_checkout(tmp_path):
    # copy the sources (the build must not write build/ or *.egg-info into the checkout)
    src = tmp_path / "src"
    src.mkdir()
    for name in ("pyproject.toml", "README.md", "LICENSE"):
        shutil.copy(ROOT / name, src / name)
    for name in ("mdsr_opt", "problems"):
        shutil.copytree(ROOT / name, src / name, ignore=shutil.ignore_patterns("__pycache__", "*.pyc"))
    dist = tmp_path / "dist"
    cmd = [sys.executable, "-m", "pip", "wheel", str(src), "--no-deps", "-w", str(dist), "-q"]
    if _setuptools_at_least(77):  # else pip fetches setuptools>=77 into an isolated build environment
        cmd.append("--no-build-isolation")
    subprocess.run(cmd, check=True, cwd=tmp_path, env=_clean_env(), timeout=300)
    (wheel,) = dist.glob("mdsr_opt-*.whl")
    names = zipfile.ZipFile(wheel).namelist()
    # the problem library is inside the package, not a top-level `problems` package in site-packages
    assert "mdsr_opt/problems/gecko.py" in names and "mdsr_opt/problems/one_muscle.py" in names
    assert not any(n.startswith("problems/") for n in names)
    assert "mdsr_opt/py.typed" in names and "mdsr_opt/__init__.pyi" in names  # the stub: read at import time
    meta = zipfile.ZipFile(wheel).read(next(n for n in names if n.endswith(".dist-info/METADATA"))).decode()
    assert "License-Expression: MIT" in meta and f"Version: {mdsr_opt.__version__}" in meta
    assert 'Provides-Extra: dask' in meta and "tqdm" in meta
    assert not any("dask" in line and "extra ==" not in line for line in meta.splitlines()
                   if line.startswith("Requires-Dist:"))  # dask only as an extra
    assert any(n.endswith("licenses/LICENSE") for n in names)

    # a fresh virtual environment that sees the dependencies of the interpreter running the tests (casadi & co.
    # without downloading), used from a folder that is not the checkout. `--system-site-packages` would show
    # the BASE interpreter's packages, which lack them when the suite itself runs inside a venv; so the new
    # venv gets a .pth file naming this interpreter's site-packages folders (appended after its own, and
    # without running their .pth files, so an editable install of the checkout stays invisible).
    # --ignore-installed because CI has already installed this very version, which pip would otherwise call
    # "already satisfied"
    venv = tmp_path / "venv"
    subprocess.run([sys.executable, "-m", "venv", str(venv)], check=True, timeout=120)
    bindir = venv / ("Scripts" if os.name == "nt" else "bin")
    py = bindir / "python"
    purelib = subprocess.run([str(py), "-c", "import sysconfig; print(sysconfig.get_paths()['purelib'])"],
                             capture_output=True, text=True, check=True).stdout.strip()
    outer = [p for p in dict.fromkeys(site.getsitepackages() + [site.getusersitepackages()]) if Path(p).is_dir()]
    Path(purelib, "mdsr_test_outer_site.pth").write_text("\n".join(outer) + "\n")
    subprocess.run([str(py), "-m", "pip", "install", "-q", "--no-index", "--no-deps",
                    "--ignore-installed", str(wheel)], check=True,
                   env=_clean_env(), timeout=300)
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()

    def mdsr(*args):
        return subprocess.run([str(bindir / "mdsr"), *args], cwd=elsewhere, env=_clean_env(),
                              capture_output=True, text=True, timeout=300)

    where = subprocess.run([str(py), "-c", "import mdsr_opt, mdsr_opt.scenes.library as s; "
                            "print(mdsr_opt.__file__); print(s.problems_dir())"],
                           cwd=elsewhere, env=_clean_env(), capture_output=True, text=True, check=True)
    init, lib = where.stdout.split("\n")[:2]
    assert Path(init).is_relative_to(venv) and Path(lib) == Path(init).parent / "problems"

    v = mdsr("--version")
    assert v.returncode == 0 and v.stdout.strip() == f"mdsr {mdsr_opt.__version__}"
    listed = mdsr("list")
    assert listed.returncode == 0, listed.stderr
    for name in ("gecko", "one_muscle", "four_muscles", "face"):
        assert f"  {name} " in listed.stdout
    ran = mdsr("run", "one_muscle", "--out", str(tmp_path / "out"), "--resolution", "coarse", "--case", "a30",
               "--no-animations", "--photo-size", "300x300")
    assert ran.returncode == 0, ran.stdout + ran.stderr
    assert "1/1 case(s) succeeded" in ran.stdout
    import json

    summary = json.loads((tmp_path / "out" / "summary.json").read_text())
    assert summary["success"] is True and summary["cases"][0]["contraction_error"] < 1e-6


def test_pyproject_declares_an_spdx_license_and_optional_dask():
    meta = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]
    assert meta["license"] == "MIT" and meta["license-files"] == ["LICENSE"]
    assert "MIT License" in (ROOT / "LICENSE").read_text()
    assert not any(d.startswith("dask") for d in meta["dependencies"])
    assert meta["optional-dependencies"]["dask"] == ["dask[distributed]>=2023.1"]
    assert (ROOT / "mdsr_opt" / "py.typed").exists()


def test_fabrication_files_need_no_dxf_library(tmp_path, monkeypatch):
    """The package writes its DXF itself: ezdxf (0.25-0.3 s to import) is only the tests' reader."""
    meta = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]
    assert not any(d.startswith("ezdxf") for d in meta["dependencies"])
    assert any(d.startswith("ezdxf") for d in meta["optional-dependencies"]["test"])
    from mdsr_opt import Mesh, Muscle
    from mdsr_opt.synthesis.export import export_fabrication

    monkeypatch.setitem(sys.modules, "ezdxf", None)  # `import ezdxf` now raises ImportError
    files = export_fabrication(Mesh.rectangle(4.0, 1.0, 4, 1), None, tmp_path, muscles=[Muscle([0, 1, 2])])
    assert open(files["dxf"]).read().endswith("  0\nEOF\n")


def test_missing_dask_extra_is_a_clear_error(monkeypatch):
    from mdsr_opt.studies.study import run_study

    monkeypatch.setitem(sys.modules, "distributed", None)  # `import distributed` now raises ImportError
    with pytest.raises(ValueError, match=r'optional dask extra.*pip install "mdsr_opt\[dask\]"'):
        run_study("quick", resolutions=[30], methods=["ipopt"], problems=["strip-stretch"], scheduler="local",
                  progress=False, figures=False)


def test_mdsr_study_dask_without_the_extra_exits_2(monkeypatch, tmp_path, capsys):
    monkeypatch.setitem(sys.modules, "distributed", None)
    rc = main(["-q", "study", "quick", "--out", str(tmp_path / "s"), "--resolutions", "30", "--methods", "ipopt",
               "--problems", "strip-stretch", "--dask"])
    assert rc == 2
    assert 'pip install "mdsr_opt[dask]"' in capsys.readouterr().err
    assert not (tmp_path / "s").exists()  # nothing written


# ---------------------------------------------------------------------------------------------- command line
def test_version_flag_prints_the_package_version(capsys):
    with pytest.raises(SystemExit) as exc:
        main(["--version"])
    assert exc.value.code == 0
    assert capsys.readouterr().out.strip() == f"mdsr {mdsr_opt.__version__}"
    assert mdsr_opt.__version__.count(".") == 2


def _walk(parser, path=("mdsr",)):
    import argparse

    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            helps = {a.dest: a.help for a in action._choices_actions}
            for name, sub in action.choices.items():
                yield path + (name,), "(the subcommand itself)", helps.get(name)
                yield from _walk(sub, path + (name,))
        elif not isinstance(action, argparse._HelpAction):
            yield path, "/".join(action.option_strings) or action.dest, action.help


def test_every_option_of_mdsr_has_help():
    seen = list(_walk(build_parser()))
    assert len(seen) > 40 and {p[0][-1] for p in seen} >= {"run", "list", "study", "demo", "evaluate", "photograph"}
    missing = [f"{' '.join(p)} {opt}" for p, opt, h in seen if not h or not str(h).strip()]
    assert missing == []


def test_each_subcommand_module_registers_what_the_owner_table_says():
    import importlib
    from mdsr_opt.cli.main import OWNERS, command_of

    full = _subcommands(build_parser())
    assert full == [c for _, cmds in OWNERS for c in cmds]
    for module, cmds in OWNERS:
        sub = argparse.ArgumentParser().add_subparsers()
        importlib.import_module(module, "mdsr_opt.cli").add_cli(sub)
        assert tuple(sub.choices) == cmds
        for c in cmds:  # a named subcommand registers its own module only
            assert _subcommands(build_parser(c)) == list(cmds)
    assert _subcommands(build_parser("no-such-command")) == full  # argparse then lists every choice
    assert command_of(["-q", "-vv", "run", "gecko"]) == "run"
    assert command_of(["--verb", "-qv", "--qui", "list"]) == "list"
    for argv in (["--version"], ["--", "run"], ["-h", "run"], ["-vh", "list"], ["--he", "run"], ["-", "list"],
                 ["-1", "list"], ["--ver", "run"], ["--bogus", "run"], []):
        assert command_of(argv) is None, argv  # the full parser answers: help lists every subcommand


def _subcommands(parser):
    return [name for a in parser._actions if isinstance(a, argparse._SubParsersAction) for name in a.choices]


def test_mdsr_list_imports_no_other_subcommand_module():
    code = ("import sys; from mdsr_opt.cli.main import main; main(['-q', 'list']); "
            "print(sorted(m for m in sys.modules if m.startswith(('mdsr_opt.cli.', 'mdsr_opt.author'))))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=ROOT, check=True)
    assert out.stdout.strip().splitlines()[-1] == "['mdsr_opt.cli.main', 'mdsr_opt.cli.run']"


def test_mdsr_run_leaves_figure_and_photograph_imports_to_its_jobs(tmp_path):
    """`mdsr run` builds scenes, routes and solves; matplotlib (its figures), scipy.spatial (the photographs'
    contour matching, the prototype's too) and the XML tools stay out of the command's own process: its
    worker processes import what the figure jobs need. The Agg backend it chooses through MPLBACKEND is not
    left behind."""
    code = ("import os, sys; from mdsr_opt.cli.main import main\n"
            f"code = main(['-q', 'run', 'gecko', '--resolution', 'coarse', '--no-animations', "
            f"'--out', {str(tmp_path / 'out')!r}])\n"
            "print(code, sorted(m for m in ('matplotlib', 'scipy.spatial', 'xml.sax') if m in sys.modules), "
            "os.environ.get('MPLBACKEND'))\n")
    for backend in (None, "svg"):
        out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=ROOT, check=True,
                             env=_clean_env(**({"MPLBACKEND": backend} if backend else {})), timeout=300)
        assert out.stdout.strip().splitlines()[-1] == f"0 [] {backend}"
        assert (tmp_path / "out" / "bend_left" / "overlay.png").stat().st_size > 1000  # the jobs drew
        table4 = (tmp_path / "out" / "validation.md").read_text().split("## Table 4")[1]
        assert "| gecko | bend_left |" in table4 and "FAILED" not in table4  # the prototype was photographed
        shutil.rmtree(tmp_path / "out")


@pytest.mark.parametrize("asked", [None, "2"])
def test_the_command_runs_with_one_blas_thread_unless_the_environment_says_otherwise(asked):
    # every OpenBLAS copy threadpoolctl sees (numpy's, scipy's) as the `mdsr` command leaves it, and the
    # variable its worker processes and CasADi's bundled copy (which threadpoolctl does not see) read
    code = ("from mdsr_opt.cli.main import main; main(['list']); import os, numpy, scipy.sparse.linalg; "
            "from threadpoolctl import threadpool_info; from mdsr_opt.core.jobs import worker_environment; "
            "print(os.environ['OPENBLAS_NUM_THREADS'], worker_environment()['OPENBLAS_NUM_THREADS'], "
            "[i['num_threads'] for i in threadpool_info() if i['user_api'] == 'blas'])")
    env = {k: v for k, v in os.environ.items() if k not in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS")}
    if asked is not None:
        env["OPENBLAS_NUM_THREADS"] = asked
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=ROOT, check=True, env=env)
    n = "1" if asked is None else asked
    variable, worker, counts = out.stdout.strip().splitlines()[-1].split(" ", 2)
    assert variable == worker == n
    assert len(counts.strip("[]").split(",")) == 2 and set(map(int, counts.strip("[]").split(","))) == {int(n)}


#: the start of a process without the POSIX-only modules (as on Windows): importing one fails, os.fork is gone;
#: the pool's workers are spawned, as on Windows and macOS
_WITHOUT_POSIX = ("import os, sys\n"
                  "for name in ('resource', 'fcntl', 'termios', 'pwd', 'grp'):\n"
                  "    sys.modules[name] = None\n"
                  "del os.fork\n"
                  "import mdsr_opt.core.jobs as jobs\n"
                  "jobs.start_method = lambda: 'spawn'\n"
                  "from mdsr_opt.cli.main import main\n"
                  "print('exit', main(sys.argv[1:]))\n")


def _without_posix(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-c", _WITHOUT_POSIX, *args], capture_output=True, text=True, cwd=ROOT,
                          env=_clean_env(), timeout=300)


def test_the_command_starts_and_lists_without_posix_only_modules():
    version = _without_posix("--version")
    assert version.returncode == 0 and version.stdout.strip() == f"mdsr {mdsr_opt.__version__}", version.stderr
    listed = _without_posix("-q", "list")
    assert listed.returncode == 0, listed.stderr[-2000:]
    assert "gecko" in listed.stdout and listed.stdout.strip().endswith("exit 0")


def test_a_run_without_posix_only_modules_writes_its_files(tmp_path):
    out = tmp_path / "out"
    run = _without_posix("-q", "run", "one_muscle", "--resolution", "coarse", "--case", "a20", "--no-animations",
                         "--photo-size", "200x200", "--out", str(out))
    assert run.returncode == 0 and run.stdout.strip().endswith("exit 0"), run.stderr[-2000:]
    assert (out / "a20" / "design.png").stat().st_size > 1000 and (out / "summary.json").is_file()


def test_every_add_argument_in_the_code_base_has_help():
    # the parsers built elsewhere (problem scripts' run_main, the benchmark scripts) too
    files = [*ROOT.joinpath("mdsr_opt").rglob("*.py"), *ROOT.joinpath("problems").glob("*.py"),
             *ROOT.joinpath("tests", "benchmarks").glob("*.py")]
    calls, missing = 0, []
    for f in files:
        for node in ast.walk(ast.parse(f.read_text())):
            # argparse's add_argument names its option with a string literal (a browser's options object has
            # an add_argument too, called with a variable)
            if isinstance(node, ast.Call) and getattr(node.func, "attr", None) == "add_argument" \
                    and node.args and isinstance(node.args[0], ast.Constant) and isinstance(node.args[0].value, str):
                calls += 1
                if not any(k.arg == "help" for k in node.keywords):
                    missing.append(f"{f.relative_to(ROOT)}:{node.lineno}")
    assert calls > 40
    assert missing == []


def test_quiet_and_verbose_flags_set_the_log_level(tmp_path, capsys):
    logger = logging.getLogger("mdsr_opt")
    try:
        assert main(["-q", "demo", "--out", str(tmp_path / "d"), "--max-area", "0.05"]) == 0
        out = capsys.readouterr()
        assert "[1/4]" not in out.out and "[1/4]" not in out.err  # no progress lines
        assert logger.level == logging.WARNING
        assert (tmp_path / "d" / "summary.json").exists()
        assert main(["-vv", "list"]) == 0
        assert logger.level == logging.DEBUG
        capsys.readouterr()
        assert main(["list"]) == 0
        assert logger.level == logging.INFO
    finally:
        logger.setLevel(logging.NOTSET)
        for h in [h for h in logger.handlers if getattr(h, "_mdsr_cli", False)]:
            logger.removeHandler(h)


def test_library_reports_through_module_loggers(caplog, tmp_path):
    from mdsr_opt.cli.demo import run_demo

    with caplog.at_level(logging.INFO, logger="mdsr_opt"):
        run_demo(str(tmp_path / "d"), max_area=0.05)
    assert any(r.name == "mdsr_opt.cli.demo" and "[1/4]" in r.getMessage() for r in caplog.records)


def test_no_print_in_library_code_outside_the_command_line():
    # prints belong to the command line: its package (mdsr_opt/cli) and the command-line functions elsewhere
    # (names starting with _cmd / _cli, run_main and the problem scripts' _script_main, main)
    allowed_funcs = ("_cmd", "_cli", "run_main", "_script_main", "main")
    offenders = []
    pkg = ROOT.joinpath("mdsr_opt")
    for f in pkg.rglob("*.py"):
        rel = f.relative_to(pkg).as_posix()
        if rel.startswith("cli/"):
            continue
        tree = ast.parse(f.read_text())
        for func in [n for n in ast.walk(tree) if isinstance(n, (ast.FunctionDef, ast.AsyncFunctionDef))]:
            if func.name.startswith(allowed_funcs):
                continue
            for node in ast.walk(func):
                if isinstance(node, ast.Call) and getattr(node.func, "id", None) == "print":
                    # nested functions of an allowed function are walked from it: skip those
                    offenders.append(f"{rel}:{node.lineno} in {func.name}")
    allowed = {"core/progress.py",  # Progress prints the messages it is handed, on the command line's behalf
               "author/__init__.py",  # serve(): `mdsr author` says where the page is served and how to stop it
               "mechanics/loadsteps.py",  # the solvers' verbose=True trace, asked for by the caller
               "mechanics/contactsteps.py",  # the same trace of a solve with contact
               "mechanics/barriersolve.py"}  # and of one with the barrier
    offenders = [o for o in offenders if o.split(":")[0] not in allowed]
    assert offenders == []
    assert len(list(pkg.rglob("*.py"))) > 50  # every module of the package, not only the top level's


# ---------------------------------------------------------------------------------------------- progress
def test_progress_bar_counts_units_and_estimates_the_time_left(capsys):
    from mdsr_opt.core.progress import Progress, advance, expect

    bar = Progress(2, "mdsr run", enabled=True, unit="case")
    bar("[s 1/2 a] target by external driving: ok")
    advance(bar)
    expect(bar, 1)
    bar("FAILED s/b: routing found no muscle")
    advance(bar, 2)
    bar.close()
    cap = capsys.readouterr()
    assert "3/3" in cap.err and "<" in cap.err  # elapsed<remaining: the time-left estimate
    assert "FAILED s/b" in cap.out and "target by external" not in cap.out  # only failures above the bar
    advance(print)  # a plain callable: nothing happens
    expect(None, 3)


def test_progress_off_prints_messages_or_nothing():
    from mdsr_opt.core.progress import Progress

    out = io.StringIO()
    with Progress(1, "x", enabled=False, stream=out) as log:
        log("one line")
        log.advance()
    assert out.getvalue() == "one line\n" and log.n == 1
    with pytest.raises(ValueError, match="total must be an integer >= 0, got -1"):
        Progress(-1)


# ---------------------------------------------------------------------------------------------- figures
def test_importing_plot_keeps_the_matplotlib_backend():
    code = ("import matplotlib\n"
            "matplotlib.use('svg')\n"
            "before = matplotlib.get_backend()\n"
            "import mdsr_opt.plot.common, mdsr_opt.plot.design, mdsr_opt.plot.photos, mdsr_opt.plot.routing\n"
            "import mdsr_opt.plot.scenes, mdsr_opt.plot.studies, mdsr_opt.scenes.runscene, mdsr_opt.photos.folder\n"
            "import mdsr_opt.studies.study\n"
            "print(before, matplotlib.get_backend())\n")
    r = subprocess.run([sys.executable, "-c", code], cwd=ROOT, env=_clean_env(), capture_output=True, text=True,
                       check=True, timeout=120)
    assert r.stdout.split() == ["svg", "svg"]
    # and without any choice made: importing the module does not settle the backend
    code = ("import matplotlib\n"
            "b0 = matplotlib.get_backend()\n"
            "import mdsr_opt.plot.common\n"
            "print(b0, matplotlib.get_backend())\n")
    r = subprocess.run([sys.executable, "-c", code], cwd=ROOT, env=_clean_env(), capture_output=True, text=True,
                       check=True, timeout=120)
    before, after = r.stdout.split()
    assert before == after


def test_plot_functions_take_an_axes_and_return_the_figure(tmp_path):
    import matplotlib.pyplot as plt

    from mdsr_opt import Mesh
    from mdsr_opt.plot.common import plot_edges, plot_mesh, save_figure

    # the figures of every stage (plot.routing's are multi-panel grids of several targets: they make their own)
    funcs = {}
    for stage in ("common", "design", "photos", "scenes", "studies"):
        mod = importlib.import_module(f"mdsr_opt.plot.{stage}")
        funcs.update({n: f for n, f in vars(mod).items() if n.startswith("plot_") and f.__module__ == mod.__name__})
    assert len(funcs) >= 10
    lacking = [n for n, f in funcs.items() if not {"ax", "axes", "fig"} & set(inspect.signature(f).parameters)]
    assert lacking == []

    mesh = Mesh.rectangle(2.0, 1.0, 4, 2)
    fig, ax = plt.subplots()
    assert plot_mesh(mesh, ax=ax) is fig
    assert plot_edges(mesh.points, mesh.edges, mesh.edge_lengths, ax=ax) is fig
    path = save_figure(fig, tmp_path / "mine.png")
    assert os.path.getsize(path) > 1000
    assert plt.fignum_exists(fig.number)  # the caller's figure stays open
    save_figure(fig, tmp_path / "mine.svg", close=True)
    assert not plt.fignum_exists(fig.number) and (tmp_path / "mine.svg").read_text().startswith("<?xml")


# ---------------------------------------------------------------------------------------------- test selection
def test_marker_slow_selects_the_long_cases_and_the_default_run_leaves_them_out():
    def collect(*args):
        r = subprocess.run([sys.executable, "-m", "pytest", "--collect-only", "-q", "-p", "no:cacheprovider",
                            "tests/test_long.py", *args], cwd=ROOT, env=_clean_env(), capture_output=True,
                           text=True, timeout=300)
        return [line for line in r.stdout.splitlines() if "::" in line], r.stdout

    slow, text = collect("-m", "slow")
    assert len(slow) >= 4 and all("test_long.py::" in t for t in slow), text
    default, text = collect()
    assert default == [] and "deselected" in text
    everything, _ = collect("--slow")
    assert sorted(everything) == sorted(slow)
