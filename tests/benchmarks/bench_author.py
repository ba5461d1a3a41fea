"""Authoring-page benchmark: drag updates per second and the settle after the last move, ~600 and ~3k nodes.

It starts the ``mdsr author`` server in this process (uvicorn in a thread, as ``mdsr author`` runs it),
connects a websocket client the way the page does (one drag request in flight; the next is sent when the
reply arrives) and moves a drag group around nine tenths of a small circle, ``--updates`` requests, each
moving the group by ``--step`` times the body size. ``--body``: a library problem (its first case's drag
nodes near the first one: the tentacle's tip, one gecko limb), a scene file, or ``outline`` (a finger with a
hole drawn here, its left end anchored and right end dragged). Per run it reports the server's solve time
(``state.solve_time``), the round trip (send to reply parsed), the update rate (requests answered per
second of wall time), how many requests needed the cold fallback or were not solved, the time from the
last move to the settled state (the release, a ``fixed`` request, sent after holding still ``--hold``
seconds), and the targets (30/s and a 0.3 s settle at ~600 nodes, 4/s at ~3k). A flood test then sends 20
drags without waiting and counts those the server dropped as stale.

    python tests/benchmarks/bench_author.py --out bench_out
    python tests/benchmarks/bench_author.py --body gecko,outline,tentacle --sizes 600 --step 0.01,0.03 --hold 0,0.2
    python tests/benchmarks/bench_author.py --sizes 600,3000 --step 0.01,0.03 --screenshot tests/benchmarks/author_page.png

``--screenshot`` also drives the page in headless chromium (route, delete the shortest rope, design, overlay
view) and saves a PNG.
"""

from __future__ import annotations

import argparse
import csv
import json
import os
import statistics
import time

import numpy as np

TARGETS = {600: 30.0, 3000: 4.0}  # updates/s (issue 36: >= 30/s at ~600 nodes)
SETTLE_TARGET_S = 0.3  # a released drag settles (the exact equilibrium) within this


def _client(url):
    """A websocket as the page opens it: its own origin, the token from the page's address."""
    from urllib.parse import urlsplit

    from websockets.sync.client import connect

    u = urlsplit(url)
    return connect(f"ws://{u.netloc}/ws?{u.query}", origin=f"http://{u.netloc}", max_size=None, compression=None)


def _recv(ws, kind, timeout=300):
    while True:
        m = json.loads(ws.recv(timeout=timeout))
        if m["type"] == kind:
            return m
        if m["type"] == "error":
            raise RuntimeError(m["message"])


#: the outline drawn for the benchmark (``--body outline``): a bent finger with a hole, meshed at ``--sizes``
OUTLINE = [[0, 0], [7, 0], [9.5, 1.2], [10, 2.4], [8.8, 2.6], [6.5, 1.6], [0, 1.6]]
OUTLINE_HOLES = [[[2.5, 0.5], [4, 0.5], [4, 1.1], [2.5, 1.1]]]


def body_spec(body: str, nodes: int):
    """What ``start_in_thread`` takes for ``--body``: ``outline`` (:data:`OUTLINE`), a library name or a file."""
    if body == "outline":
        return {"kind": "outline", "outline": OUTLINE, "holes": OUTLINE_HOLES, "resolution": nodes}
    return body


def fixed_sets(body: dict):
    """Anchors, drag nodes, their positions and the moved ones (a mask): the body's own when it has drags
    (moved: the first drag node's group, e.g. one gecko limb), else the
    left end anchored and the right end dragged."""
    P = np.asarray(body["points"])
    if body["drag_nodes"]:
        pos = np.asarray(body["drag_positions"])
        moved = np.zeros(len(pos), dtype=bool)
        moved[0] = True
        while True:  # the group of the first drag node: drag nodes closer than 5 % of the size to it, repeated
            d = np.linalg.norm(pos[:, None] - pos[moved][None], axis=2).min(1)
            grown = d <= 0.05 * body["size"]
            if grown.sum() == moved.sum():
                return body["anchors"], body["drag_nodes"], pos, moved
            moved = grown
    lo, hi = P[:, 0].min(), P[:, 0].max()
    anchors = np.flatnonzero(P[:, 0] <= lo + 0.03 * (hi - lo)).tolist()
    drags = np.flatnonzero(P[:, 0] >= hi - 0.05 * (hi - lo)).tolist()
    return anchors, drags, P[drags], np.ones(len(drags), dtype=bool)


