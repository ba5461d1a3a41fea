import os
import re
from pathlib import Path

import numpy as np
import pytest

from mdsr_opt import Mesh
from mdsr_opt.body.polygons import polygon_area


def test_rectangle_counts_and_area():
    m = Mesh.rectangle(4.0, 1.0, nx=8, ny=2)
    assert (m.n_nodes, m.n_triangles) == (27, 32)
    assert m.area == pytest.approx(4.0, rel=1e-12)
    assert np.all(m.areas > 0)  # counter-clockwise
    # Euler: V - E + F = 1 for a disc
    assert m.n_nodes - len(m.edges) + m.n_triangles == 1


def test_from_polygon_quality_and_boundary(strip):
    q = strip.quality()
    assert q["min_angle_deg"] >= 30.0 - 1e-6
    assert q["max_area"] <= 0.02 + 1e-12
    assert strip.area == pytest.approx(4.0, rel=1e-12)
    (loop,) = strip.boundary_loops
    assert polygon_area(strip.points[loop]) == pytest.approx(4.0, rel=1e-12)  # outer loop CCW
    assert set(loop.tolist()) == set(strip.boundary_nodes.tolist())


def test_holes_give_clockwise_inner_loops():
    hole = [[1.0, 0.4], [1.5, 0.4], [1.5, 0.8], [1.0, 0.8]]
    m = Mesh.from_polygon([[0, 0], [3, 0], [3, 1.2], [0, 1.2]], max_area=0.02, holes=[hole])
    outer, inner = m.boundary_loops
    assert polygon_area(m.points[outer]) == pytest.approx(3.6, rel=1e-9)
    assert polygon_area(m.points[inner]) == pytest.approx(-0.2, rel=1e-9)
    assert m.area == pytest.approx(3.4, rel=1e-9)


def test_clockwise_outline_is_accepted_and_reoriented():
    m = Mesh.from_polygon([[0, 0], [0, 1], [2, 1], [2, 0]], max_area=0.1)
    assert np.all(m.areas > 0)


def test_relabel_keeps_geometry():
    m = Mesh.rectangle(2.0, 1.0, 4, 2)
    perm = np.random.default_rng(1).permutation(m.n_nodes)
    r = m.relabel(perm)
    assert np.allclose(r.points[perm], m.points)
    assert np.allclose(np.sort(r.areas), np.sort(m.areas))
    assert len(r.edges) == len(m.edges)


def test_deformation_gradient_of_affine_map():
    m = Mesh.rectangle(2.0, 1.0, 3, 2)
    A = np.array([[1.2, 0.3], [-0.1, 0.9]])
    F = m.deformation_gradients(m.points @ A.T + [3.0, -1.0])
    assert np.allclose(F, A, atol=1e-12)
    assert np.allclose(m.jacobians(m.points @ A.T), np.linalg.det(A))


SQUARE = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]])


@pytest.mark.parametrize("points, triangles, match", [
    (SQUARE, [[0, 2, 1], [0, 3, 2]], "clockwise"),
    (SQUARE, [[0, 1, 2], [0, 3, 2]], "mixed orientation"),
    (SQUARE, [[0, 1, 1], [0, 2, 3]], "repeats a node"),
    (np.array([[0.0, 0], [1, 0], [2, 0], [0, 1]]), [[0, 1, 2], [0, 1, 3]], "degenerate"),
    (SQUARE, [[0, 1, 2], [0, 2, 4]], "out of range"),
    (SQUARE, [[0, 1, 2]], "belong to no triangle"),
    (np.array([[0.0, 0], [1, 0], [np.nan, 1], [0, 1]]), [[0, 1, 2], [0, 2, 3]], "NaN"),
    (SQUARE, [[0, 1, 2], [0, 2, 3], [1, 2, 0]], "duplicate"),
])
def test_bad_meshes_are_refused(points, triangles, match):
    with pytest.raises(ValueError, match=match):
        Mesh(points, np.array(triangles))


def test_non_manifold_edge_and_bow_tie():
    pts = np.array([[0.0, 0], [1, 0], [0.5, 1], [0.5, -1], [2, 0.2]])
    # edge (0, 1) shared by three triangles
    with pytest.raises(ValueError, match="non-manifold|overlap"):
        Mesh(pts, np.array([[0, 1, 2], [1, 0, 3], [0, 1, 4]]))
    bow = np.array([[0.0, 0], [1, 0], [1, 1], [-1, 0], [-1, -1]])
    with pytest.raises(ValueError, match="bow-tie"):
        Mesh(bow, np.array([[0, 1, 2], [0, 3, 4]]))


