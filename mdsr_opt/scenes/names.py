"""The names a run writes into its folder, the check that case and animation names do not collide, and one
name per muscle across a scene's cases (:func:`number_in_scene`)."""

from __future__ import annotations

from typing import Sequence

from .reader import SceneFileError

__all__ = ['check_output_names', 'number_in_scene']


#: Names a case or animation may not take: "rest" is the rest pose in keyframes; "summary" names the run's
#: summary files.
RESERVED_NAMES = ("rest", "summary")


def check_output_names(case_names: Sequence[str], animation_names: Sequence[str] = (), label: str = "scene",
                       where: Sequence[str] | None = None, gait_names: Sequence[str] = ()) -> None:
    """Refuse case, animation and gait names whose files would collide with each other or with a run's own files
    (:data:`RUN_FILES`; a case writes the folder ``<case>/``, an animation ``<name>.gif`` and
    ``<name>.json``, a gait the folder ``<name>/`` with ``<name>.gif`` and ``<name>.json``; a gait and an
    animation may not share a name), also on case-insensitive file systems. ``where`` names
    each name's field (cases first, then animations, then gaits) for the message.
    """
    names = list(case_names) + list(animation_names) + list(gait_names)
    fields = list(where) if where is not None else \
        [f"case {c!r}" for c in case_names] + [f"animation {a!r}" for a in animation_names]
    fields += [f"gait {g!r}" for g in gait_names]  # ``where`` covers the cases and animations only
    n_case, n_anim = len(case_names), len(animation_names)
    taken: dict[str, str] = {f.lower(): f"the run's own file {f!r}" for f in RUN_FILES}
    anims = {a.lower(): a for a in animation_names}
    for i, g in enumerate(gait_names):  # a gait writes <gait>/<gait>.gif and .json; an animation <name>.gif and
        if g.lower() in anims:          # .json; summary.json lists both under their names: one name, one thing
            raise SceneFileError(f"{label}: {fields[n_case + n_anim + i]}: the gait {g!r} has the name of the "
                                 f"animation {anims[g.lower()]!r}: two different things would share the name "
                                 "(and summary.json's entry); choose another name")
    for i, n in enumerate(names):
        kind = "case" if i < n_case else "animation" if i < n_case + n_anim else "gait"
        if n.lower() in RESERVED_NAMES or n.lower().split(".")[0] in RESERVED_NAMES:
            raise SceneFileError(f"{label}: {fields[i]}: the {kind} name {n!r} is reserved ('rest' is the rest "
                                 "pose in keyframes, 'summary' names the run's summary files); choose another")
        for entry in ([n] if kind != "animation" else [f"{n}.gif", f"{n}.json"]):
            key = entry.lower()
            if key in taken:
                raise SceneFileError(f"{label}: {fields[i]}: the {kind} {n!r} would write {entry!r}, which is "
                                     f"{taken[key]}; choose another name")
            taken[key] = f"written by the {kind} {n!r}"


def check_name(name, what: str) -> None:
    if not isinstance(name, str) or not name:
        raise TypeError(f"{what} must be a non-empty string, got {name!r}")
    if not all(ch.isalnum() or ch in "_-." for ch in name) or name.startswith("."):
        raise ValueError(f"{what} {name!r} may hold only letters, digits, '_', '-' and '.' (it names files)")


#: Files every scene run writes directly into its folder; case folders and animation files go beside them.
RUN_FILES = ("rest.png", "summary.json", "summary.md", "validation.md")


def number_in_scene(muscles: Sequence, taken: Sequence = ()) -> tuple:
    """A case's routed ``muscles`` named as one scene's: a muscle on the node path of one in ``taken`` (the
    muscles earlier cases of the run were designed with) takes that one's name; the other numbered ones
    (``M<k>``, as routing names them) are numbered on from the highest number ``taken`` holds; a muscle's
    own name stays. So in gecko's run bend_left's rope is M1 and bend_right's two are M2 and M3 in the
    cases' figures, in the gait's layout, schedule, animation and fabrication files alike, each in one
    colour (:func:`mdsr_opt.plot.style.name_color`). Without ``taken`` the muscles are returned as they are.
    """
    from ..body.muscles import Muscle
    from ..plot.style import muscle_label, muscle_name, muscle_slot

    muscles = tuple(muscles)
    if not taken:
        return muscles
    known = {tuple(m.nodes): muscle_label(m, i) for i, m in enumerate(taken)}
    labels = [muscle_label(m, i) for i, m in enumerate(taken)]
    used = set(labels)
    top = max((muscle_slot(n, -1) + 1 for n in labels), default=0)
    out = []
    for i, m in enumerate(muscles):
        own = muscle_label(m, i)
        name = known.get(tuple(m.nodes))
        if name is None:
            if muscle_slot(own, -1) < 0 and own not in used:  # a name of its own: kept
                name = own
            else:
                while muscle_name(top) in used:
                    top += 1
                name = muscle_name(top)
        used.add(name)
        out.append(Muscle(m.nodes, name=name))
    return tuple(out)
