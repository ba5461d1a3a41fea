"""One visual language (issue 36): every figure kind labels its axes with quantity and unit, and a muscle has
one name and one colour in the design figure, the schedule, Figure 6's panels and the fabrication SVG/DXF."""

from __future__ import annotations

import re
from pathlib import Path
from types import SimpleNamespace

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np
import pytest
from matplotlib.colors import to_hex

from mdsr_opt import Mesh, Muscle, NeoHookean, solve_internal
from mdsr_opt.plot.style import muscle_color, muscle_name

UNIT = re.compile(r"\(([^()]+)\)\s*$")  # "quantity (unit)"


def _has_unit(label: str) -> bool:
    return bool(label) and bool(UNIT.search(label))


def _legend(ax) -> dict:
    """{label: colour} of the muscle lines in ``ax``'s legend."""
    leg = ax.get_legend()
    return {t.get_text(): to_hex(h.get_color()) for t, h in zip(leg.get_texts(), leg.legend_handles)
            if t.get_text().startswith("M")}


@pytest.fixture(scope="module")
def strip():
    mesh = Mesh.rectangle(4.0, 1.0, 16, 4)
    bottom = [i for i in np.argsort(mesh.points[:, 0]) if mesh.points[i, 1] == 0.0]
    top = [i for i in np.argsort(mesh.points[:, 0]) if mesh.points[i, 1] == 1.0]
    muscles = [Muscle([int(i) for i in bottom[1:-1]]), Muscle([int(i) for i in top[1:-1]])]
    target = solve_internal(mesh, NeoHookean(1.0, 0.3), muscles, [0.12, 0.04]).x
    return mesh, muscles, target


def test_design_figure_schedule_and_svg_agree_on_muscle_names_and_colours(strip, tmp_path):
    from mdsr_opt.plot.design import plot_design
    from mdsr_opt.synthesis.contractions import design_contractions
    from mdsr_opt.synthesis import gait
    from mdsr_opt.synthesis.export import export_fabrication
    from mdsr_opt.plot.design import plot_schedule

    assert not hasattr(gait, "plot_schedule")  # the chart lives with the figures, no alias left behind

    mesh, muscles, target = strip
    res = design_contractions(mesh, NeoHookean(1.0, 0.3), muscles, target)
    want = {muscle_name(i): muscle_color(i) for i in range(2)}
    assert want == {"M1": "#d62728", "M2": "#1f77b4"}

    fig = plot_design(mesh, res, target, muscles, units="mm")
    ax = fig.axes[0]
    assert ax.get_xlabel() == "x (mm)" and ax.get_ylabel() == "y (mm)"
    title = ax.get_title()
    assert f"difference D = {res.difference:.3g} mm" in title
    for i in range(2):  # commanded beside achieved
        assert f"M{i + 1} {res.contractions[i]:.3f} \u2192 {res.achieved[i]:.3f}" in title
    assert _legend(ax) == want
    plt.close(fig)

    t = np.linspace(0.0, 1.0, 5)
    strokes = np.outer(t, [0.3, 0.1])
    sched = SimpleNamespace(times=t, muscle_names=("M1", "M2"), strokes=strokes, achieved=strokes * 0.98,
                            rest_lengths=np.array([3.5, 1650.0]), units="mm", keyframes=[0, 4], labels=["rest"] * 5,
                            frame_success=np.ones(5, bool), sequence=("rest", "pose"), n_frames=5)
    fig = plot_schedule(sched)
    ax = fig.axes[0]
    assert ax.get_xlabel() == "time (s)" and ax.get_ylabel().startswith("stroke (mm")
    got = {t.get_text().split()[0]: to_hex(h.get_color())
           for t, h in zip(ax.get_legend().get_texts(), ax.get_legend().legend_handles)}
    assert {k: v for k, v in got.items() if k.startswith("M")} == want
    texts = [t.get_text() for t in ax.get_legend().get_texts()]
    assert "M1 (L0 = 3.5 mm)" in texts and "M2 (L0 = 1650 mm)" in texts  # plain numbers, not 1.65e+03
    # the achieved strokes are drawn beside the commanded ones, dotted, in the muscle's colour, and the
    # legend says which line is which
    assert [h.get_linestyle() for t, h in zip(ax.get_legend().get_texts(), ax.get_legend().legend_handles)
            if t.get_text() in ("commanded", "achieved")] == ["-", ":"]
    dotted = [ln for ln in ax.get_lines() if ln.get_linestyle() == ":" and len(ln.get_xdata())]
    assert sorted(to_hex(ln.get_color()) for ln in dotted) == sorted(want.values())
    plt.close(fig)

    files = export_fabrication(mesh, res, tmp_path, muscles=muscles, units="mm", name="strip")
    svg = Path(files["svg"]).read_text()
    found = dict(re.findall(r'<polyline class="muscle" id="([^"]+)" points="[^"]*" stroke="([^"]+)"', svg))
    assert found == want
    dxf = Path(files["dxf"]).read_text().split("\n")
    texts = [i for i, v in enumerate(dxf) if v.strip() == "TEXT"]
    # each label: its layer, then group 62 with the ACI colour of the muscle's figure colour (red, blue)
    assert [dxf[i + 3].strip() for i in texts] == ["62"] * 2 and [int(dxf[i + 4]) for i in texts] == [1, 5]


