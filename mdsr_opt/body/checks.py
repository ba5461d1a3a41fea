"""The check that an argument is a :class:`~mdsr_opt.body.mesh.Mesh`, naming the argument."""

from __future__ import annotations

__all__ = ['check_mesh']


def check_mesh(mesh, name: str = "mesh"):
    """Return ``mesh`` if it is a :class:`mdsr_opt.Mesh`, else raise ``TypeError`` naming ``name``."""
    from .mesh import Mesh  # here, not at the top: mesh.py imports this module

    if not isinstance(mesh, Mesh):
        raise TypeError(f"{name} must be a mdsr_opt.Mesh, got {type(mesh).__name__}")
    return mesh
