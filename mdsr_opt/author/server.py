"""The ``mdsr author`` server: a Starlette app (served by uvicorn) with one websocket per page.

The page sends JSON messages (``load``, ``fixed``, ``drag``, ``graph``, ``route`` (with its ``fabrication``:
channel, wall and fixture sizes), ``delete_muscle``, ``design``, ``save``, ``ping``); the server answers with
``body`` (with ``kept``: what a saved scene keeps of the scene opened), ``state``, ``graph``, ``routing``
(also after a deletion), ``design``, ``saved`` (with ``notes``: what the save changes for the cases the page did not edit),
``pong`` or ``error`` messages. Work runs in a thread, one request at a time per page; while a solve runs,
a newer ``drag`` replaces a waiting one (stale drags are dropped, counted in ``state.dropped``), and while
no request waits after a drag the drag's exact equilibrium is solved ahead of its release. Bad
input of any kind is answered with an ``error`` message naming the problem, and the server keeps serving.
"""

from __future__ import annotations

import asyncio
import collections
import contextlib
import json
import math
import os
import secrets
import sys
import tempfile
import threading
import traceback
from pathlib import Path

import numpy as np

from ..core.checks import check_int
from ..core.guards import cancel_stop, request_stop
from ..scenes.reader import read_file
from .files import check_scene_refs, page_file, readable_folders
from .guard import Guard

__all__ = ["make_app", "MAX_MESSAGE", "load_body"]

#: Largest websocket message the server reads (bytes of text); larger ones get an error message.
MAX_MESSAGE = 4 * 1024 * 1024
#: Deepest nesting of lists and objects in a message (the page's deepest, an outline's holes, is 5).
MAX_DEPTH = 16
#: Seconds a drag must wait for the next move before its exact equilibrium is solved ahead of the release:
#: a pause of the hand, longer than the gaps between mouse moves (16 ms at 60 Hz, 50 ms and more on a busy
#: machine), so a moving drag does not start solves it then stops.
SPECULATE_AFTER = 0.1
STATIC = Path(__file__).with_name("static")
_SESSIONS: "collections.OrderedDict[str, object]" = collections.OrderedDict()
_KEEP_SESSIONS = 16


# ---------------------------------------------------------------------------------------------- bodies
def load_body(spec: dict, folders=None):
    """A :class:`~mdsr_opt.author.session.Session` from a load request (or the command line's argument).

    ``spec``: ``{"kind": "problem", "name", "resolution"}``, ``{"kind": "path", "path", "resolution"}``
    (a scene file or outline file on disk), ``{"kind": "scene", "filename", "text"}`` (an uploaded scene
    file), ``{"kind": "outline", "outline", "holes", "resolution"}`` or ``{"kind": "outline_file",
    "filename", "text", "resolution"}``.

    ``folders``: ``None`` for the command line's own argument (which may also be a problem script); for a
    request from the page, the folders it may read (:func:`~mdsr_opt.author.files.readable_folders`): a
    problem is then a library name, a path must be a scene or outline file inside them, and so must a
    scene's mesh file (:mod:`.files`).
    """
    try:
        return _load_body(spec, folders)
    except RecursionError:
        raise ValueError(f"{spec.get('kind')}: the file is nested too deeply to be a scene or an outline") from None


