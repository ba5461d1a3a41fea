"""Tests of mdsr_opt.photos: contour extraction, contour metrics, the synthetic camera, the batch table.

Every photograph here comes from the synthetic camera (``render_photo``) or is drawn with numpy.
"""

from __future__ import annotations

import csv
import json
import math
import warnings

import cv2
import numpy as np
import pytest
from scipy import ndimage

from mdsr_opt import Mesh
from mdsr_opt.cli.main import main as cli_main
from mdsr_opt.photos.contours import body_mask, contour_from_image, contour_loops_from_image
from mdsr_opt.photos.compare import compare_contours, evaluate_image, simulated_outline
from mdsr_opt.photos.folder import evaluate_folder
from mdsr_opt.photos.images import load_image
from mdsr_opt.photos.camera import SyntheticPhoto, render_photo
from mdsr_opt.body.io import write_mesh

# a T-shaped body (a trunk with a neck), as in the paper's humanoid-like test pieces
OUTLINE = [[0, 0], [4, 0], [4, 1], [2.5, 1], [2.5, 2.2], [1.5, 2.2], [1.5, 1], [0, 1]]
# an L-shaped body: no mirror symmetry, so a wrong flip_y cannot be rotated away
OUTLINE_L = [[0, 0], [4, 0], [4, 1], [1, 1], [1, 2.5], [0, 2.5]]
BODY_RGB = (205, 95, 35)


def bend(X: np.ndarray, k: float) -> np.ndarray:
    """Bend the body: node at abscissa s turns by k * s / 4 radians about a centre above it."""
    th = k * X[:, 0] / 4.0
    r = 4.0 / k
    return np.column_stack([(r - X[:, 1]) * np.sin(th), r - (r - X[:, 1]) * np.cos(th)])


@pytest.fixture(scope="module")
def body():
    mesh = Mesh.from_polygon(OUTLINE, max_area=0.05)
    return mesh, bend(mesh.points, 0.8)


@pytest.fixture(scope="module")
def photo(body):
    mesh, x = body
    return render_photo(mesh, x, image_size=(500, 500), seed=0)


@pytest.fixture(scope="module")
def contour(photo):
    return contour_from_image(photo.image)


def disc_image(centres, radii, shape=(200, 300)):
    yy, xx = np.mgrid[0:shape[0], 0:shape[1]]
    img = np.full(shape, 210, dtype=np.uint8)
    for (cx, cy), r in zip(centres, radii):
        img[(xx - cx) ** 2 + (yy - cy) ** 2 <= r * r] = 60
    return img


def truth_mask(outline_px, shape):
    from matplotlib.path import Path

    yy, xx = np.mgrid[0:shape[0], 0:shape[1]]
    pts = np.column_stack([xx.ravel(), yy.ravel()])
    return Path(outline_px).contains_points(pts).reshape(shape)


def polygon_area(p):
    return 0.5 * abs(np.dot(p[:, 0], np.roll(p[:, 1], -1)) - np.dot(p[:, 1], np.roll(p[:, 0], -1)))


# ------------------------------------------------------------------------------------------ self-comparison
def test_rendered_state_against_itself_is_below_one_pixel(body, photo, contour):
    mesh, x = body
    outline = simulated_outline(mesh, x)
    exact = compare_contours(photo.to_pixels(outline), contour, registration="none")
    assert exact.mean_px < 1.0
    assert exact.max_px < 2.5
    assert abs(exact.bias_px) < 0.3  # the sub-pixel contour is neither inside nor outside on average
    registered = compare_contours(outline, contour)  # rotation + unit-rectangle scaling from scratch
    assert registered.mean_px < 1.0
    assert registered.n_nodes == len(mesh.boundary_loops[0])
    assert registered.ratio == pytest.approx(registered.mean_px / math.sqrt(polygon_area(contour)), rel=1e-6)
    # the registration maps the simulation into the photo: same scale as the camera's (up to the tilt)
    cam_scale = math.sqrt(abs(np.linalg.det(photo.world_to_pixel[:2, :2])))
    assert registered.scale == pytest.approx(cam_scale, rel=0.02)


def test_distances_are_point_polygon_distances(body, photo, contour):
    mesh, x = body
    r = compare_contours(simulated_outline(mesh, x), contour)
    # brute force: distance of each mapped node to the polyline of the contour
    a, b = contour, np.roll(contour, -1, axis=0)
    for p, d in zip(r.simulated_px[::7], r.distances_px[::7]):
        t = np.clip(((p - a) * (b - a)).sum(1) / ((b - a) ** 2).sum(1), 0, 1)
        brute = np.sqrt(((a + t[:, None] * (b - a) - p) ** 2).sum(1)).min()
        assert d == pytest.approx(brute, abs=1e-3)
    assert np.allclose(r.to_pixels(simulated_outline(mesh, x)), r.simulated_px)


@pytest.mark.parametrize("extract", [{"color": BODY_RGB}, {"method": "adaptive"}, {"subpixel": False}])
def test_other_segmentations_also_fit(body, photo, extract):
    mesh, x = body
    c = contour_from_image(photo.image, **extract)
    r = compare_contours(photo.to_pixels(simulated_outline(mesh, x)), c, registration="none")
    assert r.mean_px < 1.0


def test_subpixel_contour_is_closer_than_pixel_centres(body, photo, contour):
    mesh, x = body
    ref = photo.to_pixels(simulated_outline(mesh, x))
    coarse = compare_contours(ref, contour_from_image(photo.image, subpixel=False), registration="none")
    fine = compare_contours(ref, contour, registration="none")
    assert fine.mean_px < coarse.mean_px
    assert coarse.bias_px < -0.2  # pixel centres lie inside the body's edge


