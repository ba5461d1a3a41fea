"""The faster paths of `mdsr run` give what the straightforward ones gave: the photograph's rasterisation,
the contour distances, the tight figure box, the GIF writer and the reuse of solved animation frames."""

from __future__ import annotations

import io

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pytest  # noqa: E402
from PIL import Image  # noqa: E402

from mdsr_opt import Mesh, NeoHookean  # noqa: E402
from mdsr_opt.photos.camera import _raster_triangles  # noqa: E402
from mdsr_opt.photos.compare import _PolylineDistance, unsigned_distances  # noqa: E402
from mdsr_opt.plot.common import render_cropped, save_figure, tight_bbox  # noqa: E402
from mdsr_opt.plot.scenes import gif_palette, save_animation  # noqa: E402


def raster_reference(pts, triangles, shape):
    """The per-pixel test: a pixel centre is inside when all three edge functions are >= 0."""
    H, W = shape
    mask = np.zeros(shape, dtype=np.uint8)
    for tri in triangles:
        P = pts[tri]
        if (P[1, 0] - P[0, 0]) * (P[2, 1] - P[0, 1]) - (P[1, 1] - P[0, 1]) * (P[2, 0] - P[0, 0]) < 0:
            P = P[::-1]
        x0, y0 = np.maximum(np.floor(P.min(axis=0)).astype(int), 0)
        x1, y1 = np.minimum(np.ceil(P.max(axis=0)).astype(int), [W - 1, H - 1])
        if x1 < x0 or y1 < y0:
            continue
        gx, gy = np.meshgrid(np.arange(x0, x1 + 1, dtype=float), np.arange(y0, y1 + 1, dtype=float))
        inside = np.ones(gx.shape, dtype=bool)
        for a, b in ((0, 1), (1, 2), (2, 0)):
            ex, ey = P[b] - P[a]
            inside &= ex * (gy - P[a, 1]) - ey * (gx - P[a, 0]) >= 0
        mask[y0:y1 + 1, x0:x1 + 1][inside] = 255
    return mask


@pytest.mark.parametrize("seed", range(6))
def test_scanline_rasterisation_is_the_per_pixel_test(seed):
    rng = np.random.default_rng(seed)
    H, W = 40, 57
    pts = rng.uniform(-6.0, 62.0, (25, 2))
    if seed % 2:
        pts = np.round(pts)             # vertices on pixel centres: centres exactly on edges
    if seed % 3 == 0:
        pts[:, 1] = np.round(pts[:, 1] / 5) * 5  # horizontal edges
    tris = rng.integers(0, len(pts), (60, 3))
    got = _raster_triangles(pts, tris, (H, W))
    np.testing.assert_array_equal(got, raster_reference(pts, tris, (H, W)))
    assert got.dtype == np.uint8 and set(np.unique(got)) <= {0, 255}


def test_polyline_distances_are_exact_near_and_far():
    rng = np.random.default_rng(3)
    t = np.linspace(0.0, 2 * np.pi, 400, endpoint=False)
    poly = np.column_stack([200 + 120 * np.cos(t) * (1 + 0.3 * np.cos(5 * t)), 200 + 80 * np.sin(t)])
    pts = np.vstack([poly[::7] + rng.normal(0, 2.0, (58, 2)), rng.uniform(-400, 800, (300, 2))])
    dist = _PolylineDistance(poly)
    np.testing.assert_allclose(dist(pts), unsigned_distances(pts, poly), rtol=0, atol=1e-9)
    assert dist.lower(pts) <= float(unsigned_distances(pts, poly).mean())
    # a polyline of fewer segments than the neighbours asked for
    np.testing.assert_allclose(_PolylineDistance(poly[:4])(pts), unsigned_distances(pts, poly[:4]), atol=1e-9)


