"""mdsr evaluate compares every loop, as mdsr run's validation does: a photograph of a ring whose hole is
filled in scored 0.10 px against the ring, the same as the true photograph (new-user trial 11, defect 5).
The bodies here are our own (a plate with a window)."""

from __future__ import annotations

import csv

import cv2
import numpy as np
import pytest

from mdsr_opt import Mesh, render_photo
from mdsr_opt.body.io import write_mesh
from mdsr_opt.cli.main import main as cli_main
from mdsr_opt.photos.folder import evaluate_folder


@pytest.fixture(scope="module")
def window_photos(tmp_path_factory):
    """A plate with a window (a pentagon, no symmetry, with a hole of radius 14 around (40, 30); 157 nodes): its
    state, its synthetic photograph (``true``) and the same photograph with the hole painted the body's colour
    (``filled``), each beside a state of the same name. (An outline with a symmetry, a disk, leaves the
    registration's rotation free: the holes may then be placed wrong, see compare_loops.)"""
    t = np.linspace(0, 2 * np.pi, 24, endpoint=False)
    mesh = Mesh.from_polygon(np.array([[0, 0], [100, 0], [100, 40], [60, 70], [0, 50]], float), max_area=40,
                             holes=[np.c_[40 + 14 * np.cos(t), 30 + 14 * np.sin(t)]])
    root = tmp_path_factory.mktemp("window")
    photo = render_photo(mesh, image_size=(400, 400), seed=0)
    img = photo.image.copy()
    body = img[tuple(np.round(photo.to_pixels([[85.0, 15.0]])[0][::-1]).astype(int))]  # a point of the body
    hole = np.round(photo.to_pixels(mesh.points[mesh.boundary_loops[1]])).astype(np.int32).reshape(-1, 1, 2)
    cv2.fillPoly(img, [hole], [int(v) for v in body])
    cv2.polylines(img, [hole], True, [int(v) for v in body], thickness=5)
    (root / "images").mkdir()
    for name, im in (("true", photo.image), ("filled", img)):
        cv2.imwrite(str(root / "images" / f"{name}.png"), np.ascontiguousarray(im[:, :, ::-1]))
        write_mesh(root / "states" / f"{name}.vtu", mesh, x=mesh.points)
    return root


def test_a_photograph_without_the_bodys_hole_is_no_match(window_photos):
    rows = {r.case: r for r in evaluate_folder(window_photos / "images", window_photos / "states")}
    true, filled = rows["true"], rows["filled"]
    # the outlines alone cannot tell them apart (the defect): both within a pixel
    assert true.comparison.mean_px < 1.0 and filled.comparison.mean_px < 1.0
    assert true.loops.n_unmatched == 0 and true.loops.mean_px < 1.0
    assert [row["kind"] for row in true.loops.loops] == ["outer", "hole"] and true.loops.loops[1]["matched"] == 1
    assert filled.loops.n_unmatched == 1 and filled.loops.loops[1]["matched"] is None
    assert filled.loops.mean_px > 20 * true.loops.mean_px  # the hole measured to the outline: no match


def test_mdsr_evaluate_scores_every_loop_and_says_which_hole_is_missing(window_photos, capsys):
    out = window_photos / "eval"
    assert cli_main(["evaluate", str(window_photos / "images"), str(window_photos / "states"), "--out", str(out)]) == 0
    rows = {r["case"]: r for r in csv.DictReader((out / "evaluation.csv").open())}
    assert (rows["true"]["holes"], rows["true"]["photo_holes"], rows["true"]["unmatched_holes"]) == ("1", "1", "0")
    assert (rows["filled"]["holes"], rows["filled"]["photo_holes"], rows["filled"]["unmatched_holes"]) == ("1", "0", "1")
    assert float(rows["filled"]["mean_px"]) > 20 * float(rows["true"]["mean_px"])
    assert float(rows["filled"]["outline_mean_px"]) < 1.0  # the outline alone: the old, misleading figure
    printed = capsys.readouterr().out
    assert "| Holes body/photo |" in printed and "| 1/0 UNMATCHED |" in printed and "| 1/1 |" in printed
    assert ("**filled**: the body has 1 hole(s) the photograph does not show (filled in, or another body): each is "
            "measured to the nearest photographed loop, not scored as a match.") in printed
    assert "**true**" not in printed


def test_a_body_without_holes_scores_as_its_outline(tmp_path):
    mesh = Mesh.rectangle(3.0, 1.0, 12, 4)
    x = mesh.points * [1.0, 0.8]
    write_mesh(tmp_path / "states" / "plate.vtu", mesh, x=x)
    render_photo(mesh, x, image_size=(300, 200)).save(tmp_path / "img" / "plate.png")
    (row,) = evaluate_folder(tmp_path / "img", tmp_path / "states", out=tmp_path / "out")
    assert row.loops.mean_px == row.comparison.mean_px and row.loops.n_unmatched == 0
    assert "Holes" not in (tmp_path / "out" / "evaluation.md").read_text()


def test_a_disk_with_an_off_centre_hole_is_registered_by_its_hole_too():
    """A disk's outline fits at any rotation: the registration kept one that put the hole 5-57 px away from
    the photographed hole (the true photograph scored as another body); compare_loops now turns the
    registration about the photographed outline's centre when that places the holes far better."""
    from mdsr_opt import compare_loops, contour_loops_from_image, simulated_loops

    t = np.linspace(0, 2 * np.pi, 32, endpoint=False)
    mesh = Mesh.from_polygon(np.c_[50 * np.cos(t), 50 * np.sin(t)], max_area=40,
                             holes=[np.c_[12 + 20 * np.cos(t), 5 + 20 * np.sin(t)]])
    photo = render_photo(mesh, image_size=(400, 400), seed=0)
    r = compare_loops(simulated_loops(mesh), contour_loops_from_image(photo.image))
    assert r.n_unmatched == 0 and [row["kind"] for row in r.loops] == ["outer", "hole"]
    assert r.loops[1]["mean_px"] < 1.0 and r.outer.mean_px < 0.5 and r.mean_px < 0.5
    # the turned registration maps the mesh onto the photograph: the hole's nodes land on the photographed hole
    hole_px = r.outer.to_pixels(mesh.points[mesh.boundary_loops[1]])
    np.testing.assert_allclose(hole_px.mean(axis=0), photo.to_pixels([[12.0, 5.0]])[0], atol=1.5)
