"""Checks of arguments against a body: that it is a :class:`~mdsr_opt.body.mesh.Mesh`, and that a target
shape of it is one a body can take."""

from __future__ import annotations

import numpy as np

from ..core.checks import as_float_array
from .mesh import Mesh

__all__ = ['check_mesh', 'check_target_shape', 'solved_state']

#: where :func:`check_target_shape` keeps the last target shape that passed, on the mesh
_PASSED = "_target_shape_cache"


def check_mesh(mesh, name: str = "mesh"):
    """Return ``mesh`` if it is a :class:`mdsr_opt.Mesh`, else raise ``TypeError`` naming ``name``."""
    if not isinstance(mesh, Mesh):
        raise TypeError(f"{name} must be a mdsr_opt.Mesh, got {type(mesh).__name__}")
    return mesh


def solved_state(target, name: str = "target"):
    """``target`` itself, or the state ``x`` of a solve's result (an object with ``x`` and ``success``, such as
    an :class:`~mdsr_opt.mechanics.result.EquilibriumResult`) when that solve succeeded.

    Raises
    ------
    ValueError
        ``target`` is the result of a failed solve (its state is no equilibrium: a design for it would be
        a design for a shape the body was never shown to take).
    """
    if hasattr(target, "x") and hasattr(target, "success") and not isinstance(target, np.ndarray):
        if not bool(target.success):
            status = getattr(target, "status", "")
            raise ValueError(f"{name} is the result of a failed solve ({status or 'success=False'}): its state is "
                             "not an equilibrium; solve the target again (other drags, load steps, tol) and give "
                             "a successful result or its x")
        return target.x
    return target


def check_target_shape(mesh, target, name: str = "target") -> np.ndarray:
    """The target shape of a design as a finite ``(n, 2)`` float array in which every triangle keeps its
    orientation and the outline does not cross itself: the one check of every entry point that takes a target
    (routing, :func:`~mdsr_opt.design_contractions` and its rivals, the pipeline,
    :func:`~mdsr_opt.synthesis.poses.design_poses`, :func:`~mdsr_opt.synthesis.verify.verify_design`,
    :func:`~mdsr_opt.synthesis.bands.stroke_bands`). A solve's result is taken for its state ``x``
    (:func:`solved_state`); a bare array is checked the same, so a failed solve's ``x`` is refused as its
    result is when that state is no shape of the body.

    Raises
    ------
    TypeError
        Not an array of numbers.
    ValueError
        The result of a failed solve, the wrong shape, NaN or inf, a mirror image of the body (every triangle
        inverted), some triangles inverted or degenerate (``det F <= 0``; the first is named), or an outline
        that crosses or touches itself (the body overlapping itself:
        :meth:`~mdsr_opt.body.mesh.Mesh.boundary_crossing`; no contact keeps it apart in a target).
    """
    x = as_float_array(solved_state(target, name), name, shape=(mesh.n_nodes, 2))
    # the pipeline checks one target at routing, design and verification: the last shape that passed is kept
    # on the mesh (its bytes; a ``*_cache`` entry, which pickles leave out), and the same shape passes again
    # without the element and outline tests
    key = x.tobytes()
    if mesh.__dict__.get(_PASSED) == key:
        return x
    J = mesh.jacobians(x)
    bad = J <= 0.0
    if (J == 0.0).all():
        raise ValueError(f"{name} flattens every triangle (det F = 0 in all {mesh.n_triangles}): its nodes lie on "
                         "a line or a point")
    if bad.all():
        raise ValueError(f"{name} inverts every triangle (det F <= 0 in all {mesh.n_triangles}): is it a mirror "
                         "image of the body? A body cannot turn itself over in its plane")
    if bad.any():
        k = int(np.argmax(bad))
        raise ValueError(f"{name} has {int(bad.sum())} inverted triangle(s) (det F <= 0), first: triangle {k} "
                         f"{mesh.triangles[k].tolist()} with det F = {J[k]:.3g}"
                         + (" (degenerate: its corners on a line)" if J[k] == 0 else "")
                         + "; a physical target keeps every element positively oriented")
    crossing = mesh.boundary_crossing(x)
    if crossing is not None:
        raise ValueError(f"{name} overlaps itself: {crossing}; a physical target keeps its outline from crossing "
                         "itself (is it the state of a failed solve? solve it again, with contact=True where the "
                         "body touches itself)")
    mesh.__dict__[_PASSED] = key
    return x
