"""Fabrication files a workshop can trust (new-user trial 5, defects 1-3): a layout routed with a fabrication
is drawn with it (a gait's files drew the 1 % defaults instead of the scene's [fabrication]), a failed design
or a stroke no rope can make is refused unless asked for and then marked "FAILED DESIGN ... do not build" in
every file, and ``--no-animations`` skips only the gait's GIF, not its schedule and fabrication files."""

from __future__ import annotations

import csv
import xml.etree.ElementTree as ET
import dataclasses
import html
import json
import re
import warnings
from pathlib import Path
from types import SimpleNamespace

import ezdxf
import numpy as np
import pytest

from mdsr_opt import Mesh, Muscle, NeoHookean, solve_internal
from mdsr_opt.scenes.casefab import write_case_fabrication
from mdsr_opt.scenes.runner import run_case
from mdsr_opt.scenes.runscene import n_units, run_scene
from mdsr_opt.scenes.scenefile import load_scene
from mdsr_opt.synthesis.export import export_fabrication
from mdsr_opt.synthesis.fabrication import Fabrication
from mdsr_opt.synthesis.poses import design_poses
from mdsr_opt.synthesis.poses_result import PosesResult

FAB = Fabrication(channel_diameter=1.0, wall=0.6, fixture_radius=1.5, min_fixture_radius=1.0)


def caption(svg_path) -> str:
    svg = open(svg_path, encoding="utf-8").read()
    text = re.search(r'<text class="caption"[^>]*>(.*?)</text>', svg, re.S).group(1)
    return html.unescape(re.sub(r"\s+", " ", re.sub("<[^>]+>", " ", text)).strip())


def dxf_radii(path) -> set:
    return {round(e.dxf.radius, 6) for e in ezdxf.readfile(path).modelspace() if e.dxftype() == "CIRCLE"}


def dxf_texts(path) -> list:
    """The DXF's texts but the muscles' labels."""
    return [e.dxf.text for e in ezdxf.readfile(path).modelspace() if e.dxftype() == "TEXT" and e.dxf.layer != "LABELS"]


@pytest.fixture(scope="module")
def routed():
    """One pose of a 40 x 10 mm strip, its layout routed with FAB (channel 1, wall 0.6, fixtures 1.5)."""
    mesh = Mesh.rectangle(40.0, 10.0, 20, 6)
    mat = NeoHookean(1.0, 0.4)
    mus = Muscle([i for i, p in enumerate(mesh.points) if abs(p[1] - 10 / 6) < 1e-9 and 2 < p[0] < 38])
    bent = solve_internal(mesh, mat, [mus], [0.1]).x
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        res = design_poses(mesh, mat, {"bend": bent}, routing_options={"fabrication": FAB}, units="mm", compare=False)
    assert res.success
    return mesh, res


def test_a_layout_is_drawn_with_the_fabrication_it_was_routed_with(routed, tmp_path):
    mesh, res = routed
    assert res.fabrication == FAB.for_body(mesh)  # it travels with the result (every field set) ...
    loaded = PosesResult.load(res.save(tmp_path / "layout.json"))
    assert loaded.fabrication == FAB.for_body(mesh)  # ... and with its file
    r = res.anchor_radius
    for k, design in enumerate((res, loaded)):
        files = export_fabrication(mesh, design, tmp_path / f"f{k}", name="strip")  # not given again
        assert "channel(s) 1 wide with walls of 0.6" in caption(files["svg"])
        assert dxf_radii(files["dxf"]) == {round(r, 6), round(r + 0.6, 6)}
    # the same sizes given again: fine; others: refused before anything is written
    export_fabrication(mesh, res, tmp_path / "same", name="strip", fabrication={"wall": 0.6})
    with pytest.raises(ValueError, match=r"routed \(or given\) with: wall 1 \(the layout's: 0.6\).*leave fabrication out"):
        export_fabrication(mesh, res, tmp_path / "other", fabrication=Fabrication(wall=1.0))
    assert not (tmp_path / "other").exists()
    with pytest.raises(ValueError, match=r"give the fabrication once: as design_poses\(fabrication=...\) or in"):
        design_poses(mesh, NeoHookean(1.0, 0.4), {"bend": mesh.points}, fabrication=FAB,
                     routing_options={"fabrication": FAB})


