"""A synthetic camera: photograph-like images of simulated states, captioned SYNTHETIC."""

from __future__ import annotations

import json
import math
import numbers
import os
import threading
from collections import OrderedDict
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable
import cv2
import numpy as np
from numpy.typing import ArrayLike

from ..body.checks import check_mesh
from ..core.checks import as_float_array, check_int, positive_float
from ..core.errors import InputError, checking_input
from ..core.results import to_jsonable
from .compare import rotation_matrix
from .folder import bytes_writer, write_together
from .images import check_color
from .size import check_photo_size

__all__ = ['SyntheticPhoto', 'render_photo']


# ----------------------------------------------------------------------------------------------- camera
def _raster_triangles(pts: np.ndarray, triangles: np.ndarray, shape: tuple[int, int],
                      value: int = 255) -> np.ndarray:
    """uint8 mask (``value`` inside, 0 outside) of the pixels whose centres lie in any triangle; exact
    edge functions (OpenCV's polygon filling adds up to a pixel along edges). Scanlines: per triangle and
    pixel row, the span of centres inside is found from each edge's crossing and checked with the edge
    function itself (so the mask is the per-pixel test's exactly); the spans of each row are merged into
    runs, and the runs (a few per row) are filled."""
    Hf, Wf = shape
    mask = np.zeros(shape, dtype=np.uint8)
    P = np.asarray(pts, dtype=float)[np.asarray(triangles)]
    if not len(P):
        return mask
    cross = (P[:, 1, 0] - P[:, 0, 0]) * (P[:, 2, 1] - P[:, 0, 1]) - (P[:, 1, 1] - P[:, 0, 1]) * (P[:, 2, 0] - P[:, 0, 0])
    P = np.where((cross < 0)[:, None, None], P[:, ::-1], P)  # counter-clockwise (in pixel axes)
    lo_xy = np.maximum(np.floor(P.min(axis=1)).astype(np.int64), 0)
    hi_xy = np.minimum(np.ceil(P.max(axis=1)).astype(np.int64), [Wf - 1, Hf - 1])
    keep = np.flatnonzero((hi_xy >= lo_xy).all(axis=1))
    P, lo_xy, hi_xy = P[keep], lo_xy[keep], hi_xy[keep]
    nrow = hi_xy[:, 1] - lo_xy[:, 1] + 1
    t = np.repeat(np.arange(len(P)), nrow)                              # (triangle, row) pairs
    row = lo_xy[t, 1] + np.arange(len(t)) - np.repeat(np.cumsum(nrow) - nrow, nrow)
    gy = row.astype(float)
    x0, x1 = lo_xy[:, 0][t], hi_xy[:, 0][t]
    lo, hi = x0.copy(), x1.copy()
    for a, b in ((0, 1), (1, 2), (2, 0)):
        # per pair, gathered from per-triangle columns (the same numbers as P[t, a] and P[t, b] - P[t, a])
        ax_, ay_ = P[:, a, 0], P[:, a, 1]
        Ax, Ay = ax_[t], ay_[t]
        ex, ey = (P[:, b, 0] - ax_)[t], (P[:, b, 1] - ay_)[t]
        c = ex * (gy - Ay)
        flat = ey == 0
        hi[flat & (c < 0)] = -1                                          # the whole row is outside
        with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
            cut = np.clip(Ax + c / np.where(flat, 1.0, ey), x0 - 2.0, x1 + 2.0)
        up = np.flatnonzero(ey > 0)                                      # inside: gx <= cut
        hi[up] = np.minimum(hi[up], _last_inside(np.floor(cut[up]).astype(np.int64), c[up], ey[up], Ax[up],
                                                 x0[up], x1[up], 1))
        dn = np.flatnonzero(ey < 0)                                      # inside: gx >= cut
        lo[dn] = np.maximum(lo[dn], _last_inside(np.ceil(cut[dn]).astype(np.int64), c[dn], ey[dn], Ax[dn],
                                                 x1[dn], x0[dn], -1))
    s = np.flatnonzero(lo <= hi)
    if not len(s):
        return mask
    # the spans of each row merged into runs: sorted by (row, lo, hi) in one packed key, a run ends where the
    # next span starts beyond the farthest end so far (+1: touching spans join)
    bits = max(Wf, Hf).bit_length() + 1
    key = np.sort((row[s] << (2 * bits)) | (lo[s] << bits) | (hi[s] + 1))
    rs, ls, he1 = key >> (2 * bits), (key >> bits) & ((1 << bits) - 1), key & ((1 << bits) - 1)
    far = np.maximum.accumulate((rs << bits) | he1)                      # (row, end + 1) of the run so far
    start = np.ones(len(key), dtype=bool)
    start[1:] = ((rs[1:] << bits) | ls[1:]) > far[:-1]
    first = np.flatnonzero(start)
    last = np.append(first[1:], len(key)) - 1
    v = np.uint8(value)
    for r, l0, l1 in zip(rs[first].tolist(), ls[first].tolist(), (far[last] & ((1 << bits) - 1)).tolist()):
        mask[r, l0:l1] = v
    return mask


