"""Reading and writing meshes and states through meshio (the only module that uses it), and JSON results.

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

import contextlib
import json
import os
import tempfile
import unicodedata
import warnings
from dataclasses import dataclass, field

import numpy as np

from ..core.checks import as_float_array
from .mesh import Mesh

__all__ = ["write_mesh", "read_mesh", "MeshData", "write_json", "read_json", "atomic_path", "noted_folders", "adopt_noted_folders", "check_target",
           "FORMATS", "noting_writes"]

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


def check_target(path) -> str:
    """Refuse, before any work, a file name that cannot be written: empty, a directory, or under a file.

    Returns the path as a string. Raises ``ValueError`` naming the problem.
    """
    path = os.fspath(path)
    if not path:
        raise ValueError("cannot write to an empty path")
    if os.path.isdir(path):
        raise ValueError(f"cannot write {path}: it is a directory (give a file name inside it)")
    parent = os.path.dirname(os.path.abspath(path))
    while not os.path.exists(parent) and os.path.dirname(parent) != parent:
        parent = os.path.dirname(parent)  # the nearest existing ancestor must be a directory
    if not os.path.isdir(parent):
        raise ValueError(f"cannot write {path}: {parent} is a file, not a directory")
    return path


#: folders (absolute, with a trailing separator) whose completed files are noted, each with its journal
_JOURNALS: dict[str, str] = {}


@contextlib.contextmanager
def noting_writes(folder, journal):
    """Within the block, note every file that :class:`atomic_path` completes under ``folder``: its path
    relative to ``folder`` (with ``/``) is appended as one line to the file ``journal`` (of the innermost
    such folder, when they nest).

    Worker processes note their files too once they adopt this process's folders (:func:`noted_folders`,
    :func:`adopt_noted_folders`, which a run's process pool does as each worker starts): each line is one
    small write to a file opened for appending, so lines from several processes never mix. A run folder
    (:class:`~mdsr_opt.scenes.rundir.RunFolder`) so knows every file its run completed, even after the run
    was killed outright.
    """
    key = os.path.join(os.path.abspath(os.fspath(folder)), "")
    _JOURNALS[key] = os.path.abspath(os.fspath(journal))
    try:
        yield
    finally:
        _JOURNALS.pop(key, None)


def noted_folders() -> dict[str, str]:
    """The folders whose completed files are being noted here, each with its journal (a copy, picklable)."""
    return dict(_JOURNALS)


def adopt_noted_folders(folders: dict[str, str]) -> None:
    """In a worker process: note completed files into the journals of ``folders`` (from :func:`noted_folders`
    in the process that started it), for as long as the worker lives."""
    _JOURNALS.update(folders)


def _note_written(path: str) -> None:
    """Append ``path`` to the journal of the innermost noted folder that holds it."""
    full = os.path.abspath(path)
    roots = [r for r in _JOURNALS if full.startswith(r)]
    if not roots:
        return
    root = max(roots, key=len)
    line = os.fsencode(full[len(root):].replace(os.sep, "/")) + b"\n"
    try:
        fd = os.open(_JOURNALS[root], os.O_WRONLY | os.O_APPEND | os.O_CREAT, 0o644)
        try:
            os.write(fd, line)
        finally:
            os.close(fd)
    except OSError:  # the journal is a help; the file itself is written
        pass


class atomic_path:
    """Context manager yielding a temporary path beside ``path``; renamed onto ``path`` on success only.

    Whatever ends the block (an exception, ``KeyboardInterrupt``, a failing rename) the temporary file is
    removed, so no partial or 0-byte ``.tmp-*`` file is ever left behind. A ``path`` that is a directory,
    or whose parent is a file, is refused with a ``ValueError`` before anything is created.
    """

    def __init__(self, path, suffix: str | None = None):
        self.path = os.fspath(path)
        self.suffix = suffix if suffix is not None else os.path.splitext(self.path)[1]
        self.tmp: str | None = None

    def __enter__(self) -> str:
        check_target(self.path)
        d = os.path.dirname(os.path.abspath(self.path))
        fd = None
        try:
            os.makedirs(d, exist_ok=True)
            fd, self.tmp = tempfile.mkstemp(suffix=self.suffix, prefix=".tmp-", dir=d)
        except PermissionError:
            raise PermissionError(f"cannot write {self.path}: no permission to write in {d}") from None
        finally:
            if fd is not None:
                os.close(fd)
        return self.tmp

    def __exit__(self, exc_type, exc, tb):
        try:
            if exc_type is None:
                _public_mode(self.tmp)
                os.replace(self.tmp, self.path)
                if _JOURNALS:
                    _note_written(self.path)
        finally:
            if self.tmp is not None and os.path.lexists(self.tmp):
                os.remove(self.tmp)
        return False


def _format_of(path) -> str:
    ext = os.path.splitext(os.fspath(path))[1].lower()
    if ext not in FORMATS:
        raise ValueError(f"unsupported mesh file extension {ext!r}; use one of {', '.join(FORMATS)}")
    return FORMATS[ext]


#: Characters each format cannot carry in a data name and read back as written (besides control
#: characters, refused for all): meshio writes VTU names into XML attributes unescaped, Gmsh names
#: between double quotes, and legacy VTK names as whitespace-separated words.
_NAME_FORBIDS = {
    "vtk": ("whitespace", str.isspace),
    "vtu": ("'<', '&' or '\"'", lambda c: c in '<&"'),
    "gmsh": ("'\"'", lambda c: c == '"'),
}


def _check_name(name, kind: str, fmt: str, ext: str, taken: tuple[str, ...]) -> None:
    """Refuse a point or cell data name that ``fmt`` cannot write and read back unchanged."""
    if not isinstance(name, str):
        raise TypeError(f"{kind} names must be strings, got {type(name).__name__} {name!r}")
    if not name:
        raise ValueError(f"{kind} has an empty name; give every array a name")
    if name in taken:
        raise ValueError(f"{kind}[{name!r}] would overwrite the {name!r} that write_mesh writes itself "
                         "(from x and material); rename it")
    if name.startswith("gmsh:"):
        raise ValueError(f"{kind}[{name!r}]: names starting with 'gmsh:' are Gmsh's own tags, which read_mesh "
                         "leaves out; rename it")
    bad = next((c for c in name if unicodedata.category(c) == "Cc"), None)
    if bad is not None:
        raise ValueError(f"{kind}[{name!r}] holds the control character {bad!r}, which no mesh format keeps; "
                         "rename it")
    what, forbids = _NAME_FORBIDS.get(fmt, ("", lambda c: False))
    bad = next((c for c in name if forbids(c)), None)
    if bad is not None:
        fits = ", ".join(e for e, f in FORMATS.items() if f not in _NAME_FORBIDS or not _NAME_FORBIDS[f][1](bad))
        raise ValueError(f"{kind}[{name!r}] holds {bad!r}: a {ext} file cannot carry {what} in a data name and "
                         f"be read back as written; rename it, or write {fits}")


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

    Raises
    ------
    TypeError
        ``mesh`` is not a :class:`Mesh`.
    ValueError
        An unsupported extension, a ``path`` that is a directory (or under a file), data of the wrong
        shape or with NaN/inf, or a data name the format cannot write and read back as written: empty,
        with a control character, starting with ``gmsh:``, one of the names written from ``x`` and
        ``material`` (``displacement``, ``J``, ``energy_density``) when those are given, or holding
        whitespace (``.vtk``), ``<``, ``&`` or ``"`` (``.vtu``) or ``"`` (``.msh``). Nothing is written
        then, and no temporary file is left behind (not after an interrupt either).
    """
    import meshio

    if not isinstance(mesh, Mesh):
        raise TypeError(f"mesh must be a mdsr_opt.Mesh, got {type(mesh).__name__}")
    check_target(path)
    fmt = _format_of(path)
    ext = os.path.splitext(os.fspath(path))[1].lower()
    for name in point_data or {}:
        _check_name(name, "point_data", fmt, ext, ("displacement",) if x is not None else ())
    for name in cell_data or {}:
        taken = () if x is None else ("J", "energy_density") if material is not None else ("J",)
        _check_name(name, "cell_data", fmt, ext, taken)
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


