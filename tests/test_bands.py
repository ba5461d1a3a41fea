"""Strokes with their uncertainty (issue 32, item 5): every designed stroke's band from the fixture size, nu
and one mesh refinement, shown by the stroke table, the fabrication CSV and the design figure."""

from __future__ import annotations

import csv
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import numpy as np  # noqa: E402
import pytest  # noqa: E402

from mdsr_opt import Mesh, Muscle, NeoHookean, solve_external  # noqa: E402
from mdsr_opt.synthesis.bands import refine_mesh, stroke_bands  # noqa: E402
from mdsr_opt.synthesis.contractions import design_contractions  # noqa: E402
from mdsr_opt.synthesis.pipeline import design_pipeline  # noqa: E402
from mdsr_opt.synthesis.results import DesignResult  # noqa: E402

MAT = NeoHookean(1.0, 0.3)


@pytest.fixture(scope="module")
def bent():
    """A strip bent up by dragging its right end, one muscle along its bottom: a target no layout reaches
    exactly (an exactly reached target fixes the stroke by its geometry, whatever nu)."""
    mesh = Mesh.rectangle(4.0, 1.0, 32, 8)
    mus = [Muscle(range(1, 32), name="lower")]
    left = [i for i, (x, y) in enumerate(mesh.points) if x == 0.0]
    right = {i: (x - 0.3, y + 0.8) for i, (x, y) in enumerate(mesh.points) if x == 4.0}
    target = solve_external(mesh, MAT, left, right).x
    return mesh, mus, target, design_contractions(mesh, MAT, mus, target)


def test_refine_mesh_splits_every_triangle_at_its_edges_midpoints():
    mesh = Mesh.from_polygon([[0, 0], [3, 0], [3, 1], [1, 2], [0, 1]], max_area=0.2)
    fine, edges = refine_mesh(mesh)
    assert fine.n_nodes == mesh.n_nodes + len(mesh.edges) and fine.n_triangles == 4 * mesh.n_triangles
    assert fine.area == pytest.approx(mesh.area, rel=1e-12)
    np.testing.assert_array_equal(fine.points[:mesh.n_nodes], mesh.points)
    np.testing.assert_allclose(fine.points[mesh.n_nodes:], mesh.points[edges].mean(axis=1))
    assert fine.jacobians(fine.points).min() > 0  # every triangle keeps its orientation
    assert fine.quality()["min_angle_deg"] == pytest.approx(mesh.quality()["min_angle_deg"], rel=1e-9)


def test_the_band_holds_the_nominal_stroke_and_names_its_sources(bent):
    mesh, mus, target, d = bent
    b = stroke_bands(mesh, MAT, mus, target, d)
    assert b.low[0] <= b.nominal[0] <= b.high[0] and b.high[0] - b.low[0] > 1e-3 * b.nominal[0]
    assert b.nominal[0] == pytest.approx(d.stroke[0])
    assert sorted(b.contributions) == ["anchor_radius", "mesh", "nu"] and b.notes == ()
    for c in b.contributions.values():
        assert c[0, 0] <= 0.0 <= c[0, 1]
    total = sum(c[0] for c in b.contributions.values())
    assert b.band[0] == pytest.approx(b.nominal[0] + total)
    assert b.values["anchor_radius"] == pytest.approx([0.75 * d.anchor_radius, 1.25 * d.anchor_radius])
    assert b.values["nu"] == pytest.approx([0.25, 0.35]) and b.values["mesh"] == [mesh.n_nodes + len(mesh.edges)]
    assert "lower" in b.table() and "anchor_radius" in b.table()
    assert "in the mesh's length units" in b.table()  # the unit is said


def test_the_band_widens_with_the_tolerances(bent):
    mesh, mus, target, d = bent
    narrow = stroke_bands(mesh, MAT, mus, target, d, radius_tol=0.1 * d.anchor_radius, nu_tol=0.02, refine=False)
    wide = stroke_bands(mesh, MAT, mus, target, d, radius_tol=0.4 * d.anchor_radius, nu_tol=0.1, refine=False)
    assert wide.low[0] < narrow.low[0] <= narrow.nominal[0] <= narrow.high[0] < wide.high[0]
    for src in ("anchor_radius", "nu"):
        assert (wide.contributions[src][0, 1] - wide.contributions[src][0, 0]
                > narrow.contributions[src][0, 1] - narrow.contributions[src][0, 0])
    assert narrow.notes == ("mesh: refinement left out (refine=False)",)


def test_what_the_band_leaves_out_is_said(bent):
    mesh, mus, target, d = bent
    b = stroke_bands(mesh, MAT, mus, target, d, radius_tol=5.0, max_refined_nodes=100)
    text = " | ".join(b.notes)
    assert "is at least half the body's size" in text and "; left out" in text  # the radius plus its tolerance
    assert "refined mesh would have 1105 nodes" in text and "max_refined_nodes 100" in text
    assert "mesh" not in b.contributions and b.low[0] <= b.nominal[0] <= b.high[0]
    soft = NeoHookean(1.0, 0.47)
    ds = design_contractions(mesh, soft, mus, target)
    bs = stroke_bands(mesh, soft, mus, target, ds, refine=False)
    assert any("nu 0.52 is outside" in n and "0.49 used" in n for n in bs.notes)
    assert bs.values["nu"] == pytest.approx([0.42, 0.49])
    with pytest.raises(ValueError, match="1 contraction"):
        stroke_bands(mesh, MAT, mus * 2, target, d)