# ------------------------------------------------------------------------------------------ invariance
def transform_photo(image, angle_deg, scale, shift_rc):
    """Rotate by angle_deg about the centre, scale, then shift (rows, cols); edges replicated."""
    c = (np.array(image.shape[:2]) - 1) / 2.0
    t = math.radians(angle_deg)
    R = np.array([[math.cos(t), -math.sin(t)], [math.sin(t), math.cos(t)]])
    M = R.T / scale  # output -> input
    offset = c - M @ (c + np.asarray(shift_rc, float))
    return np.stack([ndimage.affine_transform(image[..., k], M, offset=offset, order=1, mode="nearest")
                     for k in range(3)], axis=-1)


@pytest.mark.parametrize("angle, scale, shift", [(30.0, 0.8, (25.0, -15.0)), (-65.0, 0.9, (-10.0, 30.0)),
                                                 (180.0, 1.0, (5.0, 5.0))])
def test_rotating_scaling_shifting_the_photo_barely_moves_normalised_mean(body, photo, contour, angle, scale,
                                                                          shift):
    mesh, x = body
    outline = simulated_outline(mesh, x)
    base = compare_contours(outline, contour)
    moved = transform_photo(photo.image, angle, scale, shift)
    r = compare_contours(outline, contour_from_image(moved))
    assert abs(r.mean_norm - base.mean_norm) < 0.01  # less than 1 % of the unit rectangle
    # and the self-comparison stays sub-pixel: the change is under a pixel of the smaller image
    assert abs(r.mean_norm - base.mean_norm) < 1.0 / min(r.size_px, base.size_px)
    assert r.scale / base.scale == pytest.approx(scale, rel=0.01)
    turn = (r.angle_deg - base.angle_deg + 180.0) % 360.0 - 180.0
    assert abs(abs(turn) - abs((angle + 180.0) % 360.0 - 180.0)) < 1.0


def test_rotation_on_the_plate_is_recovered(body):
    mesh, x = body
    ph = render_photo(mesh, x, image_size=(400, 400), seed=4, rotation_deg=40.0, margin=0.2)
    r = compare_contours(simulated_outline(mesh, x), contour_from_image(ph.image))
    assert r.angle_deg == pytest.approx(40.0, abs=1.0)
    assert r.mean_px < 1.0


def test_segment_registration_and_stretch_scaling(body, photo, contour):
    mesh, x = body
    outline = simulated_outline(mesh, x)
    i, j = 0, len(outline) // 2
    q = photo.to_pixels(outline[[i, j]])
    seg = compare_contours(outline, contour, registration="segment", segments=((i, j), (q[0], q[1])))
    assert seg.mean_px < 1.5
    stretch = compare_contours(outline, contour, scaling="stretch")
    assert stretch.mean_px < 1.5
    assert stretch.mean_norm < 0.005


# ------------------------------------------------------------------------------------------ discrimination
def test_a_different_shape_scores_clearly_worse(body, contour):
    mesh, x = body
    same = compare_contours(simulated_outline(mesh, x), contour)
    less_bent = compare_contours(simulated_outline(mesh, bend(mesh.points, 0.3)), contour)
    straight = compare_contours(simulated_outline(mesh), contour)
    rectangle = Mesh.rectangle(4.0, 1.0, 8, 2)
    other = compare_contours(simulated_outline(rectangle), contour)
    for worse in (less_bent, straight, other):
        assert worse.mean_norm > 0.01
        assert worse.mean_norm > 8 * same.mean_norm
        assert worse.mean_px > 4.0
    assert straight.mean_norm > less_bent.mean_norm  # the further from the photo, the worse


def test_a_wrong_flip_y_scores_far_worse_on_an_asymmetric_body():
    """The T body is mirror-symmetric, so a mirrored outline fits it after a rotation; an L does not."""
    mesh = Mesh.from_polygon(OUTLINE_L, max_area=0.05)
    x = bend(mesh.points, 0.5)
    ph = render_photo(mesh, x, image_size=(400, 400), seed=2)
    c = contour_from_image(ph.image)
    right = compare_contours(simulated_outline(mesh, x), c)
    mirrored = compare_contours(simulated_outline(mesh, x), c, flip_y=False)
    assert right.mean_px < 1.0
    assert mirrored.mean_px > 8 * right.mean_px and mirrored.mean_px > 4.0
    assert mirrored.mean_norm > 0.01


def square_outline(n_side, roof=0.0):
    """A counter-clockwise unit square with ``n_side`` points per side; the top side is a gable of
    height ``roof`` (0: a square)."""
    t = np.linspace(0.0, 1.0, n_side, endpoint=False)
    z, o = np.zeros_like(t), np.ones_like(t)
    top = np.column_stack([1 - t, 1 + roof * (1 - np.abs(1 - 2 * t))])
    return np.vstack([np.column_stack([t, z]), np.column_stack([o, t]), top, np.column_stack([z, 1 - t])])


