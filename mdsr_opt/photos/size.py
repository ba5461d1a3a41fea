"""The size of a synthetic photograph: its limits, checked at the door by every entry point (the camera,
:func:`~mdsr_opt.scenes.runscene.run_scene`, ``mdsr run --photo-size``)."""

from __future__ import annotations

from ..core.checks import check_int

__all__ = ["MIN_PHOTO_SIDE", "MAX_PHOTO_SIDE", "check_photo_size"]

#: The smallest side of a synthetic photograph, in pixels.
MIN_PHOTO_SIDE = 32
#: The largest side of a synthetic photograph, in pixels: measuring a photograph takes about 60 MB per
#: megapixel (:data:`~mdsr_opt.photos.images.MAX_PIXELS`), so 3.8 GB at 8000 x 8000.
MAX_PHOTO_SIDE = 8000


def check_photo_size(size, name: str = "image_size", lo: int = MIN_PHOTO_SIDE) -> tuple[int, int]:
    """``size`` as ``(width, height)``, two integers from ``lo`` to :data:`MAX_PHOTO_SIDE` pixels.

    Raises ``TypeError`` (not integers) or ``ValueError`` (not two values, or out of range) naming ``name``.
    """
    if isinstance(size, (str, bytes)) or not hasattr(size, "__len__") or len(size) != 2:
        raise ValueError(f"{name} must be (width, height), two integers, got {size!r}")
    W, H = (check_int(v, name) for v in size)
    if not (lo <= W <= MAX_PHOTO_SIDE and lo <= H <= MAX_PHOTO_SIDE):
        raise ValueError(f"{name} must lie between {lo} and {MAX_PHOTO_SIDE} pixels per side (measuring a "
                         f"photograph takes about 60 MB per megapixel), got {W} x {H}")
    return W, H