#: Cells of lower dimension that meshing tools (Gmsh) add to mark points and boundary curves; they
#: carry no material and are skipped with a warning.
_ANNOTATION_CELLS = ("vertex", "line")


def read_mesh(path) -> MeshData:
    """Read a planar triangle mesh (any meshio format); the state is ``points + displacement`` if present.

    Parameters
    ----------
    path : str or path-like
        The mesh file.

    Returns
    -------
    MeshData
        The rest mesh, the state ``x`` and the other point and cell data (cell data of the triangles).

    Raises
    ------
    FileNotFoundError
        No such file.
    ValueError
        A file meshio cannot read; cells other than triangles (quads, polygons, quadratic triangles,
        volume cells: the message names the type) since dropping them would lose part of the body;
        points off a plane z = const; NaN or inf in the points or in any point or cell data field (the
        message names the field); a ``displacement`` with the wrong shape or out of the plane.

    Warns
    -----
    UserWarning
        ``vertex`` and ``line`` cells (marks of points and curves that Gmsh writes) are skipped.
    """
    import meshio

    path = os.fspath(path)
    if not os.path.exists(path):
        raise FileNotFoundError(f"no such mesh file: {path}")
    if os.path.isdir(path):
        raise ValueError(f"cannot read mesh file {path}: it is a directory")
    try:
        m = meshio.read(path)
    except (Exception, SystemExit) as exc:  # meshio's XML readers call sys.exit on malformed files
        raise ValueError(f"cannot read mesh file {path}: {exc}") from None
    counts: dict[str, int] = {}
    for c in m.cells:
        counts[c.type] = counts.get(c.type, 0) + len(c.data)
    other = {t: k for t, k in counts.items() if t != "triangle" and t not in _ANNOTATION_CELLS}
    if other:
        listed = ", ".join(f"{k} {t}" for t, k in other.items())
        raise ValueError(f"{path} holds cells other than triangles ({listed}); only planar triangle meshes "
                         "are supported (split quads into triangles, or re-mesh with triangles)")
    tri = [c.data for c in m.cells if c.type == "triangle"]
    if not tri:
        raise ValueError(f"{path} holds no triangle cells")
    skipped = {t: k for t, k in counts.items() if t in _ANNOTATION_CELLS}
    if skipped:
        warnings.warn(f"{path}: skipped {', '.join(f'{k} {t}' for t, k in skipped.items())} cells (marks of "
                      "points and curves; the body is its triangles)", UserWarning, stacklevel=2)
    pts = np.asarray(m.points, dtype=float)
    if not np.all(np.isfinite(pts)):
        bad = int(np.argwhere(~np.isfinite(pts))[0, 0])
        raise ValueError(f"{path}: the points contain NaN or inf (first at node {bad})")
    if pts.ndim != 2 or pts.shape[1] not in (2, 3):
        raise ValueError(f"{path}: points must have 2 or 3 coordinates, got shape {pts.shape}")
    if pts.shape[1] == 3:
        z = pts[:, 2]
        span = float(np.ptp(pts[:, :2], axis=0).max()) if len(pts) else 0.0
        if float(np.ptp(z)) > 1e-12 * max(span, np.abs(z).max(), 1e-300):
            raise ValueError(f"{path} is not planar: z varies from {z.min():.6g} to {z.max():.6g}; the body "
                             "must lie in a plane z = const")
        pts = pts[:, :2]
    for k, v in m.point_data.items():
        _check_finite(np.asarray(v), f"{path}: point data {k!r}", "node")
    for k, blocks in m.cell_data.items():
        for b, c in zip(blocks, m.cells):
            if c.type == "triangle":
                _check_finite(np.asarray(b), f"{path}: cell data {k!r}", "triangle")
    tris = np.vstack(tri).astype(np.int64)
    used = np.unique(tris)
    if len(used) != len(pts):  # e.g. gmsh geometry points not in any triangle
        remap = -np.ones(len(pts), dtype=np.int64)
        remap[used] = np.arange(len(used))
        pts, tris = pts[used], remap[tris]
        pd = {k: np.asarray(v)[used] for k, v in m.point_data.items() if not k.startswith("gmsh:")}
    else:
        pd = {k: np.asarray(v) for k, v in m.point_data.items() if not k.startswith("gmsh:")}
    try:
        mesh = Mesh(pts, tris)
    except ValueError as exc:
        raise ValueError(f"{path}: {exc}") from None
    x = mesh.points.copy()
    if "displacement" in pd:
        u = np.asarray(pd["displacement"], dtype=float)
        if u.ndim != 2 or u.shape[1] not in (2, 3):
            raise ValueError(f"{path}: point data 'displacement' must have 2 or 3 components per node, got "
                             f"shape {u.shape}")
        if u.shape[1] == 3 and np.abs(u[:, 2]).max(initial=0.0) > 1e-12 * max(mesh.size, 1e-300):
            raise ValueError(f"{path}: point data 'displacement' moves nodes out of the plane (|u_z| up to "
                             f"{np.abs(u[:, 2]).max():.3g}); a planar state has u_z = 0")
        x = x + u[:, :2]
    cd = {}
    for k, blocks in m.cell_data.items():
        vals = [np.asarray(b) for b, c in zip(blocks, m.cells) if c.type == "triangle"]
        if vals and not k.startswith("gmsh:"):
            cd[k] = np.concatenate(vals)
    return MeshData(mesh, x, pd, cd)


