"""``mdsr evaluate`` and ``mdsr photograph``: photographs from the command line."""

from __future__ import annotations

import argparse
import os
from pathlib import Path

from ..core.errors import InputError, checking_input

__all__ = ['add_cli']


# ----------------------------------------------------------------------------------------------- command
def _parse_color(text: str):
    from ..photos.images import check_color

    t = text.strip()
    if t.startswith("#"):
        try:
            return check_color(t)
        except ValueError as exc:
            raise argparse.ArgumentTypeError(str(exc)) from None
    try:
        vals = [float(v) for v in t.split(",")]
        return check_color(vals)
    except ValueError:
        raise argparse.ArgumentTypeError(f"color must be R,G,B (0-255) or #rrggbb, got {text!r}") from None


def _parse_ints(n: int, what: str, sep: str = ","):
    def parse(text: str):
        try:
            vals = tuple(int(v) for v in text.lower().split(sep))
        except ValueError:
            vals = ()
        if len(vals) != n:
            raise argparse.ArgumentTypeError(f"{what} must be {n} integers separated by {sep!r}, got {text!r}")
        return vals

    return parse


def _check_out_apart(out: str, read: dict) -> None:
    """Refuse an ``--out`` that is, or holds, a folder the command reads (``read``: what -> path): replacing
    an earlier command's files there (``--overwrite``) would remove what it reads."""
    o = os.path.realpath(out)
    for what, where in read.items():
        w = os.path.realpath(where)
        if w == o or w.startswith(o.rstrip(os.sep) + os.sep):
            raise InputError(f"--out {out} {'is' if w == o else 'holds'} the {what} {where} that this command "
                             "reads: give an output folder of its own")


def _cmd_evaluate(a) -> int:
    from ..photos.folder import evaluate_folder, evaluation_files, write_evaluation
    from ..scenes.rundir import RunFolder, check_out_path

    extract = {"method": a.method, "body": a.body, "largest": a.largest}
    if a.color is not None:
        extract["color"] = a.color
    if a.roi is not None:
        extract["roi"] = a.roi
    compare = {"registration": a.registration, "flip_y": not a.no_flip, "scaling": a.scaling}
    check_out_path(a.out)
    _check_out_apart(a.out, {"images folder": a.images, "states folder": a.states})
    # the folder first (busy, or holding files of someone else's), then the comparisons (bad input), and
    # only when all succeeded the files, together
    with RunFolder(a.out, overwrite=a.overwrite, command=getattr(a, "command_line", "")) as folder:
        results = evaluate_folder(a.images, a.states, name=a.name, extract=extract, compare=compare)
        folder.begin(evaluation_files(results, a.name, a.figures))
        write_evaluation(results, a.out, name=a.name, figures=a.figures)
    print(Path(a.out, f"{a.name}.md").read_text(), end="")
    print(f"wrote {Path(a.out, a.name + '.csv')} and {Path(a.out, a.name + '.md')} ({len(results)} case(s))")
    return 0


def _check_not_above_states(folder: Path, suffixes) -> None:
    """A folder whose state files are all in its sub-folders (``mdsr run``'s output: one folder per case, each
    with ``driven.vtu`` and ``target.vtu``, whose names repeat) is refused, naming those sub-folders."""
    if not folder.is_dir() or any(f.is_file() and f.suffix.lower() in suffixes for f in folder.iterdir()):
        return
    below = sorted(d.name for d in folder.iterdir()
                   if d.is_dir() and any(f.is_file() and f.suffix.lower() in suffixes for f in d.iterdir()))
    if below:
        raise InputError(f"no state files ({', '.join(suffixes)}) in {folder} itself (its sub-folders are not "
                         f"searched: their files share names such as driven.vtu); give one of its folders that "
                         f"hold some: {', '.join(below)} (e.g. mdsr photograph {folder / below[0]} --out ...)")


