"""Reading and writing meshes and states through meshio (the only meshio importer), and JSON results.

States are written the way ParaView expects them: ``points`` are the rest positions and the point data
``displacement`` (3 components, z = 0) moves them to the deformed state ("Warp By Vector"). Cell data
``J`` (det F) and ``energy_density`` are added when a state and a material are given. Every writer goes
through a temporary file in the target folder and renames it, so a failed write leaves nothing behind.

Example
-------
>>> import tempfile, os
>>> from mdsr_opt import Mesh
>>> mesh = Mesh.rectangle(2.0, 1.0, 2, 1)
>>> with tempfile.TemporaryDirectory() as d:
...     path = write_mesh(os.path.join(d, "body.vtk"), mesh, x=mesh.points * 1.1)
...     back = read_mesh(path)
>>> bool(abs(back.x - mesh.points * 1.1).max() < 1e-12)
True
"""

from __future__ import annotations

import json
import os
import tempfile
from dataclasses import dataclass, field

import numpy as np

from ._checks import as_float_array
from .mesh import Mesh

__all__ = ["write_mesh", "read_mesh", "MeshData", "write_json", "read_json", "atomic_path", "FORMATS"]

FORMATS = {".vtk": "vtk", ".vtu": "vtu", ".xdmf": "xdmf", ".msh": "gmsh"}


@dataclass
class MeshData:
    """A mesh read from a file: the rest ``mesh``, the deformed state ``x`` and any extra data."""

    mesh: Mesh
    x: np.ndarray
    point_data: dict = field(default_factory=dict)
    cell_data: dict = field(default_factory=dict)


def _public_mode(path) -> None:
    """Give a temporary file (created 0600 by mkstemp) the permissions a normal file would get."""
    umask = os.umask(0)
    os.umask(umask)
    os.chmod(path, 0o666 & ~umask)


class atomic_path:
    """Context manager yielding a temporary path beside ``path``; renamed onto ``path`` on success only."""

    def __init__(self, path, suffix: str | None = None):
        self.path = os.fspath(path)
        self.suffix = suffix if suffix is not None else os.path.splitext(self.path)[1]

    def __enter__(self) -> str:
        d = os.path.dirname(os.path.abspath(self.path))
        os.makedirs(d, exist_ok=True)
        fd, self.tmp = tempfile.mkstemp(suffix=self.suffix, prefix=".tmp-", dir=d)
        os.close(fd)
        return self.tmp

    def __exit__(self, exc_type, exc, tb):
        if exc_type is None:
            _public_mode(self.tmp)
            os.replace(self.tmp, self.path)
        elif os.path.exists(self.tmp):
            os.remove(self.tmp)
        return False


def _format_of(path) -> str:
    ext = os.path.splitext(os.fspath(path))[1].lower()
    if ext not in FORMATS:
        raise ValueError(f"unsupported mesh file extension {ext!r}; use one of {', '.join(FORMATS)}")
    return FORMATS[ext]


def _pad3(v: np.ndarray) -> np.ndarray:
    return np.column_stack([v, np.zeros(len(v))])


