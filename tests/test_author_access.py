"""Who may drive ``mdsr author`` and what the page may do: a real server (uvicorn in a thread) and real clients.

A web page in the user's browser can reach the loopback server (port scan, DNS rebinding): only the page
opened with the session's token may use it; foreign ``Host`` and ``Origin`` are refused; the page never runs
a Python file, opens files only in the folders named on the command line, and replaces no file it did not
write without the user's confirmation; malformed messages are answered, never a dropped socket.
"""

from __future__ import annotations

import http.client
import json
import signal
import socket
import sys
import threading
from urllib.parse import urlsplit

import pytest

from websockets.exceptions import ConnectionClosed  # uvicorn[standard] (the author extra) installs websockets
from websockets.sync.client import connect

PAYLOAD = "open({marker!r}, 'w').write('the page ran me')\ndef build(resolution='medium'):\n    raise SystemExit\n"


@pytest.fixture(scope="module")
def server(tmp_path_factory):
    """An empty page's server: ``(url, out folder, another folder outside what the page may read)``."""
    from mdsr_opt.author import start_in_thread

    out = tmp_path_factory.mktemp("authored")
    before = set(threading.enumerate())
    url, srv = start_in_thread(None, out=out)
    yield url, out, tmp_path_factory.mktemp("elsewhere")
    srv.should_exit = True
    for t in set(threading.enumerate()) - before:  # no stray thread for the modules after this one
        t.join(timeout=15)


def parts(url):
    u = urlsplit(url)
    return u.hostname, u.port, u.query.removeprefix("token=")


def client(url, *, origin="own", token=True, host=None):
    """A websocket to the server at ``url``: ``origin`` "own" is the page's; ``host``: another Host header
    (the name a rebinding page uses), sent over a socket to the real address."""
    h, port, tok = parts(url)
    name = host or f"{h}:{port}"
    uri = f"ws://{name}/ws" + (f"?token={tok}" if token is True else (f"?token={token}" if token else ""))
    sock = socket.create_connection((h, port), timeout=30)
    return connect(uri, sock=sock, origin=f"http://{name}" if origin == "own" else origin, max_size=None,
                   open_timeout=30)


def refused(url, **kw) -> str:
    """The reason the server gave when it closed the websocket at once with code 1008 (policy violation)."""
    with client(url, **kw) as ws:
        with pytest.raises(ConnectionClosed) as e:
            ws.recv(timeout=30)
    assert e.value.rcvd is not None and e.value.rcvd.code == 1008, e.value
    return e.value.rcvd.reason


def recv(ws, *kinds):
    """The next message of one of ``kinds`` or an error (others are passed over)."""
    while True:
        m = json.loads(ws.recv(timeout=60))
        if m["type"] in (*kinds, "error"):
            return m


def ask(ws, msg, *kinds):
    ws.send(msg if isinstance(msg, str) else json.dumps(msg))
    return recv(ws, *kinds)


def get(url, path, host=None, cookie=None):
    h, port, _ = parts(url)
    c = http.client.HTTPConnection(h, port, timeout=30)
    headers = {"Host": host or f"{h}:{port}"}
    if cookie:
        headers["Cookie"] = cookie
    c.request("GET", path, headers=headers)
    r = c.getresponse()
    out = r.status, r.read().decode(errors="replace"), r.getheader("set-cookie")
    c.close()
    return out


# ------------------------------------------------------------------------------------------ who
def test_foreign_origin_is_refused(server):
    url = server[0]
    assert "foreign page" in refused(url, origin="http://evil.example")
    _, port, _ = parts(url)
    assert "foreign page" in refused(url, origin=f"http://localhost:{port + 1}")  # another local server's page
    assert "foreign page" in refused(url, origin=None)


def test_websocket_without_the_token_is_refused(server):
    url = server[0]
    assert "token" in refused(url, token=None)
    assert "token" in refused(url, token="x" * 43)


def test_own_page_with_the_token_is_served(server):
    url = server[0]
    with client(url) as ws:
        assert json.loads(ws.recv(timeout=30))["type"] == "hello"
        assert ask(ws, {"type": "ping"}, "pong") == {"type": "pong", "n_nodes": None}
    h, port, _ = parts(url)
    with client(url, host=f"localhost:{port}") as ws:  # the loopback names all serve
        assert json.loads(ws.recv(timeout=30))["type"] == "hello"


