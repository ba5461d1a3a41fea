"""Contact forces carry their unit, as rope tensions do (the trial's Dragon Skin strip in mm reported
-3.45e7 on the ground with no unit field: Pa mm^2, about 34.5 N, while the tensions were in N)."""

from __future__ import annotations

import numpy as np
import pytest

from mdsr_opt import HalfPlane, Mesh, NeoHookean, nodes_in_box, silicone, solve_external
from mdsr_opt.core.quantities import contact_in_unit


def _pressed(material):
    mesh = Mesh.from_polygon([[0, 0.5], [40, 0.5], [40, 10.5], [0, 10.5]], max_area=2.0)
    top = nodes_in_box(mesh, ymin=10.5)
    return solve_external(mesh, material, None, {int(i): mesh.points[i] + [0, -2.5] for i in top},
                          obstacles=[HalfPlane((0, 0), (0, 1))])


def test_a_solve_names_the_unit_of_its_contact_forces_and_they_convert_to_newtons():
    r = _pressed(silicone("dragon-skin-30", thickness=5.0))
    assert r.success
    c = r.contact
    assert c["force_unit"] == "units of E*t*length"  # Pa x mm x mm here: the solve knows no length unit
    n = contact_in_unit(c, "Pa", "mm")  # as a design's tensions: E t length times 1e-6 is N for Pa and mm
    assert n["force_unit"] == "N"
    assert n["total_force"] == pytest.approx(1e-6 * c["total_force"], rel=1e-12)
    assert 5.0 < n["total_force"] < 200.0  # tens of newtons for 2 mm into a 40 mm strip, not 3e7
    assert np.allclose(n["obstacle_forces"], 1e-6 * np.asarray(c["obstacle_forces"]))
    assert [p["force"] for p in n["pairs"]] == pytest.approx([1e-6 * p["force"] for p in c["pairs"]])
    assert contact_in_unit(n, "Pa", "mm") == n  # already in N: left as it is
    assert c["force_unit"] == "units of E*t*length"  # the solve's report is not changed in place


def test_without_known_units_the_forces_stay_in_e_t_length():
    r = _pressed(NeoHookean(1.0, 0.3))
    out = contact_in_unit(r.contact, None, "mm")
    assert out["force_unit"] == "units of E*t*mm" and out["total_force"] == r.contact["total_force"]
    assert contact_in_unit(None, "Pa", "mm") is None


def test_a_design_reports_its_contact_forces_in_the_unit_of_its_tensions():
    from mdsr_opt import Muscle, design_contractions, solve_internal

    mesh = Mesh.rectangle(4.0, 1.0, 16, 4)
    mat, mus = NeoHookean(1.0, 0.3), [Muscle(range(1, 16))]
    res = design_contractions(mesh, mat, mus, solve_internal(mesh, mat, mus, [0.1]).x)
    res.verification.contact = _pressed(silicone("dragon-skin-30", thickness=5.0)).contact  # a report in E t L
    res.units, res.stress_unit = "mm", "Pa"
    assert res.tension_unit == "N" and res.contact["force_unit"] == "N"
    assert res.contact["total_force"] == pytest.approx(1e-6 * res.verification.contact["total_force"])
    s = res.summary()["contact"]
    assert s["force_unit"] == "N" and s["total_force"] == pytest.approx(res.contact["total_force"])
    assert s["n_pairs"] == len(res.contact["pairs"]) > 0
    res.units = None  # no length unit: both in units of E*t*length, unchanged
    assert res.contact["force_unit"] == res.tension_unit == "units of E*t*length"


@pytest.mark.parametrize("angle", [0.0, 0.6])
def test_the_default_contact_gap_is_the_same_however_the_body_is_turned(angle):
    """The default gap is a fraction of the body's diameter (body_size), not of its bounding-box diagonal, which
    grows by up to 41 % as a body turns: a C turned by 0.6 rad kept a gap 1.39 times the upright C's."""
    from mdsr_opt import body_size
    from mdsr_opt.mechanics.contactsteps import DEFAULT_GAP, contact_spec
    from mdsr_opt.mechanics.units import Units

    C = np.array([[0, 0], [4, 0], [4, 1], [1, 1], [1, 3], [4, 3], [4, 4], [0, 4]], float)
    c, s = np.cos(angle), np.sin(angle)
    mesh = Mesh.from_polygon(C @ np.array([[c, -s], [s, c]]).T, max_area=0.1)
    units = Units(mesh, NeoHookean(1.0, 0.3))
    gap = contact_spec(units, None, True, None, "ipopt").gap * units.length
    assert gap == pytest.approx(DEFAULT_GAP * 4 * np.sqrt(2), rel=1e-9)   # the C's diameter: its diagonal
    assert body_size(mesh) == pytest.approx(4 * np.sqrt(2), rel=1e-9)