def test_normalisation_is_stable_for_a_shape_without_a_long_axis():
    """A square's principal axes are set by noise; the normalisation must not be. A square with a gable
    roof (simulation) is compared with noisy photographed squares at random rotations: the shape error
    is the same each time, so mean_norm must be too (the principal-axis rectangle of the measured
    contour moved it by more than 100 %)."""
    roof = 0.2
    sim = square_outline(40, roof)
    norms, sizes = [], []
    for seed in range(10):
        rng = np.random.default_rng(seed)
        t = rng.uniform(0.0, 2 * np.pi)
        R = np.array([[np.cos(t), -np.sin(t)], [np.sin(t), np.cos(t)]])
        measured = (square_outline(100) - 0.5) * 200.0 @ R.T + [250.0, 250.0] + rng.normal(0, 0.3, (400, 2))
        r = compare_contours(sim, measured)
        norms.append(r.mean_norm)
        sizes.append(r.size_px)
    assert np.ptp(norms) / np.mean(norms) < 0.02
    assert np.ptp(sizes) / np.mean(sizes) < 0.02
    # the documented normalising length: the simulated outline's longer side (1 + roof) at the
    # registered scale, which makes the areas equal (the house has area 1 + roof / 2)
    assert np.mean(sizes) == pytest.approx((1 + roof) * 200.0 / math.sqrt(1 + roof / 2), rel=0.01)


def test_px_per_unit_makes_a_size_error_visible(body):
    mesh, x = body
    ph = render_photo(mesh, x, image_size=(500, 500), seed=0, tilt_deg=0.0)
    c = contour_from_image(ph.image)
    scale = math.sqrt(abs(np.linalg.det(ph.world_to_pixel[:2, :2])))  # pixels per unit, as on a plate
    outline = simulated_outline(mesh, x)
    small = outline.mean(axis=0) + 0.9 * (outline - outline.mean(axis=0))  # 10 % too small
    fitted_right, fitted_small = compare_contours(outline, c), compare_contours(small, c)
    # rescaling both outlines (the paper's procedure) hides a uniform size error completely ...
    assert fitted_small.mean_px < 1.0 and fitted_small.mean_px < 1.5 * fitted_right.mean_px
    # ... a known scale does not
    fixed_right = compare_contours(outline, c, px_per_unit=scale)
    fixed_small = compare_contours(small, c, px_per_unit=scale)
    assert fixed_right.mean_px < 1.0 and fixed_right.scale == pytest.approx(scale)
    assert fixed_small.mean_px > 5.0 and fixed_small.mean_px > 8 * fixed_right.mean_px
    assert fixed_small.bias_px > 3.0  # the simulation lies inside the photographed body
    for kw, msg in (({"scaling": "stretch"}, "scaling='uniform'"), ({"registration": "none"}, "none"),
                    ({}, "px_per_unit must be > 0")):
        with pytest.raises(ValueError, match=msg):
            compare_contours(outline, c, px_per_unit=-1.0 if not kw else scale, **kw)


# ------------------------------------------------------------------------------------------ robustness
def test_noisy_blurred_photo_still_extracts(body):
    mesh, x = body
    ph = render_photo(mesh, x, seed=7, noise_sigma=25.0, blur_sigma=1.5)
    r = compare_contours(ph.to_pixels(simulated_outline(mesh, x)), contour_from_image(ph.image),
                         registration="none")
    assert r.mean_px < 1.5


@pytest.mark.parametrize("extract", [{}, {"method": "adaptive"}])
def test_low_contrast_uneven_light_photo_still_extracts(body, extract):
    mesh, x = body
    ph = render_photo(mesh, x, seed=11, body_color=(192, 186, 178), plate_color=(222, 222, 216),
                      grid_color=(205, 205, 200), lighting=0.35, vignette=0.2, noise_sigma=4.0)
    outline_px = ph.to_pixels(simulated_outline(mesh, x))
    truth = truth_mask(outline_px, ph.image.shape[:2])
    grey = ph.image.astype(float).mean(axis=2)
    # low contrast indeed: the darkest plate pixels are darker than the brightest body pixels,
    # so no single grey level separates body and plate
    assert np.percentile(grey[~truth], 5) < np.percentile(grey[truth], 95)
    r = compare_contours(outline_px, contour_from_image(ph.image, **extract), registration="none")
    assert r.mean_px < 1.5


def test_roi_restricts_the_search():
    img = disc_image([(60, 100), (220, 100)], [30, 40])
    c = contour_from_image(img, roi=(150, 20, 140, 160))
    assert c[:, 0].min() > 150
    assert polygon_area(c) == pytest.approx(math.pi * 40 ** 2, rel=0.03)


# ------------------------------------------------------------------------------------------ bad input
def test_empty_image_is_rejected():
    with pytest.raises(ValueError, match="empty"):
        contour_from_image(np.zeros((0, 0), dtype=np.uint8))


def test_uniform_image_has_no_body():
    with pytest.raises(ValueError, match="uniform"):
        contour_from_image(np.full((50, 50, 3), 128, dtype=np.uint8))


def test_image_with_only_specks_has_no_contour():
    img = np.full((100, 100), 200, dtype=np.uint8)
    img[10::20, 10::20] = 40  # isolated single dark pixels: removed by the morphological cleaning
    with pytest.raises(ValueError, match="no contour"):
        contour_from_image(img)


def test_several_blobs_need_consent():
    img = disc_image([(80, 100), (220, 100)], [35, 30])
    with pytest.raises(ValueError, match="2 separate blobs.*largest=True"):
        contour_from_image(img)
    c = contour_from_image(img, largest=True)
    assert polygon_area(c) == pytest.approx(math.pi * 35 ** 2, rel=0.03)
    assert abs(c[:, 0].mean() - 80) < 1.0


def test_small_specks_beside_the_body_are_ignored():
    img = disc_image([(150, 100), (30, 30)], [50, 4])
    c = contour_from_image(img)
    assert polygon_area(c) == pytest.approx(math.pi * 50 ** 2, rel=0.03)