def measure(nodes: int, step: float, updates: int, log=print, body_name: str = "tentacle", hold: float = 0.0) -> dict:
    from mdsr_opt.author import start_in_thread

    url, server = start_in_thread(body_spec(body_name, nodes), resolution=nodes, out=os.devnull)
    try:
        with _client(url) as ws:
            body = _recv(ws, "body")
            first = _recv(ws, "state")
            size = body["size"]
            anchors, drag_nodes, P0, moved = fixed_sets(body)
            r = step * size * updates / (2 * np.pi)  # a circle of `updates` chords of length ~step * size
            u = P0[moved].mean(0) - np.asarray(body["points"]).mean(0)  # the circle lies away from the body
            u /= np.linalg.norm(u)
            v = np.array([-u[1], u[0]])
            solve, rtt, warm_failed, failed = [], [], 0, 0
            t_start, cpu_start = time.perf_counter(), time.process_time()
            for k in range(1, updates + 1):
                a = 1.8 * np.pi * k / updates  # nine tenths of the circle: released away from the start
                off = r * ((1.0 - np.cos(a)) * u + np.sin(a) * v)
                msg = {"type": "drag", "seq": k, "anchors": anchors, "drag_nodes": drag_nodes,
                       "drag_positions": (P0 + np.where(moved[:, None], off, 0.0)).tolist()}
                t0 = time.perf_counter()
                ws.send(json.dumps(msg))
                st = _recv(ws, "state")
                rtt.append(time.perf_counter() - t0)
                solve.append(st["solve_time"])
                warm_failed += bool(st["warm_failed"])
                if not st["success"]:
                    failed += 1
                    log(f"  update {k}: not solved: {st['status']}")
            wall = time.perf_counter() - t_start
            cpu = time.process_time() - cpu_start  # server and client together (same process)
            # the release (after holding still for `hold` s): the exact equilibrium at the last drag positions,
            # timed from the last move
            t0 = time.perf_counter()
            time.sleep(hold)
            ws.send(json.dumps(dict(msg, type="fixed", seq=updates + 1)))
            settled = _recv(ws, "state")
            settle_s = time.perf_counter() - t0
            if not settled["success"] or settled["live"]:
                log(f"  release: not settled: {settled['status']}")
            # flood: 20 drags at once; the server keeps only the latest waiting one
            for k in range(20):
                off = 0.002 * size * (k + 1) * np.array([1.0, 0.0])
                ws.send(json.dumps({"type": "drag", "seq": 1000 + k, "anchors": anchors, "drag_nodes": drag_nodes,
                                    "drag_positions": (P0 + np.where(moved[:, None], off, 0.0)).tolist()}))
            answered = []
            while not answered or answered[-1]["seq"] != 1019:
                answered.append(_recv(ws, "state"))
    finally:
        server.should_exit = True
    row = {"body": body_name, "nodes": body["n_nodes"], "step": step, "updates": updates, "moved": int(moved.sum()),
           "hold_s": hold, "failed_updates": failed,
           "first_solve_s": first["solve_time"],
           "solve_median_ms": 1e3 * statistics.median(solve), "solve_max_ms": 1e3 * max(solve),
           "rtt_median_ms": 1e3 * statistics.median(rtt), "rtt_max_ms": 1e3 * max(rtt),
           "rate_per_s": updates / wall, "settle_s": settle_s, "cpu_per_update_ms": 1e3 * cpu / updates, "cold_fallbacks": warm_failed,
           "flood_sent": 20, "flood_answered": len(answered), "flood_dropped": 20 - len(answered)}
    target = TARGETS.get(min(TARGETS, key=lambda n: abs(n - nodes)))
    row["target_per_s"] = target
    row["release_s"] = settle_s - hold  # the release to the settled state
    # the settled state within SETTLE_TARGET_S of the last move (held still longer: at the release)
    row["meets_target"] = row["rate_per_s"] >= target and (nodes > 1000 or row["release_s"] <= SETTLE_TARGET_S)
    return row