def _load_body(spec: dict, folders):
    from .outline import check_outline, parse_outline
    from .session import MAX_NODES, Session

    kind = spec.get("kind")
    res = spec.get("resolution")
    if res not in (None, "") and not isinstance(res, (str, int)) or isinstance(res, bool):
        raise TypeError(f"resolution must be a node count or coarse/medium/fine, got {res!r}")
    res = None if res in (None, "") else res
    if isinstance(res, str) and res.strip().isdigit():
        res = int(res)
    if res is not None:
        from ..scenes.scene import resolve_resolution

        n = resolve_resolution(int(res) if isinstance(res, str) and res.strip().isdigit() else res)
        if n > MAX_NODES:
            raise ValueError(f"resolution {n} is above the page's limit of {MAX_NODES} nodes")
    if kind == "problem":
        from ..scenes.library import list_problems

        name = spec.get("name")
        if not isinstance(name, str) or not name or "/" in name or "\\" in name or name.startswith("."):
            raise ValueError(f"problem name must be a library name, got {name!r}")
        if folders is not None and name not in list_problems():
            raise ValueError(f"unknown problem {name!r}; the library has: {', '.join(list_problems())}")
        return Session.from_problem(name, res)
    if kind == "path":
        if folders is not None:
            p = page_file(spec.get("path"), folders)
        else:
            p = Path(str(spec.get("path")))
            if not p.exists():
                raise FileNotFoundError(f"no such file: {p}")
        suffix = p.suffix.lower()
        if suffix == ".py":  # the command line's problem script (page_file refuses these)
            from ..scenes.library import get_problem

            return Session.from_scene(get_problem(p, resolution=res))
        # a scene file is read once, by the scene reader (its limits on size and nesting)
        data = None if suffix == ".svg" else read_file(p)
        if data is None or suffix == ".json" and "body" not in data:  # an outline file
            outline, holes = parse_outline(p.name, p.read_text())
            return Session.from_outline(outline, holes, 600 if res is None else res, name=_stem_name(p))
        if folders is not None:
            check_scene_refs(p, folders, data=data)
        return Session.from_scene_file(p, res, data=data)
    if kind == "scene":
        fname, text = _file_fields(spec)
        suffix = Path(fname).suffix.lower()
        if suffix not in (".toml", ".json"):
            raise ValueError(f"a scene file ends in .toml or .json, not {fname!r}")
        with tempfile.TemporaryDirectory() as d:
            path = Path(d) / Path(fname).name
            path.write_text(text)
            data = check_scene_refs(path, (), shown=Path(fname).name)
            return Session.from_scene_file(path, res, data=data)
    if kind == "outline_file":
        fname, text = _file_fields(spec)
        outline, holes = parse_outline(fname, text)
        return Session.from_outline(outline, holes, 600 if res is None else res, name=_stem_name(Path(fname)))
    if kind == "outline":
        holes = spec.get("holes") or []
        if not isinstance(holes, list):
            raise TypeError("holes must be a list of polygons")
        outline, holes = check_outline(spec.get("outline"), holes, where="drawn outline")
        return Session.from_outline(outline, holes, 600 if res is None else res)
    raise ValueError(f"unknown body kind {kind!r} (problem, path, scene, outline, outline_file)")


def _stem_name(p: Path) -> str:
    s = "".join(ch if ch.isalnum() or ch in "_-" else "_" for ch in p.stem.split(".")[0])
    return s or "authored"


def _file_fields(spec):
    fname, text = spec.get("filename"), spec.get("text")
    if not isinstance(fname, str) or not isinstance(text, str):
        raise TypeError("a file upload needs 'filename' and 'text' strings")
    return fname, text


def _is_library(s) -> bool:
    """Whether the session's body is a library problem's (its factory script), not a scene file or outline."""
    from ..scenes.library import list_problems

    src = Path(s.source) if s.source and s.source != "outline" else None
    return bool(src is not None and src.suffix == ".py" and src.stem == s.name and s.name in list_problems())


