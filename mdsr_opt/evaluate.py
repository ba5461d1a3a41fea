"""Comparing simulations with photographs: contour extraction, contour metrics, a synthetic camera.

The paper validates a design by photographing the prototype on a grid plate, extracting its outline and
measuring how far each simulated boundary node lies from it. This module does the same in four steps:

1. :func:`contour_from_image` segments the body (Otsu on an illumination-flattened grey image, adaptive
   thresholding, or distance to a known body colour), cleans the mask morphologically and returns the
   largest external contour in pixel coordinates.
2. :func:`compare_contours` aligns the simulated outline with the measured contour (rotation, then a
   scale that makes the areas equal, or a known ``px_per_unit``), measures each simulated node's
   distance to the contour with ``cv2.pointPolygonTest`` and returns a :class:`ContourComparison`.
   A fitted scale hides a simulation that is uniformly too large or too small; see
   :func:`compare_contours`.
3. :func:`render_photo` is a synthetic camera: it renders a simulated state as a photograph-like image of
   the body on a grid plate, captioned ``SYNTHETIC`` and flagged so in its metadata.
4. :func:`evaluate_folder` / ``mdsr evaluate`` score a folder of images against a design's states and write
   a table like the paper's Tables 2-4 (CSV and Markdown).

This is the only module of the package that imports OpenCV. Images given as arrays are RGB (or grey);
images read from files are converted from OpenCV's BGR to RGB. Pixel coordinates are ``(column, row)``
with the origin at the centre of the top-left pixel and ``y`` pointing down.

Example
-------
>>> import numpy as np
>>> from mdsr_opt import Mesh
>>> from mdsr_opt.evaluate import render_photo, contour_from_image, compare_contours
>>> mesh = Mesh.rectangle(4.0, 1.0, nx=8, ny=2)
>>> photo = render_photo(mesh, resolution=(400, 300), seed=1)
>>> contour = contour_from_image(photo.image)
>>> result = compare_contours(mesh.points[mesh.boundary_loops[0]], contour)
>>> bool(result.mean_px < 1.5), photo.metadata["synthetic"]
(True, True)
"""

from __future__ import annotations

import contextlib
import csv
import io
import json
import math
import numbers
import os
import tempfile
import warnings
from dataclasses import dataclass, field, fields
from pathlib import Path
from typing import Any, Callable, Sequence

import cv2
import numpy as np
from numpy.typing import ArrayLike

from ._checks import as_float_array, check_mesh, positive_float
from .io import FORMATS, atomic_path
from .mesh import polygon_area
from .results import compact_repr, to_jsonable

__all__ = [
    "MAX_PIXELS",
    "MAX_KERNEL",
    "load_image",
    "body_mask",
    "contour_from_image",
    "contour_loops_from_image",
    "simulated_outline",
    "simulated_loops",
    "LoopComparison",
    "compare_loops",
    "ContourComparison",
    "compare_contours",
    "evaluate_image",
    "SyntheticPhoto",
    "render_photo",
    "CaseResult",
    "evaluate_folder",
    "write_table",
    "add_cli",
]

#: Default limit on the pixels of the searched region (the image, or its ``roi``) of
#: :func:`contour_from_image` and :func:`body_mask`; raise it with ``max_pixels=``. Extraction takes
#: about 0.3 s and 60 MB per megapixel, so 25 megapixels (a 6000 x 4000 photograph) need about 1.5 GB.
MAX_PIXELS = 25_000_000
#: Largest morphology kernel (pixels): the opening and closing cost grows with the kernel's size
#: (a 401 px kernel on a 2000 x 2000 image takes over a minute) and a kernel wider than the body's
#: narrow parts erases them.
MAX_KERNEL = 101

IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg", ".bmp", ".tif", ".tiff")
#: State files are the mesh formats of :mod:`mdsr_opt.io` (so a ``case.svg`` figure beside ``case.vtu``
#: is not taken for a second state).
STATE_SUFFIXES = tuple(FORMATS)


def _check_bool(value: Any, name: str) -> bool:
    if not isinstance(value, (bool, np.bool_)):
        raise TypeError(f"{name} must be True or False, got {type(value).__name__} {value!r}")
    return bool(value)


def _check_int(value: Any, name: str, lo: int | None = None, hi: int | None = None) -> int:
    """An integer (not bool, not a float that happens to be whole) within [lo, hi]."""
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, numbers.Integral):
        raise TypeError(f"{name} must be an integer, got {type(value).__name__} {value!r}")
    v = int(value)
    if (lo is not None and v < lo) or (hi is not None and v > hi):
        rng = f">= {lo}" if hi is None else f"in {lo}..{hi}"
        raise ValueError(f"{name} must be an integer {rng}, got {v}")
    return v


def _write_together(writers: Sequence[tuple[Path, Callable[[str], None]]]) -> list[Path]:
    """Write several files as one: each ``write(tmp)`` fills a temporary file beside its target
    (:class:`mdsr_opt.io.atomic_path`), and only when every write has succeeded are they all renamed onto
    their targets, last writer first. An error in any write leaves no file changed and no temporary file
    behind; only a failing rename (e.g. a target that is a folder) could leave part of the set renamed."""
    paths = [Path(p) for p, _ in writers]
    for p in paths:  # the likeliest rename failure, caught before anything is written
        if p.is_dir():
            raise ValueError(f"cannot write {p}: it is a folder")
    if len(set(paths)) != len(paths):
        raise ValueError(f"the same file would be written twice: {sorted(str(p) for p in paths)}")
    with contextlib.ExitStack() as stack:
        for path, write in writers:
            write(stack.enter_context(atomic_path(path)))
    return paths


def _bytes_writer(data: bytes) -> Callable[[str], None]:
    def write(tmp: str) -> None:
        with open(tmp, "wb") as fh:
            fh.write(data)

    return write


# ----------------------------------------------------------------------------------------------- images
def load_image(image_or_path: ArrayLike | str | os.PathLike, name: str = "image") -> np.ndarray:
    """Return an image as a ``uint8`` array, (H, W) grey or (H, W, 3) RGB.

    Parameters
    ----------
    image_or_path : array_like or path
        Pixel values of any real dtype, judged by their real range: ``uint8`` as is; other integers
        (``uint16``, ``int64``, ...) as is when they all lie in 0-255 (8-bit data), else scaled by the
        smallest bit depth (10, 12, 14, 16, ... bits) that holds them; ``bool`` as 0/255; floats in
        [0, 1] scaled by 255, floats up to 255 as 8-bit values. An image whose values vary but would
        fill fewer than 32 grey levels after that scaling is stretched to 0-255 (with a warning). Grey
        (H, W) or (H, W, 1), RGB (H, W, 3) or RGBA (H, W, 4). The alpha channel is dropped, with a
        warning when some pixels are transparent (their stored colour is used as is). A path is read
        with OpenCV and converted from BGR to RGB.
    name : str
        The name used in error messages.

    Warns
    -----
    UserWarning
        An RGBA image with transparent pixels: alpha is ignored. A low-contrast image was stretched.

    Raises
    ------
    FileNotFoundError
        The path does not exist.
    TypeError
        An unsupported dtype (complex, strings, object).
    ValueError
        An empty image, a wrong shape, negative or non-finite values, floats above 255, or a file OpenCV
        cannot decode.

    Example
    -------
    >>> import numpy as np
    >>> load_image(np.zeros((4, 5, 3))).dtype
    dtype('uint8')
    """
    if isinstance(image_or_path, (str, os.PathLike)):
        path = Path(image_or_path)
        if not path.exists():
            raise FileNotFoundError(f"{name} file does not exist: {path}")
        if path.is_dir():
            raise ValueError(f"{name} path is a directory, not an image file: {path}")
        data = np.fromfile(str(path), dtype=np.uint8)
        arr = cv2.imdecode(data, cv2.IMREAD_UNCHANGED) if data.size else None
        if arr is None:
            raise ValueError(f"cannot decode {name} file {path}: not an image format OpenCV can read")
        if arr.ndim == 3 and arr.shape[2] == 4:
            _warn_alpha(arr[:, :, 3], f"{name} ({path.name})")
            arr = cv2.cvtColor(arr, cv2.COLOR_BGRA2RGB)
        elif arr.ndim == 3 and arr.shape[2] == 3:
            arr = cv2.cvtColor(arr, cv2.COLOR_BGR2RGB)
        return _as_uint8_image(arr, f"{name} ({path.name})")
    return _as_uint8_image(image_or_path, name)


def _as_uint8_image(value: Any, name: str) -> np.ndarray:
    arr = np.asarray(value)
    if arr.dtype == object or arr.dtype.kind in "USV":
        raise TypeError(f"{name} must be a numeric image array, got dtype {arr.dtype}")
    if arr.dtype.kind == "c":
        raise TypeError(f"{name} has unsupported dtype {arr.dtype}: an image holds real values")
    if arr.dtype.kind not in "biuf":
        raise TypeError(f"{name} has unsupported dtype {arr.dtype}; pass integer or float pixel values")
    if arr.size == 0:
        raise ValueError(f"{name} is empty (shape {arr.shape})")
    if arr.ndim == 3 and arr.shape[2] == 1:
        arr = arr[:, :, 0]
    if not (arr.ndim == 2 or (arr.ndim == 3 and arr.shape[2] in (3, 4))):
        raise ValueError(f"{name} must have shape (H, W), (H, W, 3) or (H, W, 4), got {arr.shape}")
    if arr.ndim == 3 and arr.shape[2] == 4:
        _warn_alpha(arr[:, :, 3], name)
        arr = arr[:, :, :3]
    if min(arr.shape[:2]) < 3:
        raise ValueError(f"{name} is too small to hold a contour: shape {arr.shape}")
    return _to_uint8(arr, name)


