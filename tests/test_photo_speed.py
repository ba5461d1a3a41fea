"""The fast paths of the photo stage (issue 13) give what the straightforward computations give: the same
pixels for photographs, the same contour points, the same distances.

Each fast path is compared with an independent or the earlier computation: the colour-canvas composition
(still the path for other colours and supersampling factors), the quadratic basis of the light field, a
fresh random generator for the sensor noise, the per-pixel raster test, the (H, W, 1) @ (1,) projection,
the one-expression illumination field and the KD-tree distances.
"""

from __future__ import annotations

import math

import cv2
import numpy as np
import pytest

from mdsr_opt import Mesh
from mdsr_opt.photos import camera
from mdsr_opt.photos import contours as ct
from mdsr_opt.photos.compare import _PolylineDistance, unsigned_distances
from mdsr_opt.photos.contours import quadratic_basis
from mdsr_opt.scenes.library import get_problem


def _random_scene(rng, ss, W=60, H=45):
    """Triangles, grid lines and colours for the composition functions, on a canvas ss times finer."""
    pts = rng.uniform(-5.0, [W * ss + 5.0, H * ss + 5.0], (30, 2))
    tris = rng.integers(0, len(pts), (40, 3))
    lines = [((int(rng.integers(-50, W * ss * 16)), int(rng.integers(-50, H * ss * 16))),
              (int(rng.integers(0, W * ss * 16)), int(rng.integers(0, H * ss * 16)))) for _ in range(6)]
    colors = tuple(np.asarray(c, dtype=float) for c in rng.integers(0, 256, (3, 3)))
    return lines, pts, tris, colors


@pytest.mark.parametrize("ss", [1, 2, 4, 8])
@pytest.mark.parametrize("seed", range(3))
def test_count_composition_is_the_colour_canvas(ss, seed):
    rng = np.random.default_rng(seed)
    lines, pts, tris, colors = _random_scene(rng, ss)
    thick = 1 + seed
    got, got_cov = camera._compose_counts(lines, thick, 4, pts, tris, colors, (60, 45), ss)
    ref, ref_cov = camera._compose_canvas(lines, thick, 4, pts, tris, colors, (60, 45), ss)
    assert got.dtype == ref.dtype == np.float32 and got.shape == (45, 60, 3)
    np.testing.assert_array_equal(got, ref)
    np.testing.assert_array_equal(got_cov, ref_cov)
    assert 0 < got_cov.sum() < got_cov.size  # the body covers some pixels and not all


