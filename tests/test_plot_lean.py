"""matplotlib imported without its docstrings' property tables (mdsr_opt.plot.lean), for the jobs' server."""

import subprocess
import sys

_LEAN = r"""
import io, sys
if sys.argv[1] == "artist-first":
    import matplotlib.artist
from mdsr_opt.plot.lean import without_property_docs
with without_property_docs():
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.lines import Line2D
import matplotlib.artist
fig, ax = plt.subplots()
(line,) = ax.plot([0, 1], [1, 0], linewidth=3)
buf = io.BytesIO()
fig.savefig(buf, format="png")
print("note" if "property table left out" in Line2D.set.__doc__ else "table",
      "linewidth" in str(__import__("inspect").signature(Line2D.set)),
      matplotlib.artist.kwdoc.__name__, line.get_linewidth(), buf.tell() > 1000)
"""


def _run(code, *args):
    out = subprocess.run([sys.executable, "-c", code, *args], capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr[-2000:]
    return out.stdout.split()


def test_tables_left_out_within_the_block_and_kwdoc_restored_after_it():
    # the setters, their signatures and drawing are as they were; only the docstring's table is a note
    assert _run(_LEAN, "fresh") == ["note", "True", "kwdoc", "3.0", "True"]


def test_a_process_that_imported_matplotlib_already_keeps_its_tables():
    assert _run(_LEAN, "artist-first") == ["table", "True", "kwdoc", "3.0", "True"]


def test_the_jobs_servers_warm_up_imports_matplotlib_without_them():
    code = ("from mdsr_opt.scenes.runscene import warm_up_server\n"
            "warm_up_server(True)\n"
            "from matplotlib.lines import Line2D\n"
            "print('property table left out' in Line2D.set.__doc__)")
    assert _run(code) == ["True"]