def _check_finite(arr: np.ndarray, what: str, row: str) -> None:
    """Refuse NaN or inf in a numeric data array, naming the field and the first bad row."""
    if arr.dtype.kind in "fc" and not np.all(np.isfinite(arr)):
        bad = int(np.argwhere(~np.isfinite(arr))[0][0])
        raise ValueError(f"{what} contains NaN or inf (first at {row} {bad})")


def _json_default(o):
    if isinstance(o, np.ndarray):
        return o.tolist()
    if isinstance(o, (np.floating, np.integer, np.bool_)):
        return o.item()
    raise TypeError(f"cannot write {type(o).__name__} to JSON")


def write_json(path, data) -> str:
    """Write ``data`` (numpy arrays allowed) as JSON atomically; NaN/inf are refused.
    An existing file of that name is replaced, without a warning (``mdsr run`` refuses to without ``--overwrite``)."""
    try:
        text = json.dumps(data, default=_json_default, indent=2, allow_nan=False)
    except ValueError as exc:
        raise ValueError(f"cannot write NaN or inf to JSON ({exc})") from None
    with atomic_path(path) as tmp:
        with open(tmp, "w") as fh:
            fh.write(text)
    return os.fspath(path)


def read_json(path):
    """The JSON file ``path`` parsed (UTF-8); a ``ValueError`` naming the file when it nests deeper than the
    parser's stack, instead of a ``RecursionError``."""
    with open(os.fspath(path), encoding="utf-8") as fh:
        try:
            return json.load(fh)
        except RecursionError:
            raise ValueError(f"{os.fspath(path)}: lists and objects are nested too deeply to read") from None