def test_raster_value_is_the_mask_scaled():
    rng = np.random.default_rng(7)
    pts, tris = rng.uniform(-3.0, 40.0, (20, 2)), rng.integers(0, 20, (30, 3))
    full = camera._raster_triangles(pts, tris, (37, 41))
    np.testing.assert_array_equal(camera._raster_triangles(pts, tris, (37, 41), value=16), (full // 255) * 16)
    assert full.any()


def _old_sensor(canvas_img, seed, lighting=0.2, vignette=0.1, blur=0.8, noise=3.0):
    """The light, optics and sensor of the earlier render_photo: the light field from the quadratic basis,
    the noise from a fresh generator at the same state (tilt axis, grid phase, light direction drawn)."""
    H, W = canvas_img.shape[:2]
    rng = np.random.default_rng(seed)
    rng.uniform(0.0, 2 * math.pi)
    rng.uniform(0.0, 1.0, size=2)
    psi = rng.uniform(0.0, 2 * math.pi)
    basis = quadratic_basis(H, W)
    u, v = basis[..., 1], basis[..., 2]
    light = 1.0 + lighting * (u * math.cos(psi) + v * math.sin(psi)) / 2.0 - vignette * (u * u + v * v) / 2.0
    img = canvas_img * light[..., None].astype(np.float32)
    img = cv2.GaussianBlur(img, (0, 0), blur)
    img = img + rng.normal(0.0, noise, img.shape).astype(np.float32)
    return np.clip(np.round(img), 0, 255).astype(np.uint8)


def test_photographs_are_the_earlier_renderers_pixels(monkeypatch):
    """Whole photographs (several states, one seed: the second and third take their noise from the cache)
    against the colour canvas and the earlier sensor, everywhere but the caption."""
    scene = get_problem("face", resolution="coarse")  # a body with holes
    mesh = scene.mesh
    canvases = []

    def recording(*args):
        out = camera._compose_canvas(*args)
        canvases.append(out[0].copy())
        return out

    rng = np.random.default_rng(0)
    states = [mesh.points, mesh.points + rng.normal(0.0, 0.05, mesh.points.shape),
              mesh.points @ np.array([[1.1, 0.2], [0.0, 0.9]])]
    camera._NOISE.clear()
    fast = [camera.render_photo(mesh, x, image_size=(300, 220), seed=5, rotation_deg=20.0, tilt_deg=3.0)
            for x in states]
    monkeypatch.setattr(camera, "_compose_counts", recording)
    slow = [camera.render_photo(mesh, x, image_size=(300, 220), seed=5, rotation_deg=20.0, tilt_deg=3.0)
            for x in states]
    for f, s, canvas in zip(fast, slow, canvases):
        np.testing.assert_array_equal(f.image, s.image)        # the count composition, in a whole photograph
        ref = _old_sensor(canvas, seed=5)
        x, y, w, h = f.metadata["caption_box"]
        outside = np.ones(ref.shape[:2], dtype=bool)
        outside[y:y + h + 1, x:x + w + 1] = False
        np.testing.assert_array_equal(f.image[outside], ref[outside])
        assert (f.image[~outside] != ref[~outside]).any()     # the caption is there, and only there
    assert not np.array_equal(fast[0].image, fast[1].image)


def test_noise_cache_holds_a_few_seeds_and_is_read_only():
    camera._NOISE.clear()
    mesh = Mesh.rectangle(2.0, 1.0, 4, 2)
    for seed in range(6):
        camera.render_photo(mesh, image_size=(200, 120), seed=seed, margin=0.25)
    assert len(camera._NOISE) == 4 and (5, 3.0, (120, 200, 3)) in camera._NOISE
    assert all(not a.flags.writeable for a in camera._NOISE.values())


def test_grey_projection_is_the_matrix_product():
    """_refine_subpixel on a grey score (one product per pixel) and on the same score as (H, W, 1) (the
    earlier (H, W, 1) @ (1,) product): the same contour points."""
    scene = get_problem("face", resolution="coarse")
    img = camera.render_photo(scene.mesh, image_size=(300, 300), seed=2).image
    outline, m8, score, outer, _ = ct._extract_outline(
        img, roi=None, color=None, method="auto", body="auto", color_tol=None, kernel=None, flatten=True,
        largest=False, min_blob_fraction=0.05, subpixel=False, max_pixels=ct.MAX_PIXELS)
    assert score.ndim == 2
    blob = np.zeros_like(m8)
    cv2.drawContours(blob, [outer.reshape(-1, 1, 2)], 0, 1, thickness=cv2.FILLED)
    got = ct._refine_subpixel(outline, blob > 0, score, reach=2.0)
    ref = ct._refine_subpixel(outline, blob > 0, score[..., None], reach=2.0)
    np.testing.assert_array_equal(got, ref)
    assert np.abs(got - outline).max() > 0.05  # the refinement moved the points


@pytest.mark.parametrize("shape", [(500, 500), (37, 91)])
def test_illumination_field_is_the_one_expression(shape):
    H, W = shape
    c = np.random.default_rng(1).normal(0.0, 50.0, 6) + [200, 0, 0, 0, 0, 0]
    u = ((np.arange(W) + 0.5) / W * 2.0 - 1.0)[None, :]
    v = ((np.arange(H) + 0.5) / H * 2.0 - 1.0)[:, None]
    ref = np.maximum(c[0] + c[1] * u + c[2] * v + c[3] * u * u + c[4] * u * v + c[5] * v * v, 1.0)
    np.testing.assert_array_equal(ct._quadratic_field(c, H, W), ref)


def test_converging_search_measures_what_the_tree_measures():
    """A rotation search closing in (points moving less and less): the kept-segment path takes over and gives
    the KD-tree's distances exactly, and the all-segments distances to 1e-9."""
    t = np.linspace(0.0, 2 * np.pi, 900, endpoint=False)
    poly = np.column_stack([250 + 150 * np.cos(t) * (1 + 0.2 * np.cos(4 * t)), 250 + 90 * np.sin(t)])
    rng = np.random.default_rng(4)
    pts = poly[::5] + rng.normal(0.0, 1.5, (180, 2))
    centre = pts.mean(axis=0)
    dist = _PolylineDistance(poly)
    used = 0
    for k in range(25):
        a = 0.3 * 0.618 ** k * (-1) ** k
        R = np.array([[math.cos(a), -math.sin(a)], [math.sin(a), math.cos(a)]])
        p = (pts - centre) @ R.T + centre
        kept = dist._keep is not None and dist._moved(p, dist._ref) <= dist.slack
        got = dist(p)
        used += kept
        np.testing.assert_array_equal(got, dist._kd(p))
        np.testing.assert_allclose(got, unsigned_distances(p, poly), rtol=0, atol=1e-9)
    assert used >= 10  # the kept segments did the late calls


def test_lower_bounds_together_are_the_bounds_one_by_one():
    t = np.linspace(0.0, 2 * np.pi, 300, endpoint=False)
    poly = np.column_stack([100 * np.cos(t), 60 * np.sin(t)])
    dist = _PolylineDistance(poly)
    sets = [np.random.default_rng(k).uniform(-200, 200, (50 + k, 2)) for k in range(5)]
    assert dist.lower_many(sets) == [dist.lower(p) for p in sets]
    assert all(b <= float(unsigned_distances(p, poly).mean()) for b, p in zip(dist.lower_many(sets), sets))


def _old_refine(contour, blob, score, reach):
    """The earlier _refine_subpixel: distance transforms, bands and projection over the whole image."""
    from mdsr_opt.body.polygons import polygon_area

    b8 = blob.astype(np.uint8)
    d_in = cv2.distanceTransform(b8, cv2.DIST_L2, 3)
    d_out = cv2.distanceTransform(1 - b8, cv2.DIST_L2, 3)
    lo_band, hi_band = 2.5 * reach / 2.0, 6.0 * reach / 2.0
    inner = (d_in > lo_band) & (d_in <= hi_band)
    outer = (d_out > lo_band) & (d_out <= hi_band)
    sc = score if score.ndim == 3 else score[..., None]
    c_in, c_out = np.median(sc[inner], axis=0), np.median(sc[outer], axis=0)
    axis = c_in - c_out
    nrm2 = float(axis @ axis)
    proj = (((sc - c_out) @ axis) / nrm2).astype(np.float32) - 0.5
    p = contour
    tang = np.roll(p, -2, axis=0) - np.roll(p, 2, axis=0)
    tl = np.linalg.norm(tang, axis=1)
    ok = tl > 1e-9
    normal = np.zeros_like(p)
    normal[ok] = np.column_stack([tang[ok, 1], -tang[ok, 0]]) / tl[ok, None]
    if polygon_area(p) < 0:
        normal = -normal
    steps = np.linspace(-reach, reach, int(round(20 * reach)) + 1)
    sx = (p[:, 0:1] + steps[None, :] * normal[:, 0:1]).astype(np.float32)
    sy = (p[:, 1:2] + steps[None, :] * normal[:, 1:2]).astype(np.float32)
    prof = cv2.remap(proj, sx, sy, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
    out = p.copy()
    inside = prof > 0
    change = inside[:, :-1] & ~inside[:, 1:]
    centre = len(steps) // 2
    rows = np.flatnonzero(ok & change.any(axis=1))
    off = np.where(change[rows], np.abs(np.arange(change.shape[1]) + 0.5 - centre), np.inf)
    j = np.argmin(off, axis=1)
    a, b = prof[rows, j], prof[rows, j + 1]
    same = a == b
    frac = np.where(same, np.float32(0.5), a / np.where(same, np.float32(1.0), a - b))
    out[rows] = p[rows] + (steps[j] + frac * (steps[j + 1] - steps[j]))[:, None] * normal[rows]
    return out


@pytest.mark.parametrize("color", [None, (205, 95, 35)])
def test_refinement_in_the_blobs_box_is_the_whole_images(color):
    """The outline and the holes (eyes, mouth) of the face, grey and colour scores, a body near the border:
    the same points as the whole-image refinement."""
    scene = get_problem("face", resolution="coarse")
    for size, margin in (((400, 360), 0.12), ((300, 300), 0.02)):
        img = camera.render_photo(scene.mesh, image_size=size, seed=3, margin=margin).image
        _, m8, score, outer, _ = ct._extract_outline(
            img, roi=None, color=color, method="auto", body="auto", color_tol=None, kernel=None, flatten=True,
            largest=True, min_blob_fraction=0.05, subpixel=False, max_pixels=ct.MAX_PIXELS)
        blob = np.zeros_like(m8)
        cv2.drawContours(blob, [outer.reshape(-1, 1, 2)], 0, 1, thickness=cv2.FILLED)
        enclosed = ((blob > 0) & (m8 == 0)).astype(np.uint8)
        holes, _ = cv2.findContours(enclosed * 255, cv2.RETR_CCOMP, cv2.CHAIN_APPROX_NONE)
        loops = [outer] + [h.reshape(-1, 2) for h in holes if len(h) > 20]
        assert len(loops) >= 3
        for loop in loops:
            filled = np.zeros_like(m8)
            cv2.drawContours(filled, [loop.reshape(-1, 1, 2)], 0, 1, thickness=cv2.FILLED)
            c = loop.astype(float)
            got = ct._refine_subpixel(c, filled > 0, score, reach=2.0)
            np.testing.assert_array_equal(got, _old_refine(c, filled > 0, score, reach=2.0))
            assert np.abs(got - c).max() > 0.05
