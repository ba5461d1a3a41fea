"""Shared scenes for the tests: small, fast, and each with a known answer."""

from __future__ import annotations

import numpy as np
import pytest

from mdsr_opt import Mesh, NeoHookean


@pytest.fixture(scope="session")
def strip():
    """A 4 x 1 strip meshed by Triangle (about 190 nodes)."""
    return Mesh.from_polygon([[0, 0], [4, 0], [4, 1], [0, 1]], max_area=0.02)


@pytest.fixture(scope="session")
def material():
    return NeoHookean(E=1.0, nu=0.3)


def ends(mesh, length=4.0):
    P = mesh.points
    left = np.nonzero(P[:, 0] < 1e-9)[0]
    right = np.nonzero(P[:, 0] > length - 1e-9)[0]
    return left, right


def arc_map(points, length=4.0, angle=np.pi / 2):
    """Map a strip's rest points onto a circular arc bending it through ``angle`` (towards +y)."""
    R = length / angle
    th = points[:, 0] / length * angle
    rr = R - points[:, 1]
    return np.column_stack([rr * np.sin(th), R - rr * np.cos(th)])


def rotation(theta):
    c, s = np.cos(theta), np.sin(theta)
    return np.array([[c, -s], [s, c]])
