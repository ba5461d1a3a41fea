"""A rope on a hole's edge is said to run on that hole, not on the outline, and a layout that cannot be
moulded is marked in its muscle CSV as in its SVG and DXF (new-user trial 11, defect 8)."""

from __future__ import annotations

import re
import warnings

import numpy as np
import pytest

from mdsr_opt import Mesh, Muscle
from mdsr_opt.synthesis.export import export_fabrication
from mdsr_opt.synthesis.fabrication import Fabrication, FabricationWarning, rope_conflicts

FAB = Fabrication(channel_diameter=1.0, wall=1.0, fixture_radius=0.5)


@pytest.fixture(scope="module")
def ring():
    """A disk of radius 50 (mm) with an off-centre hole of radius 20 around (12, 5): 181 nodes."""
    t = np.linspace(0, 2 * np.pi, 32, endpoint=False)
    return Mesh.from_polygon(np.c_[50 * np.cos(t), 50 * np.sin(t)], max_area=40,
                             holes=[np.c_[12 + 20 * np.cos(t), 5 + 20 * np.sin(t)]])


def test_a_rope_on_a_holes_edge_is_said_to_run_on_that_hole(ring):
    hole, outline = ring.boundary_loops[1], ring.boundary_loops[0]
    on_hole = rope_conflicts(ring, [Muscle(hole[3:7], name="rope")], FAB)[0]
    assert on_hole.kind == "inset"
    assert ("muscle rope: its channel is not mouldable: its smallest inset from the outline or a hole is 0 (it runs "
            "on the edge of the hole around (12, 5)), a channel 1 wide with a wall 1 needs 2") == on_hole.message
    on_outline = rope_conflicts(ring, [Muscle(outline[3:7], name="rope")], FAB)[0]
    assert "is 0 (it runs on the outline), a channel 1" in on_outline.message


def deep_edge(mesh, near):
    """Two nodes of one triangle near ``near``: a one-edge rope deep inside the body."""
    k = int(np.argmin(np.linalg.norm(mesh.points - near, axis=1)))
    tri = mesh.triangles[np.flatnonzero((mesh.triangles == k).any(axis=1))[0]]
    return [k, int(next(n for n in tri if n != k))]


def test_a_layout_that_cannot_be_moulded_says_so_in_its_csv_as_in_its_svg(ring, tmp_path):
    rope = Muscle(ring.boundary_loops[1][3:7], name="rope")
    with pytest.warns(FabricationWarning):
        files = export_fabrication(ring, None, tmp_path / "bad", muscles=[rope], units="mm", name="ring",
                                   fabrication=FAB)
    lines = open(files["csv"]).read().splitlines()
    said = ("NOT MOULDABLE as laid out (2 place(s)): muscle rope: its channel is not mouldable: its smallest inset "
            "from the outline or a hole is 0 (it runs on the edge of the hole around (12, 5))")
    assert lines[0].startswith(f"# {said}") and lines[1].startswith("muscle,edges,rest length [mm]")
    assert lines[2].startswith("rope,3,")
    svg = " ".join(re.sub(r"<[^>]+>", " ", open(files["svg"]).read()).split())  # the caption's lines joined
    assert "NOT MOULDABLE as laid out (2 place(s), red rings): muscle rope" in svg and "the hole around (12, 5)" in svg
    # a layout that can be moulded: no comment line, the header first
    with warnings.catch_warnings():
        warnings.simplefilter("error", FabricationWarning)
        files = export_fabrication(ring, None, tmp_path / "good", muscles=[Muscle(deep_edge(ring, [-35, 0]), "deep")],
                                   units="mm", name="ring", fabrication=FAB)
    lines = open(files["csv"]).read().splitlines()
    assert lines[0].startswith("muscle,edges,") and len(lines) == 2 and not any("MOULDABLE" in s for s in lines)