def _to_uint8(arr: np.ndarray, name: str) -> np.ndarray:
    """Map pixel values of any real dtype to 0-255 by their real value range.

    ``uint8`` passes unchanged; ``bool`` becomes 0/255. Other integers (``uint16``, ``int64``, ...) that
    all lie in 0-255 are 8-bit data and are kept as they are; larger ones are scaled by the smallest bit
    depth of 10, 12, 14, 16, ... bits that holds their maximum (a 12-bit camera image stored as
    ``uint16`` is scaled by 255/4095, not by 255/65535). Floats in [0, 1] are scaled by 255; floats up
    to 255 are taken as 8-bit values. When that scaling would squeeze an image whose values do vary into
    fewer than 32 grey levels, its range is stretched to 0-255 instead, with a warning.
    """
    kind = arr.dtype.kind
    if arr.dtype == np.uint8:
        return np.ascontiguousarray(arr)
    if kind == "b":
        return np.ascontiguousarray(arr.astype(np.uint8) * 255)
    if kind == "f" and not np.all(np.isfinite(arr)):
        raise ValueError(f"{name} contains NaN or inf")
    lo, hi = arr.min(), arr.max()
    flo, fhi = float(lo), float(hi)
    if flo < 0:
        raise ValueError(f"{name} has negative values (range {lo} to {hi} in dtype {arr.dtype}); pixel "
                         "values must be >= 0")
    if kind in "iu":
        if int(hi) <= 255:
            return np.ascontiguousarray(arr.astype(np.uint8))
        bits = max(10, 2 * math.ceil(math.log2(int(hi) + 1) / 2))
        scale, what = 255.0 / (2.0 ** bits - 1.0), f"{bits}-bit"
    elif fhi <= 1.0:
        scale, what = 255.0, "[0, 1]"
    elif fhi <= 255.0:
        scale, what = 1.0, "[0, 255]"
    else:
        raise ValueError(f"{name} is a float image with values in [{flo:g}, {fhi:g}]; float images must "
                         "lie in [0, 1] or [0, 255] (or pass an integer image, e.g. uint16)")
    levels = (fhi - flo) * scale
    if levels < 32 and fhi > flo and scale != 1.0:
        warnings.warn(f"{name}: its values ({lo} to {hi}, {what} {arr.dtype}) would span only "
                      f"{levels:.1f} of 255 grey levels; stretched to 0-255 (a color= is matched against "
                      "the stretched values)", UserWarning, stacklevel=4)
        out = (arr.astype(np.float32) - np.float32(flo)) * np.float32(255.0 / (fhi - flo))
    else:
        out = arr.astype(np.float32) * np.float32(scale)
    return np.ascontiguousarray(np.clip(np.round(out), 0, 255).astype(np.uint8))


def _warn_alpha(alpha: np.ndarray, name: str) -> None:
    """Warn when an alpha channel that is about to be dropped is not fully opaque."""
    a = np.asarray(alpha)
    opaque = {np.dtype(np.uint8): 255, np.dtype(np.uint16): 65535}.get(a.dtype, 1.0)
    if a.size and a.dtype.kind in "uif" and float(a.min()) < opaque:
        frac = float((a < opaque).mean())
        warnings.warn(f"{name} has an alpha channel with transparent pixels ({100 * frac:.1f} % of the "
                      "image); alpha is ignored and the colour stored under transparent pixels is used "
                      "as is; composite the image onto its background first", UserWarning, stacklevel=4)


def _check_roi(roi: Sequence[int] | None, shape: tuple[int, ...]) -> tuple[int, int, int, int]:
    H, W = shape[:2]
    if roi is None:
        return 0, 0, W, H
    vals = np.asarray(roi)
    if vals.shape != (4,) or not np.issubdtype(vals.dtype, np.integer):
        raise ValueError(f"roi must be four integers (x, y, width, height), got {roi!r}")
    x, y, w, h = (int(v) for v in vals)
    if w < 3 or h < 3:
        raise ValueError(f"roi width and height must be >= 3 pixels, got {w} x {h}")
    if x < 0 or y < 0 or x + w > W or y + h > H:
        raise ValueError(f"roi (x={x}, y={y}, w={w}, h={h}) does not lie inside the {W} x {H} image")
    return x, y, w, h


def _load_region(image: Any, roi: Sequence[int] | None, max_pixels: Any) -> tuple[np.ndarray, tuple]:
    """Load ``image`` and check ``roi`` and the size of the searched region before any image work.

    For an array the size is checked before its pixels are converted; a file has to be decoded first.
    """
    limit = _check_int(max_pixels, "max_pixels", lo=1)
    if not isinstance(image, (str, os.PathLike)):
        shape = np.shape(image)
        if len(shape) in (2, 3) and min(shape[:2]) >= 3:
            _check_pixels(_check_roi(roi, shape), limit)
    img = load_image(image)
    region = _check_roi(roi, img.shape)
    _check_pixels(region, limit)
    return img, region


def _check_pixels(region: tuple[int, int, int, int], limit: int) -> None:
    w, h = region[2], region[3]
    if w * h > limit:
        raise ValueError(
            f"the searched image region is {w} x {h} = {w * h / 1e6:.1f} megapixels, more than the limit "
            f"max_pixels={limit} ({limit / 1e6:g} megapixels; extraction takes about 0.3 s and 60 MB per "
            "megapixel); pass roi=(x, y, width, height) around the body, downscale the image (e.g. "
            "cv2.resize(image, None, fx=0.5, fy=0.5, interpolation=cv2.INTER_AREA)), or raise the limit "
            "with max_pixels=")


def _check_color(color: Any) -> np.ndarray:
    if isinstance(color, str):
        s = color.strip().lstrip("#")
        if len(s) != 6:
            raise ValueError(f"color must be (r, g, b) in 0-255 or '#rrggbb', got {color!r}")
        try:
            return np.array([int(s[i:i + 2], 16) for i in (0, 2, 4)], dtype=float)
        except ValueError:
            raise ValueError(f"color must be (r, g, b) in 0-255 or '#rrggbb', got {color!r}") from None
    c = as_float_array(color, "color")
    if c.shape != (3,):
        raise ValueError(f"color must be three numbers (r, g, b) in 0-255, got shape {c.shape}")
    if np.any(c < 0) or np.any(c > 255):
        raise ValueError(f"color components must lie in 0-255, got {c.tolist()}")
    return c


def _otsu(values: np.ndarray, bins: int = 256) -> float:
    """Otsu's threshold of a float sample (between-class variance maximised over a histogram)."""
    v = np.asarray(values, dtype=float).ravel()
    lo, hi = (float(t) for t in np.percentile(v, [0.05, 99.95]))
    if not hi - lo > 1e-6 * max(abs(hi), abs(lo), 1e-12):
        return hi
    hist, edges = np.histogram(np.clip(v, lo, hi), bins=bins, range=(lo, hi))
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


def _quadratic_basis(h: int, w: int) -> np.ndarray:
    yy, xx = np.mgrid[0:h, 0:w]
    u = (xx + 0.5) / w * 2.0 - 1.0
    v = (yy + 0.5) / h * 2.0 - 1.0
    return np.stack([np.ones_like(u), u, v, u * u, u * v, v * v], axis=-1)


def _illumination(gray: np.ndarray) -> np.ndarray:
    """A smooth (quadratic) fit to the background brightness of a grey image, found iteratively."""
    H, W = gray.shape
    f = min(1.0, 96.0 / max(H, W))
    sw, sh = max(8, round(W * f)), max(8, round(H * f))
    small = cv2.resize(gray.astype(np.float32), (sw, sh), interpolation=cv2.INTER_AREA).astype(float)
    A = _quadratic_basis(sh, sw).reshape(-1, 6)
    z = small.ravel()
    # start from a frame along the image border (the plate, as a rule); then refit to the pixels
    # classified as background
    frame = _frame((sh, sw), 0.15).ravel()
    use = frame.copy()
    coef = np.linalg.lstsq(A[use], z[use], rcond=None)[0]
    for _ in range(4):
        fit = np.maximum(A @ coef, 1.0)
        r = z / fit
        light = r > _otsu(r)
        bg = light if light[frame].mean() >= 0.5 else ~light
        if bg.sum() < 0.1 * z.size:
            break
        use = bg
        coef = np.linalg.lstsq(A[use], z[use], rcond=None)[0]
    # evaluated by broadcasting a row and a column: one (H, W) array, not six (H, W) basis images
    u = ((np.arange(W) + 0.5) / W * 2.0 - 1.0)[None, :]
    v = ((np.arange(H) + 0.5) / H * 2.0 - 1.0)[:, None]
    c = coef
    return np.maximum(c[0] + c[1] * u + c[2] * v + c[3] * u * u + c[4] * u * v + c[5] * v * v, 1.0)


def _default_kernel(h: int, w: int) -> int:
    return max(3, 2 * round(min(h, w) / 400.0) + 1)


def body_mask(image: ArrayLike | str | os.PathLike, *, roi: Sequence[int] | None = None,
              color: Any = None, method: str = "auto", body: str = "auto", color_tol: float | None = None,
              kernel: int | None = None, flatten: bool = True, max_pixels: int = MAX_PIXELS) -> np.ndarray:
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
        :data:`MAX_KERNEL` (101 px) or over a twentieth of the region's smaller side (an opening with it
        would erase every part of the body narrower than the kernel, and its cost grows with its size).
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
    img, (x0, y0, w, h) = _load_region(image, roi, max_pixels)
    m, _ = _segment(img[y0:y0 + h, x0:x0 + w], color=color, method=method, body=body,
                    color_tol=color_tol, kernel=kernel, flatten=flatten)
    out = np.zeros(img.shape[:2], dtype=bool)
    out[y0:y0 + h, x0:x0 + w] = m
    return out


