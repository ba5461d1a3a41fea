"""Who may use the ``mdsr author`` server: the ``Host``, ``Origin`` and per-session token checks.

A server on the loopback address is reachable from every web page the user's browser shows: a page can
find its port by scanning, and DNS rebinding (a hostile name that resolves to 127.0.0.1) makes the
browser treat the server as that page's own origin. So every request passes three checks, in an ASGI
middleware (:class:`Guard`) in front of the whole app, before any route runs:

* **Host**: HTTP requests and websocket handshakes whose ``Host`` header is not one of the server's own
  loopback names (``127.0.0.1:<port>``, ``localhost:<port>``, ``[::1]:<port>``; plus the ``--host``
  address when the user bound another one) get ``403``. A rebinding page's requests carry its own host
  name, so they stop here.
* **Origin** (websocket): a browser always sends the page's origin with a websocket handshake, and
  websockets are not protected by the same-origin policy; the handshake is refused unless ``Origin``
  is exactly ``http://<Host>``, the server's own page.
* **Token**: ``mdsr author`` makes a secret with :func:`secrets.token_urlsafe` and prints and opens
  ``http://127.0.0.1:<port>/?token=<secret>`` (as Jupyter does). A request presents it either as the
  ``token`` query parameter or as the cookie ``mdsr-author-<port>``, which the server sets on every
  response to a request whose query parameter was right (``HttpOnly``: no script reads it;
  ``SameSite=Strict``: no other site's page sends it; the port in its name keeps two servers apart, as
  cookies ignore ports). So the opened page, its style sheet and script, ``/api/info`` and the downloads
  work through the cookie, and the page's script also adds the token from its own address to the
  websocket's. Comparisons take constant time (:func:`hmac.compare_digest`). Without the token: ``403``.

A refused websocket is accepted and closed at once with code 1008 (policy violation) and a reason, before
any message is read, so the page can say why; a refused HTTP request gets a one-line ``403`` text.
"""

from __future__ import annotations

import hmac
import ipaddress
from urllib.parse import parse_qs

__all__ = ["Guard", "allowed_hosts", "cookie_name", "POLICY_VIOLATION"]

#: websocket close code for a refused connection (RFC 6455: policy violation)
POLICY_VIOLATION = 1008
_WILDCARD = ("0.0.0.0", "::", "")


def cookie_name(port: int) -> str:
    """The token cookie's name for the server on ``port``."""
    return f"mdsr-author-{int(port)}"


def allowed_hosts(host: str, port: int) -> frozenset | None:
    """The ``Host`` header values the server on ``host:port`` answers (lower case).

    The loopback names with the port, and ``host`` itself when it is a specific other address. ``None``
    (any ``Host``) for a wildcard bind (``0.0.0.0``, ``::``), which the user asked for explicitly: there
    the token is the only check, and ``mdsr author`` says so when it starts.
    """
    if host in _WILDCARD:
        return None
    names = ["127.0.0.1", "localhost", "[::1]"]
    h = host.lower()
    try:
        if ipaddress.ip_address(h).version == 6:
            h = f"[{h}]"
    except ValueError:
        pass
    names.append(h)
    out = {f"{n}:{int(port)}" for n in names}
    if int(port) == 80:  # a browser leaves the default port out of Host
        out.update(names)
    return frozenset(out)


def _headers(scope) -> dict:
    out = {}
    for k, v in scope.get("headers", ()):
        out.setdefault(k.decode("latin-1").lower(), v.decode("latin-1"))
    return out


def _cookies(header: str) -> dict:
    out = {}
    for part in header.split(";"):
        k, sep, v = part.strip().partition("=")
        if sep:
            out.setdefault(k.strip(), v.strip().strip('"'))
    return out


def _same(given: str | None, token: str) -> bool:
    return given is not None and hmac.compare_digest(given.encode("utf-8", "replace"), token.encode())


class Guard:
    """ASGI middleware: refuse requests with a foreign ``Host`` or ``Origin`` or without the token.

    Parameters
    ----------
    app : the ASGI application behind the checks.
    token : the session's secret.
    port : the port the server listens on (names the cookie).
    hosts : the accepted ``Host`` values (:func:`allowed_hosts`); ``None`` accepts any.
    """

    def __init__(self, app, token: str, port: int, hosts: frozenset | None):
        if not isinstance(token, str) or len(token) < 16:
            raise ValueError("the author server's token must be a string of at least 16 characters")
        self.app, self.token, self.hosts = app, token, hosts
        self.cookie = cookie_name(port)

    def check(self, scope) -> tuple[str | None, bool]:
        """``(why refused or None, the query parameter carried the token)``."""
        h = _headers(scope)
        host = h.get("host", "").strip().lower()
        if not host or self.hosts is not None and host not in self.hosts:
            return f"host {host or '(none)'!r} is not this server's address (open the address mdsr author " \
                   "printed)", False
        if scope["type"] == "websocket" and h.get("origin", "").strip().lower() != f"http://{host}":
            return f"websocket from a foreign page (origin {h.get('origin', '(none)')!r}) refused", False
        query = parse_qs(scope.get("query_string", b"").decode("latin-1")).get("token", [None])[-1]
        if _same(query, self.token):
            return None, True
        if _same(_cookies(h.get("cookie", "")).get(self.cookie), self.token):
            return None, False
        return "missing or wrong token: open the address mdsr author printed (it ends in ?token=...)", False

    async def __call__(self, scope, receive, send):
        if scope["type"] not in ("http", "websocket"):
            return await self.app(scope, receive, send)
        why, by_query = self.check(scope)
        if why is not None:
            if scope["type"] == "websocket":
                return await _close_websocket(receive, send, why)
            return await _forbidden(send, why)
        if scope["type"] == "http" and by_query:
            send = self._setting_cookie(send)
        return await self.app(scope, receive, send)

    def _setting_cookie(self, send):
        value = f"{self.cookie}={self.token}; Path=/; HttpOnly; SameSite=Strict".encode()

        async def wrapped(message):
            if message["type"] == "http.response.start":
                message = dict(message, headers=[*message.get("headers", []), (b"set-cookie", value)])
            await send(message)

        return wrapped


async def _forbidden(send, why: str) -> None:
    body = f"mdsr author: {why}\n".encode()
    await send({"type": "http.response.start", "status": 403,
                "headers": [(b"content-type", b"text/plain; charset=utf-8"),
                            (b"content-length", str(len(body)).encode()), (b"cache-control", b"no-store")]})
    await send({"type": "http.response.body", "body": body})


async def _close_websocket(receive, send, why: str) -> None:
    message = await receive()
    if message["type"] != "websocket.connect":
        return
    await send({"type": "websocket.accept"})
    await send({"type": "websocket.close", "code": POLICY_VIOLATION, "reason": why[:120]})