def test_type_errors():
    with pytest.raises(TypeError, match="integer"):
        Mesh(SQUARE, np.array([[0.0, 1, 2], [0, 2, 3]]))
    with pytest.raises(TypeError, match="numbers"):
        Mesh(np.array([["a", "b"]] * 4), np.array([[0, 1, 2], [0, 2, 3]]))
    with pytest.raises(ValueError, match=r"shape \(k, 2\)"):
        Mesh(np.zeros((4, 3)), np.array([[0, 1, 2], [0, 2, 3]]))


@pytest.mark.parametrize("outline, match", [
    ([[0, 0], [1, 1], [1, 0], [0, 1]], "self-intersecting"),
    ([[0, 0], [1, 0], [2, 0]], "zero area"),
    ([[0, 0], [1, 0]], "at least 3"),
    ([[0, 0], [1, 0], [1, 0], [0, 1]], "coincide"),
    ([[0, 0], [1, 0], [np.inf, 1]], "NaN or inf"),
])
def test_bad_outlines(outline, match):
    with pytest.raises(ValueError, match=match):
        Mesh.from_polygon(outline, max_area=0.1)


def test_bad_holes_and_parameters():
    outline = [[0, 0], [2, 0], [2, 1], [0, 1]]
    with pytest.raises(ValueError, match="not inside"):
        Mesh.from_polygon(outline, holes=[[[1.5, 0.5], [3, 0.5], [3, 0.8]]])
    with pytest.raises(ValueError, match="max_area"):
        Mesh.from_polygon(outline, max_area=-1.0)
    with pytest.raises(ValueError, match="min_angle"):
        Mesh.from_polygon(outline, min_angle=40.0)


def test_mesh_is_immutable(strip):
    with pytest.raises(ValueError):
        strip.points[0, 0] = 5.0


def test_derived_arrays_are_read_only():
    """Callers get the mesh's cached arrays; writing into them must not corrupt the mesh."""
    m = Mesh.rectangle(2.0, 1.0, 2, 1)
    for arr in (m.edges, m.edge_lengths, m.areas, m.Dm_inv, m.boundary_nodes, m.boundary_loops[0],
                m.neighbors[0], m.angles):
        with pytest.raises(ValueError, match="read-only"):
            arr[...] = 0


def test_boundary_crossing_is_detected():
    from conftest import arc_map

    m = Mesh.rectangle(4.0, 0.2, 40, 1)  # thin, so a wrap of more than a full turn keeps J > 0
    assert not m.boundary_crosses(m.points)
    assert not m.boundary_crosses(arc_map(m.points, angle=np.pi))
    # wrapped past a full turn: elements stay upright but the body passes through itself
    wrapped = arc_map(m.points, angle=2 * np.pi * 1.1)
    assert m.jacobians(wrapped).min() > 0
    assert m.boundary_crosses(wrapped)


# ---------------------------------------------------------------------------------------- meshes as asked
@pytest.mark.parametrize("max_area", [1e-3, 1e-5, 1e-7])
def test_max_area_is_honoured_at_every_scale(max_area):
    """A square of area 1000 x max_area: about 1600 triangles, none larger than asked, at any scale
    (the area switch was once written with an exponent Triangle does not read: 2 triangles)."""
    side = np.sqrt(1000 * max_area)
    m = Mesh.from_polygon(SQUARE * side, max_area=max_area)
    assert m.areas.max() <= max_area * (1 + 1e-9)
    assert 1300 <= m.n_triangles <= 1900
    assert m.area == pytest.approx(side ** 2, rel=1e-12)
    assert m.quality()["min_angle_deg"] >= 30.0 - 1e-6


def test_max_area_without_exponent_on_a_unit_square():
    m = Mesh.from_polygon(SQUARE, max_area=9.9e-5)  # was 2 triangles
    assert m.areas.max() <= 9.9e-5
    assert 10_000 * 1.4 < m.n_triangles < 10_000 * 1.8


@pytest.mark.parametrize("offset", [1e6, 1e9])
def test_body_far_from_the_origin_meshes(offset):
    m = Mesh.from_polygon(SQUARE + offset, max_area=0.01)
    assert m.areas.max() <= 0.01
    assert m.area == pytest.approx(1.0, rel=1e-6)
    assert 130 <= m.n_triangles <= 190
    # the outline's vertices come back exactly as given
    for v in SQUARE + offset:
        assert np.any(np.all(m.points == v, axis=1))