def body_message(s) -> dict:
    from .contact import contact_lines, obstacle_entries, solve_options
    from .roundtrip import kept_lines
    from .session import design_defaults, routing_defaults

    m = s.mesh
    ro = dict(s.routing_options)
    dd = design_defaults()
    dd.update({k: v for k, v in s.design_options.items() if k in dd})
    return {"type": "body", "name": s.name, "source": s.source, "library": _is_library(s), "n_nodes": m.n_nodes,
            "points": m.points.tolist(), "triangles": m.triangles.tolist(), "edges": m.edges.tolist(),
            "boundary": [[int(v) for v in loop] for loop in m.boundary_loops], "size": m.size,
            "edge_length": float(m.edge_lengths.mean()),
            "anchors": s.anchors.tolist(), "drag_nodes": s.drag_nodes.tolist(),
            "drag_positions": s.drag_positions.tolist(),
            "routing": dict(routing_defaults(), **{k: ro[k] for k in ("K_a", "K_b", "max_muscles") if k in ro}),
            "design": {k: (v if isinstance(v, (int, float, str)) else None) for k, v in dd.items()},
            "fabrication": s.fabrication_shown(), "units": s.units, "kept": kept_lines(s),
            # the edited case's obstacles (drawn), and what the page's solves do with them and the self-contact
            "obstacles": obstacle_entries(solve_options(s).get("obstacles", [])), "contact": contact_lines(s),
            "material": {"model": s.material.kind, "E": s.material.E, "nu": s.material.nu}}


# ---------------------------------------------------------------------------------------------- requests
def _number(msg, key, lo=None, hi=None, default=None):
    v = msg.get(key, default)
    if isinstance(v, bool) or not isinstance(v, (int, float)):
        raise TypeError(f"{key} must be a number, got {v!r}")
    v = float(v)
    if not math.isfinite(v):
        raise ValueError(f"{key} must be finite, got {v}")
    if lo is not None and v <= lo or hi is not None and v >= hi:
        raise ValueError(f"{key} must lie in ({lo}, {hi}), got {v}")
    return v


def _fixed(session, msg):
    for k in ("anchors", "drag_nodes", "drag_positions"):
        if k not in msg:
            raise ValueError(f"{msg.get('type')} message: missing field {k!r}")
    session.set_fixed(msg["anchors"], msg["drag_nodes"], msg["drag_positions"])