def test_foreign_host_is_refused_for_http_and_websocket(server):
    url = server[0]
    _, port, tok = parts(url)
    for host in ("evil.example", f"evil.example:{port}", f"127.0.0.1:{port + 1}"):
        status, text, cookie = get(url, f"/?token={tok}", host=host)
        assert status == 403 and "not this server's address" in text and cookie is None
    # DNS rebinding: evil.example resolves to 127.0.0.1; the page's origin is its own, the token it guessed
    assert "not this server's address" in refused(url, host=f"evil.example:{port}")


def test_http_needs_the_token_once_then_the_cookie(server):
    url = server[0]
    _, port, tok = parts(url)
    for path in ("/", "/api/info", "/static/author.js", f"/?token={tok[:-1]}"):
        status, text, _ = get(url, path)
        assert status == 403 and "token" in text, path
    status, text, cookie = get(url, f"/?token={tok}")
    assert status == 200 and "mdsr author" in text
    flags = [f.strip().lower() for f in cookie.split(";")]
    assert flags[0] == f"mdsr-author-{port}={tok}".lower() and "httponly" in flags and "samesite=strict" in flags
    jar = cookie.split(";")[0]
    assert get(url, "/static/author.js", cookie=jar)[0] == 200
    assert json.loads(get(url, "/api/info", cookie=jar)[1])["max_message"] > 0
    assert get(url, "/static/author.js", cookie=f"mdsr-author-{port}=wrong")[0] == 403
    uri = f"ws://127.0.0.1:{port}/ws"  # no token in the websocket's address: the cookie presents it
    with connect(uri, origin=f"http://127.0.0.1:{port}", additional_headers={"Cookie": jar}) as ws:
        assert json.loads(ws.recv(timeout=30))["type"] == "hello"


# ------------------------------------------------------------------------------------------ what
def test_the_page_never_runs_a_python_file(server, tmp_path, monkeypatch):
    url, out, _ = server
    marker = tmp_path / "ran.txt"
    for folder in (out, tmp_path):
        (folder / "payload.py").write_text(PAYLOAD.format(marker=str(marker)))
    monkeypatch.chdir(tmp_path)  # where a bare name would be found
    with client(url) as ws:
        recv(ws, "hello")
        for body, words in [({"kind": "path", "path": "payload.py"}, "does not run Python files"),
                            ({"kind": "path", "path": str(out / "payload.py")}, "does not run Python files"),
                            ({"kind": "problem", "name": "payload.py"}, "unknown problem"),
                            ({"kind": "problem", "name": "payload"}, "unknown problem")]:
            m = ask(ws, {"type": "load", "body": body}, "body")
            assert m["type"] == "error" and words in m["message"], m
        assert ask(ws, {"type": "ping"}, "pong")["type"] == "pong"
    assert not marker.exists()


def test_the_page_opens_files_only_in_the_named_folders(server, tmp_path):
    url, out, elsewhere = server
    square = {"outline": [[0, 0], [2, 0], [2, 1], [0, 1]]}
    (elsewhere / "plate.json").write_text(json.dumps(square))
    (out / "plate.json").write_text(json.dumps(square))
    (out / "far.json").write_text(json.dumps({"body": {"mesh": str(elsewhere / "far.vtu")}}))
    (out / "up.toml").write_text('[body]\nmesh = "../up.vtu"\n')
    (out / "notes.txt").write_text("hello")
    with client(url) as ws:
        recv(ws, "hello")
        for path, words in [(elsewhere / "plate.json", "outside the folders"),
                            (out / ".." / elsewhere.name / "plate.json", "outside the folders"),
                            (out / "far.json", "body.mesh"), (out / "up.toml", "body.mesh"),
                            (out / "notes.txt", "scene files (.toml/.json) and outlines")]:
            m = ask(ws, {"type": "load", "body": {"kind": "path", "path": str(path)}}, "body")
            assert m["type"] == "error" and words in m["message"], (path, m)
        upload = {"kind": "scene", "filename": "s.json", "text": json.dumps({"body": {"mesh": "/etc/x.vtu"}})}
        m = ask(ws, {"type": "load", "body": upload}, "body")
        assert m["type"] == "error" and "cannot bring its mesh file" in m["message"]
        m = ask(ws, {"type": "load", "body": {"kind": "path", "path": str(out / "plate.json"), "resolution": 60}},
                "body")
        assert m["type"] == "body" and m["name"] == "plate" and 40 < m["n_nodes"] < 90