def _last_inside(u, c, ey, ax, near, far, step):
    """The last column from ``u`` towards ``far`` (``step`` +1 or -1) whose centre passes the edge test
    ``c - ey * (gx - ax) >= 0``, at most one step past ``near`` when none does: first forward while the next
    column passes, then back while the column fails (the estimate ``u`` from the edge's crossing is almost
    always right; only the pairs that move are tested again)."""
    def inside(i, gx):
        return c[i] - ey[i] * (gx.astype(float) - ax[i]) >= 0

    i = np.arange(len(u))
    while len(i):
        nxt = u[i] + step
        m = ((nxt <= far[i]) if step > 0 else (nxt >= far[i])) & inside(i, nxt)
        i = i[m]
        u[i] += step
    i = np.arange(len(u))
    while len(i):
        m = ((u[i] >= near[i]) if step > 0 else (u[i] <= near[i])) & ~inside(i, u[i])
        i = i[m]
        u[i] -= step
    return u


def _compose_canvas(lines, thick, shift, body_fine, triangles, colors, size, ss):
    """The plate, its grid lines and the body painted on a canvas ``ss`` times finer than the image and
    averaged down (``INTER_AREA``): ``(image float32 (H, W, 3), covered (H, W) bool: pixels the body
    touches)``. The general path (any colours, any ``ss``); :func:`_compose_counts` is the fast one."""
    plate_rgb, grid_rgb, body_rgb = colors
    W, H = size
    Wf, Hf = W * ss, H * ss
    # with whole-number colours every value on the fine canvas is whole (grid lines without anti-aliasing),
    # so it is held in uint8 (a quarter of float32's memory traffic) and averaged down exactly
    whole = all(bool(np.all(c == np.round(c))) for c in colors)
    canvas = np.empty((Hf, Wf, 3), dtype=np.uint8 if whole else np.float32)
    canvas[0] = plate_rgb
    canvas[1:] = canvas[0]  # row by row: far cheaper than broadcasting a colour over every pixel
    for p0, p1 in lines:
        cv2.line(canvas, p0, p1, grid_rgb.tolist(), thick, cv2.LINE_8, shift)
    mask = _raster_triangles(body_fine, triangles, (Hf, Wf))
    # the mask is 0 or 255: blending by it is painting the body's colour where it is set
    if whole:
        paint = np.empty_like(canvas)
        paint[0] = body_rgb
        paint[1:] = paint[0]
        canvas = cv2.copyTo(paint, mask, canvas)  # a tenth of the time of canvas[mask > 0] = body_rgb
    else:
        canvas[mask > 0] = body_rgb
    canvas = canvas.astype(np.float32, copy=False)
    img = cv2.resize(canvas, (W, H), interpolation=cv2.INTER_AREA) if ss > 1 else canvas
    coverage = cv2.resize(mask, (W, H), interpolation=cv2.INTER_AREA) if ss > 1 else mask
    return img, coverage > 0


def _compose_counts(lines, thick, shift, body_fine, triangles, colors, size, ss):
    """:func:`_compose_canvas` for whole-number colours and ``ss`` in 1, 2, 4, 8, with the same pixels from
    counts instead of a colour canvas: each fine pixel is the body's, else a grid line's, else the plate's
    colour, so an image pixel (the mean of its ``ss * ss`` fine pixels) is ``(n_plate * plate + n_grid *
    grid + n_body * body) / ss**2``. The counts come from two one-channel masks whose set pixels hold
    ``ss**2`` (their ``INTER_AREA`` average is the count, exactly); the means, whole numbers over a power of
    two, are exact in float32 as ``INTER_AREA``'s are, so the image is the canvas path's bit for bit
    (tests/test_photo_speed.py) at a third of the memory traffic and no float canvas."""
    W, H = size
    Wf, Hf = W * ss, H * ss
    n = ss * ss
    grid = np.zeros((Hf, Wf), dtype=np.uint8)
    for p0, p1 in lines:
        cv2.line(grid, p0, p1, n, thick, cv2.LINE_8, shift)
    body = _raster_triangles(body_fine, triangles, (Hf, Wf), value=n)
    grid = cv2.subtract(grid, body, dst=grid)  # grid pixels the body covers are the body's
    if ss > 1:
        grid = cv2.resize(grid, (W, H), interpolation=cv2.INTER_AREA)
        body = cv2.resize(body, (W, H), interpolation=cv2.INTER_AREA)
    # every (n_grid, n_body) pair's colour: whole numbers (< 2**14) over n, exact in float64 and float32
    k = np.arange(n + 1, dtype=float)
    plate_rgb, grid_rgb, body_rgb = (np.asarray(c, dtype=float) for c in colors)
    lut = ((n - k[:, None, None] - k[None, :, None]) * plate_rgb + k[:, None, None] * grid_rgb
           + k[None, :, None] * body_rgb) / n
    img = np.take(lut.astype(np.float32).reshape(-1, 3), grid.astype(np.uint16) * np.uint16(n + 1) + body, axis=0)
    return img, body > 0