def test_triangle_limit_is_refused_before_meshing(monkeypatch):
    import triangle

    mesher = triangle.triangulate

    def no_meshing(*a, **k):
        raise AssertionError("the mesher ran")

    monkeypatch.setattr(triangle, "triangulate", no_meshing)  # refused before the mesher runs
    with pytest.raises(ValueError, match=r"about 1\.6e\+08 triangles.*max_triangles=2000000.*max_triangles="):
        Mesh.from_polygon(SQUARE * 1000, max_area=0.01)
    monkeypatch.setattr(triangle, "triangulate", mesher)
    with pytest.raises(ValueError, match="max_triangles=100;"):
        Mesh.from_polygon(SQUARE, max_area=0.001, max_triangles=100)
    m = Mesh.from_polygon(SQUARE, max_area=0.001, max_triangles=2000)  # raised: allowed
    assert m.n_triangles <= 2000
    with pytest.raises(ValueError, match="max_triangles must be a positive integer, got 0"):
        Mesh.from_polygon(SQUARE, max_area=0.1, max_triangles=0)
    with pytest.raises(TypeError, match="max_triangles must be an integer, got float 10000000.0"):
        Mesh.from_polygon(SQUARE, max_area=0.1, max_triangles=1e7)


def test_problem_at_absurd_resolution_is_refused_by_the_limit():
    from mdsr_opt.scenes.library import get_problem

    with pytest.raises(ValueError, match=r"resolution must be at most 200000 nodes .*got 100000000"):
        get_problem("gecko", resolution=10 ** 8)


def test_mesh_polygon_accepts_a_clockwise_outline():
    from mdsr_opt.scenes.scene import mesh_polygon

    m = mesh_polygon([[0, 0], [0, 1], [4, 1], [4, 0]], resolution=200)  # clockwise
    assert m.area == pytest.approx(4.0, rel=1e-12)
    assert 160 < m.n_nodes < 240


def test_nested_holes_are_refused():
    outline = [[0, 0], [2, 0], [2, 1.5], [0, 1.5]]
    big = [[0.2, 0.2], [1.8, 0.2], [1.8, 1.3], [0.2, 1.3]]
    small = [[0.5, 0.5], [1.5, 0.5], [1.5, 1.0], [0.5, 1.0]]
    for holes, inner, outer in (([big, small], 1, 0), ([small, big], 0, 1)):
        with pytest.raises(ValueError, match=rf"holes\[{inner}\] lies inside holes\[{outer}\]: holes nested"):
            Mesh.from_polygon(outline, max_area=0.01, holes=holes)
    # side by side is fine, and the holes are really holes
    m = Mesh.from_polygon(outline, max_area=0.01, holes=[[[0.2, 0.2], [0.8, 0.2], [0.8, 1.0], [0.2, 1.0]],
                                                         [[1.0, 0.2], [1.8, 0.2], [1.8, 1.0], [1.0, 1.0]]])
    assert m.area == pytest.approx(3.0 - 0.48 - 0.64, rel=1e-12)


def test_holes_that_touch_are_refused():
    outline = [[0, 0], [2, 0], [2, 1], [0, 1]]
    a = [[0.2, 0.2], [1.0, 0.2], [1.0, 0.8], [0.2, 0.8]]
    b = [[1.0, 0.5], [1.5, 0.5], [1.5, 0.8]]  # a vertex on a's edge
    with pytest.raises(ValueError, match=r"holes\[0\] and holes\[1\] intersect or touch"):
        Mesh.from_polygon(outline, max_area=0.01, holes=[a, b])
    with pytest.raises(ValueError, match=r"holes\[0\] is not inside the outline: they intersect or touch"):
        Mesh.from_polygon(outline, max_area=0.01, holes=[[[0.5, 0.0], [1.0, 0.5], [0.5, 0.5]]])


def test_corner_narrower_than_min_angle_is_refused():
    sliver = [[0, 0], [1, 0], [0, 0.2]]  # 11.3 degrees at (1, 0)
    with pytest.raises(ValueError, match=r"outline has a corner of 11\.31 degrees at vertex 1 \(1, 0\), "
                                         r"narrower than min_angle=30.*min_angle <= 11\.3"):
        Mesh.from_polygon(sliver, max_area=0.01)
    m = Mesh.from_polygon(sliver, max_area=0.01, min_angle=11.0)
    assert m.quality()["min_angle_deg"] >= 11.0 - 1e-9
    # a sharp spike into a hole narrows the body there: 360 - 350 = 10 degrees of body
    outline = [[0, 0], [4, 0], [4, 4], [0, 4]]
    hole = [[1, 1], [3, 1], [3, 3], [2.1, 3], [2.0, 1.2], [1.9, 3], [1, 3]]
    with pytest.raises(ValueError, match=r"holes\[0\] has a corner of .* narrower than min_angle"):
        Mesh.from_polygon(outline, max_area=0.05, holes=[hole])