def test_save_asks_before_replacing_a_file_the_page_did_not_write(server):
    url, out, _ = server
    mine = out / "mine.json"
    mine.write_text('{"the": "user\'s own scene"}')
    with client(url) as ws:
        recv(ws, "hello")
        assert ask(ws, {"type": "load", "body": {"kind": "problem", "name": "tentacle",
                                                 "resolution": "coarse"}}, "state")["type"] == "state"
        m = ask(ws, {"type": "save", "name": "mine"}, "saved", "confirm")
        assert m["type"] == "confirm" and m["files"] == [str(mine)] and "replace?" in m["message"], m
        assert mine.read_text() == '{"the": "user\'s own scene"}' and not (out / "mine.mesh.vtu").exists()
        m = ask(ws, {"type": "save", "name": "mine", "confirm": "yes"}, "saved", "confirm")  # only true confirms
        assert m["type"] == "confirm" and mine.read_text() == '{"the": "user\'s own scene"}'
        m = ask(ws, {"type": "save", "name": "mine", "confirm": True}, "saved", "confirm")
        assert m["type"] == "saved" and json.loads(mine.read_text())["name"] == "mine"
        # the page wrote these files itself: saving again replaces them without asking
        assert ask(ws, {"type": "save", "name": "mine"}, "saved", "confirm")["type"] == "saved"
        # a file only next to the scene counts as well
        (out / "other.mesh.vtu").write_text("not a mesh of the page")
        m = ask(ws, {"type": "save", "name": "other"}, "saved", "confirm")
        assert m["type"] == "confirm" and m["files"] == [str(out / "other.mesh.vtu")]
        assert not (out / "other.json").exists()
        # and the saved scene opens again from the output folder
        m = ask(ws, {"type": "load", "body": {"kind": "path", "path": str(mine)}}, "body")
        assert m["type"] == "body" and m["name"] == "mine"


# ------------------------------------------------------------------------------------------ bad messages
def test_nested_and_oversized_messages_get_an_error_reply(server):
    from mdsr_opt.author.server import MAX_DEPTH, MAX_MESSAGE

    url = server[0]
    deep_scene = json.dumps({"kind": "scene", "filename": "deep.json", "text": '{"body": ' + "[" * 50000 + "]" * 50000 + "}"})
    deep_toml = {"kind": "scene", "filename": "deep.toml", "text": "a = " + "[" * 5000 + "]" * 5000}
    with client(url) as ws:
        recv(ws, "hello")
        for raw in ("[" * 100000 + "]" * 100000, '{"type": "ping", "x": ' + "[" * (MAX_DEPTH + 1) + "]" * (MAX_DEPTH + 1) + "}",
                    '{"type": "load", "body": ' + deep_scene + "}", json.dumps({"type": "load", "body": deep_toml})):
            m = ask(ws, raw, "pong")
            # the message's nesting, or the scene reader's own limit for the scene files (read by it alone)
            assert m["type"] == "error" and ("nested too deeply" in m["message"] or "nested more than" in m["message"]), m
        m = ask(ws, json.dumps({"type": "ping", "pad": "x" * (MAX_MESSAGE + 10)}), "pong")
        assert m["type"] == "error" and "too large" in m["message"]
        assert ask(ws, {"type": "ping", "x": [[[1]]]}, "pong")["type"] == "pong"  # the server keeps serving


def test_meshing_that_runs_out_of_memory_is_an_error_on_the_page(server, monkeypatch):
    import mdsr_opt.author.session as session

    def no_memory(*a, **k):
        raise MemoryError

    monkeypatch.setattr(session, "mesh_polygon", no_memory)
    url = server[0]
    with client(url) as ws:
        recv(ws, "hello")
        m = ask(ws, {"type": "load", "body": {"kind": "outline", "outline": [[0, 0], [1, 0], [0, 1]]}}, "body")
        assert m["type"] == "error" and "out of memory" in m["message"]
        assert ask(ws, {"type": "ping"}, "pong")["type"] == "pong"