def test_figure6_panels_use_the_muscle_names_one_colour_scale_and_units(strip):
    from mdsr_opt.plot.routing import plot_convergence, plot_design_grid, plot_layout_grid

    mesh, muscles, target = strip
    cols = [{"title": "a", "mesh": mesh, "target": target, "layouts": [muscles], "row_labels": ["K_a = 4"]},
            {"title": "b", "mesh": mesh, "target": mesh.points * [0.9, 1.0], "layouts": [muscles[:1]],
             "row_labels": ["K_a = 4"]}]
    fig = plot_layout_grid(cols)
    axes = np.array(fig.axes).reshape(3, 2)
    assert axes[2, 0].get_legend() is None  # one legend for the row, beside its last panel
    assert _legend(axes[2, 1]) == {"M1": muscle_color(0), "M2": muscle_color(1)}
    clims = {ax.collections[-1].get_clim() for ax in axes[1]}
    assert len(clims) == 1  # the contraction-graph row shares one colour scale
    bar, = axes[1, -1].child_axes  # with its colour bar, the height of the panel
    assert "l_0" in bar.get_ylabel() and _has_unit(bar.get_ylabel())
    fig.canvas.draw()
    a, b = axes[1, -1].get_window_extent(), bar.get_window_extent()
    assert abs(a.height - b.height) < 2 and b.x0 >= a.x1
    plt.close(fig)

    d = {"x": target, "muscles": muscles, "difference": 0.01, "success": True}
    fig = plot_design_grid([{"title": "a", "mesh": mesh, "target": target, "designs": [d], "row_labels": ["C"],
                             "units": "cm"}])
    assert fig.axes[1].get_title() == "C: D = 0.01 cm"
    assert [ax.get_ylabel() for ax in fig.axes] == ["target", "driven"]  # rows named plainly
    plt.close(fig)
    col = {"title": "a", "mesh": mesh, "target": target, "designs": [d, d], "row_labels": ["C", "D"]}
    fig = plot_design_grid([col])
    assert [ax.get_ylabel() for ax in fig.axes] == ["target", "driven, layout 1", "driven, layout 2"]
    plt.close(fig)
    fig = plot_design_grid([col], row_names=["target", "layout C, driven", "layout D, driven"])
    assert [ax.get_ylabel() for ax in fig.axes] == ["target", "layout C, driven", "layout D, driven"]
    plt.close(fig)
    with pytest.raises(ValueError, match="2 row names for 3 rows"):
        plot_design_grid([col], row_names=["target", "driven"])
    fig = plot_convergence([{"title": "a", "traces": [("C", [0, 1, 2], [1.0, 0.1, 0.01])], "units": "cm"}])
    ax = fig.axes[0]
    assert ax.get_ylabel() == "difference D (cm)" and _has_unit(ax.get_xlabel())
    plt.close(fig)
    fig = plot_convergence([{"title": t, "traces": [("C", [0, 1], [1.0, 0.1])], "units": u}
                            for t, u in (("a", "cm"), ("b", "cm"), ("c", "mm"))])
    assert [ax.get_ylabel() for ax in fig.axes] == ["difference D (cm)", "difference D (cm)", "difference D (mm)"]
    plt.close(fig)


def test_scene_figures_label_their_axes_and_save_vector_copies(strip, tmp_path):
    from mdsr_opt.plot.common import save_figure
    from mdsr_opt.plot.style import figure_paths
    from mdsr_opt.plot.design import plot_contraction_graph, plot_routing
    from mdsr_opt.plot.scenes import plot_scene, plot_target

    mesh, muscles, target = strip
    for fig in (plot_contraction_graph(mesh, target, units="cm", ticks=False),
                plot_routing(mesh, target, muscles, units="cm"),
                plot_target(mesh, target, anchors=[0], muscles=muscles, values=np.ones(mesh.n_triangles),
                            units="cm"),
                plot_scene(mesh, {"left": [0]}, units="cm")):
        for ax in fig.axes:
            assert ax.get_xlabel() == "x (cm)" and ax.get_ylabel() == "y (cm)"
            for bar in ax.child_axes:  # colour bars: a quantity with its unit, the height of the axes
                assert _has_unit(bar.get_ylabel())
        plt.close(fig)
    fig = plot_routing(mesh, target, muscles)
    assert fig.axes[0].get_xlabel() == "x (body units)"  # no unit given: said so
    p = save_figure(fig, tmp_path / "m.png", vector=("pdf", "svg"), close=True)
    assert figure_paths(p, ("pdf", "svg")) == [str(tmp_path / f"m.{e}") for e in ("png", "pdf", "svg")]
    assert (tmp_path / "m.pdf").read_bytes()[:5] == b"%PDF-" and "<svg" in (tmp_path / "m.svg").read_text()
    with pytest.raises(ValueError, match="vector figure format must be one of pdf, svg, got 'eps'"):
        save_figure(plt.figure(), tmp_path / "n.png", vector="eps", close=True)
    assert not (tmp_path / "n.png").exists()