def _cmd_photograph(a) -> int:
    # imported here, not with the parser (every command paid for the photographs' modules)
    from ..body.io import read_mesh
    from ..photos.camera import render_photo
    from ..photos.folder import STATE_SUFFIXES, list_files, write_together
    from ..scenes.rundir import RunFolder, check_out_path

    check_out_path(a.out)
    with checking_input():  # the states named: bad input
        _check_not_above_states(Path(a.states), STATE_SUFFIXES)
        files = list_files(a.states, STATE_SUFFIXES, "state")
    _check_out_apart(a.out, {"states folder" if Path(a.states).is_dir() else "state file": a.states})
    stems = [f.stem for f in files]
    twice = sorted({st for st in stems if stems.count(st) > 1})
    if twice:
        raise InputError(f"two state files for case(s) {', '.join(twice)}: each would give {twice[0]}.png")
    writers = []
    for f in files:  # render and encode everything first, then write the whole set at once
        with checking_input():  # a state file that cannot be read: bad input
            data = read_mesh(f)
        ph = render_photo(data.mesh, data.x, image_size=a.photo_size, seed=a.seed, tilt_deg=a.tilt,
                          rotation_deg=a.rotation, noise_sigma=a.noise, blur_sigma=a.blur,
                          lighting=a.lighting)
        writers += ph.writers(Path(a.out) / f"{f.stem}.png")
    with RunFolder(a.out, overwrite=a.overwrite, command=getattr(a, "command_line", "")) as folder:
        folder.begin([p.name for p, _ in writers])
        written = write_together(writers)
    for path in written:
        if path.suffix == ".png":
            print(f"wrote {path} (SYNTHETIC, seed {a.seed})")
    return 0


def add_cli(sub) -> None:
    """Register ``mdsr evaluate`` (a folder of images against states) and ``mdsr photograph``."""
    p = sub.add_parser("evaluate", help="compare photographs with simulated states; write a CSV and "
                       "Markdown table of contour distances")
    p.add_argument("images", help="folder of images (.png/.jpg/...); case.png is compared with case.*")
    p.add_argument("states", help="folder of state mesh files (.vtu/.vtk/.xdmf/.msh)")
    p.add_argument("--out", default="evaluation_out",
                   help="output folder (default: evaluation_out); new or empty, as for mdsr run")
    p.add_argument("--overwrite", action="store_true",
                   help="replace the files of an earlier mdsr command in --out (as mdsr run --overwrite)")
    p.add_argument("--name", default="evaluation", help="table file stem (default: evaluation)")
    p.add_argument("--color", type=_parse_color, default=None,
                   help="body colour R,G,B or #rrggbb (switches to colour segmentation)")
    p.add_argument("--method", choices=("auto", "otsu", "adaptive", "color"), default="auto",
                   help="segmentation: Otsu on the flattened grey image, adaptive threshold, or colour "
                   "distance (default auto: colour when --color is given, else Otsu)")
    p.add_argument("--body", choices=("auto", "dark", "light"), default="auto",
                   help="is the body darker or lighter than the plate (default auto: the plate is what covers most of "
                   "the image border)")
    p.add_argument("--roi", type=_parse_ints(4, "roi"), default=None, help="X,Y,W,H search rectangle")
    p.add_argument("--largest", action="store_true", help="keep the largest of several blobs")
    p.add_argument("--registration", choices=("similarity", "none"), default="similarity",
                   help="fit rotation, scale and shift of the simulated outline (default), or none: states "
                   "already in pixels")
    p.add_argument("--scaling", choices=("uniform", "stretch"), default="uniform",
                   help="one scale matching the areas (default), or per-axis scales matching the bounding "
                   "rectangles")
    p.add_argument("--no-flip", action="store_true", help="states are already in image orientation (y down)")
    p.add_argument("--figures", action="store_true", help="also write <case>_overlay.png")
    p.set_defaults(func=_cmd_evaluate)

    q = sub.add_parser("photograph", help="render states as SYNTHETIC photographs (synthetic camera)")
    q.add_argument("states", help="a state mesh file or a folder of them")
    q.add_argument("--out", required=True,
                   help="output folder for <state>.png and <state>.json; new or empty, as for mdsr run")
    q.add_argument("--overwrite", action="store_true",
                   help="replace the files of an earlier mdsr command in --out (as mdsr run --overwrite)")
    q.add_argument("--seed", type=int, default=0, help="random seed of noise and placement (default 0)")
    q.add_argument("--photo-size", type=_parse_ints(2, "photo size", "x"), default=(500, 500), metavar="WxH",
                   help="size of the photographs in pixels (default 500x500), as `mdsr run --photo-size`")
    q.add_argument("--tilt", type=float, default=1.0, help="camera tilt, degrees (default 1)")
    q.add_argument("--rotation", type=float, default=0.0, help="body rotation on the plate, degrees")
    q.add_argument("--noise", type=float, default=3.0, help="noise sigma, grey levels (default 3)")
    q.add_argument("--blur", type=float, default=0.8, help="blur sigma, pixels (default 0.8)")
    q.add_argument("--lighting", type=float, default=0.2, help="lighting gradient strength (default 0.2)")
    q.set_defaults(func=_cmd_photograph)
