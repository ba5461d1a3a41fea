"""Routed ropes stay a channel and a wall apart unless they share a fixture plate the routing reports (the
fourth new-user trial: two ropes of a T with a window ended on one node, unreported), and the routing's notes
say every resolution once, in design_pipeline's result as in route_muscles'."""

from __future__ import annotations

import re
import warnings

import numpy as np
import pytest
import shapely

from mdsr_opt import NeoHookean, mesh_polygon, nodes_in_box
from mdsr_opt.mechanics.equilibrium import solve_external
from mdsr_opt.synthesis.fabrication import Fabrication, rope_conflicts
from mdsr_opt.synthesis.routing import route_for_design, route_muscles
from conftest import load_script

BENCH = load_script("tests/benchmarks/bench_buildable.py")


def _tee():
    """The trial's T with a window (tee_routed.toml, case droop): foot clamped, right arm turned down."""
    outline = [[1.5, 0], [2.5, 0], [2.5, 3], [4, 3], [4, 4], [0, 4], [0, 3], [1.5, 3]]
    window = [[1.8, 3.3], [2.2, 3.3], [2.2, 3.7], [1.8, 3.7]]
    mesh = mesh_polygon(outline, holes=[window], resolution=700)
    P = mesh.points
    foot, tip = nodes_in_box(mesh, ymax=0.0), nodes_in_box(mesh, xmin=4.0)
    drags = {int(i): q for i, q in zip(tip, _rotate(P[tip], -45, np.array([2.5, 3.5])))}
    return mesh, foot, drags


def _rotate(Q, deg, o):
    c, s = np.cos(np.radians(deg)), np.sin(np.radians(deg))
    return o + (np.asarray(Q) - o) @ np.array([[c, s], [-s, c]])


def _c_shape():
    """The trial's body C: an annular sector open on the right, the top tip turned 25 degrees down."""
    t = np.radians(np.linspace(40, 320, 29))
    outline = np.vstack([np.column_stack([3 * np.cos(t), 3 * np.sin(t)]),
                         np.column_stack([2 * np.cos(t[::-1]), 2 * np.sin(t[::-1])])])
    mesh = mesh_polygon(outline, resolution=700)
    P = mesh.points
    near = [np.flatnonzero(np.linalg.norm(P - 2.5 * np.array([np.cos(np.radians(a)), np.sin(np.radians(a))]),
                                          axis=1) < d) for a, d in ((320, 0.6), (40, 0.5))]
    return mesh, near[0], {int(i): q for i, q in zip(near[1], _rotate(P[near[1]], -25, np.zeros(2)))}


def _body(name):
    if name in ("tee", "trial C"):
        mesh, anchors, drags = _tee() if name == "tee" else _c_shape()
    else:
        mesh, anchors, drags, _, _ = BENCH.make_body(name, 700)
    ext = solve_external(mesh, NeoHookean(1.0, 0.3), anchors, drags)
    assert ext.success
    return mesh, ext.x


def _plates(P, paths, r):
    """Independent: pairs of ends (rope, node) of different ropes closer than r."""
    ends = [(i, e) for i, p in enumerate(paths) for e in (p[0], p[-1])]
    return [(a, b) for k, a in enumerate(ends) for b in ends[k + 1:]
            if a[0] != b[0] and np.linalg.norm(P[a[1]] - P[b[1]]) < r]


def _check_apart(mesh, rr):
    """No two ropes' centre lines closer than channel + wall but inside a reported shared plate (and its wall);
    every shared plate named in the notes at its place."""
    P, f, r = mesh.points, rr.fabrication, rr.fixture_radius
    paths = [list(m.nodes) for m in rr.muscles]
    need = f.channel_diameter + f.wall
    plates = _plates(P, paths, r)
    said = [n for n in rr.notes if "share one end fixture" in n]
    for (i, e), (j, g) in plates:
        q = 0.5 * (P[e] + P[g])
        assert any(f"({q[0]:.4g}, {q[1]:.4g})" in n or f"({P[e][0]:.4g}, {P[e][1]:.4g})" in n for n in said), \
            (q, said)
    assert len(said) <= len(plates)
    for i in range(len(paths)):
        for j in range(i + 1, len(paths)):
            a, b = shapely.LineString(P[paths[i]]), shapely.LineString(P[paths[j]])
            zone = [shapely.Point(P[n]).buffer(r + f.wall, 64) for (k, e), (m, g) in plates
                    if {k, m} == {i, j} for n in (e, g)]
            if zone:
                z = shapely.union_all(zone)
                a, b = a.difference(z), b.difference(z)
                if a.is_empty or b.is_empty:
                    continue
            assert a.distance(b) >= need * (1 - 1e-6), (rr.muscles[i].name, rr.muscles[j].name, a.distance(b), need)
    assert rope_conflicts(mesh, rr.muscles, f, fixture_radius=r) == []