# ------------------------------------------------------------------------------------ self-overlap, exact
def _two_triangles_mesh():
    """Two separate triangles A (around the origin) and B (far away): a mesh of two bodies."""
    pts = np.array([[0.0, 0.0], [1.0, 0.0], [0.0, 1.0], [10.0, 0.0], [11.0, 0.0], [10.0, 1.0]])
    return Mesh(pts, np.array([[0, 1, 2], [3, 4, 5]]))


def _two_squares(b):
    """A unit square A (two triangles) and a square B = ``b`` (4 corners, counter-clockwise)."""
    a = np.array([[0.0, 0], [1, 0], [1, 1], [0, 1]])
    pts = np.vstack([a, np.asarray(b, float)])
    tri = np.array([[0, 1, 2], [0, 2, 3], [4, 5, 6], [4, 6, 7]])
    return pts, tri


def test_boundary_crosses_finds_contacts_through_vertices_touching_and_collinear():
    far = [[5.0, 5], [6, 5], [6, 6], [5, 6]]
    pts, tri = _two_squares(far)
    m = Mesh(pts, tri)
    assert not m.boundary_crosses(m.points)
    cases = {
        # B is a diamond whose edges pass exactly through A's four corners: A lies inside B, yet no
        # edge crosses another except at a vertex (missed by a proper-crossing test)
        "through vertices": [[0.5, -0.5], [1.5, 0.5], [0.5, 1.5], [-0.5, 0.5]],
        # B touches A's corner (1, 1) with its own corner, from outside
        "corner on corner": [[1.0, 1.0], [2, 1], [2, 2], [1, 2]],
        # B's corner touches the middle of A's right edge, from outside
        "corner on edge": [[1.0, 0.5], [1.5, 0.0], [2.0, 0.5], [1.5, 1.0]],
        # B sits beside A sharing part of the line x = 1: collinear overlapping edges
        "collinear": [[1.0, 0.5], [2, 0.5], [2, 1.5], [1, 1.5]],
    }
    for name, b in cases.items():
        x = pts.copy()
        x[4:] = b
        assert m.boundary_crosses(x), name
    # a hair apart: no contact
    x = pts.copy()
    x[4:] = np.array(cases["collinear"]) + [1e-12, 0]
    assert not m.boundary_crosses(x)


def test_boundary_crosses_finds_a_fold_back_of_neighbouring_edges():
    m = Mesh.rectangle(3.0, 1.0, 3, 1, pattern="right")
    x = m.points.copy()
    # fold the strip's bottom-right corner back so that its bottom edge runs back along itself: the
    # node at (3, 0) moves to (1.5, 0), onto the bottom edge of the previous cell
    x[3] = [1.5, 0.0]
    assert m.boundary_crosses(x)


def test_overlapping_rest_geometry_is_refused():
    pts, tri = _two_squares([[0.5, 0.5], [1.5, 0.5], [1.5, 1.5], [0.5, 1.5]])
    with pytest.raises(ValueError, match=r"rest geometry overlaps itself: boundary edges .* meet"):
        Mesh(pts, tri)
    pts, tri = _two_squares([[1.0, 0.0], [2, 0], [2, 1], [1, 1]])  # side by side, nodes not shared
    with pytest.raises(ValueError, match="boundary crosses or touches itself"):
        Mesh(pts, tri)
    # a fan that winds twice around its centre node: every triangle upright, the body covers itself
    ang = np.radians(144.0 * np.arange(5))  # five steps of 144 degrees: two full turns
    pts = np.vstack([[0, 0], np.column_stack([np.cos(ang), np.sin(ang)])])
    tri = np.array([[0, 1 + k, 1 + (k + 1) % 5] for k in range(5)])
    with pytest.raises(ValueError, match=r"triangles around node 0 .* turn through 720\.0 degrees"):
        Mesh(pts, tri)


def test_boundary_crossing_check_on_16k_edges():
    """16k boundary edges: a half-turn arc does not cross itself, a 2.2-turn coil does (its time against the
    former all-pairs test is measured by tests/benchmarks/bench_guards.py, not here)."""
    from conftest import arc_map

    m = Mesh.rectangle(4.0, 0.01, 8000, 1)
    assert len(m.boundary_edges) == 16002
    assert not m.boundary_crosses(arc_map(m.points, angle=np.pi))
    assert m.boundary_crosses(arc_map(m.points, angle=2.2 * np.pi))


