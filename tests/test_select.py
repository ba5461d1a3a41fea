"""Node selection helpers (mdsr_opt.scenes.select): a selection that cannot select anything by its very
arguments (negative or NaN radius, a polygon without area, a box with min > max) is a ValueError naming the
argument, not an empty array (trial7)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from shapely.geometry import Point

from mdsr_opt import Mesh
from mdsr_opt.scenes.select import boundary_path, edge_path, nearest_node, nodes_in_box, nodes_in_polygon, nodes_near


@pytest.fixture(scope="module")
def mesh():
    return Mesh.rectangle(4.0, 1.0, 8, 2)  # nodes on a 0.5 x 0.5 grid


@pytest.mark.parametrize("call, exc, match", [
    (lambda m: nodes_near(m, [1.0, 0.5], -1), ValueError, r"nodes_near: radius must be >= 0, got -1"),
    (lambda m: nodes_near(m, [1.0, 0.5], math.nan), ValueError, r"nodes_near: radius must be finite, got nan"),
    (lambda m: nodes_near(m, [1.0, 0.5], math.inf), ValueError, r"nodes_near: radius must be finite"),
    (lambda m: nodes_near(m, [1.0, 0.5], "0.3"), TypeError, r"nodes_near: radius must be a real number"),
    (lambda m: nodes_near(m, [math.nan, 0.5], 0.3), ValueError, r"point contains NaN"),
    (lambda m: nodes_in_polygon(m, [[0, 0], [1, 1]]), ValueError, r"polygon needs at least 3 vertices, got 2"),
    (lambda m: nodes_in_polygon(m, [[0, 0], [1, 1], [3, 3]]), ValueError, r"3 vertices lie on one line"),
    (lambda m: nodes_in_polygon(m, [[1, 1], [1, 1], [1, 1], [1, 1]]), ValueError, r"lie on one line \(or one point\)"),
    (lambda m: nodes_in_polygon(m, [[0, 0], [1, 0], [math.nan, 1]]), ValueError, r"polygon contains NaN"),
    (lambda m: nodes_in_box(m, xmin=2, xmax=1), ValueError, r"nodes_in_box: xmin 2 is above xmax 1: the box is empty"),
    (lambda m: nodes_in_box(m, ymin=0.6, ymax=0.4), ValueError, r"ymin 0.6 is above ymax 0.4"),
    (lambda m: nodes_in_box(m, ymax=math.nan), ValueError, r"nodes_in_box: ymax is NaN"),
    (lambda m: nodes_in_box(m, xmin="0"), TypeError, r"nodes_in_box: xmin must be a real number, got str"),
    (lambda m: nodes_in_box(m, xmin=True), TypeError, r"xmin must be a real number, got bool"),
    (lambda m: nearest_node(m, [1.0, 0.5], tol=-0.1), ValueError, r"nearest_node: tol must be >= 0"),
    (lambda m: nearest_node(m, [1.0, 0.5], tol=math.nan), ValueError, r"nearest_node: tol must be finite"),
    (lambda m: edge_path(m, [[0, 0], [4, 0]], tol=math.nan), ValueError, r"tol must be finite"),
    (lambda m: boundary_path(m, [0, 0], [4, 0], inset=-1), ValueError, r"boundary_path: inset must be an integer >= 0"),
    (lambda m: boundary_path(m, [0, 0], [1, 0], inset=1), ValueError, r"inset 1 drops every node of the 3-node path"),
])
def test_a_selection_that_can_select_nothing_is_refused(mesh, call, exc, match):
    with pytest.raises(exc, match=match):
        call(mesh)


def test_the_limits_of_good_selections_still_select(mesh):
    P = mesh.points
    k = nearest_node(mesh, [1.0, 0.5])
    assert np.allclose(P[k], [1.0, 0.5])
    assert list(nodes_near(mesh, P[k], 0)) == [k]  # radius 0: the node at the point itself
    column = nodes_in_box(mesh, xmin=1.0, xmax=1.0)  # a box of no width: the nodes on a line
    assert len(column) == 3 and np.allclose(P[column, 0], 1.0)
    assert len(nodes_in_box(mesh)) == mesh.n_nodes  # no bound: every node
    assert len(nodes_in_box(mesh, xmax=-math.inf)) == 0  # a real but empty half-plane: empty, no error
    tri = nodes_in_polygon(mesh, [[-0.1, -0.1], [1.1, -0.1], [-0.1, 1.1]])
    assert sorted(map(tuple, np.round(P[tri], 9))) == [(0.0, 0.0), (0.0, 0.5), (0.0, 1.0), (0.5, 0.0), (0.5, 0.5),
                                                       (1.0, 0.0)]
    assert len(boundary_path(mesh, [0, 0], [1.5, 0], inset=1).nodes) == 2  # 4 nodes, one dropped at each end
    assert nearest_node(mesh, [1.0, 0.5], tol=0) == k


def test_a_scene_region_whose_polygon_encloses_nothing_is_named_by_its_field(tmp_path):
    from mdsr_opt.cli.main import main
    from mdsr_opt.scenes.reader import SceneFileError
    from mdsr_opt.scenes.scenefile import load_scene

    scene = tmp_path / "flat.toml"
    scene.write_text('name = "flat"\n[body]\noutline = [[0, 0], [4, 0], [4, 1], [0, 1]]\nresolution = "coarse"\n'
                     '[regions]\nbase = { box = [-1, -1, 0, 2] }\n'
                     'tip = { polygon = [[3.5, 0.2], [3.7, 0.4], [3.9, 0.6]] }\n'
                     '[[cases]]\nname = "bend"\nanchors = "base"\ndrags = [{ nodes = "tip", by = [0, 0.3] }]\n')
    with pytest.raises(SceneFileError, match=r"flat\.toml: regions\.tip\.polygon: the polygon's 3 vertices lie on "
                                             r"one line"):
        load_scene(scene)
    assert main(["run", str(scene), "--out", str(tmp_path / "o")]) == 2 and not (tmp_path / "o").exists()


@pytest.mark.parametrize("angle", [0.0, 0.7])
def test_an_edge_path_follows_its_drawn_line_not_a_straight_outline_beside_it(angle):
    """A rope drawn 4 mm inside the straight top edge of an unstructured 80 x 30 mm plate with a window: the plain
    shortest edge path ran along the outline for most of its length (trial9 #7: 22 of 31 nodes on it); the path
    now stays within an edge or so of the drawn line, at any orientation, and is still a simple path."""
    c, s = math.cos(angle), math.sin(angle)
    R = np.array([[c, -s], [s, c]])
    outline = np.array([[0, 0], [80, 0], [80, 30], [0, 30]], float) @ R.T
    window = np.array([[20, 8], [40, 8], [40, 18], [20, 18]], float) @ R.T
    mesh = Mesh.from_polygon(outline, holes=[window], max_area=3.0)
    a, b = np.array([6.0, 26.0]) @ R.T, np.array([66.0, 26.0]) @ R.T
    rope = edge_path(mesh, [a, b])
    P = mesh.points[list(rope.nodes)]
    u = (b - a) / np.linalg.norm(b - a)
    off = np.abs((P - a) @ np.array([-u[1], u[0]]))          # distance of each node from the drawn line
    h = float(mesh.edge_lengths.mean())
    assert off.max() < 1.5 * h, (off.max(), h)
    top = np.abs((P - outline[3]) @ (R @ [0.0, 1.0]))          # distance from the top edge's line
    assert top.min() > 4.0 - 1.5 * h                          # never on the outline, 4 mm away
    assert len(set(rope.nodes)) == len(rope.nodes)
    assert rope.rest_length(mesh) < 1.2 * np.linalg.norm(b - a)  # a zig-zag, not a detour


def test_an_edge_path_round_a_corner_waypoint_turns_before_it_instead_of_repeating_a_node():
    """Both joins at a right-angle waypoint may run along the same last edge (out to the corner node and back):
    the rope turns at the node before it (recheck9: 'muscle path repeats node 472: a muscle is a simple path')."""
    from shapely.geometry import LineString

    from mdsr_opt import mesh_polygon

    mesh = mesh_polygon([[0, 0], [8, 0], [8, 2], [2, 2], [2, 7], [0, 7]], resolution=900)
    way = [[0.35, 6.6], [0.35, 0.35], [7.6, 0.35]]
    rope = edge_path(mesh, way)
    P, h = mesh.points, float(mesh.edge_lengths.mean())
    assert len(set(rope.nodes)) == len(rope.nodes)
    line = LineString(way)
    assert max(line.distance(Point(p)) for p in P[list(rope.nodes)]) < 1.5 * h
    assert np.linalg.norm(P[rope.nodes[0]] - way[0]) < h and np.linalg.norm(P[rope.nodes[-1]] - way[-1]) < h