class Page:
    """One websocket connection: its session, its queue of requests and the worker that serves them."""

    def __init__(self, ws, app_state):
        self.ws = ws
        self.app = app_state
        self.sid = secrets.token_urlsafe(12)
        self.session = None
        self.queue: collections.deque = collections.deque()
        self.wake = asyncio.Event()
        self.dropped = 0
        self.tmp = tempfile.TemporaryDirectory(prefix="mdsr-author-")
        # the exact solve started while a drag waits for the next move (see _speculate)
        self.spec: dict | None = None  # the drag request it solves
        self.spec_tid: int | None = None  # the thread solving it
        self.spec_lock = threading.Lock()

    async def send(self, obj: dict) -> None:
        await self.ws.send_text(json.dumps(obj, allow_nan=False, default=_json_default))

    async def error(self, message: str, request=None) -> None:
        await self.send(_error(message, request))

    def enqueue(self, msg: dict, trusted: bool = False) -> None:
        """Queue a request; ``trusted``: the server's own (the command line's body), not the page's."""
        if msg.get("type") == "drag" and self.queue and self.queue[-1][0].get("type") == "drag":
            self.queue[-1] = (msg, trusted)  # keep only the latest drag: the page moved on
            self.dropped += 1
        else:
            self.queue.append((msg, trusted))
        spec = self.spec
        if spec is not None and not (msg.get("type") == "fixed" and all(
                msg.get(k) == spec.get(k) for k in ("anchors", "drag_nodes", "drag_positions"))):
            self.stop_speculation()  # the drag moved on
        self.wake.set()

    def stop_speculation(self) -> None:
        """Stop the exact solve of a paused drag (:meth:`_speculate`) at its next iteration."""
        with self.spec_lock:
            self.spec = None
            if self.spec_tid is not None:
                request_stop(self.spec_tid, _Superseded)

    async def _speculate(self, msg: dict) -> None:
        """While the drag ``msg`` waits for the next move, solve its exact equilibrium
        (:meth:`~mdsr_opt.author.session.Session.exact`): a release there is then answered at once. A newer
        request other than that release stops it (:meth:`enqueue`)."""
        self.spec = msg

        def run():
            tid = threading.get_ident()
            with self.spec_lock:
                if self.spec is not msg:  # superseded before it started
                    return
                self.spec_tid = tid
            try:
                self.session.exact()
            except Exception:  # stopped (_Superseded) or failed: the release solves it again and reports it
                pass
            finally:
                with self.spec_lock:
                    self.spec_tid = None
                    cancel_stop(tid)

        try:
            await asyncio.to_thread(run)
        finally:
            self.spec = None

    async def worker(self) -> None:
        while True:
            await self.wake.wait()
            self.wake.clear()
            last = None
            while self.queue:
                msg, trusted = self.queue.popleft()
                t = msg.get("type")
                last = msg if t == "drag" else None
                try:
                    reply = await asyncio.to_thread(self.handle, msg, trusted)
                except RecursionError:  # a RuntimeError: named before the general case below
                    reply = [_error(f"{t}: nested too deeply", t)]
                except (ValueError, TypeError, KeyError, OSError, RuntimeError) as exc:
                    text = str(exc.args[0]) if isinstance(exc, KeyError) and exc.args else str(exc)
                    if isinstance(exc, OSError) and exc.filename and not isinstance(exc, FileExistsError):
                        text = f"{exc.strerror or type(exc).__name__}: {exc.filename}"
                    reply = [_error(f"{t}: {text}", t)]
                except MemoryError:
                    reply = [_error(f"{t}: out of memory (a body too finely meshed? choose fewer nodes)", t)]
                except Exception as exc:  # never let one request take the server down
                    traceback.print_exc(file=sys.stderr)
                    reply = [_error(f"{t}: internal error {type(exc).__name__}: {exc}", t)]
                for r in reply:
                    try:
                        await self.send(r)
                    except (ValueError, TypeError, RecursionError) as exc:  # a reply JSON cannot hold
                        await self.error(f"{t}: cannot send the reply: {exc}", t)
            st = self.session.state if self.session is not None else None
            if last is not None and st is not None and st.live and st.success:
                try:  # a new request wakes the worker at once; else the drag pauses: solve it exactly
                    await asyncio.wait_for(self.wake.wait(), SPECULATE_AFTER)
                except asyncio.TimeoutError:
                    await self._speculate(last)

    def handle(self, msg: dict, trusted: bool = False) -> list[dict]:
        """Serve one request (in a worker thread); returns the messages to send.

        ``trusted``: the request is the server's own (the body named on the command line); a request from
        the page loads only what :mod:`.files` allows.
        """
        t = msg["type"]
        if t == "ping":
            return [{"type": "pong", "n_nodes": None if self.session is None else self.session.n_nodes}]
        if t == "load":
            spec = msg.get("body")
            if not isinstance(spec, dict):
                raise TypeError("load message: 'body' must be an object")
            self.session = load_body(spec, None if trusted else self.app["folders"])
            _SESSIONS[self.sid] = self.session
            while len(_SESSIONS) > _KEEP_SESSIONS:
                _SESSIONS.popitem(last=False)
            return [body_message(self.session), self._state(self.session.settle(), msg)]
        s = self.session
        if s is None:
            raise ValueError("no body loaded yet")
        if t in ("fixed", "drag"):
            _fixed(s, msg)
            return [self._state(s.drag() if t == "drag" else s.settle(), msg)]
        if t == "graph":
            return [{"type": "graph", "weights": s.graph_weights()}]
        if t == "route":
            mm = msg.get("max_muscles")
            if mm is not None:
                mm = check_int(mm, "max_muscles (or empty)", 1, 100)
            fab = msg.get("fabrication")
            if fab is not None:  # checked at the door: a bad length is named before any routing
                fab = s.check_fabrication_fields(fab)
            out = s.route(_number(msg, "K_a", lo=0.0, hi=1e6), _number(msg, "K_b", lo=0.0, hi=1e6), mm, fab)
            return [dict(type="routing", **out)]
        if t == "delete_muscle":
            return [dict(type="routing", **s.delete_muscle(msg.get("name")))]
        if t == "design":
            method, model = msg.get("method"), msg.get("muscle_model")
            for k, v in (("method", method), ("muscle_model", model)):
                if v is not None and not isinstance(v, str):
                    raise TypeError(f"{k} must be a string, got {v!r}")
            out = s.run_design(method=method, muscle_model=model, a_max=_number(msg, "a_max", 0.0, 1.0))
            return [dict(type="design", **out)]
        if t == "save":
            from .export import WouldReplace, save_scene

            name = msg.get("name") or s.name
            if not isinstance(name, str):
                raise TypeError(f"save name must be a string, got {name!r}")
            written = self.app["written"]  # the files this server wrote: replaced without asking
            may = True if msg.get("confirm") is True else (lambda p: p.resolve() in written)
            notes: list[str] = []  # what the save changes for the cases the page did not edit
            try:
                files = save_scene(s, self.app["out"], name, overwrite=may, notes=notes)
            except WouldReplace as exc:
                return [{"type": "confirm", "action": "save", "name": name, "files": exc.paths,
                         "message": f"{exc} and {'was' if len(exc.paths) == 1 else 'were'} not written by "
                                    "this page: replace?"}]
            written.update(Path(f).resolve() for f in files)
            return [{"type": "saved", "files": [os.path.abspath(f) for f in files], "notes": notes,
                     "download": f"/download/{self.sid}/scene.zip"}]
        raise ValueError(f"unknown message type {t!r}")

    def _state(self, rep, msg) -> dict:
        s = self.session
        d = rep.to_dict()
        d.update(type="state", seq=msg.get("seq"), dropped=self.dropped, anchors=s.anchors.tolist(),
                 drag_nodes=s.drag_nodes.tolist(), drag_positions=s.drag_positions.tolist(),
                 settled=s.target is not None)
        if s.placed:  # the obstacles as this target placed them (a free disk moves)
            from .contact import obstacle_entries
            d["obstacles"] = obstacle_entries(s.placed)
        return d