def test_polygon_contacts_are_exact():
    from mdsr_opt.body.polygons import check_polygon, segment_contacts

    with pytest.raises(ValueError, match="self-intersecting: edge 2 .* meets edge 3|self-intersecting"):
        check_polygon([[0, 0], [2, 0], [2, 2], [1, 0], [0, 2]])  # vertex 3 on edge 0
    with pytest.raises(ValueError, match="self-intersecting"):
        check_polygon([[0, 0], [3, 0], [3, 1], [2, 1], [2, 0], [1, 0], [1, 1], [0, 1]])  # collinear overlap
    ring = np.array([[0, 1], [1, 2], [2, 3], [3, 0]])
    assert segment_contacts([[0, 0], [1, 0], [1, 1], [0, 1]], ring).shape == (0, 2)
    assert segment_contacts([[0, 0], [1, 1], [1, 0], [0, 1]], ring).tolist() == [[0, 2]]
    # folding back: edge 1 runs back along edge 0
    assert [0, 1] in segment_contacts([[0, 0], [2, 0], [1, 0], [1, 1]], ring).tolist()


def test_edge_rows_find_every_edge_in_either_order_and_nothing_else():
    mesh = Mesh.rectangle(3.0, 1.0, 12, 4)
    e = mesh.edges
    rng = np.random.default_rng(5)
    rows = rng.permutation(len(e))
    np.testing.assert_array_equal(mesh.edge_rows(e[rows, 0], e[rows, 1]), rows)
    np.testing.assert_array_equal(mesh.edge_rows(e[rows, 1], e[rows, 0]), rows)  # either order
    i = rng.integers(-3, mesh.n_nodes + 3, 4000)
    j = rng.integers(-3, mesh.n_nodes + 3, 4000)
    expect = [mesh.edge_index.get((min(a, b), max(a, b)), -1) if min(a, b) >= 0 else -1 for a, b in zip(i, j)]
    np.testing.assert_array_equal(mesh.edge_rows(i, j), expect)  # non-edges, self pairs, out of range: -1
    assert mesh.has_edge(int(e[7, 1]), int(e[7, 0])) and not mesh.has_edge(0, mesh.n_nodes - 1)
    # relabelling the nodes moves the rows with the edges
    perm = rng.permutation(mesh.n_nodes)
    inv = np.argsort(perm)
    moved = Mesh(mesh.points[perm], inv[mesh.triangles])
    r = moved.edge_rows(inv[e[:, 0]], inv[e[:, 1]])
    assert (r >= 0).all() and len(set(r.tolist())) == len(e)


def test_a_mesh_pickles_without_its_solver_caches_and_solves_the_same_after():
    """A mesh that has been solved on holds CasADi models and SuperLU factorisations in its caches, which
    do not pickle; a pickle keeps the mesh and its derived arrays (read-only again) and drops those."""
    import pickle

    from mdsr_opt import Muscle, NeoHookean, solve_internal

    m = Mesh.rectangle(4.0, 1.0, nx=12, ny=3)
    mat = NeoHookean(E=1.0, nu=0.3)
    top = np.flatnonzero(np.isclose(m.points[:, 1], 1.0))
    muscle = Muscle(top[np.argsort(m.points[top, 0])])
    first = solve_internal(m, mat, [muscle], [0.2])
    assert first.success
    assert any(k.endswith("_cache") for k in m.__dict__)  # what made pickling fail before
    copy = pickle.loads(pickle.dumps(m))
    assert not any(k.endswith("_cache") for k in copy.__dict__)
    np.testing.assert_array_equal(copy.points, m.points)
    np.testing.assert_array_equal(copy.triangles, m.triangles)
    np.testing.assert_array_equal(copy.boundary_nodes, m.boundary_nodes)
    for arr in (copy.points, copy.triangles, copy.edges, copy.areas):
        assert not arr.flags.writeable
    again = solve_internal(copy, mat, [muscle], [0.2])
    assert again.success
    np.testing.assert_allclose(again.x, first.x, rtol=0, atol=1e-9 * m.size)


# ------------------------------------------------------------------------- thin parts bound the work first
def _strip(w):
    return np.array([[0.0, 0.0], [1.0, 0.0], [1.0, w], [0.0, w]])