def write_mesh(path, mesh: Mesh, x=None, point_data: dict | None = None, cell_data: dict | None = None,
               material=None) -> str:
    """Write ``mesh`` (and optionally a deformed state ``x`` (n, 2)) to VTK, VTU, XDMF or Gmsh ``.msh``.

    Parameters
    ----------
    path : file name; the extension picks the format.
    x : deformed node positions; stored as ``displacement`` point data.
    point_data, cell_data : extra arrays, one value (or row) per node / per triangle.
    material : when given with ``x``, adds the per-triangle ``energy_density`` (Psi times thickness).

    Returns the path written.
    """
    import meshio

    if not isinstance(mesh, Mesh):
        raise TypeError(f"mesh must be a mdsr_opt.Mesh, got {type(mesh).__name__}")
    fmt = _format_of(path)
    pdata, cdata = {}, {}
    if x is not None:
        x = mesh._check_state(x)
        pdata["displacement"] = _pad3(x - mesh.points)
        F = mesh.deformation_gradients(x)
        J = np.linalg.det(F)
        cdata["J"] = J
        if material is not None:
            cdata["energy_density"] = np.asarray(material.psi(F), dtype=float)
    for name, v in (point_data or {}).items():
        arr = as_float_array(v, f"point_data[{name!r}]")
        if arr.shape[0] != mesh.n_nodes:
            raise ValueError(f"point_data[{name!r}] needs {mesh.n_nodes} rows, got {arr.shape[0]}")
        pdata[name] = _pad3(arr) if arr.ndim == 2 and arr.shape[1] == 2 else arr
    for name, v in (cell_data or {}).items():
        arr = as_float_array(v, f"cell_data[{name!r}]")
        if arr.shape[0] != mesh.n_triangles:
            raise ValueError(f"cell_data[{name!r}] needs {mesh.n_triangles} rows, got {arr.shape[0]}")
        cdata[name] = arr
    if fmt == "gmsh":  # Gmsh wants element tags; meshio's ASCII reader trips on point data, so binary 2.2
        ones = np.ones(mesh.n_triangles, dtype=np.int32)
        cdata.update({"gmsh:physical": ones, "gmsh:geometrical": ones})
    m = meshio.Mesh(_pad3(mesh.points), [("triangle", np.asarray(mesh.triangles))], point_data=pdata,
                    cell_data={k: [v] for k, v in cdata.items()})
    with atomic_path(path) as tmp:
        if fmt == "xdmf":
            meshio.xdmf.write(tmp, m, data_format="XML")
        elif fmt == "gmsh":
            meshio.write(tmp, m, file_format="gmsh22", binary=True)
        else:
            meshio.write(tmp, m, file_format=fmt)
    return os.fspath(path)


def read_mesh(path) -> MeshData:
    """Read a triangle mesh (any meshio format); the state is ``points + displacement`` when present."""
    import meshio

    path = os.fspath(path)
    if not os.path.exists(path):
        raise FileNotFoundError(f"no such mesh file: {path}")
    try:
        m = meshio.read(path)
    except (Exception, SystemExit) as exc:  # meshio's XML readers call sys.exit on malformed files
        raise ValueError(f"cannot read mesh file {path}: {exc}") from None
    tri = [c.data for c in m.cells if c.type == "triangle"]
    if not tri:
        raise ValueError(f"{path} holds no triangle cells")
    pts = np.asarray(m.points, dtype=float)
    if pts.shape[1] == 3:
        if np.abs(pts[:, 2]).max() > 1e-12 * max(1.0, np.abs(pts).max()):
            raise ValueError(f"{path} is not planar: points have non-zero z")
        pts = pts[:, :2]
    tris = np.vstack(tri).astype(np.int64)
    used = np.unique(tris)
    if len(used) != len(pts):  # e.g. gmsh geometry points not in any triangle
        remap = -np.ones(len(pts), dtype=np.int64)
        remap[used] = np.arange(len(used))
        pts, tris = pts[used], remap[tris]
        pd = {k: np.asarray(v)[used] for k, v in m.point_data.items() if not k.startswith("gmsh:")}
    else:
        pd = {k: np.asarray(v) for k, v in m.point_data.items() if not k.startswith("gmsh:")}
    mesh = Mesh(pts, tris)
    x = mesh.points.copy()
    if "displacement" in pd:
        x = x + np.asarray(pd["displacement"], dtype=float)[:, :2]
    cd = {}
    for k, blocks in m.cell_data.items():
        vals = [np.asarray(b) for b, c in zip(blocks, m.cells) if c.type == "triangle"]
        if vals and not k.startswith("gmsh:"):
            cd[k] = np.concatenate(vals)
    return MeshData(mesh, x, pd, cd)


def _json_default(o):
    if isinstance(o, np.ndarray):
        return o.tolist()
    if isinstance(o, (np.floating, np.integer, np.bool_)):
        return o.item()
    raise TypeError(f"cannot write {type(o).__name__} to JSON")


def write_json(path, data) -> str:
    """Write ``data`` (numpy arrays allowed) as JSON atomically; NaN/inf are refused."""
    try:
        text = json.dumps(data, default=_json_default, indent=2, allow_nan=False)
    except ValueError as exc:
        raise ValueError(f"cannot write NaN or inf to JSON ({exc})") from None
    with atomic_path(path) as tmp:
        with open(tmp, "w") as fh:
            fh.write(text)
    return os.fspath(path)


def read_json(path):
    with open(os.fspath(path)) as fh:
        return json.load(fh)