class _Superseded(Exception):
    """Stops an exact solve started for a drag the page has moved on from."""


def _error(message: str, request=None) -> dict:
    return {"type": "error", "message": message, "request": request if isinstance(request, str) else None}


def _json_default(o):
    if isinstance(o, np.ndarray):
        return o.tolist()
    if isinstance(o, (np.floating, np.integer, np.bool_)):
        return o.item()
    raise TypeError(f"cannot send {type(o).__name__}")


def _parse(raw) -> dict:
    """One websocket frame -> a request dict (ValueError naming what is wrong)."""
    if raw.get("bytes") is not None:
        raise ValueError("binary messages are not accepted: send JSON text")
    text = raw.get("text")
    if text is None:
        raise ValueError("empty message")
    if len(text) > MAX_MESSAGE:
        raise ValueError(f"message too large: {len(text)} characters (limit {MAX_MESSAGE})")
    try:
        msg = json.loads(text, parse_constant=lambda c: float("nan"))
    except json.JSONDecodeError as exc:
        raise ValueError(f"malformed message (not JSON): {exc}") from None
    except RecursionError:
        raise ValueError(f"malformed message: nested too deeply (limit {MAX_DEPTH} levels)") from None
    if not isinstance(msg, dict) or not isinstance(msg.get("type"), str):
        raise ValueError("malformed message: expected a JSON object with a string 'type'")
    if _depth(msg) > MAX_DEPTH:
        raise ValueError(f"malformed message: nested too deeply (limit {MAX_DEPTH} levels)")
    return msg


def _depth(obj) -> int:
    """How deeply lists and objects nest in ``obj`` (a scalar: 0), without recursion."""
    deepest, todo = 0, [(obj, 1)]
    while todo:
        o, d = todo.pop()
        if isinstance(o, dict):
            o = o.values()
        elif not isinstance(o, list):
            continue
        deepest = max(deepest, d)
        if d <= MAX_DEPTH:
            todo.extend((v, d + 1) for v in o if isinstance(v, (dict, list)))
    return deepest