def screenshot(path: str, body: str = "tentacle", resolution: str | None = "coarse") -> str:
    """Drive the page in headless chromium (``body``, default tentacle: route, delete the shortest rope, design,
    overlay) and save a PNG at ``path``."""
    import shutil
    import tempfile

    from selenium import webdriver
    from selenium.webdriver.chrome.service import Service
    from selenium.webdriver.common.by import By

    from mdsr_opt.author import start_in_thread

    url, server = start_in_thread(body, resolution=resolution, out=tempfile.mkdtemp())
    opts = webdriver.ChromeOptions()
    opts.binary_location = shutil.which("chromium") or "/usr/bin/chromium"
    for flag in ("--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
                 "--disable-background-networking", "--disable-component-update", "--disable-sync",
                 "--window-size=1150,1000", f"--user-data-dir={tempfile.mkdtemp()}"):
        opts.add_argument(flag)
    drv = webdriver.Chrome(service=Service(shutil.which("chromedriver") or "/usr/bin/chromedriver"), options=opts)

    def wait(script, timeout=120):
        t0 = time.time()
        while time.time() - t0 < timeout:
            v = drv.execute_script(script)
            if v:
                return v
            time.sleep(0.1)
        raise RuntimeError(f"timed out: {script}")

    try:
        drv.get(url)
        wait("const s = mdsrAuthor.state(); return s && s.settled && !mdsrAuthor.busy();")
        drv.find_element(By.ID, "route").click()
        routing = wait("return mdsrAuthor.routing();")
        if len(routing["muscles"]) > 1:  # the shortest rope: deleted
            stub = min(routing["muscles"], key=lambda m: len(m["nodes"]))["name"]
            drv.find_element(By.CSS_SELECTOR, f"#muscle-table tr[data-name='{stub}']").click()
            drv.find_element(By.ID, "delete-muscle").click()
            wait("const r = mdsrAuthor.routing(); return r && r.deleted.length;")
        if routing["muscles"]:  # a body the routing lays no rope on is shown with its target alone
            drv.find_element(By.ID, "design").click()
            wait("return mdsrAuthor.design();", timeout=600)
            drv.find_element(By.CSS_SELECTOR, "input[name=view][value=overlay]").click()
            wait("return document.querySelector('#muscle-table tr') !== null;")
        time.sleep(0.5)
        drv.save_screenshot(path)
    finally:
        drv.quit()
        server.should_exit = True
    from PIL import Image  # matplotlib's dependency: a 64-colour palette keeps the PNG small

    Image.open(path).convert("RGB").quantize(colors=64).save(path, optimize=True)
    return path


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--body", default="tentacle", help="library problem, scene file, or 'outline' (a finger with "
                    "a hole drawn here); comma-separated for several (default tentacle)")
    ap.add_argument("--hold", default="0", help="seconds held still before the release (comma-separated)")
    ap.add_argument("--sizes", default="600,3000", help="node counts (default 600,3000)")
    ap.add_argument("--step", default="0.01,0.03", help="drag step per update, fractions of the body size")
    ap.add_argument("--updates", type=int, default=40, help="drag requests per run (default 40)")
    ap.add_argument("--out", default="bench_out", help="folder for author.csv")
    ap.add_argument("--screenshot", default=None, help="also save a screenshot of the page here (PNG)")
    a = ap.parse_args(argv)
    rows = []
    runs = [(b, int(n), float(st), float(h)) for b in a.body.split(",") for n in a.sizes.split(",")
            for st in a.step.split(",") for h in a.hold.split(",")]
    for b, n, step, hold in runs:
            row = measure(n, step, a.updates, body_name=b, hold=hold)
            rows.append(row)
            print(f"{b}: {row['nodes']:>6} nodes ({row['moved']} moved), step {step:.3f} size: solve median {row['solve_median_ms']:.0f} ms "
                  f"(max {row['solve_max_ms']:.0f}), round trip median {row['rtt_median_ms']:.0f} ms "
                  f"(max {row['rtt_max_ms']:.0f}), {row['rate_per_s']:.1f} updates/s (target {row['target_per_s']:g}: "
                  f"{'met' if row['meets_target'] else 'MISSED'}), settled {1e3 * row['settle_s']:.0f} ms after the last move (held {hold:g} s; {1e3 * row['release_s']:.0f} ms after the release), {row['failed_updates']} updates not solved, CPU {row['cpu_per_update_ms']:.0f} ms/update, cold fallbacks {row['cold_fallbacks']}, "
                  f"flood: {row['flood_dropped']}/20 stale drags dropped", flush=True)
    os.makedirs(a.out, exist_ok=True)
    with open(os.path.join(a.out, "author.csv"), "w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)
    if a.screenshot:
        print("screenshot:", screenshot(a.screenshot))
    return 0 if all(r["meets_target"] for r in rows) else 1


if __name__ == "__main__":
    raise SystemExit(main())