def test_tight_box_saves_what_bbox_inches_tight_saves():
    fig, ax = plt.subplots(figsize=(5, 3))
    ax.plot([0, 1], [0, 2], label="a line with a long label")
    ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0))  # outside the axes, as the run's figures
    ax.set_title("title")
    images = []
    for box in ("tight", tight_bbox(fig, 130)):
        buf = io.BytesIO()
        fig.savefig(buf, format="png", dpi=130, bbox_inches=box)
        images.append(np.asarray(Image.open(buf)))
    plt.close(fig)
    assert images[0].shape == images[1].shape
    np.testing.assert_array_equal(images[0], images[1])


def _legend_figure(figsize=(5, 3)):
    fig, ax = plt.subplots(figsize=figsize)
    ax.plot([0, 1], [0, 2], label="a line with a long label")
    ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0))  # outside the figure, as the run's figures
    ax.set_title("title")
    ax.set_xlabel("time [s]")
    return fig


def _drawn_box(rgb, bg=255):
    rows = np.flatnonzero((rgb != bg).any(axis=(1, 2)))
    cols = np.flatnonzero((rgb != bg).any(axis=(0, 2)))
    return rows[0], rows[-1], cols[0], cols[-1]


def test_cropped_render_is_the_tight_crop_within_a_few_pixels():
    fig = _legend_figure()
    got = render_cropped(fig, 130)
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=130, bbox_inches="tight")
    plt.close(fig)
    ref = np.asarray(Image.open(buf))[..., :3]
    assert got is not None and got.dtype == np.uint8 and got.shape[2] == 3
    # the tight box also holds the blank part of the text boxes (descenders): at most a few pixels
    assert abs(got.shape[0] - ref.shape[0]) <= 4 and abs(got.shape[1] - ref.shape[1]) <= 4
    pad = round(plt.rcParams["savefig.pad_inches"] * 130)
    r0, r1, c0, c1 = _drawn_box(got)
    assert (r0, c0) == (pad, pad) and (r1, c1) == (got.shape[0] - 1 - pad, got.shape[1] - 1 - pad)
    # the same drawing: the drawn boxes of both images have (nearly) the same size
    a, b = _drawn_box(got), _drawn_box(ref)
    assert abs((a[1] - a[0]) - (b[1] - b[0])) <= 2 and abs((a[3] - a[2]) - (b[3] - b[2])) <= 2


def test_cropped_render_takes_a_larger_margin_only_when_the_drawing_needs_it():
    """The first margin (1 in) serves a drawing that stays within it; a legend reaching farther is drawn
    again with the next margin, to the same crop as a large margin gives; past the last one, None."""
    from mdsr_opt.plot import common

    def figure(label_chars):
        fig, ax = plt.subplots(figsize=(3, 2))
        ax.plot([0, 1], [0, 1], label="x" * label_chars)
        ax.legend(loc="upper left", bbox_to_anchor=(1.02, 1.0))
        return fig

    tries = []
    real = common._draw_crop
    common._draw_crop = lambda fig, dpi, m: tries.append(m) or real(fig, dpi, m)
    try:
        for chars, margins in ((2, [1.0]), (40, [1.0, 4.0])):
            fig = figure(chars)
            tries.clear()
            got = render_cropped(fig, 100)
            assert tries == margins
            np.testing.assert_array_equal(got, render_cropped(fig, 100, margin=8.0))
            plt.close(fig)
        fig = figure(90)  # about 6 in past the figure: no margin of MARGINS holds it
        assert render_cropped(fig, 100) is None and render_cropped(fig, 100, margin=9.0) is not None
        plt.close(fig)
        # pieces placed wholly outside the figure never reach a canvas's edge: the margins start beyond
        # their anchors (a suptitle 1.2 in above, a text 3 in left of the axes, a legend anchored outside)
        fig = figure(2)
        fig.suptitle("above", y=1.4)
        fig.axes[0].text(-1.2, 0.5, "left", transform=fig.axes[0].transAxes)
        fig.axes[0].legend(loc="upper left", bbox_to_anchor=(2.5, 1.0))
        tries.clear()
        got = render_cropped(fig, 100)
        assert tries == [pytest.approx(1.0 + common._reach(fig))] and common._reach(fig) > 2.5
        np.testing.assert_array_equal(got, render_cropped(fig, 100, margin=12.0))
        buf = io.BytesIO()
        fig.savefig(buf, format="png", dpi=100, bbox_inches="tight")
        ref = np.asarray(Image.open(buf))
        assert abs(got.shape[0] - ref.shape[0]) <= 4 and abs(got.shape[1] - ref.shape[1]) <= 4
        plt.close(fig)
    finally:
        common._draw_crop = real
    assert common.MARGINS == (1.0, 4.0)