#: The sensor noise of the latest (seed, sigma, size)s: the noise of a photograph depends on its seed alone
#: (the draws before it, tilt axis, grid phase and light direction, take a fixed count of numbers), and a run
#: photographs many states with the same seed (each case's design and prototype photos): a copy from the
#: cache is much cheaper than drawing the Gaussian numbers again.
_NOISE: OrderedDict = OrderedDict()
_NOISE_LOCK = threading.Lock()


def _sensor_noise(rng: np.random.Generator, seed: int, sigma: float, shape: tuple) -> np.ndarray:
    """``rng.normal(0, sigma, shape)`` as float32, from ``rng`` (seeded with ``seed`` and at the state every
    photograph with that seed reaches here) or from the cache; read-only."""
    key = (seed, sigma, tuple(shape))
    with _NOISE_LOCK:
        hit = _NOISE.get(key)
        if hit is not None:
            _NOISE.move_to_end(key)
            return hit
    out = rng.normal(0.0, sigma, shape).astype(np.float32)
    out.setflags(write=False)
    with _NOISE_LOCK:
        _NOISE[key] = out
        while len(_NOISE) > 4:
            _NOISE.popitem(last=False)
    return out


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
        write_together(self.writers(path))
        return path

    def writers(self, path: str | os.PathLike) -> list[tuple[Path, Callable[[str], None]]]:
        """The (path, writer) pairs of :meth:`save`, encoded now, PNG first (so it is renamed last): for
        writing several photographs together (:func:`~mdsr_opt.photos.folder.write_together`)."""
        path = Path(path)
        if path.suffix.lower() != ".png":
            raise ValueError(f"synthetic photographs are saved as PNG; got {path.name}")
        ok, buf = cv2.imencode(".png", cv2.cvtColor(self.image, cv2.COLOR_RGB2BGR))
        if not ok:  # pragma: no cover - OpenCV failure
            raise ValueError(f"could not encode {path.name} as PNG")
        meta = dict(self.metadata, world_to_pixel=self.world_to_pixel.tolist())
        return [(path, bytes_writer(buf.tobytes())),
                (path.with_suffix(".json"), bytes_writer(json.dumps(meta, indent=2).encode()))]


