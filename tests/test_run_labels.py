"""'d over every loop' and 'outline d' are two numbers (mean_px and outer_mean_px): the log called the first
'target outline d' while overlay.png's title, 'outline d', gave the second. Each label says what it measures,
in the log, the table and the figure."""

from __future__ import annotations

import json
from pathlib import Path

from mdsr_opt.cli.main import main

ROOT = Path(__file__).resolve().parents[1]
HOLED = (ROOT / "tests" / "data" / "finger.toml").read_text().replace(
    'resolution = "coarse"', 'resolution = "coarse"\nholes = [[[1.4, 0.3], [2.4, 0.3], [2.4, 0.7], [1.4, 0.7]]]')


def test_every_loop_and_outline_are_told_apart(tmp_path, capsys, monkeypatch):
    import mdsr_opt.plot.photos as photos

    drawn = []
    real = photos.plot_overlay

    def overlay(image, mesh, x, comparison, **kw):
        drawn.append(comparison.mean_px)
        return real(image, mesh, x, comparison, **kw)

    monkeypatch.setattr(photos, "plot_overlay", overlay)
    scene = tmp_path / "holed.toml"
    scene.write_text(HOLED)
    out = tmp_path / "o"
    assert main(["run", str(scene), "--out", str(out), "--case", "contract", "--serial", "--no-animations",
                 "--no-prototype"]) == 0
    text = capsys.readouterr().out
    t = json.loads((out / "summary.json").read_text())["cases"][0]["photo"]["target"]
    every, outline = t["mean_px"], t["outer_mean_px"]
    assert f"{every:.2f}" != f"{outline:.2f}"  # the hole's loop counts in one and not the other
    line = [s for s in text.splitlines() if "SYNTHETIC photograph:" in s]
    assert len(line) == 1
    assert f"target d over every loop = {every:.2f} px" in line[0] and f"outline d = {outline:.2f} px" in line[0]
    assert "target outline d" not in text
    head, _, row = [s for s in text.splitlines() if s.startswith("| ")][:3]
    cells = [c.strip() for c in row.strip("|").split("|")]
    names = [c.strip() for c in head.strip("|").split("|")]
    assert cells[names.index("photo d over every loop (px)")] == f"{every:.2f}"
    assert drawn == [outline]  # the overlay draws and titles the outline: its 'outline d'
