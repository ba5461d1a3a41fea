"""Benchmark of the work guards and the exact boundary-contact test (issue 11, "hangs and unbounded work").

Measured, each in this one process (timings on a shared machine are noisy: medians of ``--repeat``):

* ``boundary_crosses`` on a strip with 16,002 boundary edges (``Mesh.rectangle(4, 0.01, 8000, 1)``) bent
  through 180 degrees (no contact) and 396 degrees (wrapped through itself), against the former
  all-pairs test (kept below as ``all_pairs_crossing`` for the comparison; it is quadratic and misses
  crossings through vertices, touching and collinear overlaps);
* the refusal of ``Mesh.from_polygon`` for a 1000 x 1000 square at ``max_area=0.01`` (about 1.6e8
  triangles) and of ``get_problem('gecko', resolution=10**8)``;
* the refusal of ``contour_from_image`` for an 8000 x 8000 image and of a 1999 px kernel;
* the time of a 1.9M-triangle mesh (just under the default limit), meshing and validation.

Usage::

    python tests/benchmarks/bench_guards.py [--repeat 5] [--skip-big]
    /usr/bin/time -f "maxrss %M KB" python tests/benchmarks/bench_guards.py --extract 4000

``--extract N`` only times ``contour_from_image`` on an N x N grey image of a dark ellipse (peak memory
from ``/usr/bin/time``).
"""

from __future__ import annotations

import argparse
import os
import sys
import time

import numpy as np

sys.path.insert(0, os.path.join(os.path.dirname(__file__), "..", ".."))

from mdsr_opt import Mesh  # noqa: E402


def all_pairs_crossing(mesh: Mesh, x: np.ndarray) -> bool:
    """The former test: proper crossings of every pair of boundary edges sharing no node, in blocks."""
    E = np.vstack([np.column_stack([lp, np.roll(lp, -1)]) for lp in mesh.boundary_loops])
    a, b = x[E[:, 0]], x[E[:, 1]]

    def orient(p, q, r):
        return (q[..., 0] - p[..., 0]) * (r[..., 1] - p[..., 1]) - (q[..., 1] - p[..., 1]) * (r[..., 0] - p[..., 0])

    for i0 in range(0, len(E), 512):
        sl = slice(i0, i0 + 512)
        A0, A1 = a[sl, None, :], b[sl, None, :]
        B0, B1 = a[None, :, :], b[None, :, :]
        cross = (orient(B0, B1, A0) * orient(B0, B1, A1) < 0) & (orient(A0, A1, B0) * orient(A0, A1, B1) < 0)
        shared = (E[sl, None, 0] == E[None, :, 0]) | (E[sl, None, 0] == E[None, :, 1]) | \
            (E[sl, None, 1] == E[None, :, 0]) | (E[sl, None, 1] == E[None, :, 1])
        if np.any(cross & ~shared):
            return True
    return False


def arc(points: np.ndarray, angle: float, length: float = 4.0) -> np.ndarray:
    R = length / angle
    th = points[:, 0] / length * angle
    rr = R - points[:, 1]
    return np.column_stack([rr * np.sin(th), R - rr * np.cos(th)])


def timed(fn, repeat: int) -> tuple[object, float]:
    ts, out = [], None
    for _ in range(repeat):
        t0 = time.perf_counter()
        out = fn()
        ts.append(time.perf_counter() - t0)
    return out, float(np.median(ts))


def refusal(fn) -> tuple[str, float]:
    t0 = time.perf_counter()
    try:
        fn()
    except ValueError as exc:
        return str(exc), time.perf_counter() - t0
    return "NOT REFUSED", time.perf_counter() - t0


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=5, help="timed repetitions per case (the median is printed)")
    ap.add_argument("--skip-big", action="store_true", help="skip the 1.9M-triangle mesh")
    ap.add_argument("--extract", type=int, default=0, help="only time contour extraction on N x N pixels")
    a = ap.parse_args(argv)
    if a.extract:
        from mdsr_opt.photos.contours import contour_from_image

        n = a.extract
        yy, xx = np.ogrid[0:n, 0:n]
        img = np.where((xx - n / 2) ** 2 / (0.3 * n) ** 2 + (yy - n / 2) ** 2 / (0.2 * n) ** 2 < 1, 60, 200)
        img = np.repeat(img.astype(np.uint8)[..., None], 3, axis=2)
        t0 = time.perf_counter()
        c = contour_from_image(img, max_pixels=max(n * n, 1))
        print(f"contour_from_image on {n} x {n} ({n * n / 1e6:.1f} MP): {time.perf_counter() - t0:.2f} s, "
              f"{len(c)} contour points")
        return

    m = Mesh.rectangle(4.0, 0.01, 8000, 1)
    print(f"strip: {m.n_nodes} nodes, {len(m.boundary_edges)} boundary edges")
    for turns in (0.5, 1.1):
        x = arc(m.points, 2 * np.pi * turns)
        new, t_new = timed(lambda: m.boundary_crosses(x), a.repeat)
        old, t_old = timed(lambda: all_pairs_crossing(m, x), 1)
        print(f"  bent {360 * turns:5.0f} deg: boundary_crosses {new} {1e3 * t_new:7.1f} ms (median of "
              f"{a.repeat}); all pairs {old} {t_old:6.2f} s; ratio {t_old / t_new:5.0f}x")

    from mdsr_opt.photos.contours import contour_from_image
    from mdsr_opt.scenes.library import get_problem

    sq = np.array([[0.0, 0], [1, 0], [1, 1], [0, 1]])
    for name, fn in [("1000 x 1000 square, max_area=0.01", lambda: Mesh.from_polygon(sq * 1000, max_area=0.01)),
                     ("get_problem('gecko', resolution=10**8)", lambda: get_problem("gecko", resolution=10 ** 8))]:
        msg, t = refusal(fn)
        print(f"{name}: refused in {1e3 * t:.1f} ms: {msg}")
    big = np.zeros((8000, 8000), np.uint8)
    big[3000:5000, 2000:6000] = 200
    msg, t = refusal(lambda: contour_from_image(big))
    print(f"8000 x 8000 image: refused in {1e3 * t:.1f} ms: {msg}")
    img = np.full((2000, 2000), 210, np.uint8)
    img[500:1500, 600:1400] = 60
    msg, t = refusal(lambda: contour_from_image(img, kernel=1999))
    print(f"kernel 1999 px on 2000 x 2000: refused in {1e3 * t:.1f} ms: {msg}")
    if not a.skip_big:
        t0 = time.perf_counter()
        mm = Mesh.from_polygon(sq, max_area=1 / 1.2e6)
        print(f"square at max_area=1/1.2e6: {mm.n_triangles} triangles in {time.perf_counter() - t0:.1f} s "
              "(meshing and validation)")


if __name__ == "__main__":
    main()