def render_photo(mesh, x: ArrayLike | None = None, *, image_size: tuple[int, int] = (500, 500), seed: int = 0,
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
    image_size : (int, int)
        (width, height) of the image in pixels, each 32-8000.
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
        ``mesh`` is not a Mesh; ``image_size``, ``seed`` or ``supersample`` are not integers (no
        silent truncation of 2.5 to 2); ``rotation_deg`` or another setting is not a real number.
    ValueError
        A setting out of range, or an ``x`` of the wrong shape or with NaN/inf.

    Example
    -------
    >>> from mdsr_opt import Mesh
    >>> photo = render_photo(Mesh.rectangle(2.0, 1.0, 4, 2), image_size=(200, 120), seed=3)
    >>> photo.image.shape, photo.metadata["synthetic"]
    ((120, 200, 3), True)
    """
    with checking_input():  # every argument before any drawing: bad input
        mesh = check_mesh(mesh)
        x = mesh.points if x is None else as_float_array(x, "x", shape=(mesh.n_nodes, 2))
        W, H = check_photo_size(image_size, "image_size")
        seed = check_int(seed, "seed", lo=0)
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
        ss = check_int(supersample, "supersample", 1, 8)
        if isinstance(rotation_deg, (bool, np.bool_)) or not isinstance(rotation_deg, numbers.Real):
            raise TypeError(f"rotation_deg must be a real number (degrees), got {type(rotation_deg).__name__}")
        rot = float(rotation_deg)
        if not math.isfinite(rot):
            raise ValueError(f"rotation_deg must be finite, got {rotation_deg!r}")
        body_rgb, plate_rgb, grid_rgb = (check_color(c) for c in (body_color, plate_color, grid_color))
    rng = np.random.default_rng(seed)

    # world -> pixel: rotate on the plate, mirror y, fit roughly, tilt the camera, then fit exactly
    F = np.diag([1.0, -1.0])
    lin = F @ rotation_matrix(math.radians(rot))
    pts = x @ lin.T
    ext = np.ptp(pts, axis=0)
    if ext.max() <= 0:
        raise InputError("the state has no extent: all nodes coincide")
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

    # the grid is fixed to the plate: plate coordinates are the simulation's rotated by rotation_deg,
    # with a random phase (the plate is not aligned with the body's origin)
    Rp = np.eye(3)
    Rp[:2, :2] = rotation_matrix(math.radians(rot))
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
    lines = []
    for axis_k in (0, 1):
        first = math.floor((wlo[axis_k] - phase[axis_k]) / g)
        last = math.ceil((whi[axis_k] - phase[axis_k]) / g)
        for k in range(first, last + 1):
            a = np.empty((2, 2))
            a[:, axis_k] = phase[axis_k] + k * g
            a[:, 1 - axis_k] = (wlo[1 - axis_k], whi[1 - axis_k])
            p0, p1 = fine(_apply_h(Hp, a))
            lines.append((tuple(int(v) for v in p0), tuple(int(v) for v in p1)))
    body_fine = _apply_h(Hw, x) * ss + (ss - 1) / 2.0
    colors = (plate_rgb, grid_rgb, body_rgb)
    if all(bool(np.all(c == np.round(c))) for c in colors) and ss in (1, 2, 4, 8):
        img, covered = _compose_counts(lines, thick, shift, body_fine, mesh.triangles, colors, (W, H), ss)
    else:
        img, covered = _compose_canvas(lines, thick, shift, body_fine, mesh.triangles, colors, (W, H), ss)

    # light, optics, sensor
    psi = rng.uniform(0.0, 2 * math.pi)
    # pixel centres in [-1, 1] as a row and a column: the same numbers as the quadratic basis's u and v, and
    # broadcasting them gives every pixel the same arithmetic at a fraction of the memory traffic
    u = ((np.arange(W) + 0.5) / W * 2.0 - 1.0)[None, :]
    v = ((np.arange(H) + 0.5) / H * 2.0 - 1.0)[:, None]
    light = 1.0 + lighting * (u * math.cos(psi) + v * math.sin(psi)) / 2.0 - vignette * (u * u + v * v) / 2.0
    img *= light[..., None].astype(np.float32)
    if blur > 0:
        img = cv2.GaussianBlur(img, (0, 0), blur)
    if noise > 0:
        img += _sensor_noise(rng, seed, noise, img.shape)
    img = np.clip(np.round(img, out=img), 0, 255, out=img).astype(np.uint8)

    # the caption, in the first corner whose box does not touch the (dilated) body
    text = "SYNTHETIC"
    font, fscale = cv2.FONT_HERSHEY_SIMPLEX, max(0.4, 0.5 * min(W, H) / 500.0)
    fthick = max(1, round(min(W, H) / 400.0))
    (tw, th), base = cv2.getTextSize(text, font, fscale, fthick)
    pad = max(3, round(min(W, H) / 100.0))
    body_px = cv2.dilate(covered.view(np.uint8), np.ones((2 * pad + 1, 2 * pad + 1), np.uint8))
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
                         "margin or image_size")
    bx, by = boxes[corner]
    cv2.putText(img, text, (bx, by + th), font, fscale, (20, 20, 20), fthick, cv2.LINE_AA)

    meta = {
        "synthetic": True, "generator": "mdsr_opt.photos.camera.render_photo", "caption": text,
        "caption_corner": corner, "caption_box": [int(bx), int(by), int(tw), int(th + base)],
        "seed": seed,
        "image_size": [W, H], "rotation_deg": rot, "tilt_deg": tilt,
        "tilt_axis_deg": math.degrees(phi), "light_direction_deg": math.degrees(psi),
        "lighting": float(lighting), "vignette": float(vignette), "blur_sigma": blur, "noise_sigma": noise,
        "body_color": body_rgb.tolist(), "plate_color": plate_rgb.tolist(), "grid_spacing": g,
    }
    Hw.setflags(write=False)
    return SyntheticPhoto(image=img, world_to_pixel=Hw, metadata=meta)