def test_mdsr_run_vector_writes_a_pdf_beside_every_png(tmp_path):
    import json

    from mdsr_opt.cli.main import main

    strip = tmp_path / "strip.json"
    strip.write_text(json.dumps({
        "name": "strip", "units": "cm", "body": {"outline": [[0, 0], [4, 0], [4, 1], [0, 1]], "resolution": 60},
        "regions": {"base": {"box": [-1, -1, 0, 2]}, "end": {"box": [4, -1, 5, 2]}},
        "cases": [{"name": "bend", "anchors": "base", "drags": [{"nodes": "end", "by": [-0.8, 1.2]}]}]}))
    out = tmp_path / "out"
    assert main(["run", str(strip), "--out", str(out), "--no-photos", "--vector", "--serial"]) == 0
    pngs = sorted(p.relative_to(out).as_posix() for p in out.rglob("*.png"))
    assert "rest.png" in pngs and "bend/design.png" in pngs
    for p in pngs:
        assert (out / p).with_suffix(".pdf").read_bytes()[:5] == b"%PDF-", p
    summary = json.loads((out / "summary.json").read_text())
    assert "bend/design.pdf" in summary["cases"][0]["files"]  # listed with the case's files
    assert main(["run", str(strip), "--out", str(tmp_path / "svg"), "--no-photos", "--vector",
                 "--vector-format", "svg", "--serial"]) == 0
    assert (tmp_path / "svg" / "bend" / "design.svg").exists() and not (tmp_path / "svg" / "rest.pdf").exists()


_FIGURE_SCRIPT = """
import os

OUTPUTS = ("a.png", "a.json")


def run_figure(out, resolution="medium", log=print{vector}):
    import matplotlib.pyplot as plt
    from mdsr_opt.plot.common import save_figure

    save_figure(plt.figure(), os.path.join(out, "a.png"), close=True{pass_vector})
    with open(os.path.join(out, "a.json"), "w") as fh:
        fh.write("{{}}")
    return 0
"""


def test_mdsr_run_passes_vector_to_a_figure_script_that_takes_it(tmp_path, capsys, monkeypatch):
    """``mdsr run FIGURE --vector``: the script's vector copies are written and listed in the run folder's
    manifest; a script without a ``vector`` argument is refused at the door, before any folder is made."""
    import json

    from mdsr_opt.cli.main import main

    lib = tmp_path / "lib"
    lib.mkdir()
    (lib / "takes.py").write_text(_FIGURE_SCRIPT.format(vector=", vector=None", pass_vector=", vector=vector"))
    (lib / "plain.py").write_text(_FIGURE_SCRIPT.format(vector="", pass_vector=""))
    monkeypatch.setenv("MDSR_PROBLEMS", str(lib))
    assert main(["run", "takes", "--out", str(tmp_path / "t"), "--vector", "--vector-format", "svg"]) == 0
    assert "<svg" in (tmp_path / "t" / "a.svg").read_text()
    files = json.loads((tmp_path / "t" / ".mdsr-run.json").read_text())["files"]
    assert files == ["a.json", "a.png", "a.svg"]
    assert main(["run", "plain", "--out", str(tmp_path / "p"), "--vector"]) == 2  # said, not ignored
    assert "writes no vector figures" in capsys.readouterr().err and not (tmp_path / "p").exists()


@pytest.mark.parametrize("script", ["figure6", "face_expressions"])
def test_figure_scripts_take_vector_and_refuse_a_bad_format_before_any_work(script, tmp_path):
    import inspect

    from mdsr_opt.scenes.library import figure_scripts, load_module

    module = load_module(figure_scripts()[script])
    assert "vector" in inspect.signature(module.run_figure).parameters
    with pytest.raises(ValueError, match="vector figure format must be one of pdf, svg, got 'eps'"):
        module.run_figure(tmp_path / "out", resolution="coarse", log=lambda s: None, vector="eps")
    assert not (tmp_path / "out").exists()


@pytest.mark.slow
def test_figure6_vector_copies_and_differences_in_the_scenes_unit(tmp_path, monkeypatch):
    """Figure 6 at the coarse resolution with --vector: a PDF beside every PNG, listed in the manifest, and
    the differences of 6b and 6c labelled with the scenes' length unit, not a bare number."""
    import json

    import mdsr_opt.plot.common as common
    from mdsr_opt.cli.main import main
    from mdsr_opt.scenes.library import get_problem

    texts, save = [], common.save_figure

    def recording(fig, path, **kw):
        texts.append((Path(path).name, [ax.get_title() for ax in fig.axes], [ax.get_ylabel() for ax in fig.axes]))
        return save(fig, path, **kw)

    monkeypatch.setattr(common, "save_figure", recording)
    out = tmp_path / "f6"
    assert main(["run", "figure6", "--out", str(out), "--resolution", "coarse", "--vector", "--quiet"]) == 0
    files = json.loads((out / ".mdsr-run.json").read_text())["files"]
    for f in ("figure6a", "figure6b", "figure6c"):
        assert (out / f"{f}.pdf").read_bytes()[:5] == b"%PDF-" and f"{f}.pdf" in files and f"{f}.png" in files
    # the scene's length unit; a scene without one (the tentacle) is in "body units", as the README says
    unit = get_problem("tentacle", resolution="coarse").units or "body units"
    (_, titles_b, ylabels_b), = [t for t in texts if t[0] == "figure6b.png"]
    assert [y for y in ylabels_b if y] == ["target", "layout C, driven", "layout D, driven"]
    driven = [t for t in titles_b if ": D = " in t]
    assert len(driven) == 10 and all(re.search(rf"D = [0-9.e+-]+ {unit}\b", t) for t in driven), driven
    (_, _, ylabels_c), = [t for t in texts if t[0] == "figure6c.png"]
    assert ylabels_c[0] == f"difference D ({unit})"


