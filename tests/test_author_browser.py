"""The authoring page (``mdsr author``) in a real headless browser: Debian's chromium + chromedriver via selenium.

Real mouse events drag a point; the state the page shows must equal ``solve_external`` with the same anchors
and drags; routing (with a channel size set on the page), a muscle's deletion and design run from the page and
the saved scene file must reproduce them with ``python -m mdsr_opt run``; bad messages get a message on the page and the server keeps answering.
"""

from __future__ import annotations

import json
import os
import shutil
import threading
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import pytest

from mdsr_opt import contraction_graph, get_problem, load_scene, prepare_case, solve_external

from selenium import webdriver  # pip install ".[test]" installs selenium; .ci/run installs chromium
from selenium.webdriver.common.action_chains import ActionChains
from selenium.webdriver.common.by import By

ROOT = Path(__file__).resolve().parents[1]
PROBLEM, RESOLUTION = "tentacle", "coarse"


def chrome_options():
    opts = webdriver.ChromeOptions()
    opts.binary_location = shutil.which("chromium") or "/usr/bin/chromium"
    for flag in ("--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
                 "--disable-background-networking", "--disable-component-update", "--disable-sync",
                 "--window-size=1200,760", f"--user-data-dir={tempfile.mkdtemp(prefix='mdsr-chromium-')}"):
        opts.add_argument(flag)
    return opts


def open_browser():
    """A headless chromium driven through Debian's chromedriver (installed by .ci/run)."""
    from selenium.webdriver.chrome.service import Service

    driver_path = shutil.which("chromedriver") or "/usr/bin/chromedriver"
    browser = shutil.which("chromium") or "/usr/bin/chromium"
    if not (Path(driver_path).exists() and Path(browser).exists()):
        hint = "Chromium and its driver are missing: apt-get install -y chromium chromium-driver"
        if os.environ.get("CI"):  # .ci/run installs them: there a missing browser is a failure
            pytest.fail(hint)
        pytest.skip(hint)  # a newcomer's machine without a browser: the page's other tests still run
    return webdriver.Chrome(service=Service(driver_path), options=chrome_options())


@pytest.fixture(scope="module")
def served(tmp_path_factory):
    from mdsr_opt.author import start_in_thread

    out = tmp_path_factory.mktemp("authored")
    before = set(threading.enumerate())
    url, server = start_in_thread(PROBLEM, resolution=RESOLUTION, out=out)
    yield url, out
    server.should_exit = True
    # the server's threads end before the next module's tests
    for t in set(threading.enumerate()) - before:
        t.join(timeout=15)


@pytest.fixture(scope="module")
def page(served):
    url, _ = served
    assert "?token=" in url  # the address mdsr author prints and opens
    drv = open_browser()
    drv.get(url)
    wait(drv, "const s = mdsrAuthor.state(); return s !== null && s.settled && !mdsrAuthor.busy();")
    yield drv
    drv.quit()


def wait(drv, script, timeout=60.0):
    t0 = time.time()
    while time.time() - t0 < timeout:
        v = drv.execute_script(script)
        if v:
            return v
        time.sleep(0.05)
    raise AssertionError(f"timed out waiting for: {script}; page errors: {drv.execute_script('return mdsrAuthor.errors()')}")


def idle(drv):
    """Wait until the page has no request in flight and shows the reply to its last request."""
    wait(drv, "const s = mdsrAuthor.state(); return !mdsrAuthor.busy() && s && (s.seq === null || s.seq === mdsrAuthor.seq());")
    return drv.execute_script("return mdsrAuthor.state();")


def drag_with_mouse(drv, node, steps):
    """Press on a drag node with the real mouse and move it by ``steps`` (list of (dx, dy) pixels)."""
    canvas = drv.find_element(By.ID, "canvas")
    sx, sy = drv.execute_script(f"return mdsrAuthor.screenOf({int(node)});")
    w, h = canvas.size["width"], canvas.size["height"]
    chain = ActionChains(drv, duration=30).move_to_element_with_offset(canvas, int(round(sx - w / 2)),
                                                                         int(round(sy - h / 2)))
    chain.click_and_hold()
    for dx, dy in steps:
        chain.move_by_offset(dx, dy).pause(0.05)
    chain.release().perform()