def test_a_body_touching_the_border_is_not_replaced_by_a_speck():
    img = np.full((200, 300), 210, dtype=np.uint8)
    img[50:150, 0:120] = 60          # the body, cut by the left image border
    img[100:106, 250:256] = 60       # a 6 x 6 speck inside the picture
    with pytest.raises(ValueError, match=r"the body touches the image border.*roi=.*largest=True"):
        contour_from_image(img)
    c = contour_from_image(img, largest=True)
    assert polygon_area(c) == pytest.approx(100 * 120, rel=0.03)
    c = contour_from_image(img, roi=(0, 20, 200, 160))  # a roi does not make the body an inner blob
    assert polygon_area(c) == pytest.approx(100 * 120, rel=0.03)


def test_a_body_cut_by_the_image_border_is_refused_not_measured():
    # the only blob runs out of the picture: its outline would follow the frame's cut
    img = np.full((200, 300), 210, dtype=np.uint8)
    img[60:200, 80:220] = 60                     # cut by the bottom border, nothing else in the picture
    with pytest.raises(ValueError, match=r"the body touches the image border.*no blob lies inside"):
        contour_from_image(img)
    with pytest.raises(ValueError, match=r"the body touches the image border"):
        contour_loops_from_image(img)
    c = contour_from_image(img, largest=True)
    assert polygon_area(c) == pytest.approx(140 * 140, rel=0.03)
    img[195:, :] = 210                           # background below it: the whole body, measured
    assert polygon_area(contour_from_image(img)) == pytest.approx(135 * 140, rel=0.03)


def test_kernel_must_be_an_odd_integer():
    img = disc_image([(150, 100)], [50])
    for bad in (4, 2):
        with pytest.raises(ValueError, match="kernel must be odd"):
            contour_from_image(img, kernel=bad)
    for bad in (3.0, True, "3"):
        with pytest.raises(TypeError, match="kernel must be an integer"):
            body_mask(img, kernel=bad)
    with pytest.raises(ValueError, match="kernel must be an integer >= 1"):
        body_mask(img, kernel=0)
    # odd kernels keep a centred disc centred
    for k in (3, 5, 7):
        c = contour_from_image(img, kernel=k, subpixel=False)
        assert np.abs(c.mean(axis=0) - [150, 100]).max() < 0.1


def test_rgba_with_transparency_says_alpha_is_ignored(tmp_path):
    rgb = np.repeat(disc_image([(150, 100)], [50])[..., None], 3, axis=2)
    alpha = np.full(rgb.shape[:2], 255, np.uint8)
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # fully opaque: nothing to say
        contour_from_image(np.dstack([rgb, alpha]))
    alpha[:, :20] = 0
    with pytest.warns(UserWarning, match="alpha is ignored"):
        c = contour_from_image(np.dstack([rgb, alpha]))
    assert polygon_area(c) == pytest.approx(math.pi * 50 ** 2, rel=0.03)
    path = tmp_path / "rgba.png"
    cv2.imwrite(str(path), np.dstack([rgb, alpha]))
    with pytest.warns(UserWarning, match=r"rgba.png.*alpha is ignored"):
        load_image(path)


@pytest.mark.parametrize("arr, err, match", [
    (np.full((20, 20), -3, dtype=np.int64), ValueError, r"negative values \(range -3 to -3 in dtype int64\)"),
    (np.zeros((20, 20), dtype=complex), TypeError, "dtype complex"),
    (np.array([["a"] * 20] * 20), TypeError, "numeric"),
    (np.full((20, 20), 300.0), ValueError, r"values in \[300, 300\]; float images must lie in \[0, 1\] or \[0, 255\]"),
    (np.full((20, 20), 7, dtype=np.uint16), ValueError, r"image is uniform \(all pixels about 7 of 255"),
    (np.full((20, 20), np.nan), ValueError, "NaN"),
    (np.zeros((20, 20, 2), dtype=np.uint8), ValueError, "shape"),
])
def test_wrong_image_types_are_named(arr, err, match):
    with pytest.raises(err, match=match):
        contour_from_image(arr)


def test_missing_and_undecodable_files(tmp_path):
    with pytest.raises(FileNotFoundError, match="nope.png"):
        contour_from_image(tmp_path / "nope.png")
    bad = tmp_path / "text.png"
    bad.write_text("not an image")
    with pytest.raises(ValueError, match="cannot decode"):
        contour_from_image(bad)


def test_bad_options_are_named():
    img = disc_image([(150, 100)], [50])
    with pytest.raises(ValueError, match="roi"):
        contour_from_image(img, roi=(250, 0, 100, 100))
    with pytest.raises(ValueError, match="method"):
        contour_from_image(img, method="magic")
    with pytest.raises(ValueError, match="RGB"):
        contour_from_image(img, color=(60, 60, 60))  # colour segmentation of a grey image
    rgb = np.repeat(img[..., None], 3, axis=2)
    with pytest.raises(ValueError, match="body colour"):
        contour_from_image(rgb, color=(0, 255, 0))


def test_compare_contours_rejects_bad_outlines():
    sq = np.array([[0, 0], [1, 0], [1, 1], [0, 1]], float)
    with pytest.raises(ValueError, match="at least 3"):
        compare_contours(sq[:2], sq)
    with pytest.raises(ValueError, match="NaN"):
        compare_contours(np.array([[0, 0], [1, np.nan], [1, 1]]), sq)
    with pytest.raises(ValueError, match="no area"):
        compare_contours(sq, np.array([[0, 0], [1, 1], [2, 2]], float))
    with pytest.raises(ValueError, match="registration"):
        compare_contours(sq, sq, registration="icp")
    with pytest.raises(ValueError, match="segments="):
        compare_contours(sq, sq, registration="segment")
    with pytest.raises(ValueError, match="shape"):
        compare_contours(np.zeros((4, 3)), sq)
    with pytest.raises(TypeError, match="flip_y must be True or False"):
        compare_contours(sq, sq, flip_y="no")
    with pytest.raises(TypeError, match="segments node index must be an integer"):
        compare_contours(sq, sq, registration="segment", segments=((0.0, 2.0), ((0, 0), (1, 1))))
    r = compare_contours(sq, sq * [1, -1], registration="segment", segments=((np.int64(0), 2), ((0, 0), (1, -1))))
    assert r.mean_px < 1e-9