def _needle(w):
    """A unit square with a needle w wide and 0.5 long on its top edge."""
    return np.array([[0, 0], [1, 0], [1, 1], [0.5 + w / 2, 1], [0.5 + w / 2, 1.5], [0.5 - w / 2, 1.5],
                     [0.5 - w / 2, 1], [0, 1]])


def _slit_by_the_edge(gap):
    """A unit square and a slit hole 0.6 long running ``gap`` above its bottom edge."""
    return SQUARE, [np.array([[0.2, gap], [0.8, gap], [0.8, gap + 1e-3], [0.2, gap + 1e-3]])]


THIN = [  # (outline, holes, width, what the message says it lies between, where along x)
    (_strip(1e-9), [], 1e-9, "the outline is", 0.5),
    (_strip(1e-6), [], 1e-6, "the outline is", 0.5),
    (_needle(1e-7), [], 1e-7, "the outline is", 0.5),
    (*_slit_by_the_edge(1e-8), 1e-8, "the body between the outline and holes[0] is", 0.5),
]


@pytest.mark.parametrize("scale", [1e-6, 1.0, 1e3])
@pytest.mark.parametrize("outline, holes, width, what, x", THIN)
def test_thin_parts_are_refused_before_triangle_runs(monkeypatch, outline, holes, width, what, x, scale):
    """A part w wide needs triangles about w across whatever max_area: a 1 x 1e-9 strip would take 2e9. The
    estimate finds it (its width, where it is, what it lies between) before Triangle is called."""
    import triangle

    def refuse(*args, **kwargs):
        raise AssertionError("Triangle ran")

    monkeypatch.setattr(triangle, "triangulate", refuse)
    off = np.array([3.0, -2.0]) * scale
    with pytest.raises(ValueError) as info:
        Mesh.from_polygon(outline * scale + off, holes=[h * scale + off for h in holes])
    msg = str(info.value)
    m = re.match(rf"{re.escape(what)} only about (\S+) wide near \((\S+), (\S+)\), over a length of about "
                 r"(\S+): a quality mesh needs triangles about that small there whatever max_area is, about "
                 r"(\S+) triangles in all, more than the limit max_triangles=2000000; at that length it must "
                 r"be at least about (\S+) wide to fit the limit\.", msg)
    assert m, msg
    w, px, _, length, n, allowed = (float(v) for v in m.groups())
    assert w == pytest.approx(width * scale, rel=0.01)
    assert px == pytest.approx(off[0] + x * scale, abs=0.3 * scale)
    assert 0.4 * scale < length < 1.2 * scale
    assert n > 2e6 and width * scale < allowed < 1e-5 * scale


def test_a_thin_refusal_is_quick_and_small_and_leaves_the_process_usable(tmp_path):
    """In a fresh process: each refusal under 1 s and the peak memory under 200 MB (the issue's bounds) (Triangle once took 12 s and
    2.8 GB on the 1e-9 strip, then failed on every later mesh); then a unit square meshes as usual."""
    pytest.importorskip("resource")  # POSIX: the child reads its peak resident memory
    import subprocess
    import sys

    script = tmp_path / "thin.py"
    script.write_text(
        "import resource, time\n"
        "resource.setrlimit(resource.RLIMIT_AS, (3 << 30, resource.getrlimit(resource.RLIMIT_AS)[1]))\n"
        "import numpy as np\n"
        "from mdsr_opt import Mesh\n"
        "sq = np.array([[0., 0], [1, 0], [1, 1], [0, 1]])\n"
        "worst = 0.0\n"
        "for w in (1e-9, 1e-6):\n"
        "    for s in (1e-6, 1.0, 1e3):\n"
        "        t = time.perf_counter()\n"
        "        try:\n"
        "            Mesh.from_polygon(np.array([[0, 0], [1, 0], [1, w], [0, w]]) * s)\n"
        "        except ValueError:\n"
        "            worst = max(worst, time.perf_counter() - t)\n"
        "        else:\n"
        "            raise SystemExit('meshed a thin strip')\n"
        "m = Mesh.from_polygon(sq, max_area=0.01)\n"
        "peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss\n"
        "try:  # Linux: ru_maxrss may carry the forking parent's peak across exec; VmHWM is this image's own\n"
        "    peak = next(int(l.split()[1]) for l in open('/proc/self/status') if l.startswith('VmHWM:'))\n"
        "except OSError:\n"
        "    pass\n"
        "print(worst, peak, m.n_nodes)\n")
    root = str(Path(__file__).resolve().parents[1])  # this checkout's mdsr_opt, as in the tests' own process
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([root] + [p for p in [os.environ.get("PYTHONPATH")] if p]))
    out = subprocess.run([sys.executable, str(script)], capture_output=True, text=True, timeout=120, cwd=root,
                         env=env)
    assert out.returncode == 0, out.stderr
    worst, peak, nodes = out.stdout.split()
    peak_mb = int(peak) / (1024 * 1024 if sys.platform == "darwin" else 1024)  # bytes on macOS, KiB on Linux
    assert float(worst) < 1.0 and peak_mb < 200.0
    assert int(nodes) == Mesh.from_polygon(SQUARE, max_area=0.01).n_nodes