def test_mouse_drag_shows_the_solve_external_equilibrium(page):
    scene = get_problem(PROBLEM, resolution=RESOLUTION)
    before = page.execute_script("return mdsrAuthor.state();")
    node = before["drag_nodes"][0]
    page.find_element(By.CSS_SELECTOR, "input[name=tool][value=move]").click()
    live0 = page.execute_script("return mdsrAuthor.nLive();")
    drag_with_mouse(page, node, [(-10, -6)] * 6)
    st = idle(page)
    assert page.execute_script("return mdsrAuthor.nLive();") > live0  # the equilibrium updated while dragging
    assert st["success"] and not st["live"] and st["settled"]
    moved = np.asarray(st["drag_positions"]) - np.asarray(before["drag_positions"])
    assert np.linalg.norm(moved, axis=1).min() > 0.05 * scene.mesh.size / 10  # the whole group moved
    assert np.allclose(moved, moved[0], atol=1e-12)  # ... rigidly, by one offset
    ref = solve_external(scene.mesh, scene.material, st["anchors"], (st["drag_nodes"], st["drag_positions"]))
    assert ref.success
    assert np.abs(np.asarray(st["x"]) - ref.x).max() <= 1e-8


def test_rotation_drag_rotates_the_group_about_the_pivot(page):
    page.find_element(By.CSS_SELECTOR, "input[name=tool][value=rotate]").click()
    before = idle(page)
    node = before["drag_nodes"][0]
    drag_with_mouse(page, node, [(0, 12)] * 4)
    st = idle(page)
    P0, P1 = np.asarray(before["drag_positions"]), np.asarray(st["drag_positions"])
    c = P0.mean(0)  # the default pivot: the group's centroid
    d0, d1 = P0 - c, P1 - c
    assert np.allclose(np.linalg.norm(d0, axis=1), np.linalg.norm(d1, axis=1), atol=1e-9)  # distances kept
    ang = np.arctan2(d0[:, 0] * d1[:, 1] - d0[:, 1] * d1[:, 0], (d0 * d1).sum(1))
    far = np.linalg.norm(d0, axis=1) > 1e-6
    assert abs(ang[far][0]) > 1e-3 and np.allclose(ang[far], ang[far][0], atol=1e-9)  # one rigid rotation
    scene = get_problem(PROBLEM, resolution=RESOLUTION)
    ref = solve_external(scene.mesh, scene.material, st["anchors"], (st["drag_nodes"], st["drag_positions"]))
    assert np.abs(np.asarray(st["x"]) - ref.x).max() <= 1e-8