# ---------------------------------------------------------------------------------------------- the app
def make_app(initial: dict | None = None, out: str | os.PathLike = "authored", *, token: str, port: int,
             hosts: frozenset | None, folders=None):
    """The Starlette application behind its access checks (:class:`~mdsr_opt.author.guard.Guard`).

    Parameters
    ----------
    initial : a :func:`load_body` spec loaded when a page connects (``None``: the page starts empty).
    out : folder where ``save`` writes scene files.
    token : the session's secret that every request must present (:mod:`.guard`).
    port : the port the server listens on.
    hosts : the ``Host`` values accepted (:func:`~mdsr_opt.author.guard.allowed_hosts`; ``None``: any).
    folders : the folders whose files the page may open by path (default: ``out``; see :mod:`.files`).
    """
    from starlette.applications import Starlette
    from starlette.responses import FileResponse, JSONResponse, Response
    from starlette.routing import Mount, Route, WebSocketRoute
    from starlette.staticfiles import StaticFiles
    from starlette.websockets import WebSocketDisconnect

    from ..scenes.library import list_problems
    from .export import DOWNLOADS, download
    from .session import design_defaults

    folders = readable_folders(None, out) if folders is None else tuple(Path(f).resolve() for f in folders)
    state = {"out": os.fspath(out), "initial": initial, "folders": folders, "written": set()}

    async def index(request):
        return FileResponse(STATIC / "index.html", headers={"Cache-Control": "no-store"})

    async def info(request):
        return JSONResponse({"problems": list_problems(), "downloads": DOWNLOADS,
                             "design": {k: v for k, v in design_defaults().items()
                                        if isinstance(v, (int, float, str))},
                             "max_message": MAX_MESSAGE, "out": os.path.abspath(state["out"]),
                             "folders": [os.fspath(f) for f in folders]})

    async def get_download(request):
        sid, what = request.path_params["sid"], request.path_params["what"]
        s = _SESSIONS.get(sid)
        if s is None:
            return JSONResponse({"error": "unknown or expired session"}, status_code=404)
        try:
            with tempfile.TemporaryDirectory() as d:
                data, media = await asyncio.to_thread(download, s, what, d)
        except (ValueError, TypeError, RuntimeError) as exc:
            return JSONResponse({"error": str(exc)}, status_code=409)
        return Response(data, media_type=media,
                        headers={"Content-Disposition": f'attachment; filename="{s.name}-{what}"'})

    async def ws_endpoint(ws):
        await ws.accept()
        page = Page(ws, state)
        await page.send({"type": "hello", "sid": page.sid})
        task = asyncio.create_task(page.worker())
        if state["initial"] is not None:
            page.enqueue({"type": "load", "body": state["initial"]}, trusted=True)
        try:
            while True:
                raw = await ws.receive()
                if raw.get("type") == "websocket.disconnect":
                    break
                try:
                    msg = _parse(raw)
                except ValueError as exc:
                    await page.error(str(exc))
                    continue
                page.enqueue(msg)
        except WebSocketDisconnect:
            pass
        except Exception:  # never drop the page without a close frame
            traceback.print_exc(file=sys.stderr)
            with contextlib.suppress(Exception):
                await ws.close(code=1011, reason="internal error (see the server's output)")
        finally:
            task.cancel()
            page.stop_speculation()  # the page is gone: no solve for it goes on
            page.tmp.cleanup()

    routes = [Route("/", index), Route("/api/info", info), Route("/download/{sid}/{what}", get_download),
              WebSocketRoute("/ws", ws_endpoint), Mount("/static", StaticFiles(directory=STATIC), name="static")]
    return Guard(Starlette(routes=routes), token, port, hosts)
