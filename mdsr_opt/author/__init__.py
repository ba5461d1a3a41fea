"""``mdsr author``: author targets by hand on a local web page (the paper's man-machine interface).

The page loads a body (a library problem, a scene file, or an outline drawn on the page or read from an
SVG/JSON file, meshed at a chosen resolution), lets the user mark anchors and drag nodes, drag and rotate
them with the mouse while the external-driving equilibrium updates live, shows the contraction graph,
routes muscles, designs their contractions and compares target and driven shape, and saves the session
as a scene file that ``mdsr run`` reproduces. The server is Starlette on uvicorn (``pip install
"mdsr_opt[author]"``); the page's scripts are served locally and work offline.

Only the page ``mdsr author`` opened can use the server: the address it prints carries a per-session
secret (``?token=...``), and requests with a foreign ``Host`` or ``Origin`` are refused (:mod:`.guard`).
The page opens files only in the folders named on the command line (:mod:`.files`), runs no Python file,
and replaces no file it did not write without asking.

Modules: :mod:`.session` (the state and the solves), :mod:`.server` (the web app), :mod:`.guard` (who
may use it), :mod:`.files` (what the page may open), :mod:`.export` (scene file, figures, meshes,
results), :mod:`.roundtrip` (what a saved scene keeps of the scene opened), :mod:`.summary` (the design
as the page shows it), :mod:`.outline` (SVG/JSON outlines). Start it from Python with :func:`serve`, or in a thread
for tests with :func:`start_in_thread`.
"""

from __future__ import annotations

import contextlib
import ipaddress
import logging
import secrets
import socket
import sys
import threading
import time
from pathlib import Path

from ..core.errors import InputError, checking_input

__all__ = ["serve", "start_in_thread", "add_cli", "body_spec"]

_MISSING = ("the web server packages for mdsr author are missing (starlette, uvicorn): "
            "python -m pip install \"mdsr_opt[author]\"")


def _require():
    try:
        import starlette  # noqa: F401
        import uvicorn  # noqa: F401
    except ImportError:
        raise ImportError(_MISSING) from None


def body_spec(body: str | None, resolution=None) -> dict | None:
    """The load spec for the command line's ``BODY``: a library name, a scene file, or an outline file.

    Checks the body now (builds it once), so a bad name or file is reported before the server starts.
    """
    from .server import load_body

    if body is None:
        return None
    p = Path(body)
    if p.suffix.lower() in (".toml", ".json", ".svg", ".py") or "/" in body or p.exists():
        spec = {"kind": "path", "path": str(p.resolve()), "resolution": resolution}
    else:
        spec = {"kind": "problem", "name": body, "resolution": resolution}
    load_body(spec)
    return spec


def _is_loopback(host: str) -> bool:
    if host == "localhost":
        return True
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return False


def _bind(host: str, port: int) -> socket.socket:
    fam = socket.AF_INET6 if ":" in host else socket.AF_INET
    sock = socket.socket(fam, socket.SOCK_STREAM)
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
    try:
        sock.bind((host, port))
    except OSError as exc:
        sock.close()
        raise InputError(f"cannot listen on {host}:{port}: {exc.strerror or exc}") from None
    sock.listen(64)
    return sock


def _server(app, sock, access_log: bool = False):
    import uvicorn

    from .server import MAX_MESSAGE

    # no per-message deflate: on the loopback, compressing a 3k-node state costs more than sending it;
    # no proxy headers: nothing stands between the page and this server; no logging set-up of uvicorn's
    # own: its records go where the caller's logging sends them (the command line: _server_logs)
    config = uvicorn.Config(app, log_config=None, log_level=None, access_log=access_log,
                            ws_max_size=2 * MAX_MESSAGE, ws_ping_interval=None, ws_per_message_deflate=False,
                            lifespan="off", proxy_headers=False, server_header=False)
    return uvicorn.Server(config)


@contextlib.contextmanager
def _server_logs(verbose: int = 0, quiet: bool = False):
    """Within the block, uvicorn's log records go to the command line's handlers (the ``mdsr_opt`` logger's,
    so in its format): warnings and errors only, as the other commands print; ``-v`` adds uvicorn's INFO lines
    (server start and stop), ``-vv`` its debug lines (and one line per request: see :func:`serve`)."""
    log = logging.getLogger("uvicorn")
    level = logging.WARNING if quiet or verbose < 1 else (logging.INFO if verbose == 1 else logging.DEBUG)
    handlers = [h for h in logging.getLogger("mdsr_opt").handlers if h not in log.handlers]
    before = (log.level, log.propagate)
    log.setLevel(level)
    log.propagate = False
    for h in handlers:
        log.addHandler(h)
    try:
        yield
    finally:
        for h in handlers:
            log.removeHandler(h)
        log.setLevel(before[0])
        log.propagate = before[1]


def _app(spec, sock, host: str, body, out, allow_dirs):
    """The guarded app for the bound ``sock`` and the page's address with its token."""
    from .files import readable_folders
    from .guard import allowed_hosts
    from .server import make_app

    h, p = sock.getsockname()[:2]
    token = secrets.token_urlsafe(32)
    folders = readable_folders(body if isinstance(body, str) else None, out, allow_dirs)
    app = make_app(spec, out, token=token, port=p, hosts=allowed_hosts(host, p), folders=folders)
    shown = "127.0.0.1" if h in ("0.0.0.0", "::") else (f"[{h}]" if ":" in h else h)
    return app, f"http://{shown}:{p}/?token={token}", folders


