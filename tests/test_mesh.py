import numpy as np
import pytest

from mdsr_opt import Mesh
from mdsr_opt.mesh import polygon_area


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