def test_cropped_render_has_the_pixels_of_a_plain_draw():
    fig, ax = plt.subplots(figsize=(4, 3))  # everything inside the figure: a plain draw holds it all
    ax.plot([0, 1], [0, 2], "r-")
    ax.set_title("inside")
    got = render_cropped(fig, 100)
    fig.set_dpi(100)
    fig.canvas.draw()
    plain = np.asarray(fig.canvas.buffer_rgba())[..., :3]
    plt.close(fig)
    pad = round(plt.rcParams["savefig.pad_inches"] * 100)
    r0, r1, c0, c1 = _drawn_box(plain)
    np.testing.assert_array_equal(got[pad:-pad, pad:-pad], plain[r0:r1 + 1, c0:c1 + 1])


def test_save_figure_writes_the_cropped_png_and_falls_back_when_it_cannot_crop(tmp_path):
    fig = _legend_figure()
    p = save_figure(fig, tmp_path / "a.png")
    im = Image.open(p)
    assert im.mode == "RGB"
    np.testing.assert_array_equal(np.asarray(im), render_cropped(fig, 130))  # lossless, channels in order
    assert np.asarray(im).min() < 50  # not blank: the line, the text
    fig.set_facecolor((1, 1, 1, 0))  # see-through: no background to crop against, savefig does it
    assert render_cropped(fig, 130) is None
    q = save_figure(fig, tmp_path / "b.png", close=True)
    assert Image.open(q).mode == "RGBA"
    far = plt.figure(figsize=(2, 2))  # a text placed far outside the figure: the margin starts beyond it
    far.text(-5.0, 0.5, "far left")
    got = render_cropped(far, 50)
    assert got is not None and got.min() < 100 and got.shape[1] < 60  # the text alone (the figure is blank)
    plt.close(far)
    big = plt.figure(figsize=(2, 2))  # a drawing running on past every margin: savefig's tight box
    big.text(0.5, 0.5, "x" * 300)
    assert render_cropped(big, 50) is None
    r = save_figure(big, tmp_path / "c.png", close=True, dpi=50)
    width = Image.open(r).size[0]
    assert np.asarray(Image.open(r).convert("L")).min() < 100 and width > 50 * 20  # the whole text


def test_gif_frames_follow_the_states(tmp_path):
    mesh = Mesh.rectangle(2.0, 1.0, 8, 4)
    states = [mesh.points * [1.0 + 0.1 * k, 1.0] for k in range(4)]
    p = save_animation(mesh, states, tmp_path / "a.gif", titles=[f"t{k}" for k in range(4)], fps=5.0)
    im = Image.open(p)
    assert im.n_frames == 4 and im.info["loop"] == 0 and im.info["duration"] == 200
    frames = []
    for k in range(4):
        im.seek(k)
        frames.append(np.asarray(im.convert("RGB")).astype(int))
    assert frames[0].shape == (550, 880, 3)  # large enough to read (issue 36)
    assert (frames[0][2, 2] == 255).all()        # the white figure background is kept exactly
    assert np.abs(frames[3] - frames[0]).sum() > 0  # the body moved
    with pytest.raises(ValueError, match="titles"):
        save_animation(mesh, states, tmp_path / "b.gif", titles=["only one"])