@pytest.mark.parametrize("scale", [1e-6, 1.0, 1e3])
def test_a_moderately_thin_strip_meshes_and_its_estimate_holds_it_to_a_lower_limit(scale):
    """A 1 x 1e-3 strip takes about 2000 triangles at any max_area: meshed under the default limit; refused
    before meshing under a limit of 1000, the message naming its width."""
    m = Mesh.from_polygon(_strip(1e-3) * scale)
    assert 1500 < m.n_triangles < 2500 and m.quality()["min_angle_deg"] >= 30 - 1e-6
    with pytest.raises(ValueError, match=rf"the outline is only about {1e-3 * scale:.3g} wide .* more than the "
                                         r"limit max_triangles=1000"):
        Mesh.from_polygon(_strip(1e-3) * scale, max_triangles=1000)


def test_gaps_across_a_hole_or_a_notch_do_not_refine():
    """Triangle refines only inside the body: a hole 1e-9 wide, a hole whose tip comes 1e-9 from the outline,
    and a notch 1e-6 wide cut into the outline all mesh with a few hundred triangles."""
    slit = [np.array([[0.2, 0.5], [0.8, 0.5], [0.8, 0.5 + 1e-9], [0.2, 0.5 + 1e-9]])]
    tip = [np.array([[0.5, 1e-9], [0.6, 0.4], [0.4, 0.4]])]
    w = 1e-6
    notch = [[0, 0], [0.5 - w / 2, 0], [0.5 - w / 2, 0.6], [0.5 + w / 2, 0.6], [0.5 + w / 2, 0], [1, 0], [1, 1],
             [0, 1]]
    for outline, holes, angle in ((SQUARE, slit, 30), (SQUARE, tip, 14), (notch, [], 30)):
        m = Mesh.from_polygon(outline, max_area=0.01, holes=holes, min_angle=angle)
        assert m.n_triangles < 3000 and m.quality()["min_angle_deg"] >= angle - 1e-6


def test_an_underestimate_is_still_stopped_by_the_cap_on_added_points(monkeypatch):
    """Should the estimate miss a thin part, Triangle stops after adding max_triangles points (a 1 x 1e-4 strip
    needs 16k triangles): a clean refusal, not a run to exhaustion."""
    from mdsr_opt.body import triangulate

    monkeypatch.setattr(triangulate, "expected_triangles", lambda rings, max_area, limit: (0.0, None))
    with pytest.raises(ValueError, match=r"meshing stopped at the limit after adding \d+ triangles, more than the "
                                         r"limit max_triangles=2000"):
        Mesh.from_polygon(_strip(1e-4), max_triangles=2000)


def test_every_entry_point_goes_through_the_bound(tmp_path):
    """mesh_polygon (resolution=), a scene file's [body] outline and the author page's outline all refuse a
    thin outline with the same message."""
    import json

    from mdsr_opt.author.session import Session
    from mdsr_opt.scenes.reader import SceneFileError
    from mdsr_opt.scenes.scene import mesh_polygon
    from mdsr_opt.scenes.scenefile import load_scene

    try:
        import tomllib
    except ImportError:  # Python < 3.11
        import tomli as tomllib
    thin = (_strip(1e-7) * 4).tolist()
    want = r"the outline is only about 4e-07 wide near \(2, 2e-07\)"
    with pytest.raises(ValueError, match=want):
        mesh_polygon(thin, resolution=300)
    with pytest.raises(ValueError, match=want):
        Session.from_outline(thin, resolution=300)
    scene = tomllib.loads((Path(__file__).parent / "data" / "finger.toml").read_text())
    scene["body"]["outline"] = thin
    (tmp_path / "thin.json").write_text(json.dumps(scene))
    with pytest.raises(SceneFileError, match=r"body\.outline: " + want):
        load_scene(tmp_path / "thin.json")


