"""Contour extraction from photographs: segmentation, morphological cleaning, sub-pixel outlines and holes."""

from __future__ import annotations

import functools
import math
import os
from typing import Any, Sequence
import cv2
import numpy as np
from numpy.typing import ArrayLike

from ..body.polygons import polygon_area
from ..core.checks import check_int, positive_float
from .images import MAX_PIXELS, check_bool, check_color, load_region

__all__ = ['body_mask', 'contour_from_image', 'contour_loops_from_image']


#: Largest morphology kernel (pixels): the opening and closing cost grows with the kernel's size
#: (a 401 px kernel on a 2000 x 2000 image takes over a minute) and a kernel wider than the body's
#: narrow parts erases them.
MAX_KERNEL = 101


def _otsu(values: np.ndarray, bins: int = 256) -> float:
    """Otsu's threshold of a float sample (between-class variance maximised over a histogram)."""
    v = np.asarray(values, dtype=float).ravel()
    work = v.copy()  # partitioned by the percentiles, then holds the clipped values (one copy, not two)
    lo, hi = (float(t) for t in np.percentile(work, [0.05, 99.95], overwrite_input=True))
    if not hi - lo > 1e-6 * max(abs(hi), abs(lo), 1e-12):
        return hi
    hist, edges = np.histogram(np.clip(v, lo, hi, out=work), bins=bins, range=(lo, hi))
    p = hist / hist.sum()
    centres = 0.5 * (edges[:-1] + edges[1:])
    w0 = np.cumsum(p)
    m0 = np.cumsum(p * centres)
    mt = m0[-1]
    denom = w0 * (1.0 - w0)
    with np.errstate(divide="ignore", invalid="ignore"):
        between = np.where(denom > 1e-12, (mt * w0 - m0) ** 2 / denom, -1.0)
    k = int(np.argmax(between[:-1]))
    return float(edges[k + 1])


def _frame(shape: tuple[int, int], frac: float = 0.03) -> np.ndarray:
    """A frame along the image border, ``frac`` of the smaller side wide (at least 2 pixels)."""
    fw = max(2, round(frac * min(shape)))
    b = np.ones(shape, dtype=bool)
    b[fw:-fw, fw:-fw] = False
    return b


@functools.lru_cache(maxsize=4)
def quadratic_basis(h: int, w: int) -> np.ndarray:
    """The six quadratic monomials (1, u, v, u^2, uv, v^2) of pixel centres in [-1, 1]^2, (h, w, 6);
    read-only and cached (the camera and the contour extraction ask for the same sizes again and again)."""
    out = _quadratic_basis(h, w)
    out.setflags(write=False)
    return out


def _quadratic_basis(h: int, w: int) -> np.ndarray:
    yy, xx = np.mgrid[0:h, 0:w]
    u = (xx + 0.5) / w * 2.0 - 1.0
    v = (yy + 0.5) / h * 2.0 - 1.0
    return np.stack([np.ones_like(u), u, v, u * u, u * v, v * v], axis=-1)


def _fit(A: np.ndarray, z: np.ndarray) -> np.ndarray:
    """Least-squares coefficients of ``A c ~ z`` for a few well-conditioned columns (the quadratic basis):
    the normal equations summed without BLAS and a 6 x 6 solve (``np.linalg.lstsq`` goes through BLAS,
    whose threads wait for each other on busy cores)."""
    return np.linalg.solve(np.einsum("ij,ik->jk", A, A), np.einsum("ij,i->j", A, z))


def _illumination(gray: np.ndarray) -> np.ndarray:
    """A smooth (quadratic) fit to the background brightness of a grey image, found iteratively."""
    H, W = gray.shape
    f = min(1.0, 96.0 / max(H, W))
    sw, sh = max(8, round(W * f)), max(8, round(H * f))
    small = cv2.resize(np.asarray(gray, dtype=np.float32), (sw, sh), interpolation=cv2.INTER_AREA).astype(float)
    A = quadratic_basis(sh, sw).reshape(-1, 6)
    z = small.ravel()
    # start from a frame along the image border (the plate, as a rule); then refit to the pixels
    # classified as background
    frame = _frame((sh, sw), 0.15).ravel()
    use = frame.copy()
    coef = _fit(A[use], z[use])
    for _ in range(4):
        fit = np.maximum(A @ coef, 1.0)
        r = z / fit
        light = r > _otsu(r)
        bg = light if light[frame].mean() >= 0.5 else ~light
        if bg.sum() < 0.1 * z.size:
            break
        use = bg
        coef = _fit(A[use], z[use])
    return _quadratic_field(coef, H, W)