def test_gif_frames_are_large_and_draw_idle_muscles_in_their_colour(strip, tmp_path):
    from PIL import Image

    from mdsr_opt.plot.scenes import save_animation

    mesh, muscles, target = strip
    states = [mesh.points, target]
    p = save_animation(mesh, states, tmp_path / "a.gif", muscles=muscles, activations=[[0.0, 0.0], [1.0, 0.2]],
                       titles=["rest", "pose"])
    im = Image.open(p)
    assert im.size[0] >= 800 and im.size[1] >= 500
    red = np.array([0xd6, 0x27, 0x28])  # M1's colour (plot.style)
    counts = []
    for k in range(2):
        im.seek(k)
        rgb = np.asarray(im.convert("RGB")).astype(int)
        counts.append(int((np.abs(rgb - red).sum(-1) < 60).sum()))
    # idle in the first frame, yet drawn in full colour (thinner than when it pulls), beside the legend's swatch
    assert counts[0] > 300 and counts[1] > counts[0]


def test_gif_frames_of_one_state_differ_by_their_line_widths_and_titles_only(strip, tmp_path):
    # an animation goes out and back: a frame of a state and widths drawn before is a copy of it (its own
    # title on it); the same state at other widths is drawn anew
    from PIL import Image

    from mdsr_opt.plot.scenes import save_animation

    mesh, muscles, target = strip
    p = save_animation(mesh, [target, target, target], tmp_path / "a.gif", muscles=muscles,
                       activations=[[1.0, 0.2], [1.0, 0.2], [0.0, 0.0]], titles=["out", "back", "idle"])
    im = Image.open(p)
    frames = []
    for k in range(3):
        im.seek(k)
        frames.append(np.asarray(im.convert("RGB")).astype(int))
    rows = np.flatnonzero((frames[0] != frames[1]).any(axis=(1, 2)))  # one line of text: the titles
    assert len(rows) and rows.max() - rows.min() < 30
    rest = np.ones(len(frames[0]), bool)
    rest[rows.min():rows.max() + 1] = False
    assert (frames[0][rest] != frames[2][rest]).any()  # other widths: the muscles drawn anew


def _svg_colours(svg: str) -> dict:
    return dict(re.findall(r'<polyline class="muscle" id="([^"]+)" points="[^"]*" stroke="([^"]+)"', svg))


def _dxf_label_colours(text: str) -> dict:
    """{label: ACI colour} of the DXF's TEXT entities (read as group code / value pairs), but those on the
    CONFLICTS layer (marks of clashes and of a failed design, not labels)."""
    v = [s.strip() for s in text.split("\n")]
    pairs = list(zip(v[0::2], v[1::2]))
    out, cur = {}, None
    for code, value in pairs + [("0", "EOF")]:
        if code == "0":
            if cur is not None and "1" in cur and cur.get("8") != "CONFLICTS":
                out[cur["1"]] = int(cur.get("62", 256))
            cur = {} if value == "TEXT" else None
        elif cur is not None:
            cur[code] = value
    return out


def test_a_scene_run_gives_each_rope_one_name_and_colour_in_every_figure_and_file(tmp_path, monkeypatch):
    """Two routed cases and a gait over both (as gecko): the second case's ropes are numbered on from the
    first's (M3, M4, not a second M1, M2), the gait's layout, schedule, animation and fabrication files keep
    those names, and every figure and drawing colours a rope by its name."""
    import json

    import mdsr_opt.plot.common as common
    from mdsr_opt.plot.style import dxf_color, muscle_slot, name_color
    from mdsr_opt.scenes.runscene import run_scene
    from mdsr_opt.scenes.scenefile import load_scene

    d = {"name": "strip", "units": "cm", "body": {"outline": [[0, 0], [4, 0], [4, 1], [0, 1]], "resolution": 90},
         "regions": {"base": {"box": [-1, -1, 0.01, 2]}, "end": {"box": [3.99, -1, 5, 2]}},
         "cases": [{"name": "up", "anchors": "base", "drags": [{"nodes": "end", "by": [-0.6, 1.0]}]},
                   {"name": "down", "anchors": "base", "drags": [{"nodes": "end", "by": [-0.6, -1.0]}]}],
         "animations": [{"name": "wave", "keyframes": [["up", 1], ["down", 1]], "frames_per_step": 1}],
         "gait": {"name": "walk", "poses": ["up", "rest", "down"], "frames_per_step": 1}}
    (tmp_path / "strip.json").write_text(json.dumps(d))
    legends, save = {}, common.save_figure

    def recording(fig, path, **kw):  # the muscles' legend of every figure written: {name: colour}
        for ax in fig.axes:
            if ax.get_legend() is not None:
                legends.setdefault(Path(path).relative_to(tmp_path / "out").as_posix(), {}).update(_legend(ax))
        return save(fig, path, **kw)

    monkeypatch.setattr(common, "save_figure", recording)
    run_scene(load_scene(tmp_path / "strip.json"), tmp_path / "out", photos=False, prototype=False, log=None,
              background=False)
    out = tmp_path / "out"
    summary = json.loads((out / "summary.json").read_text())
    cases = {c["case"]: {m["name"]: tuple(m["nodes"]) for m in c["muscles"]} for c in summary["cases"]}
    names = [n for c in cases.values() for n in c]
    assert len(names) >= 3 and len(set(names)) == len(names)  # no name used by two ropes
    assert sorted(names, key=lambda n: int(n[1:])) == [f"M{k + 1}" for k in range(len(names))]
    ropes = {n: p for c in cases.values() for n, p in c.items()}
    for f in ("walk/layout.json", "wave.json"):  # the gait's layout and the animation: the cases' names
        got = {m["name"]: tuple(m["nodes"]) for m in json.loads((out / f).read_text())["muscles"]}
        # the same rope, or (in the gait's shared layout) the part of it cut clear of another pose's ropes
        assert all(any(ropes[n][i:i + len(p)] == p for i in range(len(ropes[n]) - len(p) + 1))
                   for n, p in got.items()), f
    for case, mus in cases.items():  # every case figure with muscles colours each by its name
        for fig in (f"{case}/design.png", f"{case}/muscles.png"):
            assert legends[fig] == {n: name_color(n, 0) for n in mus}, fig
    sched = {k.split()[0]: c for k, c in legends["walk/schedule.png"].items()}  # "M1 (L0 = ...)"
    assert len(sched) >= 3 and set(sched) <= set(ropes) and sched == {n: name_color(n, 0) for n in sched}
    svg = (out / "walk" / "strip.svg").read_text()
    drawn = _svg_colours(svg)
    assert drawn == {n: name_color(n, 0) for n in drawn} and set(drawn) <= set(ropes)
    dxf = _dxf_label_colours((out / "walk" / "strip.dxf").read_text())
    assert dxf and dxf == {n: dxf_color(muscle_slot(n, 0)) for n in dxf}