def test_non_mesh_arguments_are_named(body, photo):
    mesh, x = body
    for call in (lambda: render_photo(mesh.points, x), lambda: simulated_outline(mesh.points, x),
                 lambda: evaluate_image(photo.image, mesh.points, x)):
        with pytest.raises(TypeError, match="mesh must be a mdsr_opt.Mesh, got ndarray"):
            call()
    with pytest.raises(ValueError, match=r"x must have shape"):
        simulated_outline(mesh, x[:-1])


def test_comparisons_and_photos_compare_by_identity(body, photo, contour):
    mesh, x = body
    a = compare_contours(simulated_outline(mesh, x), contour)
    b = compare_contours(simulated_outline(mesh, x), contour)
    assert a == a and a != b and hash(a) != hash(b)  # no "truth value of an array" error
    assert photo == photo and len({photo, a, b}) == 3


# ------------------------------------------------------------------------------------------ synthetic camera
def test_camera_is_deterministic_and_labelled(body):
    mesh, x = body
    a = render_photo(mesh, x, image_size=(320, 240), seed=5)
    b = render_photo(mesh, x, image_size=(320, 240), seed=5)
    c = render_photo(mesh, x, image_size=(320, 240), seed=6)
    assert a.image.shape == (240, 320, 3) and a.image.dtype == np.uint8
    assert np.array_equal(a.image, b.image)
    assert np.array_equal(a.world_to_pixel, b.world_to_pixel)
    assert np.abs(a.image.astype(int) - c.image.astype(int)).mean() > 1.0
    assert a.metadata["synthetic"] is True and a.synthetic
    # the caption is visible (dark text on the plate) in a corner that does not touch the body
    bx, by, bw, bh = a.metadata["caption_box"]
    box = a.image[by:by + bh + 1, bx:bx + bw + 1].mean(axis=2)
    assert (box < 100).sum() > 30
    inside = body_mask(a.image, color=BODY_RGB)
    assert not inside[max(0, by - 3):by + bh + 4, max(0, bx - 3):bx + bw + 4].any()


def test_camera_pixel_transform_lands_on_the_body(body, photo):
    mesh, x = body
    cent = x[mesh.triangles].mean(axis=1)  # triangle centroids are inside the body
    px = np.round(photo.to_pixels(cent)).astype(int)
    colours = photo.image[px[:, 1], px[:, 0]].astype(float)
    # body pixels are orange: red well above blue, everywhere (lighting only scales them)
    assert np.all(colours[:, 0] - colours[:, 2] > 100)
    outline_px = photo.to_pixels(simulated_outline(mesh, x))
    assert outline_px.min() > 0 and outline_px.max() < 499


def test_camera_rejects_bad_settings(body):
    mesh, x = body
    with pytest.raises(ValueError, match="image_size must lie between 32 and 8000"):
        render_photo(mesh, x, image_size=(10, 10))
    for kw, exc, msg in [({"image_size": (400.5, 300)}, TypeError, "image_size must be an integer"),
                         ({"image_size": (400,)}, ValueError, r"image_size must be \(width, height\)"),
                         ({"image_size": "400x300"}, ValueError, r"image_size must be \(width, height\)"),
                         ({"seed": -1}, ValueError, "seed must be an integer >= 0"),
                         ({"seed": 1.5}, TypeError, "seed must be an integer"),
                         ({"supersample": 2.5}, TypeError, "supersample must be an integer"),
                         ({"supersample": 0}, ValueError, "supersample must be an integer in 1..8"),
                         ({"rotation_deg": "10"}, TypeError, "rotation_deg must be a real number"),
                         ({"rotation_deg": float("inf")}, ValueError, "rotation_deg must be finite")]:
        with pytest.raises(exc, match=msg):
            render_photo(mesh, x, **kw)
    with pytest.raises(ValueError, match="margin"):
        render_photo(mesh, x, margin=0.5)
    with pytest.raises(ValueError, match="tilt_deg"):
        render_photo(mesh, x, tilt_deg=45.0)
    with pytest.raises(ValueError, match="shape"):
        render_photo(mesh, x[:-1])


def test_saved_photo_round_trips_with_sidecar(tmp_path, body):
    mesh, x = body
    ph = render_photo(mesh, x, image_size=(160, 120), seed=2)
    path = ph.save(tmp_path / "case.png")
    assert np.array_equal(load_image(path), ph.image)
    meta = json.loads((tmp_path / "case.json").read_text())
    assert meta["synthetic"] is True and meta["seed"] == 2
    assert np.allclose(meta["world_to_pixel"], ph.world_to_pixel)
    with pytest.raises(ValueError, match="PNG"):
        ph.save(tmp_path / "case.jpg")


def test_failed_save_leaves_neither_image_nor_sidecar(tmp_path, body, monkeypatch):
    mesh, x = body
    ph = render_photo(mesh, x, image_size=(160, 120), seed=2)
    (tmp_path / "case.json").mkdir()  # the sidecar cannot be written
    with pytest.raises(ValueError, match="case.json: it is a folder"):
        ph.save(tmp_path / "case.png")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["case.json"]

    def broken(tmp):  # the second file's writer fails after the first was written
        raise OSError("disk full")

    real = ph.writers

    def writers(path):
        w = real(path)
        return [w[0], (w[1][0], broken)]

    monkeypatch.setattr(SyntheticPhoto, "writers", lambda self, path: writers(path))
    with pytest.raises(OSError, match="disk full"):
        ph.save(tmp_path / "other.png")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["case.json"]  # no PNG, no temporary file