@pytest.mark.parametrize("name", ["tee", "T_hole", "tentacle", "C", "L_window"])
def test_routed_ropes_are_apart_or_share_a_reported_plate(name):
    mesh, x = _body(name)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        rr = route_for_design(mesh, x)
        offset = route_muscles(mesh, x, band="offset")
    for r in (rr, offset):
        assert len(r) >= 1
        _check_apart(mesh, r)
        assert len(set(r.notes)) == len(r.notes)                         # each resolution said once
        assert len({tuple(m.nodes) for m in r.muscles}) == len(r.muscles)


def test_the_tee_ropes_ending_on_one_node_share_a_reported_plate():
    mesh, x = _body("tee")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        rr = route_for_design(mesh, x)
    P = mesh.points
    same = [(a, b) for a, b in _plates(P, [list(m.nodes) for m in rr.muscles], rr.fixture_radius)
            if a[1] == b[1]]
    assert same, "the trial's case no longer routes two ropes to one node: pick another witness"
    (_, node), _ = same[0]
    note = next(n for n in rr.notes if "share one end fixture" in n and f"({P[node][0]:.4g}, {P[node][1]:.4g})" in n)
    assert "their ends lie 0 apart" in note and f"fixture radius {rr.fixture_radius:.4g}" in note
    # a shared plate loses nothing: route_for_design's re-routings start on the other notes alone
    from mdsr_opt.synthesis.routing_fixtures import fitting_notes

    fitting = fitting_notes(P, rr)
    assert note not in fitting and all("share one end fixture" not in n for n in fitting)
    assert len(fitting) + sum("share one end fixture" in n for n in rr.notes) == len(rr.notes)


def test_shrunk_fixtures_are_said_in_the_notes():
    """Whenever the routing designs with fixtures smaller than the fabrication's, a note says so with both
    radii (route_for_design's band routing with the smallest fixtures said nothing)."""
    shrunk = []
    for name in ("tee", "trial C", "T_hole"):
        mesh, x = _body(name)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            rr = route_for_design(mesh, x)
        r0 = Fabrication().for_body(mesh).fixture_radius   # the default the routing started from
        if rr.fixture_radius < r0 * (1 - 1e-9):
            said = [n for n in rr.notes if re.search(rf"fixtures shrunk from radius {r0:.4g} to (the smallest, )?"
                                                     rf"{rr.fixture_radius:.4g}", n)]
            assert len(said) == 1, (name, rr.notes[:3])
            shrunk.append(name)
    assert "trial C" in shrunk  # the trial's witness: routed in the band with the smallest fixtures


@pytest.mark.parametrize("max_muscles", [1, 2, 3])
def test_shared_plates_are_said_only_among_the_ropes_kept(max_muscles):
    """A rope cut by max_muscles shares no plate in the notes (the gecko's notes named cut ropes)."""
    mesh, x = _body("tee")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        rr = route_for_design(mesh, x, max_muscles=max_muscles)
    P = mesh.points
    ends = {f"({P[e][0]:.4g}, {P[e][1]:.4g})" for m in rr.muscles for e in (m.nodes[0], m.nodes[-1])}
    for n in (n for n in rr.notes if "share one end fixture" in n):
        named = re.findall(r"\(-?[\d.e+-]+, -?[\d.e+-]+\)", n.split(" share one end fixture")[0])
        assert named and set(named) <= ends, (n, ends)
    _check_apart(mesh, rr)
