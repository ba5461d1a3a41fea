"""Photographs: extracting contours (with holes), contour metrics, the synthetic camera, folder tables."""