def test_overlay_figure_shows_photo_mesh_and_contour(body, photo):
    from mdsr_opt.plot.photos import plot_overlay

    mesh, x = body
    r = evaluate_image(photo.image, mesh, x)
    fig = plot_overlay(photo.image, mesh, x, r, synthetic=True, title="T")
    ax = fig.axes[0]
    assert ax.images[0].get_array().shape == (500, 500, 3)
    assert "SYNTHETIC" in ax.get_title() and f"{r.mean_px:.2f} px" in ax.get_title()
    assert len(ax.collections[0].get_paths()) == mesh.n_triangles
    import matplotlib.pyplot as plt

    plt.close(fig)


# ------------------------------------------------------------------------------------------ batch
@pytest.fixture
def design(tmp_path, body):
    """A design folder: two states and their synthetic photographs, written by the `photograph` command."""
    mesh, _ = body
    states = tmp_path / "states"
    for k in (0.5, 0.8):
        write_mesh(states / f"bend_{k}.vtu", mesh, x=bend(mesh.points, k))
    assert cli_main(["photograph", str(states), "--out", str(tmp_path / "images"), "--seed", "3",
                     "--photo-size", "400x400"]) == 0
    return tmp_path


def test_batch_command_writes_csv_and_markdown(design, capsys):
    out = design / "out"
    assert cli_main(["evaluate", str(design / "images"), str(design / "states"), "--out", str(out),
                     "--figures"]) == 0
    rows = list(csv.DictReader((out / "evaluation.csv").open()))
    assert [r["case"] for r in rows] == ["bend_0.5", "bend_0.8"]
    for r in rows:
        assert r["source"] == "synthetic"
        assert float(r["mean_px"]) < 1.0 and float(r["std_px"]) < 1.0
    md = (out / "evaluation.md").read_text()
    assert md.count("| bend_0.") == 2 and "**SYNTHETIC**" in md
    assert "Average distance" in capsys.readouterr().out
    assert (out / "bend_0.8_overlay.png").stat().st_size > 1000
    assert [p.name for p in out.iterdir() if p.name.startswith(".")] == [".mdsr-run.json"]  # no temporaries


def test_batch_swapped_states_score_worse(design):
    matched = evaluate_folder(design / "images", design / "states")
    (design / "images" / "bend_0.5.png").rename(design / "images" / "tmp.png")
    (design / "images" / "bend_0.8.png").rename(design / "images" / "bend_0.5.png")
    (design / "images" / "tmp.png").rename(design / "images" / "bend_0.8.png")
    swapped = evaluate_folder(design / "images", design / "states")
    worst_match = max(r.comparison.mean_px for r in matched)
    assert all(r.comparison.mean_px > 4 * worst_match for r in swapped)


def test_batch_error_leaves_previous_table_untouched(design, capsys):
    out = design / "out"
    out.mkdir()
    (out / "evaluation.csv").write_text("old table\n")
    (design / "images" / "zz_broken.png").write_text("not a png")
    mesh = Mesh.from_polygon(OUTLINE, max_area=0.05)
    write_mesh(design / "states" / "zz_broken.vtu", mesh)
    with pytest.raises(ValueError, match="case 'zz_broken'.*cannot decode"):
        evaluate_folder(design / "images", design / "states", out=out)
    assert (out / "evaluation.csv").read_text() == "old table\n"
    assert sorted(p.name for p in out.iterdir()) == ["evaluation.csv"]
    # the command: a new folder is left as it was (not made), a used one is refused before any work
    assert cli_main(["evaluate", str(design / "images"), str(design / "states"), "--out", str(design / "new")]) == 2
    assert "cannot decode" in capsys.readouterr().err
    assert not (design / "new").exists()
    assert cli_main(["evaluate", str(design / "images"), str(design / "states"), "--out", str(out)]) == 2
    assert "already holds 1 entry ('evaluation.csv')" in capsys.readouterr().err
    assert sorted(p.name for p in out.iterdir()) == ["evaluation.csv"]


def test_photograph_and_evaluate_keep_their_folders_apart_and_replace_only_with_overwrite(design, capsys):
    """A second command into a used --out is refused (one folder never mixes two commands' files); with
    --overwrite only the earlier command's files go; an --out that is or holds a folder the command reads is
    refused even with --overwrite (replacing would delete what it reads)."""
    images, states, out = design / "images", design / "states", design / "ev"
    assert cli_main(["evaluate", str(images), str(states), "--out", str(out), "--figures"]) == 0
    assert (out / "bend_0.5_overlay.png").is_file()
    (out / "notes.txt").write_text("mine")
    assert cli_main(["evaluate", str(images), str(states), "--out", str(out)]) == 2
    assert "pass --overwrite" in capsys.readouterr().err
    assert cli_main(["evaluate", str(images), str(states), "--out", str(out), "--overwrite"]) == 0
    assert sorted(p.name for p in out.iterdir() if not p.name.startswith(".")) == ["evaluation.csv", "evaluation.md",
                                                                                 "notes.txt"]
    capsys.readouterr()
    before = sorted(p.name for p in images.iterdir())
    assert cli_main(["photograph", str(states), "--out", str(images)]) == 2
    assert "pass --overwrite" in capsys.readouterr().err
    for cmd in (["evaluate", str(images), str(states), "--out", str(images)],
                ["evaluate", str(images), str(states), "--out", str(design)],
                ["photograph", str(states), "--out", str(states)]):
        assert cli_main(cmd + ["--overwrite"]) == 2
        assert "that this command reads: give an output folder of its own" in capsys.readouterr().err
    assert sorted(p.name for p in images.iterdir()) == before
    assert cli_main(["photograph", str(states), "--out", str(images), "--overwrite"]) == 0
    assert sorted(p.name for p in images.iterdir()) == before