def test_a_numbered_name_keeps_its_colour_and_shared_layouts_keep_names(strip, tmp_path):
    """M3 drawn alone is M3's colour in the design figure, the GIF's legend, the SVG and the DXF; number_in_scene
    numbers a later case's ropes on, keeps a rope an earlier case has and a name of its own; shared_layout keeps
    names that do not collide."""
    from mdsr_opt.plot.design import plot_design
    from mdsr_opt.plot.style import dxf_color, muscle_color, name_color
    from mdsr_opt.scenes.names import number_in_scene
    from mdsr_opt.synthesis.contractions import design_contractions
    from mdsr_opt.synthesis.export import export_fabrication
    from mdsr_opt.synthesis.layouts import shared_layout

    mesh, muscles, target = strip
    assert name_color("M3", 0) == muscle_color(2) and name_color("flexor", 1) == muscle_color(1)
    late = [Muscle(m.nodes, name=n) for m, n in zip(muscles, ("M3", "M4"))]
    res = design_contractions(mesh, NeoHookean(1.0, 0.3), late, target)
    fig = plot_design(mesh, res, target, late, units="mm")
    assert _legend(fig.axes[0]) == {"M3": muscle_color(2), "M4": muscle_color(3)}
    assert "M3 0.1" in fig.axes[0].get_title()
    plt.close(fig)
    files = export_fabrication(mesh, res, tmp_path, muscles=late, units="mm", name="late")
    assert _svg_colours(Path(files["svg"]).read_text()) == {"M3": muscle_color(2), "M4": muscle_color(3)}
    assert _dxf_label_colours(Path(files["dxf"]).read_text()) == {"M3": dxf_color(2), "M4": dxf_color(3)}

    a = [Muscle(muscles[0].nodes, name="M1")]
    b = [Muscle(muscles[1].nodes, name="M1"), Muscle(muscles[0].nodes, name="M2")]
    got = number_in_scene(b, a)
    assert [m.name for m in got] == ["M2", "M1"] and [m.nodes for m in got] == [m.nodes for m in b]
    assert number_in_scene(b) == tuple(b) and [m.name for m in number_in_scene(b)] == ["M1", "M2"]
    own = number_in_scene([Muscle(muscles[1].nodes, name="flexor")], a)
    assert [m.name for m in own] == ["flexor"]
    lay, _ = shared_layout(mesh, {"up": [Muscle(muscles[1].nodes, name="M2")],
                                  "down": [Muscle(muscles[0].nodes, name="M1")]})
    assert [m.name for m in lay] == ["M2", "M1"]  # kept: one name a rope
    lay, _ = shared_layout(mesh, {"up": [Muscle(muscles[1].nodes, name="M1")],
                                  "down": [Muscle(muscles[0].nodes, name="M1")]})
    assert [m.name for m in lay] == ["M1", "M2"]  # two poses' own M1: numbered by place


def test_a_gif_title_on_two_lines_stays_above_the_axes(strip, tmp_path):
    from PIL import Image

    from mdsr_opt.plot.scenes import save_animation

    mesh, muscles, target = strip
    long = [Muscle(m.nodes, name=f"a_rather_long_case_name:M{i + 1}") for i, m in enumerate(muscles)]
    title = "wave 1/2: " + ", ".join(f"{m.name} 0.00 \u2192 0.00" for m in long)
    p = save_animation(mesh, [mesh.points, target], tmp_path / "t.gif", muscles=long, titles=[title, title])
    rgb = np.asarray(Image.open(p).convert("RGB")).astype(int)
    black = (rgb < 60).all(-1)
    rows = np.flatnonzero(black.sum(1) > 0.4 * black.shape[1])  # the axes' frame: its top and bottom edges
    cols = np.flatnonzero(black.sum(0) > 0.3 * (rows[-1] - rows[0]))
    top, bottom, left, right = rows[0], rows[-1], cols[0], cols[-1]
    assert bottom - top > 100 and right - left > 400
    inside = black[top + 3:bottom - 2, left + 3:right - 2]
    assert inside.sum() == 0  # no title glyph over the drawing (the mesh and muscles are not black)
    above = black[:top - 1, left:right]
    lines = np.flatnonzero(above.any(1))
    assert len(lines) and np.diff(lines).max() > 3  # two lines of text above the frame