def start_in_thread(body: str | dict | None = None, *, host: str = "127.0.0.1", port: int = 0,
                    out="authored", resolution=None, allow_dirs=()):
    """Start the server in a daemon thread; returns ``(url, server)`` (stop with ``server.should_exit = True``).

    ``body`` is what ``mdsr author`` takes (a name or path) or a load spec dict; ``url`` is the page's
    address with its token (``http://127.0.0.1:<port>/?token=...``), as ``mdsr author`` prints it.
    """
    _require()
    spec = body if isinstance(body, dict) or body is None else body_spec(body, resolution)
    sock = _bind(host, port)
    try:
        app, url, _ = _app(spec, sock, host, body, out, allow_dirs)
    except BaseException:
        sock.close()
        raise
    server = _server(app, sock)
    th = threading.Thread(target=server.run, kwargs={"sockets": [sock]}, daemon=True)
    th.start()
    t0 = time.time()
    while not server.started:
        if time.time() - t0 > 30 or not th.is_alive():
            raise RuntimeError("the author server did not start")
        time.sleep(0.02)
    return url, server


def serve(body: str | None = None, *, host: str = "127.0.0.1", port: int = 0, open_browser: bool = True,
          out="authored", resolution=None, allow_dirs=(), access_log: bool = False) -> int:
    """Serve the authoring page until interrupted (what ``mdsr author`` runs).

    Returns 0 when the server stops by itself. Ctrl-C (SIGINT) and SIGTERM stop the server, which then
    re-sends the signal to the handler that was there before (uvicorn does): Ctrl-C raises
    ``KeyboardInterrupt`` here, SIGTERM does what its handler does (the ``mdsr`` command's raises one too,
    so ``mdsr author`` exits 130 or 143, as every command). The server's log records go to the ``uvicorn``
    loggers, left for the caller to configure.

    Parameters
    ----------
    body : library problem name, problem script (``.py``), scene file (``.toml``/``.json``) or outline
        file (``.svg``/``.json``).
    host : address to bind; loopback by default (any other address is announced with a warning).
    port : 0 picks a free port.
    open_browser : open the page in the default browser.
    out : folder for saved scene files.
    resolution : node count (or coarse/medium/fine) for the body.
    allow_dirs : more folders whose scene, outline and mesh files the page may open by path (besides
        ``body``'s folder and ``out``).
    access_log : log one line per request (logger ``uvicorn.access``, INFO).
    """
    _require()
    import webbrowser

    with checking_input():  # the body (a name or a file) and its resolution: bad input, before serving
        spec = body_spec(body, resolution)
    if not _is_loopback(host):
        print(f"mdsr author: WARNING: listening on {host}, not the loopback address: anyone who can reach "
              "this machine and has the address below (with its token) can use the page and save files into "
              "the output folder", file=sys.stderr)
    sock = _bind(host, port)
    try:
        app, url, folders = _app(spec, sock, host, body, out, allow_dirs)
    except BaseException:
        sock.close()
        raise
    print(f"mdsr author: serving {body or 'an empty page'} on {url}\n"
          f"  Save writes scene files to {Path(out).resolve()} (--out)\n"
          f"  figures, meshes and the scene bundle are downloads: your browser's download folder\n"
          f"  the page may open files in {', '.join(map(str, folders))}\n"
          f"  Ctrl-C stops", flush=True)
    server = _server(app, sock, access_log)
    if open_browser:
        threading.Timer(0.8, webbrowser.open, args=(url,)).start()
    server.run(sockets=[sock])  # Ctrl-C: uvicorn stops, then raises it again here (KeyboardInterrupt)
    return 0


def _cmd(a) -> int:
    try:
        _require()
    except ImportError as exc:  # one line and the install command, no traceback
        print(f"mdsr author: error: {exc}", file=sys.stderr)
        return 2
    import matplotlib

    matplotlib.use("Agg")  # figures are drawn in worker threads for downloads
    if not 0 <= a.port <= 65535:
        raise InputError(f"--port must be in [0, 65535], got {a.port}")
    verbose, quiet = getattr(a, "log_verbose", 0), getattr(a, "log_quiet", False)
    with _server_logs(verbose, quiet):
        return serve(a.body, host=a.host, port=a.port, open_browser=not a.no_browser, out=a.out,
                     resolution=a.resolution, allow_dirs=a.allow_dir, access_log=verbose >= 2 and not quiet)


def add_cli(sub) -> None:
    """Register ``mdsr author``."""
    p = sub.add_parser("author", help="author targets by hand on a local web page: anchors, live drags, "
                       "muscles, design, save as a scene file")
    p.add_argument("body", nargs="?", default=None, metavar="PROBLEM|SCENE_FILE|OUTLINE",
                   help="a library problem (mdsr list), a scene file (.toml/.json) or an outline (.svg, or .json "
                   "with outline and holes); omit to choose on the page")
    p.add_argument("--resolution", default=None,
                   help="mesh resolution: a node count or coarse/medium/fine (default: the body's own, 600 for "
                   "outlines)")
    p.add_argument("--host", default="127.0.0.1", help="address to bind (default 127.0.0.1, loopback only)")
    p.add_argument("--port", type=int, default=0, help="port (default 0: a free port)")
    p.add_argument("--no-browser", action="store_true", help="do not open a browser; just print the address")
    p.add_argument("--out", default="authored", help="folder for saved scene files (default ./authored)")
    p.add_argument("--allow-dir", action="append", default=[], metavar="DIR",
                   help="another folder whose scene, outline and mesh files the page may open (repeatable; "
                   "it may always open those in the BODY file's folder and in --out)")
    p.set_defaults(func=_cmd)