def test_gif_palette_keeps_flat_colours_exact():
    rng = np.random.default_rng(0)
    frames = []
    for k in range(7):  # flat colours plus noise-like antialiasing
        f = np.full((40, 60, 3), 255, np.uint8)
        f[5:30, 5 + k:40 + k] = (143, 179, 217)
        f[10:12, :] = rng.integers(0, 256, (2, 60, 3))
        frames.append(f)
    pal = gif_palette(frames)
    for f in frames:
        q = np.asarray(Image.fromarray(f).quantize(palette=pal, dither=Image.Dither.NONE).convert("RGB"))
        np.testing.assert_array_equal(q[20, 20], (143, 179, 217))  # the fill and the white stay exact
        np.testing.assert_array_equal(q[35, 59], (255, 255, 255))
    with pytest.raises(ValueError, match="at least one frame"):
        gif_palette([])


def test_gif_frames_are_close_to_the_drawn_frames(tmp_path):
    mesh = Mesh.rectangle(2.0, 1.0, 8, 4)
    states = [mesh.points * [1.0 + 0.1 * k, 1.0] for k in range(5)]
    p = save_animation(mesh, states, tmp_path / "a.gif", titles=[f"t{k}" for k in range(5)])
    im = Image.open(p)
    assert im.n_frames == 5 and im.size == (880, 550)
    im.seek(4)
    last = np.asarray(im.convert("RGB")).astype(int)
    # the body's fill colour is a palette colour, exactly; the body spans more width in the last frame
    body = (np.abs(last - (143, 179, 217)).sum(-1) == 0)
    assert body.sum() > 2000
    im.seek(0)
    first = np.asarray(im.convert("RGB")).astype(int)
    width = lambda m: np.ptp(np.flatnonzero(m.any(axis=0)))  # noqa: E731
    assert width(body) > 1.3 * width(np.abs(first - (143, 179, 217)).sum(-1) == 0)
    # the title: dark text centred over the axes, above the frame's top spine
    dark = first.sum(-1) < 200
    spine = np.flatnonzero(dark.sum(axis=1) > 200)[0]  # the frame's top edge
    frame = np.flatnonzero(dark[spine])
    ink = np.flatnonzero(dark[:spine].any(axis=0))
    centre = (frame[0] + frame[-1]) / 2
    assert len(ink) > 5 and abs((ink[0] + ink[-1]) / 2 - centre) < 10 and ink[-1] - ink[0] < 60
    rows = np.flatnonzero(dark[:spine].any(axis=1))
    assert rows[-1] - rows[0] >= 10  # a title at 12 pt: legible (issue 36)


def test_animation_solves_each_distinct_frame_once(monkeypatch):
    from mdsr_opt.body.muscles import Muscle
    from mdsr_opt.mechanics import equilibrium
    from mdsr_opt.scenes.animate import animate
    from mdsr_opt.scenes.scene import Animation, Case, Scene

    mesh = Mesh.rectangle(4.0, 1.0, 12, 3)
    bottom = Muscle([int(i) for i in np.argsort(mesh.points[:, 0]) if mesh.points[i, 1] == 0.0], name="b")
    scene = Scene(name="s", mesh=mesh, material=NeoHookean(1.0, 0.3), cases=(Case("pull", contractions=[0.1]),),
                  muscles=(bottom,),
                  animations=(Animation("a", (("rest", 1.0), ("pull", 1.0), ("rest", 1.0)), frames_per_step=3),))
    calls = []
    real = equilibrium.solve_internal

    def counting(*args, **kwargs):
        calls.append(np.asarray(args[3], dtype=float).copy())
        return real(*args, **kwargs)

    monkeypatch.setattr(equilibrium, "solve_internal", counting)
    res = animate(scene, "a", {"pull": ((bottom,), np.array([0.1]))})
    assert res.success and len(res.states) == 7
    # rest, 1/3, 2/3, pull, 2/3, 1/3, rest: three distinct contracted frames, each solved once
    assert len(calls) == 3
    for k in (1, 2):
        np.testing.assert_array_equal(res.states[k], res.states[6 - k])
    np.testing.assert_array_equal(res.states[0], mesh.points)
    reached = 1.0 - bottom.length(res.states[3]) / bottom.rest_length(mesh)
    assert abs(reached - 0.1) < 1e-4  # the keyframe reaches its contraction