def test_a_fixture_plate_two_muscles_share_is_drawn_once(tmp_path):
    """Ends closer than a fixture's radius share one plate: one outline (black, naming both muscles), not
    two circles; the DXF likewise; and no two names sit on each other."""
    import warnings

    from mdsr_opt.synthesis.export import SHARED_PLATE, export_fabrication

    mesh = Mesh.rectangle(10.0, 4.0, 40, 16)
    P = mesh.points

    def row(y, x0, x1):
        return [int(np.argmin(np.linalg.norm(P - [x, y], axis=1))) for x in np.arange(x0, x1 + 1e-9, 0.25)]

    mus = [Muscle(row(2.0, 1.0, 5.0)), Muscle(row(2.0, 5.0, 9.0)[::-1]),  # meet at one node
           Muscle(row(1.0, 1.0, 4.5)), Muscle(row(1.0, 4.75, 9.0))]        # ends 0.25 apart
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        files = export_fabrication(mesh, None, tmp_path, muscles=mus, units="mm", name="plates")
    svg = Path(files["svg"]).read_text()
    ends = re.findall(r'<(circle|polygon) class="end( shared)?"(?: data-muscles="([^"]*)")?', svg)
    assert len(ends) == 6  # 8 ends, two plates shared
    shared = sorted((kind, who) for kind, s, who in ends if s)
    assert shared == [("circle", "M1 M2"), ("polygon", "M3 M4")]
    assert 'class="end shared" data-muscles="M1 M2" cx' in svg and f'stroke="{SHARED_PLATE}"' in svg
    caption = " ".join(re.findall(r"<tspan[^>]*>([^<]*)</tspan>", svg))
    assert "(black: 2 plate(s) that muscles ending closer than a radius share)" in caption
    dxf = [s.strip() for s in Path(files["dxf"]).read_text().split("\n")]
    on_ends = [i for i in range(1, len(dxf)) if dxf[i] == "ENDS" and dxf[i - 1] == "8"
               and dxf[i - 2] in ("CIRCLE", "POLYLINE")]
    assert len(on_ends) == 6
    at = {n: (float(x), float(y)) for x, y, n in
          re.findall(r'<text class="label" x="([^"]+)" y="([^"]+)"[^>]*>([^<]+)</text>', svg)}
    assert abs(at["M2"][1] - at["M4"][1]) > 0.5  # the two right-hand names apart (they overlapped)


def test_an_animation_solves_with_the_fixtures_its_cases_were_designed_with(tmp_path, monkeypatch):
    """animate() takes the cases' designs' anchor radius (the fixtures their routed ropes were fitted to);
    only cases whose radii differ get one common size, and the message says so."""
    import json

    import mdsr_opt.mechanics.equilibrium as eq
    from mdsr_opt.scenes.animate import animate
    from mdsr_opt.scenes.scenefile import load_scene

    d = {"name": "strip", "body": {"outline": [[0, 0], [4, 0], [4, 1], [0, 1]], "resolution": 60},
         "regions": {"base": {"box": [-1, -1, 0.01, 2]}, "end": {"box": [3.99, -1, 5, 2]}},
         "cases": [{"name": "up", "anchors": "base", "drags": [{"nodes": "end", "by": [-0.6, 1.0]}]},
                   {"name": "down", "anchors": "base", "drags": [{"nodes": "end", "by": [-0.6, -1.0]}]}],
         "animations": [{"name": "one", "keyframes": [["rest", 1], ["up", 1]], "frames_per_step": 1},
                        {"name": "both", "keyframes": [["up", 1], ["down", 1]], "frames_per_step": 1}]}
    (tmp_path / "s.json").write_text(json.dumps(d))
    scene = load_scene(tmp_path / "s.json")
    P = scene.mesh.points
    top = [int(i) for i in np.argsort(P[:, 0]) if P[i, 1] > 1 - 1e-9][2:-2]
    bottom = [int(i) for i in np.argsort(P[:, 0]) if P[i, 1] < 1e-9][2:-2]
    radii = []

    def fake(mesh, material, muscles, a, **kw):  # records the fixtures each frame is solved with
        radii.append(kw.get("anchor_radius"))
        return SimpleNamespace(x=mesh.points.copy(), success=True)

    monkeypatch.setattr(eq, "solve_internal", fake)
    up, down = [Muscle(top, name="M1")], [Muscle(bottom, name="M2")]
    res = animate(scene, "one", {"up": (up, [0.2], 0.123)})
    assert res.success and radii and set(radii) == {0.123} and res.message == ""
    radii.clear()
    res = animate(scene, "both", {"up": (up, [0.2], 0.123), "down": (down, [0.2], 0.123)})
    assert set(radii) == {0.123}
    radii.clear()
    res = animate(scene, "both", {"up": (up, [0.2], 0.123), "down": (down, [0.2], 0.2)})
    assert len(set(radii)) == 1 and radii[0] not in (0.123, 0.2)
    assert res.success and "the cases' designs: up 0.123, down 0.2" in res.message