# ------------------------------------------------------------------------------------- scale invariance
def _ring(n=40):
    a = 2 * np.pi * np.arange(n) / n
    return np.column_stack([np.cos(a), np.sin(a)])


@pytest.mark.parametrize("outline, holes", [
    (SQUARE, []),
    ([[0, 0], [2, 0], [2, 1], [1, 1], [1, 2], [0, 2]], []),
    (_ring(), [0.5 * _ring()]),
    ([[0, 0], [3, 0.4], [2.5, 1.7], [1.1, 2.2], [-0.4, 1.1]], [[[0.8, 0.6], [1.6, 0.7], [1.2, 1.3]]]),
])
def test_meshes_do_not_depend_on_scale_or_place(outline, holes):
    """The outline scaled by s (and moved) with max_area scaled by s**2 gives the same triangles, the nodes
    scaled and moved alike (Triangle splits segments at powers of two of its own coordinates, so the
    coordinates it sees must not depend on s)."""
    outline = np.asarray(outline, dtype=float)
    holes = [np.asarray(h, dtype=float) for h in holes]
    ref = Mesh.from_polygon(outline, max_area=0.01, holes=holes)
    for s in (1e-6, 1e-3, 0.37, 3.0, 1e3, 1e6):
        off = np.array([12.3, -4.5]) * s
        m = Mesh.from_polygon(outline * s + off, max_area=0.01 * s * s, holes=[h * s + off for h in holes])
        np.testing.assert_array_equal(m.triangles, ref.triangles)
        np.testing.assert_allclose((m.points - off) / s, ref.points, rtol=0, atol=1e-12 * np.ptp(outline))


# ---------------------------------------------------------------------------------------- min_angle holds
PENTAGON = [[-0.75, -0.07], [-0.59, -0.41], [-0.5, -0.71], [-0.18, -0.49], [0.3, -0.35]]


def test_triangle_leaves_angles_below_min_angle_near_input_corners_and_they_are_repaired():
    """Triangle spares skinny triangles whose shortest edge joins points it put at equal distances on the two
    edges of an input corner (narrower than 60 degrees here); a refinement pass splits them."""
    import triangle as tr

    from mdsr_opt.body.polygons import ring_segments
    from mdsr_opt.body.triangulate import quality_triangulation, triangle_min_angles

    p = np.array(PENTAGON)
    out = tr.triangulate({"vertices": p, "segments": ring_segments([5])}, "pq30a0.01Q")
    assert triangle_min_angles(out["vertices"], out["triangles"]).min() < 25.0
    v, t, _, capped = quality_triangulation(p, ring_segments([5]), None, 30.0, 0.01, 10 ** 6)
    assert not capped and triangle_min_angles(v, t).min() >= 30.0 - 1e-6
    assert Mesh.from_polygon(p, max_area=0.01).quality()["min_angle_deg"] >= 30.0 - 1e-6


def test_min_angle_holds_on_fuzzed_outlines_with_holes():
    """Random star-shaped outlines (and a hole in every other one) at 20 to 33 degrees: every angle of every
    mesh meets min_angle (before the repair, about one mesh in nine fell short, by up to 11 degrees)."""
    rng = np.random.default_rng(7)

    def star(k):
        a = np.sort(rng.uniform(0, 2 * np.pi, k))
        return np.column_stack([np.cos(a), np.sin(a)]) * rng.uniform(0.4, 1.0, k)[:, None]

    meshed = 0
    for i in range(120):
        q = float(rng.choice([20.0, 25.0, 30.0, 33.0]))
        outline = star(int(rng.integers(5, 20)))
        holes = [0.15 * star(6) + rng.uniform(-0.1, 0.1, 2)] if i % 2 else []
        try:
            m = Mesh.from_polygon(outline, max_area=float(rng.uniform(5e-4, 0.05)), holes=holes, min_angle=q)
        except ValueError:  # a corner narrower than q, a crossing or a hole outside: refused at the door
            continue
        meshed += 1
        assert m.quality()["min_angle_deg"] >= q - 1e-6, (i, q)
    assert meshed > 50


def test_an_angle_left_below_min_angle_is_reported(monkeypatch):
    from mdsr_opt.body import triangulate

    monkeypatch.setattr(triangulate, "_REPAIR_PASSES", 0)
    with pytest.warns(UserWarning, match=r"the mesh's smallest angle is 2\d\.?\d* degrees, in the triangle centred "
                                         r"at \(-?0\.\d+, -?0\.\d+\), below min_angle=30"):
        Mesh.from_polygon(PENTAGON, max_area=0.01)
