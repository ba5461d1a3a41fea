"""The page draws a scene's obstacles (a disk, a half-plane and a case's polygon) and says what its solves do with
them, in headless chromium (trial 11, defect 2: the page showed no obstacle and solved through them)."""

from __future__ import annotations

import threading

import numpy as np
import pytest

from test_author_browser import open_browser, wait  # noqa: E402  the browser tests' chromium and waiting
from test_author_obstacles import CENTRE, DISK, RADIUS  # noqa: E402  the strip beside a disk

from selenium.webdriver.common.by import By


@pytest.fixture(scope="module")
def page(tmp_path_factory):
    from mdsr_opt.author import start_in_thread

    folder = tmp_path_factory.mktemp("obstacles")
    scene = folder / "strip_disk.toml"
    scene.write_text(DISK)
    before = set(threading.enumerate())
    url, server = start_in_thread(str(scene), out=folder / "authored")
    drv = open_browser()
    try:
        drv.get(url)
        wait(drv, "const s = mdsrAuthor.state(); return s !== null && s.settled && !mdsrAuthor.busy();")
        yield drv
    finally:
        drv.quit()
        server.should_exit = True
        for t in set(threading.enumerate()) - before:
            t.join(timeout=15)


def pixel(drv, world):
    """The canvas's RGBA at the world point ``world`` (the page's own transform, read through worldOf)."""
    return drv.execute_script("""
        const w0 = mdsrAuthor.worldOf([0, 0]), w1 = mdsrAuthor.worldOf([1, 0]), s = 1 / (w1[0] - w0[0]);
        const q = [-w0[0] * s + s * arguments[0], w0[1] * s - s * arguments[1]];
        const c = document.getElementById("canvas"), k = c.width / c.getBoundingClientRect().width;
        return Array.from(c.getContext("2d").getImageData(Math.round(q[0] * k), Math.round(q[1] * k), 1, 1).data);
    """, float(world[0]), float(world[1]))


def test_the_page_draws_every_obstacle_and_keeps_the_body_out_of_the_disk(page):
    st = page.execute_script("return mdsrAuthor.state();")
    assert st["success"]
    x = np.asarray(st["x"])
    assert (np.linalg.norm(x - CENTRE, axis=1) < RADIUS).sum() == 0
    kinds = page.execute_script("return mdsrAuthor.body().obstacles.map((o) => o.kind);")
    assert kinds == ["disk", "halfplane", "polygon"]
    for where in (CENTRE, (50.0, -75.0), (-50.0, -35.0)):  # inside the disk, below the floor, in the triangle
        r, g, b, a = pixel(page, where)
        assert a > 40 and max(r, g, b) - min(r, g, b) < 8, (where, (r, g, b, a))  # the obstacles' grey
    assert pixel(page, (50.0, -45.0))[3] == 0  # above the floor, beside everything: nothing drawn
    # the method offered is the one the design will choose ("auto": with obstacles the nested design checked
    # with them, derivative-free when touched), not "flattened", which the obstacles never ran
    assert page.execute_script("return document.getElementById('method').value;") == "auto"


def test_the_page_says_what_its_solves_do_with_the_obstacles(page):
    contact = page.find_element(By.ID, "contact").text
    assert "obstacles (disk, halfplane, polygon), friction 0" in contact
    assert "live drag: no fast preview" in contact
    assert "obstacles (2 of the scene; case 'up''s own): kept as loaded" in page.find_element(By.ID, "kept").text