def strip_with_muscles():
    mesh = Mesh.rectangle(40.0, 10.0, 20, 6)
    rows = [[i for i, p in enumerate(mesh.points) if abs(p[1] - y) < 1e-9 and x0 < p[0] < x0 + 14]
            for x0, y in ((4, 10 / 3), (22, 20 / 3))]  # fixtures apart
    return mesh, [Muscle(rows[0], name="low"), Muscle(rows[1], name="high")]


def test_a_failed_design_is_refused_unless_asked_for_and_then_every_file_says_so(tmp_path):
    mesh, mus = strip_with_muscles()
    bad = SimpleNamespace(contractions=np.array([0.1, 0.05]), success=False,
                          status="Maximum_Iterations_Exceeded; rejected: the design's state inverts an element")
    good = SimpleNamespace(contractions=np.array([0.1, 0.05]), success=True, status="Solve_Succeeded")
    with pytest.raises(ValueError, match=r"the design failed \(up: Maximum_Iterations_Exceeded.*allow_failed=True"):
        export_fabrication(mesh, {"up": bad, "down": good}, tmp_path / "no", muscles=mus, units="mm")
    assert not (tmp_path / "no").exists()
    with pytest.warns(UserWarning, match="FAILED DESIGN: the design failed"):
        files = export_fabrication(mesh, bad, tmp_path / "yes", muscles=mus, units="mm", allow_failed=True)
    mark = "FAILED DESIGN: the design failed (Maximum_Iterations_Exceeded; rejected: the design's state inverts"
    assert caption(files["svg"]).strip().startswith(mark)
    assert "do not build" in open(files["svg"], encoding="utf-8").read().split("</title>")[0]
    svg = ET.parse(files["svg"]).getroot()  # across the drawing in red, and the caption in red
    ns = {"s": "http://www.w3.org/2000/svg"}
    mark_text = svg.find("s:text[@id='failed']", ns)
    assert mark_text is not None and mark_text.text == "FAILED DESIGN: DO NOT BUILD" and mark_text.get("fill") == "#d00000"
    assert svg.find("s:text[@class='caption']", ns).get("fill") == "#d00000"
    assert " ".join(dxf_texts(files["dxf"])).startswith(mark)
    lines = open(files["csv"], encoding="utf-8").read().splitlines()
    assert lines[0].startswith("# " + mark) and lines[0].endswith("do not build")
    assert [r["muscle"] for r in csv.DictReader(lines[1:])] == ["low", "high"]
    # a design that succeeded: no mark anywhere
    ok = export_fabrication(mesh, good, tmp_path / "ok", muscles=mus, units="mm")
    assert not any("FAILED" in open(f, encoding="utf-8").read() for f in ok.values())
    assert 'fill="#d00000"' not in open(ok["svg"], encoding="utf-8").read()


def test_a_stroke_that_would_stretch_its_rope_is_never_paired_silently(tmp_path):
    """The trial's star: contraction 0.16 commanded, the rope's path 2.3x its rest length (achieved -1.31)."""
    mesh, mus = strip_with_muscles()
    L0 = np.array([m.rest_length(mesh) for m in mus])
    d = SimpleNamespace(contractions=np.array([0.16, 0.05]), stroke=np.array([-1.31, 0.05]) * L0, success=True)
    with pytest.raises(ValueError, match=r"muscle low in design: commanded contraction 0.16 but achieved -1.31 "
                                         r"\(its path 2.31x its rest length.*a rope cannot stretch"):
        export_fabrication(mesh, d, tmp_path / "no", muscles=mus, units="mm")
    with pytest.warns(UserWarning, match="FAILED DESIGN"):
        files = export_fabrication(mesh, d, tmp_path / "yes", muscles=mus, units="mm", allow_failed=True)
    rows = list(csv.DictReader(open(files["csv"], encoding="utf-8").read().splitlines()[1:]))
    assert [float(r["achieved design [1]"]) for r in rows] == pytest.approx([-1.31, 0.05])
    assert [float(r["contraction design [1]"]) for r in rows] == pytest.approx([0.16, 0.05])