def test_route_design_save_reproduced_by_mdsr_run(page, served, tmp_path):
    _, out = served
    # the body afresh (its own case): routed with a channel size set on the page, it has a stub to delete
    page.find_element(By.ID, "resolution").send_keys(RESOLUTION)
    page.execute_script("const s = document.getElementById('problem'); s.value = arguments[0]; "
                        "s.dispatchEvent(new Event('change'));", PROBLEM)
    seq = page.execute_script("return mdsrAuthor.seq();")
    page.find_element(By.ID, "load-problem").click()
    wait(page, "const s = mdsrAuthor.state(); return s && s.settled && s.seq === null && !mdsrAuthor.busy() "
               f"&& mdsrAuthor.seq() === {seq} && mdsrAuthor.routing() === null;")
    st = idle(page)
    assert np.array_equal(st["anchors"], get_problem(PROBLEM, resolution=RESOLUTION).cases[0].anchors)
    assert page.execute_script("return [document.getElementById('problem').value, mdsrAuthor.body().library, "
                               "document.getElementById('load-problem').disabled];") == [PROBLEM, True, False]
    # the page says what Save keeps of the scene opened: its other case, its regions
    kept = page.find_element(By.ID, "kept").text
    assert "case 'curl': anchors and drags as set here; cases s_curve: kept as loaded" in kept, kept
    assert "muscles routed here: case 'curl''s alone; cases s_curve: their muscles (or routing) as loaded" in kept
    page.find_element(By.ID, "show-graph").click()
    weights = wait(page, "return mdsrAuthor.graph();")
    scene0 = get_problem(PROBLEM, resolution=RESOLUTION)
    G = contraction_graph(scene0.mesh, np.asarray(st["x"]))
    assert np.allclose(weights, [G.edges[int(a), int(b)]["weight"] for a, b in scene0.mesh.edges], rtol=0, atol=1e-12)
    # the fabrication fields show the body's defaults (Fabrication.for_body); the user sets a channel size
    from mdsr_opt.synthesis.fabrication import Fabrication

    fab = Fabrication().for_body(scene0.mesh).to_dict()
    for k, v in fab.items():
        assert float(page.find_element(By.ID, k).get_attribute("value")) == v
    channel = page.find_element(By.ID, "channel_diameter")
    channel.clear()
    channel.send_keys("0.1")
    page.find_element(By.ID, "route").click()
    routing = wait(page, "const r = mdsrAuthor.routing(); return r && r.fabrication.channel_diameter === 0.1 && r;")
    assert len(routing["muscles"]) >= 2  # one to delete, one to design (ropes keep a channel and wall apart)
    shown_notes = page.find_element(By.ID, "routing-notes").text
    assert f"radius {routing['fixture_radius']:.4g}" in shown_notes and all(t in shown_notes for t in routing["notes"])
    # select a muscle on the canvas with the Muscle tool and delete it
    page.find_element(By.CSS_SELECTOR, "input[name=tool][value=muscle]").click()
    victim = min(routing["muscles"], key=lambda m: len(m["nodes"]))  # the shortest rope: a stub
    a, b = victim["nodes"][len(victim["nodes"]) // 2 - 1: len(victim["nodes"]) // 2 + 1]
    pa, pb = (page.execute_script(f"return mdsrAuthor.screenOf({int(v)});") for v in (a, b))
    canvas = page.find_element(By.ID, "canvas")
    w, h = canvas.size["width"], canvas.size["height"]
    ActionChains(page, duration=30).move_to_element_with_offset(canvas, round((pa[0] + pb[0]) / 2 - w / 2),
                                                                round((pa[1] + pb[1]) / 2 - h / 2)).click().perform()
    assert page.execute_script("return mdsrAuthor.selected();") == victim["name"]
    page.find_element(By.ID, "delete-muscle").click()
    routing = wait(page, "const r = mdsrAuthor.routing(); return r && r.deleted.length && r;")
    assert routing["deleted"] == [victim["name"]] and victim["name"] not in [m["name"] for m in routing["muscles"]]
    assert page.execute_script("return mdsrAuthor.design();") is None
    page.find_element(By.ID, "design").click()
    design = wait(page, "return mdsrAuthor.design();", timeout=180)
    assert design["success"], design["status"]
    name = page.find_element(By.ID, "save-name")
    assert name.get_attribute("value") == ""  # the box starts empty: typing gives the name typed
    name.send_keys("authored_tentacle")
    page.find_element(By.ID, "save").click()
    saved = wait(page, "return mdsrAuthor.saved();")
    scene_file = Path(saved["files"][0])
    shown = page.find_element(By.ID, "save-notes").text  # the channel size set here: the kept case's too
    assert saved["notes"] and all(n in shown for n in saved["notes"]) and "also s_curve" in shown, shown
    assert "channel_diameter 0.1" in shown, shown
    assert scene_file.parent == Path(out).resolve() and scene_file.name == "authored_tentacle.json"
    # the scene file holds the same target and muscles ...
    scene = load_scene(scene_file)
    setup = prepare_case(scene, "curl")  # the case edited keeps its name
    assert np.array_equal(setup.target, np.asarray(st["x"]))
    assert [list(m.nodes) for m in setup.muscles] == [m["nodes"] for m in routing["muscles"]]  # less the deleted
    saved_fab = json.loads(scene_file.read_text())["fabrication"]
    assert saved_fab == dict(fab, channel_diameter=0.1) and scene.routing_options["fabrication"] == saved_fab
    # curl's own ropes, designed with the fixtures they were fitted to; the scene's design radius as it was
    assert scene.case("curl").anchor_radius == routing["fixture_radius"] and "anchor_radius" not in scene.design_options
    # ... and `mdsr run` designs the same contractions
    res = subprocess.run([sys.executable, "-m", "mdsr_opt", "run", str(scene_file), "--out", str(tmp_path / "run"),
                          "--no-photos", "--no-figures", "--no-animations", "--quiet"], cwd=ROOT,
                         capture_output=True, text=True, timeout=300)
    # s_curve, kept as loaded, routes its own layout (not curl's) and succeeds, as it did before the save
    assert res.returncode == 0, res.stdout + res.stderr
    cases = {c["case"]: c for c in json.loads((tmp_path / "run" / "summary.json").read_text())["cases"]}
    assert list(cases) == ["curl", "s_curve"] and "also s_curve" in scene.description
    assert cases["s_curve"]["success"] and scene.case("s_curve").muscles is None
    assert [m["nodes"] for m in cases["s_curve"]["muscles"]] != [m["nodes"] for m in routing["muscles"]]
    case = cases["curl"]
    assert case["n_muscles"] == len(routing["muscles"]) and case["success"]
    np.testing.assert_allclose(case["contractions"], design["contractions"], rtol=0, atol=1e-9)
    assert abs(case["difference"] - design["difference"]) <= 1e-9
    # downloads: figures, meshes, results and the scene as a zip (with the token, as the page's cookie has it)
    url, _ = served
    sid = page.execute_script("return mdsrAuthor.sid();")
    import io
    import urllib.request
    import zipfile
    from urllib.parse import urlsplit

    u = urlsplit(url)

    def get(what):
        with urllib.request.urlopen(f"http://{u.netloc}/download/{sid}/{what}?{u.query}", timeout=120) as r:
            return r.read()

    for png in ("target.png", "graph.png", "muscles.png", "design.png"):
        assert get(png)[:8] == b"\x89PNG\r\n\x1a\n"
    from mdsr_opt import read_mesh

    (tmp_path / "driven.vtu").write_bytes(get("driven.vtu"))
    np.testing.assert_allclose(read_mesh(tmp_path / "driven.vtu").x, design["x_aligned"], rtol=0, atol=1e-12)
    results = json.loads(get("results.json"))
    assert results["design"]["contractions"] == design["contractions"]
    names = zipfile.ZipFile(io.BytesIO(get("scene.zip"))).namelist()
    assert sorted(names) == ["tentacle.json", "tentacle.mesh.vtu"]
    shot = tmp_path / "page.png"
    page.find_element(By.CSS_SELECTOR, "input[name=view][value=overlay]").click()
    page.save_screenshot(str(shot))
    assert shot.stat().st_size > 10_000


def test_replacing_a_file_the_page_did_not_write_asks_on_the_page(page, served):
    _, out = served
    theirs = Path(out) / "theirs.json"
    theirs.write_text("the user's own file")
    idle(page)
    name = page.find_element(By.ID, "save-name")
    name.clear()
    name.send_keys("theirs")
    page.find_element(By.ID, "save").click()
    ask = wait(page, "return mdsrAuthor.confirmation();")
    box = page.find_element(By.ID, "confirm")
    assert box.is_displayed() and "theirs.json" in box.text and "replace?" in box.text
    assert ask["files"] == [str(theirs)] and theirs.read_text() == "the user's own file"
    page.find_element(By.ID, "confirm-no").click()
    assert not box.is_displayed() and theirs.read_text() == "the user's own file"
    assert not (Path(out) / "theirs.mesh.vtu").exists()
    page.find_element(By.ID, "save").click()
    wait(page, "return mdsrAuthor.confirmation();")
    page.find_element(By.ID, "confirm-yes").click()
    saved = wait(page, "const s = mdsrAuthor.saved(); return s && s.files[0].endsWith('theirs.json') ? s : null;")
    assert Path(saved["files"][0]) == theirs.resolve() and json.loads(theirs.read_text())["name"] == "theirs"
    assert not box.is_displayed()


def test_a_page_of_another_origin_is_refused_even_with_the_token(page, served):
    url, _ = served
    from urllib.parse import urlsplit

    u = urlsplit(url)
    own = page.current_window_handle
    page.switch_to.new_window("tab")
    try:
        page.get(f"http://localhost:{u.port}/")  # another origin of the same server: no cookie, no token
        assert "missing or wrong token" in page.find_element(By.TAG_NAME, "body").text
        page.execute_script("window.closed_with = null; const ws = new WebSocket(arguments[0]);"
                            "ws.onclose = (e) => { window.closed_with = [e.code, e.reason]; };",
                            f"ws://{u.netloc}/ws?{u.query}")
        code, reason = wait(page, "return window.closed_with;")
        assert code == 1008 and "foreign page" in reason
    finally:
        page.close()
        page.switch_to.window(own)
    st = idle(page)  # the own page still works: a new settle with its fixed nodes comes back
    page.execute_script("window.before = mdsrAuthor.state(); mdsrAuthor.send({type: 'fixed', seq: mdsrAuthor.seq(),"
                        " anchors: arguments[0], drag_nodes: arguments[1], drag_positions: arguments[2]});",
                        st["anchors"], st["drag_nodes"], st["drag_positions"])
    wait(page, "return mdsrAuthor.state() !== window.before;")
    assert idle(page)["success"]


def errors_after(page, n0):
    return page.execute_script(f"return mdsrAuthor.errors().slice({n0});")


@pytest.mark.parametrize("raw, words", [
    ("this is not json", "malformed message"),
    ('{"no": "type"}', "string 'type'"),
    ('{"type": "drag", "anchors": [0, 100000], "drag_nodes": [], "drag_positions": []}', "out of range"),
    ('{"type": "fixed", "anchors": [0], "drag_nodes": [1], "drag_positions": [[NaN, 0]]}', "finite"),
    ('{"type": "fixed", "anchors": [0], "drag_nodes": [1], "drag_positions": [[1e200, 0]]}', "too large"),
    ('{"type": "load", "body": {"kind": "outline", "outline": [[0, 0], [1, 1], [1, 0], [0, 1]]}}',
     "self-intersecting"),
    ('{"type": "route", "K_a": "ten", "K_b": 4}', "K_a must be a number"),
    ('{"type": "load", "body": {"kind": "problem", "name": "no_such_robot"}}', "unknown problem"),
    ('{"type": "load", "body": {"kind": "path", "path": "payload.py"}}', "does not run Python files"),
    ('{"type": "load", "body": {"kind": "path", "path": "/etc/passwd.json"}}', "outside the folders"),
    ('{"type": "ping", "x": ' + "[" * 5000 + "]" * 5000 + "}", "nested too deeply"),
])
def test_bad_message_is_named_on_the_page_and_server_keeps_serving(page, raw, words):
    n0 = len(page.execute_script("return mdsrAuthor.errors();"))
    page.execute_script("mdsrAuthor.sendRaw(arguments[0]);", raw)
    msgs = wait(page, f"const e = mdsrAuthor.errors().slice({n0}); return e.length ? e : null;")
    assert any(words in m for m in msgs), msgs
    shown = page.find_element(By.ID, "errors").text
    assert words in shown
    page.execute_script("mdsrAuthor.send({type: 'ping'});")
    assert wait(page, "const p = mdsrAuthor.pong(); return p && p.n_nodes;") > 0


def test_oversized_message_is_refused_and_server_keeps_serving(page):
    from mdsr_opt.author.server import MAX_MESSAGE

    n0 = len(page.execute_script("return mdsrAuthor.errors();"))
    page.execute_script("mdsrAuthor.sendRaw(JSON.stringify({type: 'ping', pad: 'x'.repeat(arguments[0])}));",
                        MAX_MESSAGE + 10)
    msgs = wait(page, f"const e = mdsrAuthor.errors().slice({n0}); return e.length ? e : null;")
    assert any("too large" in m for m in msgs), msgs
    page.execute_script("mdsrAuthor.send({type: 'ping'});")
    assert wait(page, "const p = mdsrAuthor.pong(); return p && p.n_nodes;") > 0
    st = idle(page)  # still solving: a settle with the current fixed nodes
    page.execute_script("mdsrAuthor.send({type: 'fixed', seq: 999999, anchors: arguments[0], drag_nodes: arguments[1],"
                        " drag_positions: arguments[2]});", st["anchors"], st["drag_nodes"], st["drag_positions"])
    wait(page, "return mdsrAuthor.state().seq === 999999;")


def click_at(drv, points):
    """Left clicks at canvas pixels ``points`` (real mouse events; the pointer moves there in 30 ms, as in
    :func:`drag_with_mouse`, not selenium's default 250 ms: a click is where it lands)."""
    canvas = drv.find_element(By.ID, "canvas")
    w, h = canvas.size["width"], canvas.size["height"]
    for x, y in points:
        chain = ActionChains(drv, duration=30).move_to_element_with_offset(canvas, int(x - w / 2), int(y - h / 2))
        chain.click().perform()


def test_svg_outline_file_with_a_hole(page, tmp_path):
    svg = tmp_path / "plate.svg"
    svg.write_text('<svg xmlns="http://www.w3.org/2000/svg"><path d="M0 0 H 60 V 20 H 0 Z"/>'
                   '<rect x="25" y="5" width="10" height="10"/></svg>')
    res = page.find_element(By.ID, "resolution")
    res.clear()
    res.send_keys("200")
    page.find_element(By.ID, "file").send_keys(str(svg))
    body = wait(page, "const b = mdsrAuthor.body(); return b && b.name === 'plate' ? b : null;")
    assert len(body["boundary"]) == 2 and 150 < body["n_nodes"] < 260
    # the body drop-down names the loaded file's body, not the library problem it showed before
    sel = page.execute_script("const s = document.getElementById('problem'); "
                              "return [s.value, s.options[s.selectedIndex].textContent, "
                              "document.getElementById('load-problem').disabled];")
    assert sel == ["", "plate (outline)", True] and body["library"] is False


def test_draw_outline_anchor_drag_on_the_page(page):
    canvas = page.find_element(By.ID, "canvas")
    w, h = canvas.size["width"], canvas.size["height"]
    n0 = len(page.execute_script("return mdsrAuthor.errors();"))
    # a bow tie crosses itself: refused with a message naming it
    page.find_element(By.ID, "draw").click()
    click_at(page, [(w * 0.3, h * 0.3), (w * 0.7, h * 0.7), (w * 0.7, h * 0.3), (w * 0.3, h * 0.7)])
    page.find_element(By.ID, "draw-close").click()
    page.find_element(By.ID, "draw-mesh").click()
    msgs = wait(page, f"const e = mdsrAuthor.errors().slice({n0}); return e.length ? e : null;")
    assert any("self-intersecting" in m for m in msgs), msgs
    page.find_element(By.ID, "draw").click()  # cancel
    # a bar: meshed, anchored on the left by brushing, dragged on the right by the mouse
    page.find_element(By.ID, "draw").click()
    click_at(page, [(w * 0.2, h * 0.45), (w * 0.8, h * 0.45), (w * 0.8, h * 0.55), (w * 0.2, h * 0.55)])
    page.find_element(By.ID, "draw-close").click()
    page.find_element(By.ID, "draw-mesh").click()
    body = wait(page, "const b = mdsrAuthor.body(); return b && b.name === 'authored' ? b : null;")
    P = np.asarray(body["points"])
    idle(page)
    page.execute_script("document.getElementById('brush').value = 30;")
    page.find_element(By.CSS_SELECTOR, "input[name=tool][value=anchor]").click()
    left = int(np.argmin(P[:, 0]))
    sx, sy = page.execute_script(f"return mdsrAuthor.screenOf({left});")
    click_at(page, [(sx + 2, sy)])
    page.find_element(By.CSS_SELECTOR, "input[name=tool][value=handle]").click()
    right = int(np.argmax(P[:, 0]))
    sx, sy = page.execute_script(f"return mdsrAuthor.screenOf({right});")
    click_at(page, [(sx - 2, sy)])
    st = idle(page)
    assert len(st["anchors"]) >= 2 and right in st["drag_nodes"] and left in st["anchors"]
    page.find_element(By.CSS_SELECTOR, "input[name=tool][value=move]").click()
    drag_with_mouse(page, right, [(0, -8)] * 5)
    st = idle(page)
    assert st["success"] and np.asarray(st["x"])[right, 1] > P[right, 1]  # moved up on screen = +y
    from mdsr_opt import Mesh, NeoHookean

    mesh = Mesh(P, body["triangles"])
    ref = solve_external(mesh, NeoHookean(1.0, 0.3), st["anchors"], (st["drag_nodes"], st["drag_positions"]))
    assert np.abs(np.asarray(st["x"]) - ref.x).max() <= 1e-8


#: Loose bounds for the 600-node drags below (issue 36 asks >= 30 updates/s and a settle within 0.3 s of the
#: last move; tests/benchmarks/bench_author.py measures them; a shared CI machine gets this much room)
#: a drag must be live: the page shows at least this many solved states while the mouse moves (the rate
#: itself is a performance figure, measured by tests/benchmarks/bench_author.py, not asserted here)
MIN_LIVE = 3

#: an outline of our own (a bent finger with a hole, ~600 nodes): its base anchored, its tip dragged
FINGER = """name = "finger"
[body]
outline = [[0, 0], [7, 0], [9.5, 1.2], [10, 2.4], [8.8, 2.6], [6.5, 1.6], [0, 1.6]]
holes = [[[2.5, 0.5], [4, 0.5], [4, 1.1], [2.5, 1.1]]]
resolution = 600
[regions]
base = { box = [-1, -1, 0.3, 3] }
tip = { near = [9.4, 2.5], radius = 0.45 }
[[cases]]
name = "lift"
anchors = "base"
drags = [{ nodes = "tip", by = [-1.0, 1.0] }]
"""

#: mouse moves at the display's frame rate for `ms` milliseconds, held still for `hold` ms, then the release;
#: returns the live updates per second and the times from the last move and from the release to the settled state
DRAG_SCRIPT = """
  const [ms, hold, done] = arguments;
  const c = document.getElementById('canvas'), r = c.getBoundingClientRect();
  const [sx, sy] = mdsrAuthor.screenOf(mdsrAuthor.state().drag_nodes[0]);
  const ev = (target, type, x, y) => target.dispatchEvent(new MouseEvent(type,
      {clientX: r.left + x, clientY: r.top + y, button: 0, bubbles: true}));
  ev(c, 'mousedown', sx, sy);
  const n0 = mdsrAuthor.nLive(), t0 = performance.now();
  let moves = 0, last = t0;
  function step() {
    const t = performance.now() - t0;
    if (t < ms) {
      moves += 1;
      ev(c, 'mousemove', sx + 25 * Math.sin(t / 300), sy + 15 * (1 - Math.cos(t / 300)));
      last = performance.now();
      requestAnimationFrame(step);
      return;
    }
    const live = mdsrAuthor.nLive() - n0, rate = live / (t / 1000);
    setTimeout(() => {
      ev(window, 'mouseup', sx, sy);
      const up = performance.now();
      (function poll() {
        const s = mdsrAuthor.state();
        if (!mdsrAuthor.busy() && s && !s.live && s.seq === mdsrAuthor.seq())
          done({live: live, rate: rate, settle: (performance.now() - last) / 1000, release: (performance.now() - up) / 1000, success: s.success, moves: moves,
                x: s.x, anchors: s.anchors, drag_nodes: s.drag_nodes, drag_positions: s.drag_positions});
        else setTimeout(poll, 5);
      })();
    }, hold);
  }
  requestAnimationFrame(step);
"""


# the drawn finger in the default run (a library scene is on the page in every test of the module fixture);
# the gecko, the same drag on a library body of the same size, is slow
@pytest.mark.parametrize("which", [pytest.param("gecko", marks=pytest.mark.slow), "finger"])
def test_drag_on_a_600_node_body_updates_live_and_settles_exactly(tmp_path, which):
    """Real mouse moves on gecko (556 nodes) and a drawn finger (576 nodes): live updates while the mouse
    moves, and after the release (at once, and after holding still) the state is exactly the equilibrium
    mdsr run solves (solve_external with its defaults, the same bits)."""
    from mdsr_opt.author import start_in_thread

    if which == "gecko":
        body, scene = "gecko", get_problem("gecko", resolution=600)
    else:
        body = tmp_path / "finger.toml"
        body.write_text(FINGER)
        scene = load_scene(body)
    url, server = start_in_thread(str(body), resolution=600 if which == "gecko" else None, out=tmp_path)
    drv = open_browser()
    try:
        drv.get(url)
        wait(drv, "const s = mdsrAuthor.state(); return s !== null && s.settled && !mdsrAuthor.busy();")
        assert np.array_equal(drv.execute_script("return mdsrAuthor.body().points;"), scene.mesh.points)
        assert scene.mesh.n_nodes > 500
        drv.find_element(By.CSS_SELECTOR, "input[name=tool][value=move]").click()
        drv.set_script_timeout(60)
        runs = {hold: drv.execute_async_script(DRAG_SCRIPT, 2000, hold) for hold in (0, 400)}
    finally:
        drv.quit()
        server.should_exit = True
    for hold, got in runs.items():
        print(f"{which} ({scene.mesh.n_nodes} nodes) drag in the browser: {got['rate']:.1f} updates/s "
              f"({got['moves']} mouse moves), settled {1e3 * got['settle']:.0f} ms after the last move "
              f"(held {hold} ms), {1e3 * got['release']:.0f} ms after the release")
        assert got["success"] and got["moves"] > 20
        assert got["live"] >= MIN_LIVE  # live updates while dragging; their rate is the benchmark's
        ref = solve_external(scene.mesh, scene.material, got["anchors"], (got["drag_nodes"], got["drag_positions"]))
        assert np.array_equal(np.asarray(got["x"]), ref.x)  # exactly the settled state mdsr run computes
