"""A scene's run as a whole (:class:`SceneReport`): its cases' reports, its table (``summary.md``, the end of
``mdsr run``'s output) and the notes of what the pipeline resolved on its own in each case (fixtures shrunk,
ropes cut, dropped or moved, idle muscles dropped), which ``summary.md`` lists under its table."""

from __future__ import annotations

import re
from dataclasses import asdict, dataclass, field

from ..core.quantities import band_text
from ..core.results import compact_repr, to_jsonable
from ..plot.style import unit_label
from .verdict import design_verdict

__all__ = ["SceneReport", "case_notes"]

#: the head of a FabricationWarning's message that names its scene and case
_NAMED = r"^scene '[^']*', case '[^']*': "


@dataclass
class SceneReport:
    """The outcome of :func:`~mdsr_opt.scenes.runscene.run_scene`: one
    :class:`~mdsr_opt.scenes.runner.CaseReport` per case, animations, timing, and the scene's length ``units``
    in which :meth:`table` quotes differences and strokes (``""``: body units)."""

    scene: str
    title: str
    n_nodes: int
    cases: list
    animations: dict = field(default_factory=dict)
    out: str = ""
    time: float = 0.0
    units: str = ""

    def __repr__(self) -> str:
        n_ok = sum(bool(c.success) for c in self.cases)
        why = "; ".join([f"{c.case}: {c.message}" for c in self.cases if not c.success]  # the failures, first first
                        + [f"{k}: {a.get('message') or 'failed'}" for k, a in self.animations.items()
                           if not a.get("success", False)])
        return compact_repr(self, ("scene", "success"), why=why, extra={
            "cases": f"{n_ok}/{len(self.cases)} ok", "animations": len(self.animations), "n_nodes": self.n_nodes,
            "time": self.time, "out": self.out})

    @property
    def success(self) -> bool:
        """Every case succeeded and every animation's forward solves succeeded."""
        return all(c.success for c in self.cases) and all(a.get("success", False)
                                                             for a in self.animations.values())

    def table(self) -> str:
        """A Markdown table of the key figures, one row per case; differences and strokes carry the scene's
        unit in every cell (:func:`~mdsr_opt.plot.style.unit_label`), so tables of scenes in different units
        can be joined. The difference is the design's weighted RMS (what the ok/FAILED verdict judges); the
        largest node error after the same alignment stands beside it, since an RMS can pass a pose missed at
        an extremity."""
        u = unit_label(self.units)
        head = ("| scene | case | kind | nodes | muscles | achieved contractions | strokes | difference | "
                "diff/size (%) | largest node error (% of size) | design | photo d over every loop (px) | ratio (%) | "
                "prototype d over every loop (px) | time (s) |")
        rows = [head, "| --- | --- | --- | ---: | ---: | --- | --- | ---: | ---: | ---: | --- | ---: | ---: | ---: | ---: |"]
        for c in self.cases:
            a = ", ".join(f"{v:.3f}" for v in (c.achieved or c.contractions)) if c.contractions else "-"
            names = [m.get("name") for m in (c.muscles or [])]
            at = [len(names) == len(c.stroke) and names[i] in (c.saturated or ()) for i in range(len(c.stroke))]
            s = ", ".join(f"{v:.4g}" + (f" {band_text(b[0], b[1], at[i])}" if len(c.stroke_band) == len(c.stroke) else "")
                          for i, (v, b) in enumerate(zip(c.stroke, c.stroke_band or [()] * len(c.stroke)))) \
                if c.stroke else "-"
            s += f" {u}" if c.stroke else ""
            d = "-" if c.difference is None else f"{c.difference:.4g} {u}"
            r = "-" if c.relative_difference is None else f"{100 * c.relative_difference:.2f}"
            e, re_ = getattr(c, "max_error", None), getattr(c, "relative_max_error", None)
            mx = "-" if e is None or re_ is None else f"{e:.4g} {u} ({100 * re_:.2f})"
            ok = design_verdict(c)  # the cause of a failure first, then the secondary flags
            ph = (c.photo or {}).get("target")
            pd = "-" if not ph else f"{ph['mean_px']:.2f}"
            pr = "-" if not ph else f"{100 * ph['ratio']:.2f}"
            pt = ((c.photo or {}).get("prototype") or {}).get("design") or {}
            pp = f"{pt['mean_px']:.2f}" if pt.get("success") else "FAILED (validation.md)" if pt else "-"
            rows.append(f"| {c.scene} | {c.case} | {c.kind} | {c.n_nodes} | {c.n_muscles} | {a} | {s} | {d} | {r} | {mx} | "
                        f"{ok} | {pd} | {pr} | {pp} | {c.times.get('total', 0.0):.1f} |")
        return "\n".join(rows)

    def notes(self) -> str:
        """What the pipeline resolved on its own in each case (:func:`case_notes`) and in a gait's shared layout
        (its ``notes``: ropes merged or shortened, fixtures shrunk, idle muscles dropped) as a Markdown section,
        the end of ``summary.md``; ``""`` when none has any."""
        groups: dict = {}  # cases with the same notes (an internal scene's muscles, say) listed once
        for c in self.cases:
            lines = tuple(case_notes(c))
            if lines:
                groups.setdefault(lines, []).append(c.case)
        for name, anim in self.animations.items():  # a gait's shared layout: what it resolved, idle muscles dropped
            lines = tuple(dict.fromkeys(str(n).replace("\n", " ") for n in (anim.get("notes") or ())))
            if anim.get("kind") == "gait" and lines:
                groups.setdefault(lines, []).append("gait" if name == "gait" else f"gait {name}")
        if not groups:
            return ""
        out = ["## Notes", "", "What the pipeline resolved on its own to make each case's ropes buildable, and what "
               "it could not (each case's `notes` and `fabrication` in summary.json, a gait's `notes` under "
               "`animations`):", ""]
        for lines, names in groups.items():
            out.append(f"- **{', '.join(names)}**")
            out += [f"  - {line}" for line in lines]
        return "\n".join(out) + "\n"

    def markdown(self) -> str:
        """``summary.md``: the title, the table (:meth:`table`) and the notes (:meth:`notes`)."""
        notes = self.notes()
        return f"# {self.title or self.scene}\n\n{self.table()}\n" + (f"\n{notes}" if notes else "")

    def to_dict(self) -> dict:
        """JSON-ready (``summary.json`` holds it): the cases' reports and the animations' figures."""
        return to_jsonable({"format": "mdsr_opt.scene_run/1", "scene": self.scene, "title": self.title,
                            "n_nodes": self.n_nodes, "success": self.success, "time": self.time,
                            "cases": [asdict(c) for c in self.cases], "animations": self.animations})


def case_notes(case) -> list[str]:
    """A case report's notes (:class:`~mdsr_opt.scenes.runner.CaseReport`): what the pipeline resolved on its
    own (``notes``: fixtures shrunk, ropes cut, dropped or moved, idle muscles dropped), then the places of the
    muscles the scene gives that cannot be moulded as laid out (``fabrication``), each once."""
    lines = list(getattr(case, "notes", None) or [])
    # a FabricationWarning names its scene and case first: said by the list's heading already
    lines += [f"fabrication: {re.sub(_NAMED, '', str(m))}" for m in getattr(case, "fabrication", None) or []]
    return list(dict.fromkeys(str(line).replace("\n", " ") for line in lines))
