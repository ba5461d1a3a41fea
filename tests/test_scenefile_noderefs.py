"""How a scene file names nodes (mdsr_opt.scenes.noderefs): ``anchors = []`` is no anchor, as the key left out
(trial9 refused it with "expected a region name, node indices or [x, y] points, got []", though an empty list
is node indices); an empty list where nodes must be named says so."""

from __future__ import annotations

import numpy as np
import pytest

from mdsr_opt import load_scene
from mdsr_opt.scenes.reader import SceneFileError
from conftest import STRIP_HEAD

HEAD = STRIP_HEAD


def _load(tmp_path, text):
    path = tmp_path / "strip.toml"
    path.write_text(HEAD + text)
    return load_scene(path)


def test_empty_anchors_are_no_anchors_as_the_key_left_out(tmp_path):
    case = """[[cases]]
name = "pull"
{anchors}drags = [{{ nodes = "left", by = [0, 0] }}, {{ nodes = "right", by = [0.3, 0] }}]
"""
    given = _load(tmp_path, case.format(anchors="anchors = []\n")).case("pull")
    left_out = _load(tmp_path, case.format(anchors="")).case("pull")
    assert given.anchors.dtype == left_out.anchors.dtype and len(given.anchors) == len(left_out.anchors) == 0
    np.testing.assert_array_equal(given.drag_nodes, left_out.drag_nodes)
    np.testing.assert_allclose(given.drag_positions, left_out.drag_positions)


def test_empty_anchors_and_too_few_drags_is_refused_for_that(tmp_path):
    with pytest.raises(SceneFileError, match=r"cases\[0\].*needs at least two fixed nodes"):
        _load(tmp_path, '[[cases]]\nname = "c"\nanchors = []\ndrags = [{ at = [4, 0.5], by = [0.1, 0] }]\n')


@pytest.mark.parametrize("where, text", [
    (r"cases\[0\]\.drags\[0\]\.nodes", '[[cases]]\nname = "c"\nanchors = "left"\ndrags = [{ nodes = [], by = [1, 0] }]\n'),
    (r"regions\.none\.nodes", '[[cases]]\nname = "c"\nanchors = "left"\ndrags = [{ nodes = "right", by = [1, 0] }]\n'
                              '[regions.none]\nnodes = []\n'),
])
def test_an_empty_list_where_nodes_are_needed_says_it_is_empty(tmp_path, where, text):
    with pytest.raises(SceneFileError, match=where + r".*is an empty list, which names no node") as info:
        _load(tmp_path, text)
    assert "got []" not in str(info.value)