def _segment(crop: np.ndarray, *, color: Any, method: str, body: str, color_tol: float | None,
             kernel: int | None, flatten: bool) -> tuple[np.ndarray, np.ndarray]:
    """Mask of a (cropped) uint8 image and a continuous score map for sub-pixel refinement."""
    h, w = crop.shape[:2]
    if method not in ("auto", "otsu", "adaptive", "color"):
        raise ValueError(f"method must be 'auto', 'otsu', 'adaptive' or 'color', got {method!r}")
    if body not in ("auto", "dark", "light"):
        raise ValueError(f"body must be 'auto', 'dark' or 'light', got {body!r}")
    flatten = _check_bool(flatten, "flatten")
    rgb_color = None if color is None else _check_color(color)
    if method == "auto":
        method = "color" if rgb_color is not None else "otsu"
    if method == "color" and rgb_color is None:
        raise ValueError("method='color' needs the body's colour: pass color=(r, g, b)")
    if method == "color" and crop.ndim == 2:
        raise ValueError("colour segmentation needs an RGB image; this image is grey")
    if int(crop.max()) - int(crop.min()) < 2:
        raise ValueError(f"image is uniform (all pixels about {int(crop.min())}): there is no body to "
                         "extract")
    if kernel is None:
        k = _default_kernel(h, w)
    else:
        k = _check_int(kernel, "kernel", lo=1)
        if k % 2 == 0:
            # an even elliptical kernel has no centre pixel: opening and closing shift the mask
            raise ValueError(f"kernel must be odd (an even kernel has no centre pixel and shifts the "
                             f"contour by about a pixel), got {k}; use {k - 1} or {k + 1}")
        k_max = min(MAX_KERNEL, max(3, min(h, w) // 20) | 1)
        if k > k_max:
            raise ValueError(f"kernel={k} is too large for a {w} x {h} search region: at most {k_max} px "
                             f"(MAX_KERNEL={MAX_KERNEL} px, and a twentieth of the smaller side); an opening "
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
        score = (grey(smooth) / light_field).astype(np.float32)
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
    body's and the background's values measured in bands inside and outside the blob."""
    b8 = blob.astype(np.uint8)
    d_in = cv2.distanceTransform(b8, cv2.DIST_L2, 3)
    d_out = cv2.distanceTransform(1 - b8, cv2.DIST_L2, 3)
    lo_band, hi_band = 2.5 * reach / 2.0, 6.0 * reach / 2.0
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
    proj = (((sc - c_out) @ axis) / nrm2).astype(np.float32) - 0.5   # > 0 inside the body
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
    prof = cv2.remap(proj, sx, sy, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
    out = p.copy()
    inside = prof > 0
    change = inside[:, :-1] & ~inside[:, 1:]            # body -> background going outward
    centre = len(steps) // 2
    for i in np.flatnonzero(ok & change.any(axis=1)):
        js = np.flatnonzero(change[i])
        j = js[np.argmin(np.abs(js + 0.5 - centre))]
        a, b = prof[i, j], prof[i, j + 1]
        frac = a / (a - b) if a != b else 0.5
        s = steps[j] + frac * (steps[j + 1] - steps[j])
        out[i] = p[i] + s * normal[i]
    return out


def contour_from_image(image: ArrayLike | str | os.PathLike, *, roi: Sequence[int] | None = None,
                       color: Any = None, method: str = "auto", body: str = "auto",
                       color_tol: float | None = None, kernel: int | None = None, flatten: bool = True,
                       largest: bool = False, min_blob_fraction: float = 0.05,
                       subpixel: bool = True, max_pixels: int = MAX_PIXELS) -> np.ndarray:
    """Extract the body's outline from a photograph as (k, 2) pixel coordinates.

    The image is segmented by :func:`body_mask` (thresholding, opening and closing) and the external
    contours of the mask are found. Blobs that touch the border of the image (or ``roi``) give way to
    blobs inside it, and blobs smaller than ``min_blob_fraction`` of the largest are treated as noise
    (specks, grid-line fragments, the caption of a synthetic photo). If every blob inside is smaller
    than ``min_blob_fraction`` of a blob touching the border, the body itself probably touches the
    border: that is an error (pass ``roi`` or ``largest=True``), never a speck returned as the body.

    Parameters
    ----------
    image : array_like or path
        See :func:`load_image`.
    roi, color, method, body, color_tol, kernel, flatten, max_pixels
        See :func:`body_mask`.
    largest : bool
        When several blobs of comparable size remain, or the only large blob touches the border, keep
        the largest blob instead of raising.
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
        No contour, several separate blobs (unless ``largest``), a body that touches the border next to
        specks (unless ``largest``), a mask that fills the search region, or bad options. See
        :func:`load_image` for the image errors.
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
                            subpixel=subpixel, max_pixels=max_pixels)[0]


def _extract_outline(image, *, roi, color, method, body, color_tol, kernel, flatten, largest, min_blob_fraction,
                     subpixel, max_pixels):
    """:func:`contour_from_image`, also returning what hole extraction needs: ``(outline, mask (uint8,
    0/255, search region), score, the outline's integer contour, (x0, y0, w, h))``."""
    img, (x0, y0, w, h) = _load_region(image, roi, max_pixels)
    largest = _check_bool(largest, "largest")
    subpixel = _check_bool(subpixel, "subpixel")
    frac = positive_float(min_blob_fraction, "min_blob_fraction")
    if frac > 1.0:
        raise ValueError(f"min_blob_fraction must lie in (0, 1], got {frac}")
    mask, score = _segment(img[y0:y0 + h, x0:x0 + w], color=color, method=method, body=body,
                           color_tol=color_tol, kernel=kernel, flatten=flatten)
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
    subpixel = _check_bool(subpixel, "subpixel")
    opts = dict(roi=None, color=None, method="auto", body="auto", color_tol=None, kernel=None, flatten=True,
                largest=False, min_blob_fraction=0.05, max_pixels=MAX_PIXELS)
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


# ----------------------------------------------------------------------------------------------- metrics
def simulated_outline(mesh, x: ArrayLike | None = None) -> np.ndarray:
    """The simulated outline: deformed nodes of the mesh's outer boundary loop, (b, 2), counter-clockwise.

    Raises ``TypeError`` if ``mesh`` is not a :class:`~mdsr_opt.Mesh`, ``TypeError``/``ValueError`` for
    an ``x`` that is not a finite (n, 2) array.

    Example
    -------
    >>> from mdsr_opt import Mesh
    >>> simulated_outline(Mesh.rectangle(2.0, 1.0, 2, 1)).shape
    (6, 2)
    """
    mesh = check_mesh(mesh)
    x = mesh.points if x is None else as_float_array(x, "x", shape=(mesh.n_nodes, 2))
    return np.asarray(x)[mesh.boundary_loops[0]]


def _as_contour(value: ArrayLike, name: str) -> np.ndarray:
    c = as_float_array(value, name)
    if c.ndim == 3 and c.shape[1] == 1 and c.shape[2] == 2:  # OpenCV's (k, 1, 2)
        c = c[:, 0, :]
    if c.ndim != 2 or c.shape[1] != 2:
        raise ValueError(f"{name} must have shape (k, 2), got {c.shape}")
    if len(c) >= 2 and np.allclose(c[0], c[-1]):
        c = c[:-1]
    if len(c) < 3:
        raise ValueError(f"{name} needs at least 3 points, got {len(c)}")
    if abs(polygon_area(c)) <= 1e-12 * float(np.ptp(c, axis=0).max()) ** 2:
        raise ValueError(f"{name} encloses no area (degenerate contour)")
    return c


def _moments(p: np.ndarray) -> tuple[np.ndarray, float]:
    """Area centroid and principal-axis angle of a closed polygon (area: :func:`mesh.polygon_area`)."""
    o = p.mean(axis=0)
    q = p - o
    x, y = q[:, 0], q[:, 1]
    xn, yn = np.roll(x, -1), np.roll(y, -1)
    cr = x * yn - xn * y
    a = 0.5 * cr.sum()
    if abs(a) < 1e-300:
        return o, 0.0
    cx = ((x + xn) * cr).sum() / (6 * a)
    cy = ((y + yn) * cr).sum() / (6 * a)
    ixx = ((x * x + x * xn + xn * xn) * cr).sum() / (12 * a) - cx * cx
    iyy = ((y * y + y * yn + yn * yn) * cr).sum() / (12 * a) - cy * cy
    ixy = ((x * yn + 2 * x * y + 2 * xn * yn + xn * y) * cr).sum() / (24 * a) - cx * cy
    theta = 0.5 * math.atan2(2 * ixy, ixx - iyy)
    return o + np.array([cx, cy]), float(theta)


def _golden(f, a: float, b: float, tol: float) -> tuple[float, float]:
    """Golden-section search for a minimum of ``f`` on [a, b]; returns (x, f(x))."""
    g = (math.sqrt(5.0) - 1.0) / 2.0
    c, d = b - g * (b - a), a + g * (b - a)
    fc, fd = f(c), f(d)
    while b - a > tol:
        if fc <= fd:
            b, d, fd = d, c, fc
            c = b - g * (b - a)
            fc = f(c)
        else:
            a, c, fc = c, d, fd
            d = a + g * (b - a)
            fd = f(d)
    return (c, fc) if fc <= fd else (d, fd)


def _rot(t: float) -> np.ndarray:
    c, s = math.cos(t), math.sin(t)
    return np.array([[c, -s], [s, c]])


def _signed_distances(points: np.ndarray, contour32: np.ndarray) -> np.ndarray:
    """Signed distance of each point to a closed contour by ``cv2.pointPolygonTest`` (positive inside)."""
    return np.array([cv2.pointPolygonTest(contour32, (float(px), float(py)), True) for px, py in points])


def _unsigned_distances(points: np.ndarray, contour: np.ndarray) -> np.ndarray:
    """Distance of each point to a closed polyline, vectorised (all points against all segments)."""
    a = contour
    d = np.roll(contour, -1, axis=0) - a
    dd = np.maximum((d * d).sum(axis=1), 1e-300)
    out = np.empty(len(points))
    step = max(1, 2_000_000 // max(len(a), 1))
    for i in range(0, len(points), step):
        p = points[i:i + step, None, :]
        t = np.clip(((p - a) * d).sum(axis=2) / dd, 0.0, 1.0)
        q = a + t[..., None] * d
        out[i:i + step] = np.sqrt(((p - q) ** 2).sum(axis=2).min(axis=1))
    return out


class _PolylineDistance:
    """Exact distances of points to one closed polyline, many times (the rotation search).

    A KD-tree over the segments' midpoints: the nearest midpoint, at ``r0``, bounds a point's distance, so
    its nearest segment has its midpoint within ``r0 + L/2`` (``L`` the longest segment); only those
    segments (a ball query, a few per point) are measured exactly."""

    def __init__(self, contour: np.ndarray):
        from scipy.spatial import cKDTree

        self.a = np.asarray(contour, dtype=float)
        self.d = np.roll(self.a, -1, axis=0) - self.a
        self.dd = np.maximum((self.d * self.d).sum(axis=1), 1e-300)
        self.half = 0.5 * float(np.sqrt(self.dd.max()))
        self.tree = cKDTree(self.a + 0.5 * self.d)

    def __call__(self, points: np.ndarray) -> np.ndarray:
        points = np.asarray(points, dtype=float).reshape(-1, 2)
        if len(points) == 0:
            return np.empty(0)
        r0, _ = self.tree.query(points)
        lists = self.tree.query_ball_point(points, r0 * (1 + 1e-12) + self.half + 1e-12)
        lens = np.fromiter((len(c) for c in lists), dtype=np.int64, count=len(lists))
        seg = np.fromiter((j for c in lists for j in c), dtype=np.int64, count=int(lens.sum()))
        p = np.repeat(points, lens, axis=0)
        a, d = self.a[seg], self.d[seg]
        t = np.clip(((p - a) * d).sum(axis=1) / self.dd[seg], 0.0, 1.0)
        dist2 = ((p - a - t[:, None] * d) ** 2).sum(axis=1)
        starts = np.concatenate([[0], np.cumsum(lens)[:-1]])
        return np.sqrt(np.minimum.reduceat(dist2, starts))


@dataclass(frozen=True, eq=False)
class ContourComparison:
    """How well a simulated outline fits a measured contour.

    Distances are from each simulated boundary node to the measured contour (``cv2.pointPolygonTest``).
    ``*_px`` fields are in pixels of the photograph; ``*_norm`` fields are in the unit rectangle: the
    simulated outline's bounding rectangle (in the simulation's frame, at the registered scale) has its
    longer side 1. Comparisons are equal only if they are the same object (``eq=False``: they hold
    arrays).

    Attributes
    ----------
    mean_px, std_px, max_px : float
        Mean, standard deviation (population) and maximum of the absolute node distances, pixels.
    mean_norm, std_norm, max_norm : float
        The same in the unit rectangle (``scaling="stretch"``: in the unit square in which both
        bounding rectangles coincide).
    ratio : float
        Distance-difference ratio: ``mean_px`` over the measured contour's size ``sqrt(area)`` (pixels);
        a fraction (0.01 = 1 %).
    bias_px : float
        Mean signed distance; positive when simulated nodes lie inside the measured contour on average
        (the simulation is smaller than the photographed body).
    angle_deg : float
        The rotation (degrees, counter-clockwise in the simulation's frame) that aligns the simulated
        outline with the photographed one.
    scale : float
        Pixels per simulation length unit of the registration (geometric mean for ``scaling="stretch"``;
        ``px_per_unit`` when that was given).
    size_px : float
        Length of the unit rectangle's longer side in pixels, the normalising length of ``*_norm``:
        ``scale`` times the longer side of the simulated outline's bounding rectangle in the
        simulation's frame. It depends neither on how the photograph is rotated nor on the measured
        contour's principal axes (arbitrary for a shape without a clear long axis, such as a square),
        and as ``scale`` comes from areas, little on contour noise. For ``scaling="stretch"``: the
        longer side of the measured contour's bounding rectangle in the simulation's orientation.
    n_nodes : int
        Number of simulated boundary nodes measured.
    distances_px : numpy.ndarray
        Absolute distance of each simulated node, pixels.
    signed_px : numpy.ndarray
        Signed distance of each node (positive inside the measured contour), pixels.
    simulated_px : numpy.ndarray
        The simulated outline mapped into the photograph's pixels, (b, 2).
    measured_px : numpy.ndarray
        The measured contour, (k, 2) pixels.
    transform : numpy.ndarray
        (2, 3) affine map from simulation coordinates to pixels: ``p = A[:, :2] @ x + A[:, 2]``.
    registration : str
        How the outlines were registered.
    """

    mean_px: float
    std_px: float
    max_px: float
    mean_norm: float
    std_norm: float
    max_norm: float
    ratio: float
    bias_px: float
    angle_deg: float
    scale: float
    size_px: float
    n_nodes: int
    distances_px: np.ndarray = field(repr=False)
    signed_px: np.ndarray = field(repr=False)
    simulated_px: np.ndarray = field(repr=False)
    measured_px: np.ndarray = field(repr=False)
    transform: np.ndarray = field(repr=False)
    registration: str = "similarity"

    def to_pixels(self, points: ArrayLike) -> np.ndarray:
        """Map simulation coordinates (e.g. all mesh nodes) into the photograph's pixels."""
        p = as_float_array(points, "points", shape=(None, 2))
        return p @ self.transform[:, :2].T + self.transform[:, 2]

    def __repr__(self) -> str:
        return compact_repr(self, ("mean_px", "std_px", "max_px", "mean_norm", "ratio", "angle_deg", "scale",
                                   "n_nodes", "registration"))

    def to_dict(self) -> dict:
        """Every field (arrays as lists) as a JSON-ready dict."""
        return to_jsonable({f.name: getattr(self, f.name) for f in fields(self)})

    def summary(self) -> dict[str, float]:
        """The scalar metrics as a dict (for tables)."""
        return {k: getattr(self, k) for k in ("mean_px", "std_px", "max_px", "mean_norm", "std_norm",
                                              "max_norm", "ratio", "bias_px", "angle_deg", "n_nodes")}


def compare_contours(simulated_outline: ArrayLike, measured_contour: ArrayLike, *,
                     registration: str = "similarity", flip_y: bool = True, scaling: str = "uniform",
                     segments: tuple | None = None, refine: bool = True,
                     px_per_unit: float | None = None) -> ContourComparison:
    """Measure how far a simulated outline lies from a contour measured in a photograph.

    The paper's procedure: (1) rotational alignment, (2) both outlines scaled to a common size,
    (3) each simulated boundary node's distance to the measured contour by ``cv2.pointPolygonTest``,
    reported as mean, standard deviation and distance-difference ratio, in pixels and normalised.

    Deviation from the paper, on purpose: the paper scales both outlines into a unit (bounding)
    rectangle. Here the uniform scale makes the two *areas* equal and the translation puts the area
    centroids together, because a bounding rectangle rests on a few extreme points (contour noise and
    rounded corners move it) and on a frame that is arbitrary for shapes without a clear long axis.
    On 24 synthetic photographs of the bent T-shaped body in the README the self-distance fell from
    0.51 to 0.41 px on average at 1 degree camera tilt (1.50 to 1.23 px at 5 degrees). The normalised
    distances are still reported in a unit rectangle: the simulated outline's, see
    :class:`ContourComparison`.

    .. warning::
       Because the simulated outline is rescaled to the photograph (as in the paper), a simulation
       that is uniformly too large or too small by any factor scores as well as the right size: only
       shape differences show.
       When the photograph's scale is known (from the grid plate), pass ``px_per_unit`` to fix the
       scale instead of fitting it; then a size error shows as distance.

    Parameters
    ----------
    simulated_outline : array_like, shape (b, 2)
        Simulated boundary nodes in order (e.g. :func:`simulated_outline`), simulation coordinates.
    measured_contour : array_like, shape (k, 2)
        The measured contour in pixels (e.g. :func:`contour_from_image`).
    registration : {"similarity", "segment", "none"}
        ``"similarity"``: candidate rotations from the principal axes of both outlines (and a coarse
        sweep), the best refined to minimise the mean distance (``refine``); the scale and translation
        follow from ``scaling``.
        ``"segment"``: the rotation is the angle between two reference segments (``segments``), as in
        the paper; scaling as above. ``"none"``: the simulated outline is already in pixels.
    flip_y : bool
        Simulation coordinates point ``y`` up while pixel rows point down; mirror the simulated outline
        before registering (ignored for ``"none"``).
    scaling : {"uniform", "stretch"}
        ``"uniform"`` (shape kept): one scale that makes the areas equal, area centroids together.
        ``"stretch"``: each axis of the simulation's frame is scaled so that both bounding rectangles
        (the measured one in the simulation's orientation) become the same rectangle.
    segments : ((i, j), ((x0, y0), (x1, y1))), optional
        For ``"segment"``: integer node indices ``i, j`` into ``simulated_outline`` and the same two
        points in the photograph's pixels.
    refine : bool
        Refine the rotation for ``"similarity"``.
    px_per_unit : float, optional
        The photograph's scale in pixels per simulation length unit (e.g. measured on the grid plate).
        Fixes the registration's scale instead of fitting it, so a simulation of the wrong size scores
        worse. Only with ``scaling="uniform"`` and a fitted registration (not ``"none"``).

    Returns
    -------
    ContourComparison

    Example
    -------
    >>> import numpy as np
    >>> sq = np.array([[0, 0], [2, 0], [2, 1], [0, 1]], float)
    >>> px = np.array([[10, 10], [210, 10], [210, 110], [10, 110]], float)
    >>> r = compare_contours(sq, px)
    >>> round(r.mean_px, 6), round(r.scale, 3)
    (0.0, 100.0)
    """
    S = _as_contour(simulated_outline, "simulated_outline")
    M = _as_contour(measured_contour, "measured_contour")
    if registration not in ("similarity", "segment", "none"):
        raise ValueError(f"registration must be 'similarity', 'segment' or 'none', got {registration!r}")
    if scaling not in ("uniform", "stretch"):
        raise ValueError(f"scaling must be 'uniform' or 'stretch', got {scaling!r}")
    flip_y = _check_bool(flip_y, "flip_y")
    refine = _check_bool(refine, "refine")
    if px_per_unit is not None:
        px_per_unit = positive_float(px_per_unit, "px_per_unit")
        if registration == "none":
            raise ValueError("px_per_unit fixes the scale of a registration; registration='none' has "
                             "none (the outline is already in pixels)")
        if scaling != "uniform":
            raise ValueError("px_per_unit fixes one scale for both axes; use scaling='uniform'")
    M32 = M.astype(np.float32).reshape(-1, 1, 2)
    area_m = abs(polygon_area(M))
    cm, thm = _moments(M)
    Rm = _rot(-thm)                       # pixels -> measured principal frame (rotation candidates only)

    if registration == "none":
        A = np.hstack([np.eye(2), np.zeros((2, 1))])
        angle = 0.0
        scale = 1.0
        Q = np.eye(2)
    else:
        F = np.diag([1.0, -1.0]) if flip_y else np.eye(2)
        Sf = S @ F.T
        s_lo, s_hi = Sf.min(axis=0), Sf.max(axis=0)
        s_size, s_mid = s_hi - s_lo, 0.5 * (s_lo + s_hi)   # > 0: _as_contour rejects flat outlines
        cs, _ = _moments(Sf)
        # uniform scale: equal areas (or the known px_per_unit); area and centroid are integrals over
        # the whole outline, so neither noise at a few extreme points nor an arbitrary frame moves them
        s_uniform = px_per_unit if px_per_unit is not None else math.sqrt(area_m / abs(polygon_area(Sf)))

        def affine(theta: float) -> np.ndarray:
            Q = Rm.T @ _rot(theta)             # simulation axes (after the flip) -> pixel axes
            if scaling == "uniform":
                D = s_uniform * np.eye(2)
                return np.hstack([Q @ D @ F, (cm - Q @ D @ cs)[:, None]])
            # stretch: the bounding rectangles in the simulation's orientation are made to coincide
            Mq = M @ Q
            lo, hi = Mq.min(axis=0), Mq.max(axis=0)
            D = np.diag((hi - lo) / s_size)
            return np.hstack([Q @ D @ F, (Q @ (0.5 * (lo + hi) - D @ s_mid))[:, None]])

        to_contour = _PolylineDistance(M)  # one KD-tree for the whole rotation search

        def cost(theta: float) -> float:
            Aff = affine(theta)
            p = S @ Aff[:, :2].T + Aff[:, 2]
            return float(to_contour(p).mean())

        if registration == "segment":
            if segments is None:
                raise ValueError("registration='segment' needs segments=((i, j), ((x0, y0), (x1, y1)))")
            try:
                (i, j), (q0, q1) = segments
                q0, q1 = np.asarray(q0, float), np.asarray(q1, float)
            except (TypeError, ValueError):
                raise ValueError("segments must be ((i, j), ((x0, y0), (x1, y1)))") from None
            i, j = (_check_int(v, "segments node index") for v in (i, j))
            if not (0 <= i < len(S) and 0 <= j < len(S)) or i == j:
                raise ValueError(f"segment node indices must be two different indices in [0, {len(S)}), "
                                 f"got ({i}, {j})")
            if q0.shape != (2,) or q1.shape != (2,) or np.allclose(q0, q1):
                raise ValueError("the measured segment must be two different (x, y) points")
            ds = F @ (S[j] - S[i])
            dm = Rm @ (q1 - q0)
            theta = math.atan2(dm[1], dm[0]) - math.atan2(ds[1], ds[0])
        else:
            _, ths = _moments(Sf)
            cands = [-ths + k * math.pi / 2 for k in range(4)] + [k * math.pi / 12 for k in range(24)]
            costs = [cost(t) for t in cands]
            theta = cands[int(np.argmin(costs))]
            if refine:
                step = math.radians(8.0)
                t_best, f_best = _golden(cost, theta - step, theta + step, tol=1e-5)
                if f_best <= min(costs):
                    theta = t_best
        A = affine(theta)
        Q = Rm.T @ _rot(theta)
        lin = A[:, :2]
        det = float(np.linalg.det(lin))
        scale = math.sqrt(abs(det))
        Rw = (F @ lin) if flip_y else lin   # rotation part in the simulation's (y-up) frame
        angle = math.degrees(math.atan2(Rw[1, 0] - Rw[0, 1], Rw[0, 0] + Rw[1, 1]))

    Mq = M @ Q
    m_lo, m_size = Mq.min(axis=0), np.ptp(Mq, axis=0)
    if scaling == "stretch" and registration != "none":
        size_px = float(m_size.max())   # both rectangles coincide
    else:
        # the unit rectangle: the simulated outline's bounding rectangle in its own frame, in pixels
        size_px = scale * float(np.ptp(S, axis=0).max())
    P = S @ A[:, :2].T + A[:, 2]
    signed = _signed_distances(P, M32)
    dist = np.abs(signed)
    if registration != "none" and scaling == "stretch":
        # distances measured in the unit square, where both rectangles coincide
        Mn = ((Mq - m_lo) / m_size).astype(np.float32).reshape(-1, 1, 2)
        Pn = (P @ Q - m_lo) / m_size
        dn = np.abs(_signed_distances(Pn, Mn))
    else:
        dn = dist / size_px
    return ContourComparison(
        mean_px=float(dist.mean()), std_px=float(dist.std()), max_px=float(dist.max()),
        mean_norm=float(dn.mean()), std_norm=float(dn.std()), max_norm=float(dn.max()),
        ratio=float(dist.mean() / math.sqrt(area_m)), bias_px=float(signed.mean()),
        angle_deg=float(angle), scale=float(scale), size_px=size_px, n_nodes=len(S),
        distances_px=dist, signed_px=signed, simulated_px=P, measured_px=M, transform=A,
        registration=registration)


def simulated_loops(mesh, x: ArrayLike | None = None) -> list[np.ndarray]:
    """Every boundary loop of the mesh in state ``x``: the outer outline first (counter-clockwise), then
    the holes (clockwise), each (b, 2). Checks as :func:`simulated_outline`."""
    mesh = check_mesh(mesh)
    x = mesh.points if x is None else as_float_array(x, "x", shape=(mesh.n_nodes, 2))
    return [np.asarray(x)[loop] for loop in mesh.boundary_loops]


@dataclass(frozen=True, eq=False)
class LoopComparison:
    """How well a simulated body with holes fits a photographed one, loop by loop.

    Attributes
    ----------
    outer : ContourComparison
        The outer outline's comparison; its registration (rotation, scale, translation) maps the holes too.
    loops : list of dict
        One entry per simulated loop (outline first) and per photographed hole without a simulated
        counterpart: ``kind`` (``"outer"``, ``"hole"`` or ``"photo-only hole"``), ``index`` (simulated
        loop index, or the measured hole's for a photo-only hole), ``matched`` (index of the measured
        loop it was compared with, ``None`` when it has no counterpart), ``n``, ``mean_px``, ``std_px``,
        ``max_px``. A simulated hole with no counterpart is measured to the nearest photographed loop of
        any kind (a mouth painted shut: the distance to the lips' surroundings); a photographed hole with
        no counterpart, each of its points to the nearest simulated loop.
    mean_px, std_px, max_px : float
        Over every distance of every loop together (so a loop counts by its number of points).
    ratio : float
        ``mean_px`` over the square root of the area the measured outline encloses.
    n_unmatched : int
        Simulated holes without a photographed counterpart plus photographed holes without a simulated one.
    """

    outer: ContourComparison
    loops: list
    mean_px: float
    std_px: float
    max_px: float
    ratio: float
    n_unmatched: int

    def __repr__(self) -> str:
        return compact_repr(self, ("mean_px", "std_px", "max_px", "ratio", "n_unmatched"))

    def summary(self) -> dict:
        """The scalar metrics and the per-loop rows (JSON-ready)."""
        return {"mean_px": self.mean_px, "std_px": self.std_px, "max_px": self.max_px, "ratio": self.ratio,
                "n_unmatched": self.n_unmatched, "outer_mean_px": self.outer.mean_px,
                "loops": [dict(r) for r in self.loops]}


def compare_loops(simulated: Sequence[ArrayLike], measured: Sequence[ArrayLike], **compare) -> LoopComparison:
    """Compare a simulated body's outline and holes with a photograph's (e.g. :func:`simulated_loops` with
    :func:`contour_loops_from_image`).

    The outer outlines are registered and compared by :func:`compare_contours` (``compare`` holds its
    options). The same map takes every simulated hole into the photograph's pixels, where each is matched
    to its photographed counterpart: an optimal one-to-one assignment on centroid distance, a pair
    accepted only when the centroids lie closer than the larger hole's equivalent radius
    (``sqrt(area / pi)``) plus a fifth of the smaller's. Each simulated hole node is then measured to its
    counterpart by ``cv2.pointPolygonTest``; holes without a counterpart are measured as described in
    :class:`LoopComparison`, so a hole that is open in the simulation and shut in the photograph (or the
    reverse) costs its full distance.

    Raises
    ------
    ValueError
        An empty ``simulated`` or ``measured``, or loops that are not (k >= 3, 2) arrays.
    """
    from scipy.optimize import linear_sum_assignment

    if len(simulated) == 0 or len(measured) == 0:
        raise ValueError("simulated and measured need at least the outer outline each")
    S = [_as_contour(c, f"simulated[{i}]") for i, c in enumerate(simulated)]
    M = [_as_contour(c, f"measured[{i}]") for i, c in enumerate(measured)]
    outer = compare_contours(S[0], M[0], **compare)
    A = outer.transform
    Sp = [c @ A[:, :2].T + A[:, 2] for c in S[1:]]
    Mh = M[1:]

    def centre_radius(c):
        a = abs(polygon_area(c))
        return c.mean(axis=0), math.sqrt(a / math.pi)

    cs = [centre_radius(c) for c in Sp]
    cm = [centre_radius(c) for c in Mh]
    pairs: dict[int, int] = {}
    if Sp and Mh:
        C = np.array([[np.linalg.norm(a[0] - b[0]) for b in cm] for a in cs])
        for i, j in zip(*linear_sum_assignment(C)):
            if C[i, j] < max(cs[i][1], cm[j][1]) + 0.2 * min(cs[i][1], cm[j][1]):
                pairs[int(i)] = int(j)
    rows = [{"kind": "outer", "index": 0, "matched": 0, "n": int(outer.n_nodes), "mean_px": outer.mean_px,
             "std_px": outer.std_px, "max_px": outer.max_px}]
    every = [outer.distances_px]
    for i, p in enumerate(Sp):
        if i in pairs:
            d = np.abs(_signed_distances(p, Mh[pairs[i]].astype(np.float32).reshape(-1, 1, 2)))
        else:
            d = np.min([_unsigned_distances(p, m) for m in M], axis=0)
        every.append(d)
        rows.append({"kind": "hole", "index": i + 1, "matched": pairs[i] + 1 if i in pairs else None,
                     "n": len(d), "mean_px": float(d.mean()), "std_px": float(d.std()), "max_px": float(d.max())})
    sim_px = [outer.simulated_px] + Sp
    matched_m = set(pairs.values())
    for j, m in enumerate(Mh):
        if j in matched_m:
            continue
        d = np.min([_unsigned_distances(m, p) for p in sim_px], axis=0)
        every.append(d)
        rows.append({"kind": "photo-only hole", "index": j + 1, "matched": None, "n": len(d),
                     "mean_px": float(d.mean()), "std_px": float(d.std()), "max_px": float(d.max())})
    d = np.concatenate(every)
    n_un = (len(Sp) - len(pairs)) + (len(Mh) - len(matched_m))
    return LoopComparison(outer=outer, loops=rows, mean_px=float(d.mean()), std_px=float(d.std()),
                          max_px=float(d.max()), ratio=float(d.mean() / math.sqrt(abs(polygon_area(M[0])))),
                          n_unmatched=int(n_un))


def evaluate_image(image: ArrayLike | str | os.PathLike, mesh, x: ArrayLike | None = None, *,
                   extract: dict | None = None, **compare) -> ContourComparison:
    """Extract the contour of ``image`` and compare the outline of ``mesh`` in state ``x`` with it.

    ``extract`` holds keyword arguments of :func:`contour_from_image`; the rest go to
    :func:`compare_contours`.

    Example
    -------
    >>> from mdsr_opt import Mesh
    >>> mesh = Mesh.rectangle(3.0, 1.0, 6, 2)
    >>> r = evaluate_image(render_photo(mesh, resolution=(300, 200)).image, mesh)
    >>> bool(r.mean_norm < 0.01)
    True
    """
    outline = simulated_outline(mesh, x)  # checks mesh and x before the (slower) image work
    contour = contour_from_image(image, **(extract or {}))
    return compare_contours(outline, contour, **compare)


# ----------------------------------------------------------------------------------------------- camera
def _raster_triangles(pts: np.ndarray, triangles: np.ndarray, shape: tuple[int, int]) -> np.ndarray:
    """uint8 mask (255 inside) of the pixels whose centres lie in any triangle; exact edge functions
    (OpenCV's polygon filling adds up to a pixel along edges)."""
    Hf, Wf = shape
    mask = np.zeros(shape, dtype=np.uint8)
    for tri in np.asarray(triangles):
        P = pts[tri]
        if (P[1, 0] - P[0, 0]) * (P[2, 1] - P[0, 1]) - (P[1, 1] - P[0, 1]) * (P[2, 0] - P[0, 0]) < 0:
            P = P[::-1]
        x0, y0 = np.maximum(np.floor(P.min(axis=0)).astype(int), 0)
        x1, y1 = np.minimum(np.ceil(P.max(axis=0)).astype(int), [Wf - 1, Hf - 1])
        if x1 < x0 or y1 < y0:
            continue
        gx, gy = np.meshgrid(np.arange(x0, x1 + 1, dtype=float), np.arange(y0, y1 + 1, dtype=float))
        inside = np.ones(gx.shape, dtype=bool)
        for a, b in ((0, 1), (1, 2), (2, 0)):
            ex, ey = P[b] - P[a]
            inside &= ex * (gy - P[a, 1]) - ey * (gx - P[a, 0]) >= 0
        mask[y0:y1 + 1, x0:x1 + 1][inside] = 255
    return mask


def _apply_h(H: np.ndarray, pts: np.ndarray) -> np.ndarray:
    q = np.column_stack([pts, np.ones(len(pts))]) @ H.T
    return q[:, :2] / q[:, 2:3]


@dataclass(frozen=True, eq=False)
class SyntheticPhoto:
    """A rendered, photograph-like image of a simulated state. Always labelled synthetic.

    Photos are equal only if they are the same object (``eq=False``: they hold arrays).

    Attributes
    ----------
    image : numpy.ndarray
        (H, W, 3) ``uint8`` RGB, with a visible ``SYNTHETIC`` caption in a corner.
    world_to_pixel : numpy.ndarray
        (3, 3) homography from simulation coordinates to pixel coordinates (see :meth:`to_pixels`).
    metadata : dict
        Rendering parameters; ``metadata["synthetic"]`` is always True.
    """

    image: np.ndarray = field(repr=False)
    world_to_pixel: np.ndarray = field(repr=False)
    metadata: dict = field(default_factory=dict)

    @property
    def synthetic(self) -> bool:
        return True

    def __repr__(self) -> str:
        h, w = self.image.shape[:2]
        return f"SyntheticPhoto({w}x{h} px, seed={self.metadata.get('seed')}, SYNTHETIC)"

    def to_dict(self) -> dict:
        """The metadata and the homography (not the pixels: :meth:`save` writes those) as a JSON-ready dict."""
        return to_jsonable(dict(self.metadata, world_to_pixel=self.world_to_pixel, shape=self.image.shape))

    def to_pixels(self, points: ArrayLike) -> np.ndarray:
        """Map simulation coordinates (k, 2) to pixel coordinates (k, 2) of :attr:`image`."""
        p = as_float_array(points, "points", shape=(None, 2))
        return _apply_h(self.world_to_pixel, p)

    def save(self, path: str | os.PathLike) -> Path:
        """Write the image (PNG) and a ``.json`` sidecar with the metadata, as a pair.

        The sidecar carries ``"synthetic": true`` so :func:`evaluate_folder` marks the case synthetic.
        Both files are encoded first, written to temporary files and renamed together at the end (the
        sidecar first), so a failure leaves neither a PNG without its sidecar nor an orphan sidecar.
        """
        path = Path(path)
        _write_together(self._writers(path))
        return path

    def _writers(self, path: Path) -> list[tuple[Path, Callable[[str], None]]]:
        """The (path, writer) pairs of :meth:`save`, PNG first (so it is renamed last)."""
        if path.suffix.lower() != ".png":
            raise ValueError(f"synthetic photographs are saved as PNG; got {path.name}")
        ok, buf = cv2.imencode(".png", cv2.cvtColor(self.image, cv2.COLOR_RGB2BGR))
        if not ok:  # pragma: no cover - OpenCV failure
            raise ValueError(f"could not encode {path.name} as PNG")
        meta = dict(self.metadata, world_to_pixel=self.world_to_pixel.tolist())
        return [(path, _bytes_writer(buf.tobytes())),
                (path.with_suffix(".json"), _bytes_writer(json.dumps(meta, indent=2).encode()))]


def render_photo(mesh, x: ArrayLike | None = None, *, resolution: tuple[int, int] = (500, 500), seed: int = 0,
                 body_color: Any = (205, 95, 35), plate_color: Any = (226, 226, 218),
                 grid_color: Any = (185, 187, 183), grid_spacing: float | None = None,
                 margin: float = 0.12, rotation_deg: float = 0.0, tilt_deg: float = 1.0,
                 lighting: float = 0.2, vignette: float = 0.1, blur_sigma: float = 0.8,
                 noise_sigma: float = 3.0, supersample: int = 4) -> SyntheticPhoto:
    """Render a simulated state as a photograph-like image: a synthetic camera over a grid plate.

    The body (all triangles of ``mesh`` in state ``x``) is drawn in ``body_color`` on a plate with grid
    lines, seen by a camera looking almost straight down (a perspective tilt of ``tilt_deg`` about a
    random axis), under a lighting gradient and vignetting, then blurred and given Gaussian noise. The
    caption ``SYNTHETIC`` is written in a corner that does not touch the body. Everything random comes
    from ``seed``: the same arguments give the same image.

    Parameters
    ----------
    mesh : Mesh
    x : array_like, shape (n, 2), optional
        The state to photograph (default: the rest shape).
    resolution : (width, height)
        Image size in pixels: two integers, 32-8000.
    seed : int
        Non-negative seed of the tilt axis, light direction and noise.
    body_color, plate_color, grid_color : (r, g, b) in 0-255
    grid_spacing : float, optional
        Grid pitch in simulation units (default: a tenth of the body's larger extent, rounded).
    margin : float
        Fraction of the image left free around the body on its tighter side (0 < margin < 0.45).
    rotation_deg : float
        Rotation of the body on the plate, counter-clockwise in the simulation frame.
    tilt_deg : float
        Camera tilt away from straight down (perspective), degrees, 0-20.
    lighting, vignette : float
        Strength of the linear lighting gradient and of the radial darkening.
    blur_sigma, noise_sigma : float
        Gaussian blur (pixels) and Gaussian noise (grey levels 0-255).
    supersample : int
        Anti-aliasing factor of the rasterisation, an integer 1-8.

    Returns
    -------
    SyntheticPhoto

    Raises
    ------
    TypeError
        ``mesh`` is not a Mesh; ``resolution``, ``seed`` or ``supersample`` are not integers (no
        silent truncation of 2.5 to 2); ``rotation_deg`` or another setting is not a real number.
    ValueError
        A setting out of range, or an ``x`` of the wrong shape or with NaN/inf.

    Example
    -------
    >>> from mdsr_opt import Mesh
    >>> photo = render_photo(Mesh.rectangle(2.0, 1.0, 4, 2), resolution=(200, 120), seed=3)
    >>> photo.image.shape, photo.metadata["synthetic"]
    ((120, 200, 3), True)
    """
    mesh = check_mesh(mesh)
    x = mesh.points if x is None else as_float_array(x, "x", shape=(mesh.n_nodes, 2))
    if isinstance(resolution, (str, bytes)) or not hasattr(resolution, "__len__") or len(resolution) != 2:
        raise ValueError(f"resolution must be (width, height), two integers, got {resolution!r}")
    W, H = (_check_int(v, "resolution", 1) for v in resolution)
    if W < 32 or H < 32 or W > 8000 or H > 8000:
        raise ValueError(f"resolution must lie between 32 and 8000 pixels per side, got {W} x {H}")
    seed = _check_int(seed, "seed", lo=0)
    margin = positive_float(margin, "margin")
    if margin >= 0.45:
        raise ValueError(f"margin must be < 0.45, got {margin}")
    tilt = positive_float(tilt_deg, "tilt_deg", allow_zero=True)
    if tilt > 20.0:
        raise ValueError(f"tilt_deg must be <= 20 degrees, got {tilt}")
    for v, nm in ((lighting, "lighting"), (vignette, "vignette")):
        if positive_float(v, nm, allow_zero=True) >= 1.0:
            raise ValueError(f"{nm} must be < 1, got {v}")
    blur = positive_float(blur_sigma, "blur_sigma", allow_zero=True)
    noise = positive_float(noise_sigma, "noise_sigma", allow_zero=True)
    ss = _check_int(supersample, "supersample", 1, 8)
    if isinstance(rotation_deg, (bool, np.bool_)) or not isinstance(rotation_deg, numbers.Real):
        raise TypeError(f"rotation_deg must be a real number (degrees), got {type(rotation_deg).__name__}")
    rot = float(rotation_deg)
    if not math.isfinite(rot):
        raise ValueError(f"rotation_deg must be finite, got {rotation_deg!r}")
    body_rgb, plate_rgb, grid_rgb = (_check_color(c) for c in (body_color, plate_color, grid_color))
    rng = np.random.default_rng(seed)

    # world -> pixel: rotate on the plate, mirror y, fit roughly, tilt the camera, then fit exactly
    F = np.diag([1.0, -1.0])
    lin = F @ _rot(math.radians(rot))
    pts = x @ lin.T
    ext = np.ptp(pts, axis=0)
    if ext.max() <= 0:
        raise ValueError("the state has no extent: all nodes coincide")
    s0 = min(W, H) / ext.max()
    S0 = np.eye(3)
    S0[:2, :2] = s0 * lin
    S0[:2, 2] = np.array([W / 2.0, H / 2.0]) - s0 * (pts.min(axis=0) + pts.max(axis=0)) / 2.0
    f = 2.0 * max(W, H)
    K = np.array([[f, 0, (W - 1) / 2.0], [0, f, (H - 1) / 2.0], [0, 0, 1.0]])
    phi = rng.uniform(0.0, 2 * math.pi)
    axis = np.array([math.cos(phi), math.sin(phi), 0.0])
    R3, _ = cv2.Rodrigues(axis * math.radians(tilt))
    T = K @ R3 @ np.linalg.inv(K)
    HT = T @ S0
    q = _apply_h(HT, x)
    lo, hi = q.min(axis=0), q.max(axis=0)
    fit = min(W * (1 - 2 * margin) / (hi - lo)[0] if (hi - lo)[0] > 0 else np.inf,
              H * (1 - 2 * margin) / (hi - lo)[1] if (hi - lo)[1] > 0 else np.inf)
    Afit = np.array([[fit, 0, (W - 1) / 2.0 - fit * (lo[0] + hi[0]) / 2.0],
                     [0, fit, (H - 1) / 2.0 - fit * (lo[1] + hi[1]) / 2.0], [0, 0, 1.0]])
    Hw = Afit @ HT
    Hw = Hw / Hw[2, 2]

    # rasterise at ss x resolution; a pixel centre p maps to (p + 0.5) * ss - 0.5 on the fine canvas
    shift = 4

    def fine(p: np.ndarray) -> np.ndarray:
        return np.round(((p + 0.5) * ss - 0.5) * (1 << shift)).astype(np.int32)

    Wf, Hf = W * ss, H * ss
    canvas = np.empty((Hf, Wf, 3), dtype=np.float32)
    canvas[:] = plate_rgb
    # the grid is fixed to the plate: plate coordinates are the simulation's rotated by rotation_deg,
    # with a random phase (the plate is not aligned with the body's origin)
    Rp = np.eye(3)
    Rp[:2, :2] = _rot(math.radians(rot))
    Hp = Hw @ np.linalg.inv(Rp)                      # plate -> pixel
    corners = np.array([[-0.5, -0.5], [W - 0.5, -0.5], [W - 0.5, H - 0.5], [-0.5, H - 0.5]])
    wc = _apply_h(np.linalg.inv(Hp), corners)
    wlo, whi = wc.min(axis=0), wc.max(axis=0)
    if grid_spacing is None:
        e = float(np.ptp(x, axis=0).max()) / 10.0
        mag = 10.0 ** math.floor(math.log10(e))
        g = min((m * mag for m in (1.0, 2.0, 5.0, 10.0)), key=lambda v: abs(math.log(v / e)))
    else:
        g = positive_float(grid_spacing, "grid_spacing")
    if float(((whi - wlo) / g).max()) > 2000:
        raise ValueError(f"grid_spacing {g:g} draws more than 2000 grid lines; choose a larger spacing")
    phase = rng.uniform(0.0, g, size=2)
    thick = max(1, round(1.2 * ss * min(W, H) / 500.0))
    for axis_k in (0, 1):
        first = math.floor((wlo[axis_k] - phase[axis_k]) / g)
        last = math.ceil((whi[axis_k] - phase[axis_k]) / g)
        for k in range(first, last + 1):
            a = np.empty((2, 2))
            a[:, axis_k] = phase[axis_k] + k * g
            a[:, 1 - axis_k] = (wlo[1 - axis_k], whi[1 - axis_k])
            p0, p1 = fine(_apply_h(Hp, a))
            cv2.line(canvas, tuple(int(v) for v in p0), tuple(int(v) for v in p1), grid_rgb.tolist(),
                     thick, cv2.LINE_8, shift)
    mask = _raster_triangles(_apply_h(Hw, x) * ss + (ss - 1) / 2.0, mesh.triangles, (Hf, Wf))
    alpha = (mask.astype(np.float32) / 255.0)[..., None]
    canvas = canvas * (1.0 - alpha) + body_rgb.astype(np.float32) * alpha
    img = cv2.resize(canvas, (W, H), interpolation=cv2.INTER_AREA) if ss > 1 else canvas
    coverage = cv2.resize(mask, (W, H), interpolation=cv2.INTER_AREA) if ss > 1 else mask

    # light, optics, sensor
    psi = rng.uniform(0.0, 2 * math.pi)
    basis = _quadratic_basis(H, W)
    u, v = basis[..., 1], basis[..., 2]
    light = 1.0 + lighting * (u * math.cos(psi) + v * math.sin(psi)) / 2.0 - vignette * (u * u + v * v) / 2.0
    img = img * light[..., None].astype(np.float32)
    if blur > 0:
        img = cv2.GaussianBlur(img, (0, 0), blur)
    if noise > 0:
        img = img + rng.normal(0.0, noise, img.shape).astype(np.float32)
    img = np.clip(np.round(img), 0, 255).astype(np.uint8)

    # the caption, in the first corner whose box does not touch the (dilated) body
    text = "SYNTHETIC"
    font, fscale = cv2.FONT_HERSHEY_SIMPLEX, max(0.4, 0.5 * min(W, H) / 500.0)
    fthick = max(1, round(min(W, H) / 400.0))
    (tw, th), base = cv2.getTextSize(text, font, fscale, fthick)
    pad = max(3, round(min(W, H) / 100.0))
    body_px = cv2.dilate((coverage > 0).astype(np.uint8), np.ones((2 * pad + 1, 2 * pad + 1), np.uint8))
    boxes = {"bottom-left": (pad, H - pad - th - base), "bottom-right": (W - pad - tw, H - pad - th - base),
             "top-left": (pad, pad), "top-right": (W - pad - tw, pad)}
    corner = None
    for name, (bx, by) in boxes.items():
        if bx < 0 or by < 0:
            continue
        if not body_px[by:by + th + base + 1, bx:bx + tw + 1].any():
            corner = name
            break
    if corner is None:
        raise ValueError("no image corner is free of the body for the 'SYNTHETIC' caption; increase "
                         "margin or the resolution")
    bx, by = boxes[corner]
    cv2.putText(img, text, (bx, by + th), font, fscale, (20, 20, 20), fthick, cv2.LINE_AA)

    meta = {
        "synthetic": True, "generator": "mdsr_opt.evaluate.render_photo", "caption": text,
        "caption_corner": corner, "caption_box": [int(bx), int(by), int(tw), int(th + base)],
        "seed": seed,
        "resolution": [W, H], "rotation_deg": rot, "tilt_deg": tilt,
        "tilt_axis_deg": math.degrees(phi), "light_direction_deg": math.degrees(psi),
        "lighting": float(lighting), "vignette": float(vignette), "blur_sigma": blur, "noise_sigma": noise,
        "body_color": body_rgb.tolist(), "plate_color": plate_rgb.tolist(), "grid_spacing": g,
    }
    Hw.setflags(write=False)
    return SyntheticPhoto(image=img, world_to_pixel=Hw, metadata=meta)


# ----------------------------------------------------------------------------------------------- batch
@dataclass(frozen=True)
class CaseResult:
    """One row of an evaluation table: an image compared with the state of the same name."""

    case: str
    image: str
    state: str
    synthetic: bool
    comparison: ContourComparison

    def to_dict(self) -> dict:
        """The row with its comparison (arrays as lists) as a JSON-ready dict."""
        return {"case": self.case, "image": self.image, "state": self.state, "synthetic": self.synthetic,
                "comparison": self.comparison.to_dict()}


def _list_files(where: str | os.PathLike | Sequence, suffixes: tuple[str, ...], what: str) -> list[Path]:
    if isinstance(where, (str, os.PathLike)):
        p = Path(where)
        if not p.exists():
            raise FileNotFoundError(f"{what} folder does not exist: {p}")
        if p.is_dir():
            files = sorted(f for f in p.iterdir() if f.is_file() and f.suffix.lower() in suffixes)
            if not files:
                raise ValueError(f"no {what} files ({', '.join(suffixes)}) in {p}")
            return files
        return [p]
    files = [Path(f) for f in where]
    for f in files:
        if not f.exists():
            raise FileNotFoundError(f"{what} file does not exist: {f}")
    if not files:
        raise ValueError(f"no {what} files given")
    return files


def _is_synthetic(image_path: Path) -> bool:
    side = image_path.with_suffix(".json")
    if not side.is_file():
        return False
    try:
        return bool(json.loads(side.read_text()).get("synthetic", False))
    except (ValueError, OSError, AttributeError):
        return False


def evaluate_folder(images: str | os.PathLike | Sequence, states: str | os.PathLike | Sequence, *,
                    out: str | os.PathLike | None = None, name: str = "evaluation",
                    extract: dict | None = None, compare: dict | None = None,
                    figures: bool = False) -> list[CaseResult]:
    """Compare every image of a folder with the simulated state of the same name; write a table.

    Parameters
    ----------
    images : folder or list of image files
        Photographs (``.png``, ``.jpg``, ...). An image ``case.png`` is compared with the state file
        ``case.*`` in ``states``. A ``case.json`` sidecar with ``"synthetic": true`` (written by
        :meth:`SyntheticPhoto.save`) marks the case synthetic in the table.
    states : folder or list of mesh files
        States in a format of :mod:`mdsr_opt.io` (``.vtu``, ``.vtk``, ``.xdmf``, ``.msh``; rest mesh plus
        ``displacement``, or points holding the deformed state). Other files in a states folder (a
        ``case.svg`` figure, say) are ignored.
    out : folder, optional
        Where to write ``<name>.csv`` and ``<name>.md`` (and ``<case>_overlay.png`` with ``figures``).
        Everything, figures included, is computed before anything is written; then every file goes to
        a temporary file beside its target and all are renamed together at the end. An error therefore
        leaves the previous files untouched and no partial set (only a failing rename itself, e.g. a
        target that is a folder, could leave part of the set renamed).
    name : str
        Base name of the table files.
    extract, compare : dict, optional
        Keyword arguments of :func:`contour_from_image` and :func:`compare_contours`.
    figures : bool
        Also write an overlay figure per case.

    Returns
    -------
    list of CaseResult, in the order of the image names.

    Raises
    ------
    FileNotFoundError
        A folder or listed file does not exist.
    ValueError
        No images or states, an image without a state (or two states for one case), or any error while
        reading, extracting or comparing a case: the message starts with ``case '<name>':`` and the
        original exception is chained (``__cause__``).

    Example
    -------
    >>> import tempfile
    >>> from mdsr_opt import Mesh
    >>> from mdsr_opt.io import write_mesh
    >>> mesh = Mesh.rectangle(3.0, 1.0, 6, 2)
    >>> with tempfile.TemporaryDirectory() as d:
    ...     _ = write_mesh(f"{d}/states/bent.vtu", mesh, x=mesh.points * [1.0, 0.8])
    ...     _ = render_photo(mesh, mesh.points * [1.0, 0.8], resolution=(300, 200)).save(f"{d}/img/bent.png")
    ...     rows = evaluate_folder(f"{d}/img", f"{d}/states", out=f"{d}/out")
    >>> rows[0].case, rows[0].synthetic, bool(rows[0].comparison.mean_px < 1.0)
    ('bent', True, True)
    """
    from .io import read_mesh

    if not isinstance(name, str) or not name or any(c in name for c in "/\\") or name.startswith("."):
        raise ValueError(f"name must be a plain file stem, got {name!r}")
    image_files = _list_files(images, IMAGE_SUFFIXES, "image")
    state_files = _list_files(states, STATE_SUFFIXES, "state")
    by_stem: dict[str, Path] = {}
    for f in state_files:
        if f.stem in by_stem:
            raise ValueError(f"two state files for case {f.stem!r}: {by_stem[f.stem].name} and {f.name}")
        by_stem[f.stem] = f
    missing = [f.name for f in image_files if f.stem not in by_stem]
    if missing:
        raise ValueError(f"no state file for image(s) {', '.join(missing)} (states are matched by file name "
                         f"without extension; available: {', '.join(sorted(by_stem)) or 'none'})")
    seen: set[str] = set()
    results, overlays = [], []
    for img_path in image_files:
        case = img_path.stem
        if case in seen:
            raise ValueError(f"two images for case {case!r}")
        seen.add(case)
        try:
            data = read_mesh(by_stem[case])
            image = load_image(img_path)
            contour = contour_from_image(image, **(extract or {}))
            comp = compare_contours(simulated_outline(data.mesh, data.x), contour, **(compare or {}))
        except (ValueError, TypeError, OSError, cv2.error) as exc:
            # one type for every per-case failure (re-raising type(exc) breaks for exceptions whose
            # constructors need more arguments); the original is chained
            raise ValueError(f"case {case!r}: {exc}") from exc
        results.append(CaseResult(case, str(img_path), str(by_stem[case]), _is_synthetic(img_path), comp))
        if figures:
            overlays.append((image, data.mesh, data.x, comp, results[-1].synthetic))
    if out is not None:
        out = Path(out)
        writers = _table_writers(results, out / f"{name}.csv", out / f"{name}.md")
        if figures:
            from . import plot

            # render every figure to PNG bytes now (one figure open at a time), write with the tables
            with tempfile.TemporaryDirectory() as scratch:
                for k, ((image, mesh, x, comp, synth), row) in enumerate(zip(overlays, results)):
                    fig = plot.plot_overlay(image, mesh, x, comp, synthetic=synth, title=row.case)
                    try:
                        png = Path(plot.save_figure(fig, Path(scratch, f"{k}.png")))
                    finally:
                        plot.close_figure(fig)
                    writers.insert(k, (out / f"{row.case}_overlay.png", _bytes_writer(png.read_bytes())))
        _write_together(writers)
    return results


def _table_rows(results: Sequence[CaseResult]) -> list[dict[str, Any]]:
    rows = []
    for r in results:
        c = r.comparison
        rows.append({"case": r.case, "source": "synthetic" if r.synthetic else "photo",
                     "mean_px": c.mean_px, "std_px": c.std_px, "max_px": c.max_px,
                     "mean_norm": c.mean_norm, "std_norm": c.std_norm, "ratio": c.ratio,
                     "bias_px": c.bias_px, "angle_deg": c.angle_deg, "n_nodes": c.n_nodes,
                     "image": r.image, "state": r.state})
    return rows


def write_table(results: Sequence[CaseResult], csv_path: str | os.PathLike,
                md_path: str | os.PathLike | None = None) -> list[Path]:
    """Write the evaluation table as CSV (all fields) and Markdown (like the paper's Tables 2-4).

    Both files are first written to temporary files beside their targets and then renamed together, so
    an error leaves the previous files (if any) untouched and never a partial file or a lone table.

    Example
    -------
    >>> import tempfile, numpy as np
    >>> sq = np.array([[0, 0], [2, 0], [2, 1], [0, 1]], float)
    >>> r = CaseResult("a", "a.png", "a.vtu", False, compare_contours(sq, sq * [100, -100]))
    >>> with tempfile.TemporaryDirectory() as d:
    ...     paths = write_table([r], f"{d}/t.csv", f"{d}/t.md")
    ...     print(open(paths[0]).readline().strip()[:30])
    case,source,mean_px,std_px,max
    """
    return _write_together(_table_writers(results, csv_path, md_path))


def _table_writers(results: Sequence[CaseResult], csv_path: str | os.PathLike,
                   md_path: str | os.PathLike | None) -> list[tuple[Path, Callable[[str], None]]]:
    if not results:
        raise ValueError("no results to write")
    rows = _table_rows(results)
    buf = io.StringIO()
    writer = csv.DictWriter(buf, fieldnames=list(rows[0]), lineterminator="\n")
    writer.writeheader()
    for row in rows:
        writer.writerow({k: (f"{v:.6g}" if isinstance(v, float) else v) for k, v in row.items()})
    writers = [(Path(csv_path), _bytes_writer(buf.getvalue().encode()))]
    if md_path is not None:
        lines = ["| Case | Source | Average distance d (px) | Standard deviation (px) | Max (px) | "
                 "d normalised | Ratio d/size (%) |",
                 "| --- | --- | ---: | ---: | ---: | ---: | ---: |"]
        for row in rows:
            lines.append(f"| {row['case']} | {row['source']} | {row['mean_px']:.2f} | {row['std_px']:.2f} | "
                         f"{row['max_px']:.2f} | {row['mean_norm']:.4f} | {100 * row['ratio']:.2f} |")
        mean = {k: float(np.mean([row[k] for row in rows])) for k in ("mean_px", "std_px", "max_px",
                                                                        "mean_norm", "ratio")}
        lines.append(f"| **mean** | | {mean['mean_px']:.2f} | {mean['std_px']:.2f} | {mean['max_px']:.2f} | "
                     f"{mean['mean_norm']:.4f} | {100 * mean['ratio']:.2f} |")
        lines.append("")
        lines.append("d: mean distance of the simulated boundary nodes to the measured contour "
                     "(cv2.pointPolygonTest); normalised: in the unit rectangle (the simulated outline's "
                     "bounding rectangle at the registered scale, longer side 1); ratio: d over the "
                     "square root of the measured contour's area.")
        if any(row["source"] == "synthetic" for row in rows):
            lines.append("")
            lines.append("**SYNTHETIC**: rows marked synthetic compare with images rendered by the synthetic "
                         "camera (mdsr_opt.evaluate.render_photo), not with photographs of a prototype.")
        writers.append((Path(md_path), _bytes_writer(("\n".join(lines) + "\n").encode())))
    return writers


# ----------------------------------------------------------------------------------------------- command
def _parse_color(text: str):
    import argparse

    t = text.strip()
    if t.startswith("#"):
        try:
            return _check_color(t)
        except ValueError as exc:
            raise argparse.ArgumentTypeError(str(exc)) from None
    try:
        vals = [float(v) for v in t.split(",")]
        return _check_color(vals)
    except ValueError:
        raise argparse.ArgumentTypeError(f"color must be R,G,B (0-255) or #rrggbb, got {text!r}") from None


def _parse_ints(n: int, what: str, sep: str = ","):
    import argparse

    def parse(text: str):
        try:
            vals = tuple(int(v) for v in text.lower().split(sep))
        except ValueError:
            vals = ()
        if len(vals) != n:
            raise argparse.ArgumentTypeError(f"{what} must be {n} integers separated by {sep!r}, got {text!r}")
        return vals

    return parse


def _cmd_evaluate(a) -> int:
    extract = {"method": a.method, "body": a.body, "largest": a.largest}
    if a.color is not None:
        extract["color"] = a.color
    if a.roi is not None:
        extract["roi"] = a.roi
    compare = {"registration": a.registration, "flip_y": not a.no_flip, "scaling": a.scaling}
    results = evaluate_folder(a.images, a.states, out=a.out, name=a.name, extract=extract, compare=compare,
                              figures=a.figures)
    print(Path(a.out, f"{a.name}.md").read_text(), end="")
    print(f"wrote {Path(a.out, a.name + '.csv')} and {Path(a.out, a.name + '.md')} ({len(results)} case(s))")
    return 0


def _cmd_photograph(a) -> int:
    from .io import read_mesh

    files = _list_files(a.states, STATE_SUFFIXES, "state")
    stems = [f.stem for f in files]
    twice = sorted({st for st in stems if stems.count(st) > 1})
    if twice:
        raise ValueError(f"two state files for case(s) {', '.join(twice)}: each would give {twice[0]}.png")
    writers = []
    for f in files:  # render and encode everything first, then write the whole set at once
        data = read_mesh(f)
        ph = render_photo(data.mesh, data.x, resolution=a.resolution, seed=a.seed, tilt_deg=a.tilt,
                          rotation_deg=a.rotation, noise_sigma=a.noise, blur_sigma=a.blur,
                          lighting=a.lighting)
        writers += ph._writers(Path(a.out) / f"{f.stem}.png")
    for path in _write_together(writers):
        if path.suffix == ".png":
            print(f"wrote {path} (SYNTHETIC, seed {a.seed})")
    return 0


def add_cli(sub) -> None:
    """Register ``mdsr evaluate`` (a folder of images against states) and ``mdsr photograph``."""
    p = sub.add_parser("evaluate", help="compare photographs with simulated states; write a CSV and "
                       "Markdown table of contour distances")
    p.add_argument("images", help="folder of images (.png/.jpg/...); case.png is compared with case.*")
    p.add_argument("states", help="folder of state mesh files (.vtu/.vtk/.xdmf/.msh)")
    p.add_argument("--out", default="evaluation_out", help="output folder (default: evaluation_out)")
    p.add_argument("--name", default="evaluation", help="table file stem (default: evaluation)")
    p.add_argument("--color", type=_parse_color, default=None,
                   help="body colour R,G,B or #rrggbb (switches to colour segmentation)")
    p.add_argument("--method", choices=("auto", "otsu", "adaptive", "color"), default="auto",
                   help="segmentation: Otsu on the flattened grey image, adaptive threshold, or colour "
                   "distance (default auto: colour when --color is given, else Otsu)")
    p.add_argument("--body", choices=("auto", "dark", "light"), default="auto",
                   help="is the body darker or lighter than the plate (default auto: the plate is what covers most of "
                   "the image border)")
    p.add_argument("--roi", type=_parse_ints(4, "roi"), default=None, help="X,Y,W,H search rectangle")
    p.add_argument("--largest", action="store_true", help="keep the largest of several blobs")
    p.add_argument("--registration", choices=("similarity", "none"), default="similarity",
                   help="fit rotation, scale and shift of the simulated outline (default), or none: states "
                   "already in pixels")
    p.add_argument("--scaling", choices=("uniform", "stretch"), default="uniform",
                   help="one scale matching the areas (default), or per-axis scales matching the bounding "
                   "rectangles")
    p.add_argument("--no-flip", action="store_true", help="states are already in image orientation (y down)")
    p.add_argument("--figures", action="store_true", help="also write <case>_overlay.png")
    p.set_defaults(func=_cmd_evaluate)

    q = sub.add_parser("photograph", help="render states as SYNTHETIC photographs (synthetic camera)")
    q.add_argument("states", help="a state mesh file or a folder of them")
    q.add_argument("--out", required=True, help="output folder for <state>.png and <state>.json")
    q.add_argument("--seed", type=int, default=0, help="random seed of noise and placement (default 0)")
    q.add_argument("--resolution", type=_parse_ints(2, "resolution", "x"), default=(500, 500),
                   help="WIDTHxHEIGHT (default 500x500)")
    q.add_argument("--tilt", type=float, default=1.0, help="camera tilt, degrees (default 1)")
    q.add_argument("--rotation", type=float, default=0.0, help="body rotation on the plate, degrees")
    q.add_argument("--noise", type=float, default=3.0, help="noise sigma, grey levels (default 3)")
    q.add_argument("--blur", type=float, default=0.8, help="blur sigma, pixels (default 0.8)")
    q.add_argument("--lighting", type=float, default=0.2, help="lighting gradient strength (default 0.2)")
    q.set_defaults(func=_cmd_photograph)