def test_a_failed_pose_of_a_layout_is_refused_and_named(routed, tmp_path):
    mesh, res = routed
    failed = dataclasses.replace(res, pose_success=np.array([False]), status=("Restoration_Failed",))
    with pytest.raises(ValueError, match=r"the layout's design failed \(pose bend: Restoration_Failed\)"):
        export_fabrication(mesh, failed, tmp_path / "no")
    files = export_fabrication(mesh, failed, tmp_path / "yes", allow_failed=True, failure="frames [3] failed")
    assert caption(files["svg"]).startswith("FAILED DESIGN: the layout's design failed (pose bend: Restoration_Failed); "
                                            "frames [3] failed, do not build. robot: 1 muscle channel(s) 1 wide")


def ring(r: float, n: int = 48) -> list:
    t = 2 * np.pi * np.arange(n) / n
    return np.round(np.c_[r * np.cos(t), r * np.sin(t)], 3).tolist()


def ring_scene(tmp_path, **extra):
    spec = {"name": "thick_ring", "units": "mm",
            "body": {"outline": ring(50.0), "holes": [ring(28.0)], "resolution": "coarse"},
            "material": {"E": 1.0, "nu": 0.4},
            "fabrication": {"channel_diameter": 2.0, "wall": 1.5, "fixture_radius": 4.0, "min_fixture_radius": 2.5},
            "regions": {"bottom": {"near": [0, -50], "radius": 8, "boundary": True},
                        "top": {"near": [0, 50], "radius": 8, "boundary": True}},
            "cases": [{"name": "squash", "anchors": "bottom", "drags": [{"nodes": "top", "by": [0, -20]}]}],
            "gait": {"poses": ["rest", "squash"]}, **extra}
    path = tmp_path / "thick_ring.json"
    path.write_text(json.dumps(spec))
    return load_scene(path)


def test_a_scene_gait_without_animations_writes_its_files_with_the_scenes_fabrication(tmp_path):
    scene = ring_scene(tmp_path)
    assert n_units(scene, None, False, photos=False, figures=False) == 2  # the case and the gait
    out = tmp_path / "out"
    run_scene(scene, out, photos=False, figures=False, animations=False, prototype=False, log=None,
              background=False)
    names = {p.name for p in (out / "gait").iterdir()}
    assert {"layout.json", "schedule.csv", "thick_ring.svg", "thick_ring.dxf", "thick_ring_muscles.csv"} <= names
    assert "gait.gif" not in names
    gait = json.loads((out / "gait" / "gait.json").read_text())
    assert gait["success"] and "gait/thick_ring.svg" in gait["files"]
    assert "channel(s) 2 wide with walls of 1.5" in caption(out / "gait" / "thick_ring.svg")
    r = gait["fixture_radius"]
    assert 2.5 <= r <= 4.0 and dxf_radii(out / "gait" / "thick_ring.dxf") == {round(r, 6), round(r + 1.5, 6)}
    assert json.loads((out / "gait" / "layout.json").read_text())["fabrication"]["wall"] == 1.5


def test_a_failed_gait_writes_its_fabrication_files_marked(tmp_path):
    scene = ring_scene(tmp_path, acceptance={"max_difference": 1e-9})  # no pose can be reached that closely
    out = tmp_path / "out"
    run_scene(scene, out, photos=False, figures=False, animations=False, prototype=False, log=None,
              background=False)
    gait = json.loads((out / "gait" / "gait.json").read_text())
    assert not gait["success"]
    assert caption(out / "gait" / "thick_ring.svg").strip().startswith("FAILED DESIGN: ")
    first = (out / "gait" / "thick_ring_muscles.csv").read_text().splitlines()[0]
    assert first.startswith("# FAILED DESIGN: ") and first.endswith(", do not build")
    assert any(t.startswith("FAILED DESIGN: ") for t in dxf_texts(out / "gait" / "thick_ring.dxf"))


