import json

import pytest

from mdsr_opt.cli.main import main


def test_demo_command_writes_results(tmp_path, capsys):
    out = tmp_path / "demo"
    code = main(["demo", "--out", str(out), "--max-area", "0.05", "--contraction", "0.3"])
    assert code == 0
    names = sorted(p.name for p in out.iterdir())
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
