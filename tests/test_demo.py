import json
from pathlib import Path

import pytest

from mdsr_opt.cli.main import main


def test_demo_command_writes_results(tmp_path, capsys):
    out = tmp_path / "demo"
    code = main(["demo", "--out", str(out), "--max-area", "0.05", "--contraction", "0.3"])
    assert code == 0
    names = sorted(p.name for p in out.iterdir() if not p.name.startswith("."))
    assert names == ["external.png", "external.vtu", "internal_cable.png", "internal_cable.vtu",
                     "internal_springs.png", "internal_springs.vtu", "summary.json"]
    summary = json.loads((out / "summary.json").read_text())
    assert summary["success"] is True
    # 30 % asked: the exact cable reaches it, the penalty springs fall a little short
    assert abs(summary["internal_cable"]["muscle_length_ratio"] - 0.7) < 1e-6
    assert 0.7 < summary["internal_springs"]["muscle_length_ratio"] < 0.75
    for key in ("internal_springs", "internal_cable"):
        s = summary[key]
        assert s["achieved"][0] == pytest.approx(1 - s["muscle_length_ratio"], abs=1e-9)
        assert s["commanded"] == [0.3] and s["tension"][0] > 0
    text = capsys.readouterr().out
    assert "[4/4]" in text  # progress is shown
    got = summary["internal_springs"]["achieved"][0]
    assert f"achieved contraction {got:.1%} (commanded 30%)" in text  # the log states what was reached


def test_demo_rejects_bad_contraction(tmp_path, capsys):
    assert main(["demo", "--out", str(tmp_path / "d"), "--contraction", "1.5"]) == 2
    assert "outside [0, 1)" in capsys.readouterr().err


def _stub_demo(monkeypatch, calls):
    """The demo's work replaced by one written file (the folder rules are what is tested)."""
    def write(out, max_area, contraction, log):
        calls.append(out)
        (Path(out) / "summary.json").write_text("{}")
        return {"success": True}

    monkeypatch.setattr("mdsr_opt.cli.demo._write_demo", write)


def test_demo_refuses_its_earlier_output_without_overwrite(tmp_path, capsys, monkeypatch):
    """As mdsr run: a second demo into the same folder is refused (it overwrote silently), --overwrite
    replaces it, and a file of the user's there is never removed."""
    calls = []
    _stub_demo(monkeypatch, calls)
    out = tmp_path / "demo_out"
    assert main(["-q", "demo", "--out", str(out)]) == 0
    assert main(["-q", "demo", "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip()
    assert "holds an earlier mdsr output (`mdsr -q demo --out" in err and "pass --overwrite" in err
    assert len(err.splitlines()) == 1 and len(calls) == 1
    assert main(["-q", "demo", "--out", str(out), "--overwrite"]) == 0 and len(calls) == 2
    manifest = json.loads((out / ".mdsr-run.json").read_text())
    assert manifest["status"] == "complete" and manifest["files"] == ["summary.json"]
    (out / "mine.txt").write_text("keep")  # a user's file beside the demo's: --overwrite keeps it
    assert main(["-q", "demo", "--out", str(out), "--overwrite"]) == 0
    assert (out / "mine.txt").read_text() == "keep"
    other = tmp_path / "other"
    other.mkdir()
    (other / "notes.txt").write_text("x")
    for extra in ([], ["--overwrite"]):  # a folder of the user's: refused either way, nothing written
        assert main(["-q", "demo", "--out", str(other), *extra]) == 2
        assert "notes.txt" in capsys.readouterr().err
    assert sorted(p.name for p in other.iterdir()) == ["notes.txt"] and len(calls) == 3
