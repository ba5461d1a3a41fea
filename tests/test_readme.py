"""The README's code blocks hold: Python blocks run as written (each in a fresh namespace, in a temporary
folder), the scene file loads, and every command line parses with the real parser and names real files."""

import os
import re
import shlex
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
README = ROOT / "README.md"
TEXT = README.read_text()
BLOCKS = re.findall(r"```python\n(.*?)```", TEXT, flags=re.S)
SHELL = re.findall(r"```bash\n(.*?)```", TEXT, flags=re.S)
TOML = re.findall(r"```toml\n(.*?)```", TEXT, flags=re.S)


def test_readme_is_a_guide_not_a_notebook():
    assert len(TEXT.splitlines()) <= 400
    assert len(BLOCKS) >= 6 and len(SHELL) >= 2 and len(TOML) == 1
    separators = [line for line in TEXT.splitlines() if re.fullmatch(r"\|(\s*:?-{3,}:?\s*\|)+", line.strip())]
    assert len(separators) == 1  # one table: the performance table


@pytest.mark.parametrize("index", range(len(BLOCKS)))
def test_readme_block_runs(index, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    namespace = {"__name__": f"readme_block_{index}"}
    exec(compile(BLOCKS[index], f"README.md[python block {index}]", "exec"), namespace)
    # the core example writes its mesh; check the file is really there when it says so
    if "write_mesh(\"bent.vtu\"" in BLOCKS[index]:
        assert os.path.getsize(tmp_path / "bent.vtu") > 0


def test_readme_scene_file_loads(tmp_path):
    from mdsr_opt.scenes.scenefile import load_scene

    path = tmp_path / "finger.toml"
    path.write_text(TOML[0])
    scene = load_scene(path)
    assert scene.name == "finger" and [c.name for c in scene.cases] == ["bend"]
    assert set(scene.regions) == {"base", "tip"}


def _command_lines():
    for block in SHELL:
        for line in block.splitlines():
            words = shlex.split(line, comments=True)
            if words:
                yield words


def test_readme_command_lines_parse_and_name_real_files():
    from mdsr_opt.cli.main import build_parser

    parser = build_parser()
    seen = set()
    for words in _command_lines():
        for part in " ".join(words).split(" && "):
            argv = part.split()
            if argv[0] == "mdsr":
                seen.add(argv[1])
                if argv[1] == "--version":
                    with pytest.raises(SystemExit) as exc:
                        parser.parse_args(argv[1:])
                    assert exc.value.code == 0
                    continue
                args = parser.parse_args(argv[1:])  # argparse exits (SystemExit 2) on a bad option
                for value in vars(args).values():
                    for v in (value if isinstance(value, list) else [value]):
                        if isinstance(v, str) and v.startswith(("tests/", "problems/")):
                            assert (ROOT / v).exists(), v
            elif argv[0] == "python" and argv[1].endswith(".py"):
                assert (ROOT / argv[1]).exists(), argv[1]
    assert {"demo", "list", "run", "study", "evaluate", "photograph", "--version"} <= seen


def test_every_warning_class_the_readme_names_is_a_top_level_name():
    """recheck10: the README named MuscleWarning, AcceptanceWarning... that ``from mdsr_opt import`` could not give
    (a user filters warnings by class)."""
    import warnings

    import mdsr_opt

    names = sorted(set(re.findall(r"\b([A-Z][A-Za-z]*Warning)\b", README.read_text())))
    assert names and all(issubclass(getattr(mdsr_opt, n), UserWarning) for n in names), names
    with warnings.catch_warnings():
        warnings.simplefilter("error", mdsr_opt.MuscleWarning)  # usable as a filter's category
        warnings.simplefilter("ignore", mdsr_opt.AcceptanceWarning)