def _quadratic_field(c: np.ndarray, H: int, W: int) -> np.ndarray:
    """``max(c0 + c1 u + c2 v + c3 u u + c4 u v + c5 v v, 1)`` over the (H, W) pixel centres (the quadratic
    basis's u and v), added up in that order, by broadcasting a row and a column: every term of u or v alone
    is worked out once per column or row, into one (H, W) array written in place (a fresh (H, W)
    temporary costs a page fault per 4 kB)."""
    u = ((np.arange(W) + 0.5) / W * 2.0 - 1.0)[None, :]
    v = ((np.arange(H) + 0.5) / H * 2.0 - 1.0)[:, None]
    out = (c[0] + c[1] * u) + c[2] * v
    out += c[3] * u * u
    c4u = c[4] * u
    for i in range(0, H, 16):  # the u v term by blocks of rows: no (H, W) temporary
        out[i:i + 16] += np.multiply(c4u, v[i:i + 16])
    out += c[5] * v * v
    return np.maximum(out, 1.0, out=out)


def _default_kernel(h: int, w: int) -> int:
    return max(3, 2 * round(min(h, w) / 400.0) + 1)


def body_mask(image: ArrayLike | str | os.PathLike, *, roi: Sequence[int] | None = None,
              color: Any = None, method: str = "auto", body: str = "auto", color_tol: float | None = None,
              kernel: int | None = None, flatten: bool = True, max_pixels: int = MAX_PIXELS,
              max_kernel: int = MAX_KERNEL) -> np.ndarray:
    """Segment the body: a boolean mask of the image's shape (False outside ``roi``).

    Parameters
    ----------
    image : array_like or path
        See :func:`load_image`.
    roi : (x, y, width, height), optional
        Only this rectangle (pixels) is searched.
    color : (r, g, b) or '#rrggbb', optional
        The body's colour. With ``method="auto"`` a colour switches to colour segmentation: the distance
        to ``color`` in CIELAB (lightness down-weighted, so shading matters little) thresholded by Otsu,
        or at ``color_tol`` when given.
    method : {"auto", "otsu", "adaptive", "color"}
        ``"otsu"``: Otsu's threshold on the grey image divided by a smooth (quadratic) fit of the
        background (``flatten``), which removes lighting gradients. ``"adaptive"``: a threshold that
        varies over the image: starting from the Otsu mask, the local background level is a normalised
        Gaussian average of the background pixels (interpolated under the body) and the body is where
        the image departs from it by more than half the body-background contrast; for uneven light
        (spots, shading) that a quadratic does not follow. ``"auto"``: ``"color"`` if a colour is given,
        else ``"otsu"``.
    body : {"auto", "dark", "light"}
        For grey methods, whether the body is darker or lighter than the plate; ``"auto"`` takes the
        class that touches the image (or roi) border least.
    color_tol : float, optional
        Fixed CIELAB distance for colour segmentation.
    kernel : int, optional
        Size (pixels, odd) of the elliptical kernel of the morphological opening and closing; default
        scales with the image (3 px at 500 px). An even size raises ``ValueError`` (it has no centre
        pixel and would shift the contour), a non-integer ``TypeError``, and so does a kernel over
        ``max_kernel`` (default :data:`MAX_KERNEL`, 101 px) or over a twentieth of the region's smaller side
        (an opening with it would erase every part of the body narrower than the kernel, and its cost grows
        with its size).
    max_kernel : int
        The largest kernel accepted (pixels; raise it knowingly: minutes for hundreds of pixels).
    flatten : bool
        Flatten the illumination before Otsu.
    max_pixels : int
        Refuse a search region (the image, or ``roi``) of more pixels than this, before any image work;
        default :data:`MAX_PIXELS` (25 megapixels). Raise it, or pass a ``roi``, for larger photographs.

    Example
    -------
    >>> import numpy as np
    >>> img = np.full((50, 60), 200, np.uint8); img[10:40, 15:45] = 60
    >>> m = body_mask(img)
    >>> bool(m[25, 30]), bool(m[5, 5]), bool(abs(int(m.sum()) - 900) < 20)  # corners are rounded a little
    (True, False, True)
    """
    img, (x0, y0, w, h) = load_region(image, roi, max_pixels)
    m, _ = _segment(img[y0:y0 + h, x0:x0 + w], color=color, method=method, body=body,
                    color_tol=color_tol, kernel=kernel, flatten=flatten, max_kernel=max_kernel)
    out = np.zeros(img.shape[:2], dtype=bool)
    out[y0:y0 + h, x0:x0 + w] = m
    return out


