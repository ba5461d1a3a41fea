import json

from mdsr_opt.cli import main


def test_demo_command_writes_results(tmp_path, capsys):
    out = tmp_path / "demo"
    code = main(["demo", "--out", str(out), "--max-area", "0.05", "--contraction", "0.3"])
    assert code == 0
    names = sorted(p.name for p in out.iterdir())
    assert names == ["external.png", "external.vtu", "internal_cable.png", "internal_cable.vtu",
                     "internal_springs.png", "internal_springs.vtu", "summary.json"]
    summary = json.loads((out / "summary.json").read_text())
    assert summary["success"] is True
    for key in ("internal_springs", "internal_cable"):
        assert 0.7 < summary[key]["muscle_length_ratio"] < 0.9  # 30 % asked, the body resists a little
    assert "[4/4]" in capsys.readouterr().out  # progress is shown


def test_demo_rejects_bad_contraction(tmp_path, capsys):
    assert main(["demo", "--out", str(tmp_path / "d"), "--contraction", "1.5"]) == 2
    assert "outside [0, 1)" in capsys.readouterr().err
