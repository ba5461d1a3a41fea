"""Which files the ``mdsr author`` page may open: scene, outline and mesh files in the folders the user named.

The page is a client of the server, and whatever it sends is checked as input from outside. It may load a
problem of the library by name, a file it uploads (its text), or a file on disk by path; a path must lie
inside one of the *readable folders* (:func:`readable_folders`: the folder of the file named on the command
line, the ``--out`` folder, and each ``--allow-dir``), after symbolic links are resolved, and name a scene
file (``.toml``/``.json``) or an outline (``.svg``/``.json``); a scene file's mesh file must lie inside
them too. A Python file is never imported for the page: only the command line can name a problem script.
"""

from __future__ import annotations

import os
from pathlib import Path

from ..scenes.reader import read_file

__all__ = ["readable_folders", "page_file", "check_scene_refs", "PAGE_SUFFIXES"]

#: the kinds of file the page may open by path
PAGE_SUFFIXES = (".toml", ".json", ".svg")


def readable_folders(body: str | None, out, extra=()) -> tuple[Path, ...]:
    """The folders whose files the page may open: ``body``'s folder (when it is a file), ``out``, ``extra``.

    Each is resolved (absolute, links followed); repeated folders appear once.
    """
    folders = []
    if body is not None and Path(body).is_file():
        folders.append(Path(body).resolve().parent)
    folders.append(Path(out).resolve())
    for d in extra:
        p = Path(d)
        if not p.is_dir():
            raise ValueError(f"--allow-dir {d}: not a folder")
        folders.append(p.resolve())
    return tuple(dict.fromkeys(folders))


def _inside(p: Path, folders) -> bool:
    return any(p == f or p.is_relative_to(f) for f in folders)


def page_file(path, folders) -> Path:
    """The resolved file the page asked for by ``path``; ValueError unless it may open it.

    Refused: a path that is not a string, a Python file (never imported for the page), a kind the page
    cannot open (see :data:`PAGE_SUFFIXES`), and a file outside ``folders``.
    """
    if not isinstance(path, str) or not path or "\x00" in path:
        raise TypeError(f"path must be a file name, got {path!r}")
    suffix = Path(path).suffix.lower()
    if suffix == ".py":
        raise ValueError(f"{path}: the page does not run Python files; name a problem script on the command "
                         "line (mdsr author SCRIPT.py), or load a library problem, a scene or an outline file")
    if suffix not in PAGE_SUFFIXES:
        raise ValueError(f"{path}: the page opens scene files (.toml/.json) and outlines (.svg/.json) only")
    p = Path(path).resolve()
    if not _inside(p, folders):
        raise ValueError(f"{path}: outside the folders the page may read ({_names(folders)}); give its folder "
                         "with mdsr author --allow-dir")
    if not p.is_file():
        raise FileNotFoundError(f"no such file: {path}")
    return p


def check_scene_refs(scene: Path, folders, shown: str | None = None, data: dict | None = None) -> dict:
    """The parsed scene file ``scene``; ValueError when it names a mesh file outside ``folders``.

    The file is read by the scene reader (:func:`~mdsr_opt.scenes.reader.read_file`, with its limits on size
    and nesting; ``data``: the file already read so) and only its ``body.mesh`` entry is looked at here (a
    file the scene reader would open, relative to the scene file). ``shown``: the name of an uploaded file
    (written to a temporary folder as ``scene``), whose mesh file is not on the server.
    """
    if data is None:
        data = read_file(scene)
    body = data.get("body")
    mesh = body.get("mesh") if isinstance(body, dict) else None
    if not isinstance(mesh, str):
        return data
    if shown is not None:
        raise ValueError(f"{shown}: an uploaded scene cannot bring its mesh file ({mesh}): start mdsr author "
                         "with the scene file's path instead")
    p = (scene.parent / mesh).resolve()
    if not _inside(p, folders):
        raise ValueError(f"{scene.name}: body.mesh {mesh!r} lies outside the folders the page may read "
                         f"({_names(folders)}); open the scene with mdsr author PATH or give its mesh's folder "
                         "with --allow-dir")
    return data


def _names(folders) -> str:
    return ", ".join(os.fspath(f) for f in folders) or "none"