def test_batch_ignores_non_state_files_beside_the_states(design):
    (design / "states" / "bend_0.8.svg").write_text("<svg/>")  # a figure of the state, say
    rows = evaluate_folder(design / "images", design / "states")
    assert [r.case for r in rows] == ["bend_0.5", "bend_0.8"]
    assert all(r.state.endswith(".vtu") for r in rows)


@pytest.mark.parametrize("error", [cv2.error("synthetic OpenCV failure"),
                                   UnicodeDecodeError("utf-8", b"\xff", 0, 1, "invalid start byte"),
                                   TypeError("bad type")])
def test_batch_case_errors_become_value_errors_naming_the_case(design, monkeypatch, error):
    def fail(*args, **kwargs):
        raise error

    monkeypatch.setattr("mdsr_opt.photos.folder.contour_loops_from_image", fail)  # the outline and holes
    with pytest.raises(ValueError, match="case 'bend_0.5'") as info:
        evaluate_folder(design / "images", design / "states")
    assert info.value.__cause__ is error


def test_batch_writes_figures_and_tables_together(design, monkeypatch):
    out = design / "out"
    out.mkdir()
    (out / "evaluation.csv").write_text("old table\n")
    from mdsr_opt.plot import common

    calls = []
    real = common.save_figure

    def failing_second(fig, path):
        calls.append(path)
        if len(calls) == 2:
            import matplotlib.pyplot as plt

            plt.close(fig)
            raise RuntimeError("figure failed")
        return real(fig, path)

    monkeypatch.setattr(common, "save_figure", failing_second)
    with pytest.raises(RuntimeError, match="figure failed"):
        evaluate_folder(design / "images", design / "states", out=out, figures=True)
    assert sorted(p.name for p in out.iterdir()) == ["evaluation.csv"]  # no table, no first figure
    assert (out / "evaluation.csv").read_text() == "old table\n"
    monkeypatch.setattr(common, "save_figure", real)
    evaluate_folder(design / "images", design / "states", out=out, figures=True)
    assert sorted(p.name for p in out.iterdir()) == ["bend_0.5_overlay.png", "bend_0.8_overlay.png",
                                                     "evaluation.csv", "evaluation.md"]


def test_photograph_command_writes_all_or_nothing(tmp_path, body, capsys):
    mesh, _ = body
    states = tmp_path / "states"
    for k in (0.5, 0.8):
        write_mesh(states / f"bend_{k}.vtu", mesh, x=bend(mesh.points, k))
    (tmp_path / "images" / "bend_0.8.png").mkdir(parents=True)  # the second photo cannot be written
    assert cli_main(["photograph", str(states), "--out", str(tmp_path / "images")]) == 2
    assert "already holds 1 entry ('bend_0.8.png')" in capsys.readouterr().err  # refused before rendering
    assert sorted(p.name for p in (tmp_path / "images").iterdir()) == ["bend_0.8.png"]


def test_batch_needs_a_state_for_every_image(design):
    (design / "states" / "bend_0.8.vtu").unlink()
    with pytest.raises(ValueError, match="no state file for image.*bend_0.8.png"):
        evaluate_folder(design / "images", design / "states")
    with pytest.raises(FileNotFoundError, match="does not exist"):
        evaluate_folder(design / "nothing", design / "states")


