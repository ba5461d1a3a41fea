"""Contour evaluation with holes (mdsr_opt.photos.contours.contour_loops_from_image / compare_loops).

The photographs come from the synthetic camera; the face is the problem library's (coarse, ~300 nodes).
"""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from mdsr_opt.photos.compare import compare_contours, simulated_outline
from mdsr_opt.photos.loops import compare_loops, simulated_loops
from mdsr_opt.photos.contours import contour_from_image, contour_loops_from_image
from mdsr_opt.photos.camera import render_photo
from mdsr_opt.scenes.library import get_problem


@pytest.fixture(scope="module")
def face():
    scene = get_problem("face", resolution="coarse")
    photo = render_photo(scene.mesh, image_size=(500, 500), seed=0)
    return scene, photo


def _mouth(scene):
    """Index of the mouth among simulated_loops (the hole whose centre is lowest)."""
    loops = simulated_loops(scene.mesh)
    return 1 + int(np.argmin([c[:, 1].mean() for c in loops[1:]]))


def _paint_mouth_shut(scene, photo):
    img = photo.image.copy()
    mouth = simulated_loops(scene.mesh)[_mouth(scene)]
    body = img[tuple(np.round(photo.to_pixels([[0.0, -3.0]])[0][::-1]).astype(int))]  # the chin's colour
    poly = np.round(photo.to_pixels(mouth)).astype(np.int32).reshape(-1, 1, 2)
    cv2.fillPoly(img, [poly], [int(v) for v in body])
    cv2.polylines(img, [poly], True, [int(v) for v in body], thickness=5)
    return img


def test_holes_are_extracted_and_the_outline_is_unchanged(face):
    scene, photo = face
    loops = contour_loops_from_image(photo.image)
    assert len(loops) == 4  # the outline, two eyes and the mouth
    assert np.array_equal(loops[0], contour_from_image(photo.image))
    r = compare_loops(simulated_loops(scene.mesh), loops)
    assert r.n_unmatched == 0
    assert [row["kind"] for row in r.loops] == ["outer", "hole", "hole", "hole"]
    assert all(row["matched"] is not None for row in r.loops)
    assert r.mean_px < 1.0 and r.max_px < 3.0


def test_a_mouth_painted_shut_scores_clearly_worse(face):
    scene, photo = face
    shut = _paint_mouth_shut(scene, photo)
    sim = simulated_loops(scene.mesh)
    good = compare_loops(sim, contour_loops_from_image(photo.image))
    bad_loops = contour_loops_from_image(shut)
    assert len(bad_loops) == 3  # the mouth is gone from the photograph
    bad = compare_loops(sim, bad_loops)
    assert bad.n_unmatched == 1
    mouth_row = bad.loops[_mouth(scene)]
    assert mouth_row["matched"] is None and mouth_row["mean_px"] > 5.0
    assert bad.mean_px > 4 * good.mean_px
    # the outer outline alone cannot tell: it scores the painted photograph (nearly) as well
    o_good = compare_contours(simulated_outline(scene.mesh), contour_from_image(photo.image)).mean_px
    o_bad = compare_contours(simulated_outline(scene.mesh), contour_from_image(shut)).mean_px
    assert abs(o_bad - o_good) < 0.2


def test_a_mouth_that_does_not_move_scores_worse_than_one_that_does(face):
    """The photograph shows the rest face; the simulation opens the mouth wider (its lower lip down)."""
    scene, photo = face
    X = scene.mesh.points.copy()
    lips = np.flatnonzero((np.abs(X[:, 0]) < 1.3) & (X[:, 1] < -1.9) & (X[:, 1] > -2.6))
    x = X.copy()
    x[lips, 1] -= 0.25 * (1.0 - np.abs(X[lips, 0]) / 1.3)
    loops = contour_loops_from_image(photo.image)
    moved = compare_loops(simulated_loops(scene.mesh, x), loops)
    still = compare_loops(simulated_loops(scene.mesh), loops)
    assert moved.n_unmatched == 0
    assert moved.loops[_mouth(scene)]["mean_px"] > 5 * still.loops[_mouth(scene)]["mean_px"]


def test_bad_input_is_refused(face):
    scene, photo = face
    with pytest.raises(ValueError, match="at least the outer outline"):
        compare_loops([], [np.eye(3, 2)])
    with pytest.raises(ValueError, match="min_hole_fraction"):
        contour_loops_from_image(photo.image, min_hole_fraction=1.5)
    with pytest.raises(TypeError, match="unknown option"):
        contour_loops_from_image(photo.image, colour=(1, 2, 3))
