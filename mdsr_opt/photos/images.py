"""Images in: reading any dtype by its real value range, regions of interest, size guards."""

from __future__ import annotations

import math
import os
import warnings
from pathlib import Path
from typing import Any, Sequence
import cv2
import numpy as np
from numpy.typing import ArrayLike

from ..core.checks import as_float_array, check_int

__all__ = ['load_image']


#: Default limit on the pixels of the searched region (the image, or its ``roi``) of
#: :func:`contour_from_image` and :func:`body_mask`; raise it with ``max_pixels=``. Extraction takes
#: about 60 MB per megapixel, so 25 megapixels (a 6000 x 4000 photograph) need about 1.5 GB.
MAX_PIXELS = 25_000_000


IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg", ".bmp", ".tif", ".tiff")


def check_bool(value: Any, name: str) -> bool:
    if not isinstance(value, (bool, np.bool_)):
        raise TypeError(f"{name} must be True or False, got {type(value).__name__} {value!r}")
    return bool(value)


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


def load_region(image: Any, roi: Sequence[int] | None, max_pixels: Any) -> tuple[np.ndarray, tuple]:
    """Load ``image`` and check ``roi`` and the size of the searched region before any image work.

    For an array the size is checked before its pixels are converted; a file has to be decoded first.
    """
    limit = check_int(max_pixels, "max_pixels", lo=1)
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


def check_color(color: Any) -> np.ndarray:
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