def _segment(crop: np.ndarray, *, color: Any, method: str, body: str, color_tol: float | None,
             kernel: int | None, flatten: bool, max_kernel: int = MAX_KERNEL) -> tuple[np.ndarray, np.ndarray]:
    """Mask of a (cropped) uint8 image and a continuous score map for sub-pixel refinement."""
    h, w = crop.shape[:2]
    if method not in ("auto", "otsu", "adaptive", "color"):
        raise ValueError(f"method must be 'auto', 'otsu', 'adaptive' or 'color', got {method!r}")
    if body not in ("auto", "dark", "light"):
        raise ValueError(f"body must be 'auto', 'dark' or 'light', got {body!r}")
    flatten = check_bool(flatten, "flatten")
    rgb_color = None if color is None else check_color(color)
    if method == "auto":
        method = "color" if rgb_color is not None else "otsu"
    if method == "color" and rgb_color is None:
        raise ValueError("method='color' needs the body's colour: pass color=(r, g, b)")
    if method == "color" and crop.ndim == 2:
        raise ValueError("colour segmentation needs an RGB image; this image is grey")
    if int(crop.max()) - int(crop.min()) < 2:
        raise ValueError(f"image is uniform (all pixels about {int(crop.min())} of 255, as load_image reads "
                         "its dtype's range): there is no body to extract")
    max_kernel = check_int(max_kernel, "max_kernel", lo=1)
    if kernel is None:
        k = _default_kernel(h, w)
    else:
        k = check_int(kernel, "kernel", lo=1)
        if k % 2 == 0:
            # an even elliptical kernel has no centre pixel: opening and closing shift the mask
            raise ValueError(f"kernel must be odd (an even kernel has no centre pixel and shifts the "
                             f"contour by about a pixel), got {k}; use {k - 1} or {k + 1}")
        k_max = min(max_kernel, max(3, min(h, w) // 20) | 1)
        if k > k_max:
            raise ValueError(f"kernel={k} is too large for a {w} x {h} search region: at most {k_max} px "
                             f"(max_kernel={max_kernel} px, and a twentieth of the smaller side); an opening "
                             "with a larger kernel erases every part of the body narrower than the kernel, "
                             "and its cost grows with its size (minutes for hundreds of pixels)")
    sigma = max(0.8, min(h, w) / 600.0)
    # the mask is thresholded after a median filter, which removes thin dark lines (grid plate,
    # scratches) and speckle but keeps edges; the score for sub-pixel refinement is only Gaussian-smoothed
    smooth = cv2.GaussianBlur(crop, (0, 0), sigma).astype(np.float32)
    robust = cv2.GaussianBlur(cv2.medianBlur(crop, 5), (0, 0), sigma).astype(np.float32)

    if method == "color":
        lab = cv2.cvtColor(robust / 255.0, cv2.COLOR_RGB2Lab).astype(float)
        ref = cv2.cvtColor((rgb_color.astype(np.float32) / 255.0).reshape(1, 1, 3),
                           cv2.COLOR_RGB2Lab).reshape(3).astype(float)
        diff = lab - ref
        dist = np.sqrt(0.25 * diff[..., 0] ** 2 + diff[..., 1] ** 2 + diff[..., 2] ** 2)
        tol = _otsu(dist) if color_tol is None else positive_float(color_tol, "color_tol")
        fg = dist <= tol
        if not fg.any() or float(np.median(dist[fg])) > 30.0:
            raise ValueError(f"no region of the image is close to the body colour {rgb_color.tolist()} "
                             f"(nearest CIELAB distance {dist.min():.1f}); check color=")
        score = smooth
    else:
        def grey(a: np.ndarray) -> np.ndarray:
            return a if a.ndim == 2 else cv2.cvtColor(a, cv2.COLOR_RGB2GRAY)

        gray = grey(robust)
        light_field = _illumination(gray) if flatten else np.ones_like(gray, dtype=float)
        flat = gray / light_field
        # divided in float64 and rounded to float32 as it is written (no float64 temporary)
        score = np.divide(grey(smooth), light_field, out=np.empty(light_field.shape, dtype=np.float32))
        t = _otsu(flat)
        light = flat > t
        if body == "auto":
            edge = _frame(light.shape)
            fl, fd = light[edge].mean(), (~light)[edge].mean()
            dark_body = fl > fd or (fl == fd and light.mean() > 0.5)
        else:
            dark_body = body == "dark"
        fg = ~light if dark_body else light
        if method == "adaptive":
            # the threshold follows the local background: a normalised Gaussian average of the pixels
            # classified as background, interpolated under the body; the body is where the image
            # departs from it by more than half the body-background contrast
            sig = max(5.0, min(h, w) / 8.0)
            g = gray.astype(np.float32)
            for _ in range(2):
                bgm = (~fg).astype(np.float32)
                den = cv2.GaussianBlur(bgm, (0, 0), sig)
                num = cv2.GaussianBlur(g * bgm, (0, 0), sig)
                fallback = light_field * float(np.median(flat[~fg])) if (~fg).any() else light_field
                local = np.where(den > 0.02, num / np.maximum(den, 1e-6), fallback)
                rel = g / np.maximum(local, 1.0)
                if not fg.any():
                    break
                level = 0.5 * (1.0 + float(np.median(rel[fg])))
                fg = rel < level if dark_body else rel > level
            score = (grey(smooth) / np.maximum(local, 1.0)).astype(np.float32)
    m8 = fg.astype(np.uint8) * 255
    se = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (k, k))
    m8 = cv2.morphologyEx(m8, cv2.MORPH_OPEN, se)
    m8 = cv2.morphologyEx(m8, cv2.MORPH_CLOSE, se)
    return m8 > 0, score


def _refine_subpixel(contour: np.ndarray, blob: np.ndarray, score: np.ndarray, reach: float) -> np.ndarray:
    """Move each contour point along its normal to the edge: where the score crosses half-way between the
    body's and the background's values measured in bands inside and outside the blob.

    ``blob`` is the filled ``contour``. All the work is done in the blob's bounding box plus a margin that
    holds both bands (the 3 x 3 chamfer distance is at least 0.955 of the larger coordinate offset) and
    every profile sample: OpenCV's distance transform takes the image border as far (not as background),
    so the distances in the box are the whole image's, and the sample coordinates move by whole pixels,
    which float32 subtracts exactly and the remap's fixed point keeps (the same contour points as the whole
    image gives, with a fraction of its distance transforms, masks and projection)."""
    lo_band, hi_band = 2.5 * reach / 2.0, 6.0 * reach / 2.0
    H, W = blob.shape
    m = int(math.ceil(max(hi_band / 0.95, reach))) + 3
    x0, y0 = (max(0, int(math.floor(v)) - m) for v in contour.min(axis=0))
    x1, y1 = int(math.ceil(contour[:, 0].max())) + m + 1, int(math.ceil(contour[:, 1].max())) + m + 1
    x1, y1 = min(W, x1), min(H, y1)
    b8 = blob[y0:y1, x0:x1].astype(np.uint8)
    score = score[y0:y1, x0:x1]
    d_in = cv2.distanceTransform(b8, cv2.DIST_L2, 3)
    d_out = cv2.distanceTransform(1 - b8, cv2.DIST_L2, 3)
    inner = (d_in > lo_band) & (d_in <= hi_band)
    outer = (d_out > lo_band) & (d_out <= hi_band)
    if inner.sum() < 10 or outer.sum() < 10:
        return contour
    sc = score if score.ndim == 3 else score[..., None]
    c_in = np.median(sc[inner], axis=0)
    c_out = np.median(sc[outer], axis=0)
    axis = c_in - c_out
    nrm2 = float(axis @ axis)
    if nrm2 < 1e-6:
        return contour
    if score.ndim == 2:  # one channel: the product of one pair, as the matrix product below gives it
        proj = score - c_out[0]
        proj *= axis[0]
    else:
        proj = (sc - c_out) @ axis
    proj /= nrm2
    proj -= 0.5   # > 0 inside the body
    p = contour
    tang = np.roll(p, -2, axis=0) - np.roll(p, 2, axis=0)
    tl = np.linalg.norm(tang, axis=1)
    ok = tl > 1e-9
    normal = np.zeros_like(p)
    normal[ok] = np.column_stack([tang[ok, 1], -tang[ok, 0]]) / tl[ok, None]
    if polygon_area(p) < 0:  # make the normals point out of the body
        normal = -normal
    steps = np.linspace(-reach, reach, int(round(20 * reach)) + 1)
    sx = (p[:, 0:1] + steps[None, :] * normal[:, 0:1]).astype(np.float32)
    sy = (p[:, 1:2] + steps[None, :] * normal[:, 1:2]).astype(np.float32)
    sx -= np.float32(x0)
    sy -= np.float32(y0)
    prof = cv2.remap(proj, sx, sy, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
    out = p.copy()
    inside = prof > 0
    change = inside[:, :-1] & ~inside[:, 1:]            # body -> background going outward
    centre = len(steps) // 2
    rows = np.flatnonzero(ok & change.any(axis=1))
    # per point, the crossing nearest the centre of its profile (the first of equally near ones)
    off = np.where(change[rows], np.abs(np.arange(change.shape[1]) + 0.5 - centre), np.inf)
    j = np.argmin(off, axis=1)
    a, b = prof[rows, j], prof[rows, j + 1]
    same = a == b
    frac = np.where(same, np.float32(0.5), a / np.where(same, np.float32(1.0), a - b))
    s = steps[j] + frac * (steps[j + 1] - steps[j])
    out[rows] = p[rows] + s[:, None] * normal[rows]
    return out


def contour_from_image(image: ArrayLike | str | os.PathLike, *, roi: Sequence[int] | None = None,
                       color: Any = None, method: str = "auto", body: str = "auto",
                       color_tol: float | None = None, kernel: int | None = None, flatten: bool = True,
                       largest: bool = False, min_blob_fraction: float = 0.05,
                       subpixel: bool = True, max_pixels: int = MAX_PIXELS,
                       max_kernel: int = MAX_KERNEL) -> np.ndarray:
    """Extract the body's outline from a photograph as (k, 2) pixel coordinates.

    The image is segmented by :func:`body_mask` (thresholding, opening and closing) and the external
    contours of the mask are found. Blobs that touch the border of the image (or ``roi``) give way to
    blobs inside it, and blobs smaller than ``min_blob_fraction`` of the largest are treated as noise
    (specks, grid-line fragments, the caption of a synthetic photo). If every blob inside is smaller
    than ``min_blob_fraction`` of a blob touching the border, or every blob touches the image's border, the
    body itself probably touches the border: that is an error (pass ``roi`` or ``largest=True``), never a
    speck, or an outline cut by the frame, returned as the body.

    Parameters
    ----------
    image : array_like or path
        See :func:`load_image`.
    roi, color, method, body, color_tol, kernel, flatten, max_pixels, max_kernel
        See :func:`body_mask`.
    largest : bool
        When several blobs of comparable size remain, or the body touches the border (the only blobs touch
        it, or those inside are specks), keep the largest blob instead of raising.
    min_blob_fraction : float
        Blobs with less than this fraction of the largest blob's area are ignored.
    subpixel : bool
        Move each contour point along its normal to where the image crosses half-way between the body's
        and the background's values (measured in bands just inside and outside the body); without it
        the contour runs through the centres of the body's boundary pixels.

    Returns
    -------
    numpy.ndarray, shape (k, 2)
        The closed outline (no repeated end point) as float ``(x, y)`` pixel coordinates of the image
        (``roi`` offset included), refined to sub-pixel edge positions unless ``subpixel=False``.

    Raises
    ------
    ValueError
        No contour, several separate blobs (unless ``largest``), a body that touches the image's border
        (unless ``largest`` or ``roi``) or the roi's next to specks (unless ``largest``), a mask that fills
        the search region, or bad options. See :func:`load_image` for the image errors.
    TypeError
        A non-integer ``kernel`` or a non-bool flag.

    Example
    -------
    >>> import numpy as np
    >>> img = np.full((60, 80, 3), 220, np.uint8); img[20:40, 10:70] = (200, 90, 40)
    >>> c = contour_from_image(img, color=(200, 90, 40))
    >>> c.min(axis=0).round(2).tolist(), c.max(axis=0).round(2).tolist()  # edges between pixels
    ([9.5, 19.5], [69.5, 39.5])
    """
    return _extract_outline(image, roi=roi, color=color, method=method, body=body, color_tol=color_tol,
                            kernel=kernel, flatten=flatten, largest=largest, min_blob_fraction=min_blob_fraction,
                            subpixel=subpixel, max_pixels=max_pixels, max_kernel=max_kernel)[0]


def _extract_outline(image, *, roi, color, method, body, color_tol, kernel, flatten, largest, min_blob_fraction,
                     subpixel, max_pixels, max_kernel=MAX_KERNEL):
    """:func:`contour_from_image`, also returning what hole extraction needs: ``(outline, mask (uint8,
    0/255, search region), score, the outline's integer contour, (x0, y0, w, h))``."""
    img, (x0, y0, w, h) = load_region(image, roi, max_pixels)
    largest = check_bool(largest, "largest")
    subpixel = check_bool(subpixel, "subpixel")
    frac = positive_float(min_blob_fraction, "min_blob_fraction")
    if frac > 1.0:
        raise ValueError(f"min_blob_fraction must lie in (0, 1], got {frac}")
    mask, score = _segment(img[y0:y0 + h, x0:x0 + w], color=color, method=method, body=body,
                           color_tol=color_tol, kernel=kernel, flatten=flatten, max_kernel=max_kernel)
    m8 = mask.astype(np.uint8) * 255
    contours, _ = cv2.findContours(m8, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_NONE)
    contours = [c.reshape(-1, 2) for c in contours if len(c) >= 3]
    areas = np.array([cv2.contourArea(c.astype(np.float32)) for c in contours])
    if len(contours) == 0 or areas.max() <= 0.0:
        raise ValueError("no contour found: thresholding left no body in the image"
                         + (" region of interest" if roi is not None else "")
                         + " (try color=, body='dark'/'light' or method='adaptive')")
    # blobs touching the border of the search region (plate edges, grid lines cut by the frame, the
    # table) give way to blobs inside it: a photographed body lies inside the picture. But a blob
    # inside that is a speck next to a border blob is not the body: then the body itself probably
    # touches the border, and guessing would return the speck.
    touches = np.array([bool(c[:, 0].min() <= 0 or c[:, 1].min() <= 0 or c[:, 0].max() >= w - 1
                             or c[:, 1].max() >= h - 1) for c in contours])
    inner = np.flatnonzero(~touches & (areas > 0))
    border = np.flatnonzero(touches & (areas > 0))
    pool = inner if len(inner) else np.flatnonzero(areas > 0)
    if not len(inner) and not largest and roi is None:
        # every blob touches the border: the body runs out of the picture (or merged with the plate's edge), and
        # its outline would be the frame's cut, measured as if it were the body's (a roi is the user's own frame)
        a_border = float(areas[border].max())
        raise ValueError(
            f"the body touches the image border: the largest blob ({a_border:.0f} px) touches the border of the "
            "image and no blob lies inside it, so its outline would be cut by the frame; photograph the whole "
            "body, or pass roi=(x, y, width, height) or largest=True to keep the blob as it is")
    if len(inner) and len(border):
        a_in, a_border = float(areas[inner].max()), float(areas[border].max())
        if a_in < frac * a_border:
            if not largest:
                raise ValueError(
                    f"the body touches the image border: the largest blob ({a_border:.0f} px) touches the "
                    f"border of the {'roi' if roi is not None else 'image'} and the largest blob inside "
                    f"it has only {a_in:.0f} px (less than min_blob_fraction={frac:g} of it); pass "
                    "roi=(x, y, width, height) around the body, or largest=True to keep the largest blob")
            pool = np.flatnonzero(areas > 0)
    order = pool[np.argsort(-areas[pool])]
    big = areas[order[0]]
    if big > 0.9 * w * h:
        raise ValueError("the segmented region fills the image: the body cannot be told from the "
                         "background (try color=, body='dark'/'light', or a roi around the body)")
    significant = [i for i in order if areas[i] >= frac * big]
    if len(significant) > 1 and not largest:
        listed = ", ".join(f"{areas[i]:.0f}" for i in significant[:6])
        raise ValueError(f"found {len(significant)} separate blobs of comparable size (areas {listed} px); "
                         "pass largest=True to keep the largest, or restrict the search with "
                         "roi=(x, y, width, height)")
    c = contours[order[0]].astype(float)
    if subpixel:
        blob = np.zeros_like(m8)
        cv2.drawContours(blob, [contours[order[0]].reshape(-1, 1, 2)], 0, 1, thickness=cv2.FILLED)
        c = _refine_subpixel(c, blob > 0, score, reach=max(2.0, min(h, w) / 250.0))
    c[:, 0] += x0
    c[:, 1] += y0
    return c, m8, score, contours[order[0]], (x0, y0, w, h)


def contour_loops_from_image(image: ArrayLike | str | os.PathLike, *, min_hole_fraction: float = 0.002,
                             subpixel: bool = True, **extract) -> list[np.ndarray]:
    """Extract the body's outline AND its holes (eyes, a mouth, windows) from a photograph.

    The outline is :func:`contour_from_image`'s (same options in ``extract``, same errors). The holes
    are the background regions enclosed by it (the inner contours of OpenCV's two-level hierarchy,
    ``RETR_CCOMP``, of the body's blob), each refined to sub-pixel edge positions like the outline.

    Parameters
    ----------
    image : array_like or path
    min_hole_fraction : float in (0, 1), default 0.002
        Holes smaller than this fraction of the area enclosed by the outline are ignored (pores, specks
        of glare, segmentation noise).
    subpixel : bool
        As in :func:`contour_from_image`.
    **extract
        Other options of :func:`contour_from_image` (``roi``, ``color``, ``method``, ...).

    Returns
    -------
    list of (k, 2) ndarrays
        The outline first, then the holes by decreasing area, in pixel coordinates.

    Raises
    ------
    ValueError
        As :func:`contour_from_image`; a ``min_hole_fraction`` outside (0, 1).
    """
    frac = positive_float(min_hole_fraction, "min_hole_fraction")
    if frac >= 1.0:
        raise ValueError(f"min_hole_fraction must lie in (0, 1), got {frac}")
    subpixel = check_bool(subpixel, "subpixel")
    opts = dict(roi=None, color=None, method="auto", body="auto", color_tol=None, kernel=None, flatten=True,
                largest=False, min_blob_fraction=0.05, max_pixels=MAX_PIXELS, max_kernel=MAX_KERNEL)
    unknown = set(extract) - set(opts)
    if unknown:
        raise TypeError(f"contour_loops_from_image got unknown option(s) {sorted(unknown)}; it takes "
                        f"min_hole_fraction, subpixel and {sorted(opts)}")
    opts.update(extract)
    outline, m8, score, outer_int, (x0, y0, w, h) = _extract_outline(image, subpixel=subpixel, **opts)
    blob = np.zeros_like(m8)
    cv2.drawContours(blob, [outer_int.reshape(-1, 1, 2)], 0, 1, thickness=cv2.FILLED)
    # background enclosed by the outline: the blob's holes (a hole touching the outline is not a hole)
    enclosed = ((blob > 0) & (m8 == 0)).astype(np.uint8)
    found, _ = cv2.findContours(enclosed * 255, cv2.RETR_CCOMP, cv2.CHAIN_APPROX_NONE)
    area_out = abs(polygon_area(outline))
    holes = []
    for hc in found:
        hc = hc.reshape(-1, 2)
        if len(hc) < 3:
            continue
        a = cv2.contourArea(hc.astype(np.float32))
        if a < frac * area_out:
            continue
        c = hc.astype(float)
        if subpixel:
            hb = np.zeros_like(m8)
            cv2.drawContours(hb, [hc.reshape(-1, 1, 2)], 0, 1, thickness=cv2.FILLED)
            c = _refine_subpixel(c, hb > 0, score, reach=max(2.0, min(h, w) / 250.0))
        c[:, 0] += x0
        c[:, 1] += y0
        holes.append((a, c))
    holes.sort(key=lambda t: -t[0])
    return [outline] + [c for _, c in holes]