def test_warm_start_state_puts_the_gauge_at_rest_and_moves_rigidly():
    from mdsr_opt.mechanics.equilibrium import gauge_coordinates
    from mdsr_opt.synthesis.gait import warm_start_state

    mesh = Mesh.rectangle(4.0, 1.0, 12, 3)
    X = mesh.points
    t = 0.4
    R = np.array([[np.cos(t), -np.sin(t)], [np.sin(t), np.cos(t)]])
    x = (X * [0.9, 1.05]) @ R.T + [3.0, -2.0]       # a deformed state, rotated and moved
    y = warm_start_state(mesh, x)
    g = list(gauge_coordinates(mesh))
    np.testing.assert_allclose(y.reshape(-1)[g], X.reshape(-1)[g], atol=1e-12)
    d = lambda z: np.linalg.norm(z[:, None] - z[None], axis=2)  # noqa: E731
    np.testing.assert_allclose(d(y), d(x), atol=1e-12)
    assert warm_start_state(mesh, np.zeros_like(X)) is None  # no rigid motion puts a collapsed state there


def test_ticks_false_hides_the_coordinates_but_keeps_the_colour_bar():
    from mdsr_opt.plot.design import plot_contraction_graph, plot_routing

    mesh = Mesh.rectangle(2.0, 1.0, 8, 4)
    t = mesh.points * [0.9, 1.0]
    fig = plot_contraction_graph(mesh, t, ticks=False)
    drawing, = fig.axes
    bar, = drawing.child_axes  # the colour bar: an inset the height of the drawing
    fig.canvas.draw()
    few = len(drawing.xaxis.get_majorticklocs())
    assert few <= 5 and len(drawing.yaxis.get_majorticklocs()) <= 5   # three a side (and the ends)
    assert drawing.get_xlabel() == "x (body units)" and drawing.get_ylabel() == "y (body units)"
    assert len(bar.get_yticks()) > 2 and "contraction" in bar.get_ylabel()
    plt.close(fig)
    fig = plot_contraction_graph(mesh, t, units="mm")  # the default keeps them all
    fig.canvas.draw()
    assert len(fig.axes[0].xaxis.get_majorticklocs()) > few and fig.axes[0].get_xlabel() == "x (mm)"
    plt.close(fig)
    fig = plot_routing(mesh, t, [], ticks=False)
    assert all(len(ax.get_xticks()) <= 5 and ax.get_xlabel() == "x (body units)" for ax in fig.axes)
    assert [ax.get_title() for ax in fig.axes] == ["0 muscle(s) over the rest mesh", "0 muscle(s) over the target mesh"]
    plt.close(fig)


def test_plot_mesh_draws_one_colour_as_fill_and_edge_paths():
    from mdsr_opt.plot.common import plot_mesh

    mesh = Mesh.rectangle(2.0, 1.0, 8, 4)
    x = mesh.points * [1.5, 1.0] + [3.0, -2.0]
    fig, ax = plt.subplots()
    plot_mesh(mesh, x, ax=ax, label="body")
    fill, edges = ax.patches
    assert len(fill.get_path().vertices) == 4 * mesh.n_triangles  # closed triangles, one path
    assert len(edges.get_path().vertices) == 2 * len(mesh.edges)  # each mesh edge once
    assert fill.get_label() == "body" and ax.get_legend_handles_labels()[1] == ["body"]
    lo, hi = ax.get_xlim(), ax.get_ylim()  # autoscaled to the state (add_artist adds no data limits)
    assert lo[0] <= 3.0 and lo[1] >= 6.0 and hi[0] <= -2.0 and hi[1] >= -1.0
    plot_mesh(mesh, x, ax=ax, values=np.arange(mesh.n_triangles, dtype=float))  # per triangle: a collection
    assert len(ax.collections[-1].get_paths()) == mesh.n_triangles
    plt.close(fig)