# ------------------------------------------------------------------- dtypes by real range, bounded work
def test_images_of_every_dtype_are_judged_by_their_real_range():
    img8 = disc_image([(150, 100)], [50])
    want = contour_from_image(img8)
    # uint16 / int64 holding 8-bit data: the same image (was "image is uniform" after dividing by 257)
    for arr in (img8.astype(np.uint16), img8.astype(np.int64), img8.astype(float)):
        assert np.array_equal(load_image(arr), img8)
        assert np.allclose(contour_from_image(arr), want)
    # 12-bit data in uint16 is scaled by 255 / 4095, not 255 / 65535
    img12 = (img8.astype(np.int64) * 4095 // 255).astype(np.uint16)
    assert np.abs(load_image(img12).astype(int) - img8).max() <= 1
    # floats in [0, 1], and a binary mask
    assert np.abs(load_image(img8 / 255.0).astype(int) - img8).max() == 0
    mask = img8 < 128
    assert set(np.unique(load_image(mask)).tolist()) == {0, 255}
    assert polygon_area(contour_from_image(mask)) == pytest.approx(math.pi * 50 ** 2, rel=0.03)


def test_low_contrast_deep_image_is_stretched_with_a_warning():
    img = np.where(disc_image([(150, 100)], [50]) < 128, 1000, 1100).astype(np.uint16)  # 12-bit range, 100 levels
    with pytest.warns(UserWarning, match=r"\(1000 to 1100, 12-bit uint16\) would span only 6\.2 of 255 grey levels; stretched to 0-255"):
        c = contour_from_image(img)
    assert polygon_area(c) == pytest.approx(math.pi * 50 ** 2, rel=0.03)


class _NoImageWork:
    """Stands in for cv2 where a guard must refuse before any image processing: any use fails the test."""

    def __getattr__(self, name):
        raise AssertionError(f"cv2.{name} was used before the input was refused")


def test_image_size_is_limited_before_any_work(monkeypatch):
    import mdsr_opt.photos.contours as contours_mod
    import mdsr_opt.photos.images as images_mod

    big = np.zeros((8000, 8000), np.uint8)
    big[3000:5000, 2000:6000] = 200
    with monkeypatch.context() as mp:  # refused before OpenCV touches a pixel
        mp.setattr(contours_mod, "cv2", _NoImageWork())
        mp.setattr(images_mod, "cv2", _NoImageWork())
        with pytest.raises(ValueError, match=r"8000 x 8000 = 64\.0 megapixels, more than the limit "
                                             r"max_pixels=25000000.*roi=.*downscale.*max_pixels="):
            contour_from_image(big)
        with pytest.raises(ValueError, match="more than the limit max_pixels=25000000"):
            body_mask(big.astype(np.uint16))  # refused before the pixels are converted
    # a roi around the body is within the limit
    c = contour_from_image(big, roi=(1800, 2800, 4400, 2400), subpixel=False)
    assert c.min(axis=0).tolist() == [2000, 3000] and c.max(axis=0).tolist() == [5999, 4999]
    small = disc_image([(150, 100)], [50])
    with pytest.raises(ValueError, match="300 x 200 = 0.1 megapixels, more than the limit max_pixels=50000"):
        contour_from_image(small, max_pixels=50_000)
    assert len(contour_from_image(small, max_pixels=60_000)) > 100
    with pytest.raises(ValueError, match="max_pixels must be an integer >= 1"):
        contour_from_image(small, max_pixels=0)


def test_huge_kernel_is_refused_before_any_work(monkeypatch):
    import mdsr_opt.photos.contours as contours_mod
    import mdsr_opt.photos.images as images_mod

    img = np.full((2000, 2000), 210, np.uint8)
    img[500:1500, 600:1400] = 60
    with monkeypatch.context() as mp:
        mp.setattr(contours_mod, "cv2", _NoImageWork())
        mp.setattr(images_mod, "cv2", _NoImageWork())
        with pytest.raises(ValueError, match=r"kernel=1999 is too large for a 2000 x 2000 search region: at "
                                             r"most 101 px \(max_kernel=101 px"):
            contour_from_image(img, kernel=1999)
        with pytest.raises(ValueError, match=r"max_kernel must be an integer >= 1"):
            contour_from_image(img, kernel=5, max_kernel=0)
    # the limit can be raised knowingly (up to a twentieth of the region's side, 99 px here would pass anyway)
    with pytest.raises(ValueError, match=r"at most 21 px \(max_kernel=21 px"):
        contour_from_image(img, kernel=51, max_kernel=21)
    big_k = contour_from_image(img, kernel=51, max_kernel=51, subpixel=False)
    assert big_k.min(axis=0).tolist() == [600, 500] and big_k.max(axis=0).tolist() == [1399, 1499]
    small = disc_image([(150, 100)], [50])  # 300 x 200: at most 200 // 20 = 10 -> 11 px
    with pytest.raises(ValueError, match="kernel=13 is too large for a 300 x 200 search region: at most 11 px"):
        body_mask(small, kernel=13)
    assert body_mask(small, kernel=11)[100, 150]


def test_polyline_distance_tree_matches_all_segments():
    """The KD-tree distance used in the rotation search equals the all-segments one (exact, not sampled)."""
    from mdsr_opt.photos.compare import _PolylineDistance, unsigned_distances

    rng = np.random.default_rng(3)
    for trial in range(40):
        n = int(rng.integers(3, 300))
        th = np.sort(rng.uniform(0, 2 * np.pi, n))
        r = 50 + 15 * rng.standard_normal(n) * (trial % 2)  # odd trials: very uneven segments
        M = np.column_stack([r * np.cos(th), r * np.sin(th)])
        P = rng.uniform(-200, 200, (int(rng.integers(1, 200)), 2))
        assert np.abs(_PolylineDistance(M)(P) - unsigned_distances(P, M)).max() < 1e-9
    square = np.array([[0.0, 0.0], [10.0, 0.0], [10.0, 10.0], [0.0, 10.0]])
    got = _PolylineDistance(square)(np.array([[5.0, 5.0], [13.0, 14.0], [-2.0, 5.0]]))
    assert got == pytest.approx([5.0, 5.0, 2.0], abs=1e-12)


def test_write_together_writes_all_files_or_none(tmp_path):
    """A target that is a folder is refused before anything is written; a writer that fails leaves every
    earlier file as it was and no temporary file behind."""
    from mdsr_opt.photos.folder import bytes_writer, write_together

    (tmp_path / "a.txt").write_text("old a")
    (tmp_path / "c.txt").mkdir()
    with pytest.raises(ValueError, match="c.txt: it is a folder"):
        write_together([(tmp_path / "a.txt", bytes_writer(b"new a")), (tmp_path / "c.txt", bytes_writer(b"c"))])

    def broken(tmp):
        raise OSError("disk full")

    with pytest.raises(OSError, match="disk full"):
        write_together([(tmp_path / "a.txt", bytes_writer(b"new a")), (tmp_path / "b.txt", broken)])
    assert (tmp_path / "a.txt").read_text() == "old a"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.txt", "c.txt"]
    assert write_together([(tmp_path / "a.txt", bytes_writer(b"new a")),
                           (tmp_path / "b.txt", bytes_writer(b"b"))]) == [tmp_path / "a.txt", tmp_path / "b.txt"]
    assert (tmp_path / "a.txt").read_text() == "new a" and (tmp_path / "b.txt").read_text() == "b"