def test_a_case_of_a_scene_stating_its_fabrication_gets_its_files(tmp_path):
    """mdsr run writes them beside the case's figures (runner's shapes job); a scene stating none gets none."""
    scene = ring_scene(tmp_path)
    run = run_case(scene, "squash", photo=False)
    assert run.report.success
    files = write_case_fabrication(scene, run, tmp_path / "ok")
    assert sorted(Path(f).name for f in files) == ["thick_ring_squash.dxf", "thick_ring_squash.svg",
                                                   "thick_ring_squash_muscles.csv"]
    assert caption(files[0]).startswith("thick_ring_squash: ") and "2 wide with walls of 1.5" in caption(files[0])
    failed = dataclasses.replace(run, report=dataclasses.replace(run.report, success=False, message="too far"))
    with pytest.warns(UserWarning, match="FAILED DESIGN: the case failed"):
        files = write_case_fabrication(scene, failed, tmp_path / "failed")
    assert caption(files[0]).startswith("FAILED DESIGN: the case failed (too far), do not build. thick_ring_squash")
    scene.routing_options.pop("fabrication")
    assert write_case_fabrication(scene, run, tmp_path / "none") == [] and not (tmp_path / "none").exists()


def test_a_pipeline_of_given_muscles_is_drawn_with_the_fabrication_it_was_given(tmp_path):
    from mdsr_opt.synthesis.pipeline import PipelineResult, design_pipeline

    mesh, mus = strip_with_muscles()
    mat = NeoHookean(1.0, 0.4)
    bent = solve_internal(mesh, mat, [mus[0]], [0.1]).x
    left = [i for i, (x, y) in enumerate(mesh.points) if x == 0.0]
    right = {i: tuple(bent[i]) for i, (x, y) in enumerate(mesh.points) if x == 40.0}
    fab = Fabrication(channel_diameter=0.5, wall=0.3)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        res = design_pipeline(mesh, mat, left, right, muscles=[mus[0]], fabrication=fab, units="mm")
    assert res.success and res.fabrication == fab
    res.save(tmp_path / "saved")
    loaded = PipelineResult.load(tmp_path / "saved")
    for k, design in enumerate((res, loaded)):
        files = export_fabrication(mesh, design, tmp_path / f"f{k}", name="strip")
        assert "channel(s) 0.5 wide with walls of 0.3" in caption(files["svg"])
    with pytest.raises(ValueError, match=r"channel_diameter 1 \(the layout's: 0.5\)"):
        export_fabrication(mesh, res, tmp_path / "other", fabrication={"channel_diameter": 1.0})


def test_a_layout_pose_beyond_the_5_percent_rule_is_exported_as_failed(routed, tmp_path):
    """A pose of a layout that is designed (``pose_success``) but whose difference is above 5 % of the body's
    size is the pose a gait reports not reached and ``mdsr run`` fails: the export refuses it, naming the pose
    and the rule, and marks its files when told to write them; at 4.9 % it is exported unmarked."""
    import dataclasses

    from mdsr_opt.mechanics.anchors import body_size

    mesh, res = routed
    size = body_size(mesh)
    far = dataclasses.replace(res, differences=np.array([0.06 * size]))
    with pytest.raises(ValueError, match=r"pose bend: too far from its target \(difference .* mm is 6\.00 % of "
                                         r"the size .* more than max_difference 5 %\)"):
        export_fabrication(mesh, far, tmp_path / "no", name="strip")
    assert not (tmp_path / "no").exists() or not any((tmp_path / "no").iterdir())
    with pytest.warns(UserWarning):
        files = export_fabrication(mesh, far, tmp_path / "yes", name="strip", allow_failed=True)
    csv_text = open(files["csv"], encoding="utf-8").read()
    assert csv_text.startswith("# FAILED DESIGN") and "pose bend: too far from its target" in csv_text
    near = dataclasses.replace(res, differences=np.array([0.049 * size]))
    files = export_fabrication(mesh, near, tmp_path / "near", name="strip")
    assert "FAILED" not in open(files["csv"], encoding="utf-8").read()