def test_pipeline_band_in_the_table_the_csv_and_the_figure(tmp_path):
    from mdsr_opt.plot.design import plot_design
    from mdsr_opt.synthesis.export import export_fabrication

    mesh = Mesh.rectangle(4.0, 1.0, 16, 4)
    left = [i for i, (x, y) in enumerate(mesh.points) if x == 0.0]
    right = {i: (x - 0.3, y - 0.4) for i, (x, y) in enumerate(mesh.points) if x == 4.0}
    out = design_pipeline(mesh, MAT, left, right, bands=True)
    assert out.success and out.bands is not None and "bands" in out.times
    band = out.design.stroke_band
    assert band.shape == (len(out.muscles), 2)
    assert np.all(band[:, 0] <= out.design.stroke) and np.all(out.design.stroke <= band[:, 1])
    assert "stroke band" in out.table() and f"{band[0, 0]:.4g} .. {band[0, 1]:.4g}" in out.table()
    files = export_fabrication(mesh, out, tmp_path, name="plate", units="mm")
    rows = list(csv.reader(Path(files["csv"]).read_text().splitlines()))
    assert rows[0][-2:] == ["stroke design low [mm]", "stroke design high [mm]"]
    assert [float(v) for v in rows[1][-2:]] == pytest.approx(band[0], rel=1e-8)
    title = plot_design(mesh, out.design, out.target, out.muscles).axes[0].get_title()
    assert f"[{band[0, 0]:.3g}, {band[0, 1]:.3g}]" in title
    # the band is saved with the design
    back = DesignResult.from_dict(out.design.to_dict())
    np.testing.assert_allclose(back.stroke_band, band)
    back = DesignResult.load(out.design.save(tmp_path / "d.npz"))
    np.testing.assert_allclose(back.stroke_band, band)
    with pytest.raises(ValueError, match="band_options: unknown key 'nu_tolerance'"):
        design_pipeline(mesh, MAT, left, right, bands=True, band_options={"nu_tolerance": 0.1})
    plain = design_pipeline(mesh, MAT, left, right)
    assert plain.bands is None and plain.design.stroke_band.shape == (0, 2)
    plain_csv = Path(export_fabrication(mesh, plain, tmp_path / "p", name="plate")["csv"])
    rows = list(csv.reader(plain_csv.read_text().splitlines()))
    assert not any("low" in h for h in rows[0])


def test_a_saturated_stroke_has_a_point_band_said_to_be_its_bound(bent):
    """At a_max in every design of the band, the stroke is the bound's: the band is a point, which the notes
    and the stroke table call the bound rather than showing "s .. s" (trial10)."""
    import warnings

    mesh, mus, target, d = bent
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        sat = design_contractions(mesh, MAT, mus, target, a_max=0.5 * float(d.contractions[0]))
    assert sat.saturated.tolist() == [True]
    b = stroke_bands(mesh, MAT, mus, target, sat)
    assert b.high[0] - b.low[0] <= 1e-6 * b.nominal[0]  # the bound to IPOPT's bound relaxation
    assert any(n.startswith("lower: saturated (at its bound)") for n in b.notes)
    sat.stroke_band = b.band.copy()
    row = sat.muscle_table().splitlines()[1]
    assert f"{b.nominal[0]:.4g} (its bound)" in row and ".." not in row
    d.stroke_band = stroke_bands(mesh, MAT, mus, target, d).band.copy()  # not saturated: a real band
    assert ".." in d.muscle_table().splitlines()[1]
    d.stroke_band = np.zeros((0, 2))


def test_mdsr_run_bands_call_a_saturated_point_band_its_bound(tmp_path, capsys):
    """recheck10: summary.md and the log of ``mdsr run --bands`` printed "3.093 [3.093, 3.093]"."""
    from mdsr_opt.cli.main import main

    scene = tmp_path / "sat.toml"
    scene.write_text('name = "sat"\n[body]\noutline = [[0, 0], [60, 0], [60, 12], [0, 12]]\nresolution = 300\n'
                     '[regions]\nbase = { box = [-1, -1, 0.5, 13] }\ntip = { box = [59.5, -1, 61, 13] }\n'
                     '[[muscles]]\nname = "top"\npath = [[5, 8], [55, 8]]\n[design]\na_max = 0.05\n'
                     '[[cases]]\nname = "bend"\nanchors = "base"\n'
                     'drags = [{ nodes = "tip", rotate = 57, about = [60, 6], by = [-12, 30] }]\n')
    out = tmp_path / "o"
    assert main(["run", str(scene), "--out", str(out), "--bands", "--serial", "--no-photos", "--no-animations",
                 "--no-prototype"]) == 0
    log = capsys.readouterr().out
    row = next(line for line in (out / "summary.md").read_text().splitlines() if line.startswith("| sat | bend"))
    assert "(its bound)" in row and "saturated top" in row and "[" not in row.split("|")[7]
    assert "stroke bands: " in log and "(its bound); top: saturated (at its bound)" in log