# ------------------------------------------------------------------------------------------ command line
def test_missing_author_extra_is_one_line_and_exit_2(monkeypatch, capsys):
    import sys

    from mdsr_opt.cli.main import main

    monkeypatch.setitem(sys.modules, "uvicorn", None)  # `import uvicorn` raises ImportError
    assert main(["author", "tentacle", "--no-browser"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "Traceback" not in err
    assert 'python -m pip install "mdsr_opt[author]"' in err


def test_the_printed_address_carries_the_token(monkeypatch, capsys, tmp_path):
    import mdsr_opt.author as author

    class Stop(Exception):
        pass

    def no_run(self, sockets):
        sockets[0].close()
        raise Stop

    monkeypatch.setattr("uvicorn.Server.run", no_run)
    with pytest.raises(Stop):
        author.serve(None, open_browser=False, out=tmp_path / "out", allow_dirs=[str(tmp_path)])
    line = capsys.readouterr().out
    token = line.split("?token=")[1].split()[0]
    assert len(token) >= 40 and str(tmp_path) in line
    with pytest.raises(ValueError, match="not a folder"):
        author.serve(None, open_browser=False, allow_dirs=[str(tmp_path / "nothing")])


@pytest.mark.skipif(sys.platform == "win32", reason="sends POSIX signals to a child process")
@pytest.mark.parametrize("sig, code, name", [(signal.SIGINT, 130, "Ctrl-C"), (signal.SIGTERM, 143, "SIGTERM")])
def test_mdsr_author_exits_as_every_command_on_ctrl_c_and_sigterm(tmp_path, sig, code, name):
    """README: every command exits 130 on Ctrl-C and 143 on SIGTERM, with one line; the server's own INFO lines
    (uvicorn's) are not printed without -v, as no other command prints a library's progress."""
    import os
    import re
    import subprocess
    import time
    import urllib.error
    import urllib.request
    from pathlib import Path

    root = Path(__file__).resolve().parents[1]
    proc = subprocess.Popen([sys.executable, "-m", "mdsr_opt", "author", "tentacle", "--resolution", "coarse",
                             "--no-browser", "--out", str(tmp_path)], cwd=root,
                            env=dict(os.environ, PYTHONPATH=str(root), OPENBLAS_NUM_THREADS="1"),
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        url = re.search(r"http://\S+", proc.stdout.readline()).group(0)
        deadline = time.monotonic() + 60
        while True:  # signalled while serving, not while starting
            try:
                assert urllib.request.urlopen(url, timeout=5).status == 200
                break
            except urllib.error.URLError:
                assert time.monotonic() < deadline and proc.poll() is None, proc.stderr.read()
                time.sleep(0.05)
        proc.send_signal(sig)
        out, err = proc.communicate(timeout=60)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    assert proc.returncode == code, err
    assert err.strip().splitlines() == [f"mdsr author: interrupted ({name}); files already complete are kept"]


@pytest.mark.parametrize("verbose, quiet, lines", [
    (0, False, ["Invalid HTTP request received."]),
    (1, False, ["INFO uvicorn.error: Started server process", "WARNING uvicorn.error: Invalid HTTP request received."]),
    (0, True, ["Invalid HTTP request received."])])
def test_the_servers_log_lines_follow_the_command_lines_verbosity(capsys, verbose, quiet, lines):
    """uvicorn's records go through the command line's handler: its INFO lines only with -v (then with the
    logger's name, as -v shows every logger's), its warnings always."""
    import logging

    from mdsr_opt.author import _server_logs
    from mdsr_opt.cli.main import configure_logging

    lib, server = logging.getLogger("mdsr_opt"), logging.getLogger("uvicorn")
    before = (list(lib.handlers), lib.level, list(server.handlers), server.level, server.propagate)
    try:
        configure_logging(verbose, quiet)
        with _server_logs(verbose, quiet):
            logging.getLogger("uvicorn.error").info("Started server process")
            logging.getLogger("uvicorn.error").warning("Invalid HTTP request received.")
        assert (list(server.handlers), server.level, server.propagate) == before[2:]  # left as it was
    finally:
        lib.handlers[:] = before[0]
        lib.setLevel(before[1])
    assert capsys.readouterr().err.splitlines() == lines