def test_figure6_drawings_carry_a_scale_bar_and_legends_and_6c_plain_ticks(strip):
    """Figure 6's drawings have no coordinate ticks: a scale bar in the scene's unit gives their size; row A
    says what its marks are; 6b names its muscles as 6a does; 6c's log axis reads 0.06, not 6 x 10^-2."""
    from matplotlib.offsetbox import AnchoredOffsetbox, TextArea

    from mdsr_opt.plot.routing import plot_convergence, plot_design_grid, plot_layout_grid
    from mdsr_opt.plot.style import name_color

    mesh, muscles, target = strip

    def bars(ax):
        out = []
        for a in ax.artists:
            if isinstance(a, AnchoredOffsetbox):
                stack = [a.get_child()]
                while stack:
                    c = stack.pop()
                    if isinstance(c, TextArea):
                        out.append(c.get_text())
                    stack += list(c.get_children()) if hasattr(c, "get_children") else []
        return out

    late = [Muscle(m.nodes, name=n) for m, n in zip(muscles, ("M2", "M5"))]
    cols = [{"title": "a", "mesh": mesh, "target": target, "layouts": [late], "row_labels": ["C"], "anchors": [0],
             "drag_nodes": [16], "units": "cm"}]
    fig = plot_layout_grid(cols)
    axes = np.array(fig.axes[:3]).reshape(3, 1)
    assert bars(axes[0, 0]) == ["0.5 cm"]
    leg = axes[0, 0].get_legend()
    assert [t.get_text() for t in leg.get_texts()] == ["anchors", "drag points"]
    assert _legend(axes[2, 0]) == {"M2": name_color("M2", 0), "M5": name_color("M5", 1)}
    plt.close(fig)
    d = {"x": target, "muscles": late, "difference": 0.01, "success": True}
    fig = plot_design_grid([{"title": "a", "mesh": mesh, "target": target, "designs": [d], "row_labels": ["C"]}])
    assert bars(fig.axes[0]) == ["0.5 body units"]
    assert _legend(fig.axes[1]) == {"M2": name_color("M2", 0), "M5": name_color("M5", 1)}
    plt.close(fig)
    fig = plot_convergence([{"title": "a", "traces": [("C", [0, 1, 2], [0.12, 0.025, 0.022])]}])
    fig.canvas.draw()
    ax = fig.axes[0]
    labels = [t.get_text() for t in ax.yaxis.get_majorticklabels() + ax.yaxis.get_minorticklabels() if t.get_text()]
    assert "0.1" in labels and all(re.fullmatch(r"[0-9.]+", t) for t in labels), labels
    assert len(labels) == len(set(labels))
    plt.close(fig)


def test_demo_figures_label_axes_and_marks_and_share_one_scale(tmp_path, monkeypatch):
    """mdsr demo: every panel's axes and colour bar carry a quantity and unit, the external figure says what
    its marks are, and the springs and cable panels share one colour scale and quote commanded -> achieved."""
    import mdsr_opt.plot.common as common
    from mdsr_opt.cli.main import main

    seen, save = {}, common.save_figure

    def recording(fig, path, **kw):
        ax = fig.axes[0]
        bar = ax.child_axes[0]
        leg = ax.get_legend()
        seen[Path(path).name] = (ax.get_xlabel(), ax.get_ylabel(), bar.get_ylabel(), ax.collections[0].get_clim(),
                                 ax.get_title(), [t.get_text() for t in leg.get_texts()] if leg else [])
        return save(fig, path, **kw)

    monkeypatch.setattr(common, "save_figure", recording)
    assert main(["demo", "--out", str(tmp_path / "d"), "--max-area", "0.05"]) == 0
    assert set(seen) == {"external.png", "internal_springs.png", "internal_cable.png"}
    for name, (xl, yl, bl, _, _, _) in seen.items():
        assert (xl, yl) == ("x (body units)", "y (body units)") and _has_unit(bl), name
    assert seen["external.png"][5] == ["anchored nodes", "dragged tip", "rest shape"]
    assert seen["internal_springs.png"][3] == seen["internal_cable.png"][3]  # one scale: the panels compare
    for name in ("internal_springs.png", "internal_cable.png"):
        assert "commanded \u2192 achieved M1 0.300 \u2192 " in seen[name][4] and seen[name][5] == ["M1"]


def test_study_charts_label_their_axes_with_units_and_keep_legends_off_the_data():
    from mdsr_opt.plot.studies import plot_fidelity, plot_recommendation, plot_study_pareto, plot_study_scaling

    rows = [{"kind": "equilibrium", "method": m, "nodes": n, "error": e, "success": True, "build_time": 0.01,
             "solve_time": 0.001 * n, "problem": "strip", "load": 1.0, "material": mat, "resolution": str(n),
             "failure": ""}
            for m, mat in (("newton", "neo"), ("ipopt", "svk")) for n, e in ((100, 1e-2), (400, 3e-3), (1600, 1e-3))]
    figs = [plot_study_pareto(rows), plot_study_scaling(rows),
            plot_fidelity(rows, [{"problem": "strip", "load": 1.0, "tol": 5e-3, "nodes": 400, "material": "neo",
                                  "error": 3e-3, "met": True}]),
            plot_recommendation(rows, {"scene": "strip", "tol": 5e-3, "met": True, "method": "newton",
                                       "resolution": "400"})]
    for fig in figs:
        fig.canvas.draw()
        for ax in fig.axes:
            if not ax.axison:
                continue
            assert _has_unit(ax.get_xlabel()) and _has_unit(ax.get_ylabel()), (ax.get_xlabel(), ax.get_ylabel())
            leg = ax.get_legend()
            if leg is not None:  # a legend of one panel lies beside it, not over it
                a, b = ax.get_window_extent(), leg.get_window_extent()
                assert b.x0 >= a.x1 - 1 or b.y1 <= a.y0 + 1, fig
        plt.close(fig)
    assert figs[2].legends and [t.get_text() for t in figs[2].legends[0].get_texts()] == ["neo", "svk"]
    for fig in figs[:2]:  # log axes read 0.001 and 300, not 10^-3 and 3 x 10^2
        for ax in fig.axes:
            ticks = [t.get_text() for t in ax.get_xticklabels() + ax.get_yticklabels() if t.get_text()]
            assert ticks and not any("times" in t or "^" in t for t in ticks), ticks


def test_muscles_drawn_together_never_share_a_colour():
    """A numbered name keeps its number's colour; any other name takes the first colour no muscle of the
    figure takes, so a scene's own 'flexor' beside a routed M1 is not drawn red as well."""
    from mdsr_opt.plot.style import label_colors, muscle_color

    assert label_colors(["flexor", "M1"]) == [muscle_color(1), muscle_color(0)]
    assert label_colors(["M3", "a", "b"]) == [muscle_color(2), muscle_color(0), muscle_color(1)]
    assert label_colors(["a", "b"]) == [muscle_color(0), muscle_color(1)]
    assert len(set(label_colors(["M2", "x", "M1", "y"]))) == 4


def test_a_row_of_panels_pulling_subsets_of_one_layout_names_every_muscle_once():
    """The face's expressions each pull another subset of one 13-muscle layout: each panel draws a muscle of
    a name in one colour, the row's legend lists every name drawn (not the places M1..M8 of the longest
    panel), no two of the 13 share a colour, and a long panel title breaks before its difference."""
    from mdsr_opt.plot.routing import plot_design_grid
    from mdsr_opt.plot.style import muscle_color

    mesh = Mesh.rectangle(4.0, 1.0, 16, 4)
    layout = [Muscle([k, k + 1], name=f"M{k + 1}") for k in range(13)]
    picks = ([0, 4, 8, 9, 11, 12], [1, 2, 5, 6, 7, 9, 10, 12], [2, 3, 7, 10])
    cols = [{"title": f"e{j}", "mesh": mesh, "target": mesh.points, "row_labels": ["pulls " + ", ".join(
                 layout[k].name for k in p)],
             "designs": [{"x": mesh.points, "muscles": [layout[k] for k in p], "difference": 0.04, "success": True}]}
            for j, p in enumerate(picks)]
    fig = plot_design_grid(cols)
    axes = np.array(fig.axes).reshape(2, 3)
    drawn = sorted({k for p in picks for k in p})
    assert _legend(axes[1, -1]) == {f"M{k + 1}": muscle_color(k) for k in drawn}
    assert len({muscle_color(k) for k in range(13)}) == 13
    for ax, p in zip(axes[1], picks):  # each muscle in its name's colour in every panel
        got = sorted(to_hex(ln.get_color()) for ln in ax.get_lines() if ln.get_linestyle() == "-")
        assert got == sorted(muscle_color(k) for k in p)
    assert axes[1, 1].get_title().endswith(":\nD = 0.04 body units")
    plt.close(fig)


def test_commanded_achieved_never_reads_minus_zero():
    from mdsr_opt.plot.style import commanded_achieved

    assert commanded_achieved([0.0, 0.26], [-0.001, -0.02], fmt=".2f") == "M1 0.00 \u2192 0.00, M2 0.26 \u2192 -0.02"


def test_energy_maps_say_their_unit_and_the_overlay_title_says_it_measures_the_outline():
    """Trial 3: a silicone target's energy bar read 'units of E' at values near 1.6e5 Pa·mm; the overlay's d
    was the outline's while the table's is every loop's."""
    import matplotlib.pyplot as plt

    from mdsr_opt.plot.scenes import plot_target
    from mdsr_opt.plot.style import energy_label

    assert energy_label("Pa", "mm") == "strain energy per area (Pa·mm)"
    assert energy_label(None, "mm") == "strain energy per area (units of E*t)"
    mesh = Mesh.rectangle(2.0, 1.0, 4, 2)
    fig = plot_target(mesh, mesh.points * 1.1, values=np.ones(len(mesh.triangles)), units="mm",
                      colorbar_label=energy_label("Pa", "mm"))
    labels = [a.get_ylabel() for ax in fig.axes for a in [ax, *ax.child_axes]]  # the bar is an inset axes
    assert "strain energy per area (Pa·mm)" in labels
    plt.close(fig)
    import inspect

    from mdsr_opt.plot import photos
    assert "outline d = " in inspect.getsource(photos.plot_overlay)
