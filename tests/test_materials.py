"""Materials of a sheet: plane strain and plane stress Neo-Hookean, Yeoh, Mooney-Rivlin, silicone presets.

Each law against closed-form uniaxial and equibiaxial stresses (independent 3-D formulas, not the code's),
its derivatives against finite differences, its small-strain moduli, frame indifference, the compressible
sheet's incompressible limit, input checks, and a solve with each on a small mesh."""

from __future__ import annotations

import json
import math
import tomllib
from pathlib import Path

import numpy as np
import pytest
from scipy.optimize import brentq

from mdsr_opt import LinearElastic, Mesh, MooneyRivlin, NeoHookean, Yeoh, silicone, solve_external
from mdsr_opt.body.material import material_dict, material_from_dict
from mdsr_opt.body.silicone import SILICONES
from mdsr_opt.mechanics.model import get_model
from mdsr_opt.mechanics.units import Units
from mdsr_opt.scenes.scenefile import load_scene, material_table

from conftest import rotation

SHEETS = [NeoHookean(2.0, 0.3, 0.7, plane="stress"), NeoHookean(2.0, 0.45, plane="stress"),
          NeoHookean(1.5, 0.5, plane="stress"), Yeoh(1.0, 0.2, 0.03, 0.5), Yeoh(1.0, -0.1, 0.01),
          MooneyRivlin(0.4, 0.1, 0.6), silicone("dragon-skin-30", 2.0)]
ALL = [NeoHookean(2.0, 0.3, 0.7), LinearElastic(1.0, 0.3, plane="stress"), *SHEETS]


def _P(mat, F):
    """First Piola stress of one 2 x 2 ``F`` from the material's closed form."""
    mu, lam = mat.params
    return mat.stress_tangent(np.asarray(F, float)[:, :, None], mu, lam, False)[0][:, :, 0]


def _uniaxial(mat, lam1):
    """``(P11, lam2)`` of an in-plane uniaxial stretch: the lateral stretch where ``P22 = 0``."""
    lam2 = brentq(lambda l2: _P(mat, np.diag([lam1, l2]))[1, 1], 0.2, 2.0, xtol=1e-15, rtol=1e-15)
    return _P(mat, np.diag([lam1, lam2]))[0, 0], lam2


def _nh3d_lateral(mu, lam, lam1, J_of):
    """The traction-free stretch ``l`` of a 3-D compressible Neo-Hookean solid: ``mu (l - 1/l) + lam ln J / l
    = 0`` with ``J = J_of(l)``."""
    return brentq(lambda l: mu * (l - 1 / l) + lam * math.log(J_of(l)) / l, 0.05, 5.0, xtol=1e-15, rtol=1e-15)


# ------------------------------------------------------------------------------------ closed-form stretches
@pytest.mark.parametrize("stretch", [0.7, 1.3, 2.0, 3.0])
def test_incompressible_sheets_under_uniaxial_and_equibiaxial_stretch(stretch):
    """Incompressible plane stress: uniaxial ``P11 = 2 (l - l^-2)(dW/dI1 + dW/dI2 / l)`` at lateral stretch
    ``l^-1/2``, equibiaxial ``P11 = 2 (l - l^-5)(dW/dI1 + l^2 dW/dI2)``."""
    l = stretch
    I1u, I1b = l * l + 2 / l, 2 * l * l + l ** -4
    cases = [(NeoHookean(3.0, 0.5, plane="stress"), lambda I1: 0.5, 0.0),
             (MooneyRivlin(0.4, 0.15), lambda I1: 0.4, 0.15),
             (Yeoh(0.7, -0.05, 0.004), lambda I1: 0.7 - 0.1 * (I1 - 3) + 0.012 * (I1 - 3) ** 2, 0.0)]
    for mat, W1, W2 in cases:
        P11, l2 = _uniaxial(mat, l)
        assert l2 == pytest.approx(l ** -0.5, rel=1e-12) and mat.stretch3(np.diag([l, l2])) == pytest.approx(l2)
        assert P11 == pytest.approx(2 * (l - l ** -2) * (W1(I1u) + W2 / l), rel=1e-12)
        P = _P(mat, np.diag([l, l]))
        assert P[0, 0] == pytest.approx(2 * (l - l ** -5) * (W1(I1b) + l * l * W2), rel=1e-12)
        assert P[1, 1] == pytest.approx(P[0, 0], rel=1e-14) and P[0, 1] == 0.0
    # the Neo-Hookean sheet's textbook forms: mu (l - l^-2) and mu (l - l^-5), mu = E/3 = 1
    nh = cases[0][0]
    assert _uniaxial(nh, l)[0] == pytest.approx(l - l ** -2, rel=1e-12)
    assert _P(nh, np.diag([l, l]))[0, 0] == pytest.approx(l - l ** -5, rel=1e-12)


@pytest.mark.parametrize("nu", [0.0, 0.3, 0.45, 0.49])
@pytest.mark.parametrize("stretch", [0.6, 1.4, 2.5])
def test_compressible_sheet_is_the_3d_solid_under_uniaxial_and_equibiaxial_stress(nu, stretch):
    """A compressible Neo-Hookean sheet pulled in its plane is the 3-D solid in uniaxial stress (both lateral
    stretches equal by isotropy) and, pulled equally both ways, in equibiaxial stress: ``P11 = mu (l - 1/l) +
    lam ln J / l`` with the lateral stretches from the 3-D traction-free condition, solved here by bisection."""
    mat = NeoHookean(2.0, nu, plane="stress")
    mu, lam, l = mat.mu, mat.lam, stretch
    lt = _nh3d_lateral(mu, lam, l, lambda t: l * t * t)
    P11, l2 = _uniaxial(mat, l)
    assert l2 == pytest.approx(lt, rel=1e-11) and mat.stretch3(np.diag([l, l2])) == pytest.approx(lt, rel=1e-11)
    assert P11 == pytest.approx(mu * (l - 1 / l) + lam * math.log(l * lt * lt) / l, rel=1e-11, abs=1e-13)
    l3 = _nh3d_lateral(mu, lam, l, lambda t: l * l * t)
    assert _P(mat, np.diag([l, l]))[0, 0] == pytest.approx(mu * (l - 1 / l) + lam * math.log(l * l * l3) / l,
                                                          rel=1e-11, abs=1e-13)


@pytest.mark.parametrize("stretch", [0.6, 1.4, 2.5])
def test_plane_strain_under_uniaxial_and_equibiaxial_stretch(stretch):
    """Plane strain (``l3 = 1``): uniaxial ``P11 = mu (l - 1/l) + lam ln(l l2)/l`` with ``l2`` traction-free
    in the plane, equibiaxial ``P11 = mu (l - 1/l) + 2 lam ln(l)/l``."""
    mat = NeoHookean(2.0, 0.4)
    mu, lam, l = mat.mu, mat.lam, stretch
    l2 = brentq(lambda t: mu * (t - 1 / t) + lam * math.log(l * t) / t, 0.05, 5.0, xtol=1e-15, rtol=1e-15)
    P11, l2_code = _uniaxial(mat, l)
    assert l2_code == pytest.approx(l2, rel=1e-11) and mat.stretch3(np.diag([l, l2])) == 1.0
    assert P11 == pytest.approx(mu * (l - 1 / l) + lam * math.log(l * l2) / l, rel=1e-11)
    assert _P(mat, np.diag([l, l]))[0, 0] == pytest.approx(mu * (l - 1 / l) + 2 * lam * math.log(l) / l, rel=1e-12)


@pytest.mark.parametrize("plane", ["strain", "stress"])
def test_linear_material_uniaxial_and_equibiaxial(plane):
    """Linear elasticity: uniaxial stress ``E' eps``, lateral strain ``-nu' eps``; equibiaxial ``E' eps /
    (1 - nu')`` with ``(E', nu')`` the in-plane moduli."""
    mat = LinearElastic(2.0, 0.3, plane=plane)
    E, nu = mat.plane_moduli
    assert (E, nu) == ((2.0, 0.3) if plane == "stress" else pytest.approx((2.0 / 0.91, 0.3 / 0.7)))
    P11, l2 = _uniaxial(mat, 1.1)
    assert P11 == pytest.approx(E * 0.1, rel=1e-12) and l2 - 1 == pytest.approx(-nu * 0.1, rel=1e-12)
    assert _P(mat, np.diag([1.1, 1.1]))[0, 0] == pytest.approx(E * 0.1 / (1 - nu), rel=1e-12)


# ------------------------------------------------------------------------------------ limits and invariance
@pytest.mark.parametrize("mat", ALL, ids=lambda m: m.kind[:24])
def test_small_strain_moduli_are_the_in_plane_E_and_nu(mat):
    """The tangent at rest gives the in-plane Young's modulus ``(A0000^2 - A0011^2) / A0000`` and Poisson's
    ratio ``A0011 / A0000`` of :attr:`plane_moduli` (times the thickness), and the shear modulus ``mu``."""
    mu_t, lam_t = mat.params
    A = mat.stress_tangent(np.eye(2)[:, :, None], mu_t, lam_t)[1][..., 0] / mat.thickness
    E, nu = mat.plane_moduli
    assert (A[0, 0, 0, 0] ** 2 - A[0, 0, 1, 1] ** 2) / A[0, 0, 0, 0] == pytest.approx(E, rel=1e-12)
    assert A[0, 0, 1, 1] / A[0, 0, 0, 0] == pytest.approx(nu, rel=1e-12, abs=1e-15)
    assert A[0, 1, 0, 1] == pytest.approx(mat.mu, rel=1e-12)
    if mat.plane == "stress":
        assert (E, nu) == (pytest.approx(mat.E), mat.nu)


def test_compressible_sheet_tends_to_the_incompressible_one():
    """At ``nu -> 0.5`` (E fixed) the compressible sheet's energy and stress approach the closed-form
    incompressible ones, the gap shrinking in proportion to ``0.5 - nu``."""
    rng = np.random.default_rng(3)
    F = np.eye(2)[:, :, None] + 0.3 * rng.standard_normal((2, 2, 50))
    F = F[:, :, F[0, 0] * F[1, 1] - F[0, 1] * F[1, 0] > 0.3]
    inc = NeoHookean(2.0, 0.5, plane="stress")
    Fm = np.moveaxis(F, -1, 0)
    gaps = []
    for nu in (0.499, 0.4999, 0.49999):
        mat = NeoHookean(2.0, nu, plane="stress")
        dpsi = np.abs(mat.psi(Fm) - inc.psi(Fm)).max()
        dP = np.abs(mat.stress_tangent(F, *mat.params, False)[0] - inc.stress_tangent(F, *inc.params, False)[0]).max()
        gaps.append((dpsi, dP))
    for (a, b), (c, d) in zip(gaps, gaps[1:]):
        assert 9 < a / c < 11 and 9 < b / d < 11  # first order in 0.5 - nu
    assert gaps[-1][1] < 2e-3 * np.abs(inc.stress_tangent(F, *inc.params, False)[0]).max()


@pytest.mark.parametrize("mat", ALL, ids=lambda m: m.kind[:24])
def test_rotation_invariance(mat):
    """``Psi(R F) = Psi(F)`` and ``P(R F) = R P(F)`` (frame indifference), but for the linear material."""
    F = np.array([[1.3, 0.2], [-0.1, 0.8]])
    R = rotation(0.7)
    if isinstance(mat, LinearElastic):
        assert mat.rotation_invariant is False and abs(mat.psi(R @ F) - mat.psi(F)) > 1e-3
        return
    assert mat.rotation_invariant
    assert mat.psi(R @ F) == pytest.approx(mat.psi(F), rel=1e-13)
    np.testing.assert_allclose(_P(mat, R @ F), R @ _P(mat, F), rtol=1e-12, atol=1e-14)
    assert mat.psi(np.eye(2)) == pytest.approx(0.0, abs=1e-15) and mat.psi(np.diag([1.0, -1.0])) == np.inf


@pytest.mark.parametrize("mat", SHEETS, ids=lambda m: m.kind[:24])
def test_derivatives_against_finite_differences(mat):
    """Stress against central differences of ``psi``, tangent against those of the stress, tangent derivative
    against those of the tangent, at random deformation gradients."""
    rng = np.random.default_rng(11)
    mu, lam = mat.params
    h = 1e-6
    for _ in range(5):
        F = np.eye(2) + 0.3 * rng.standard_normal((2, 2))
        if np.linalg.det(F) < 0.3:
            continue
        P, A = (v[..., 0] for v in mat.stress_tangent(F[:, :, None], mu, lam))
        E4 = np.eye(4).reshape(4, 2, 2)
        fdP = np.array([(mat.psi(F + h * e) - mat.psi(F - h * e)) / (2 * h) for e in E4]).reshape(2, 2)
        scale = max(1.0, np.abs(A).max())
        assert np.abs(fdP - P).max() < 1e-7 * scale
        fdA = np.stack([(_P(mat, F + h * e) - _P(mat, F - h * e)) / (2 * h) for e in E4], -1).reshape(2, 2, 2, 2)
        assert np.abs(fdA - A).max() < 1e-7 * scale
        dF = rng.standard_normal((2, 2))
        dA = mat.tangent_derivative(F[:, :, None], dF[:, :, None], mu, lam)[..., 0]
        Ap, Am = (mat.stress_tangent((F + s * h * dF)[:, :, None], mu, lam)[1][..., 0] for s in (1, -1))
        assert np.abs((Ap - Am) / (2 * h) - dA).max() < 1e-6 * scale


@pytest.mark.parametrize("mat", [Yeoh(0.5, 0.1, -0.004), MooneyRivlin(0.4, 0.1)], ids=lambda m: m.kind[:24])
def test_model_third_derivative_of_incompressible_sheets(mat):
    """The model's ``third_data`` against central differences of its Hessian: the error falls as ``h^2``
    (100x per 10x step), so it is the differences' truncation, not the closed form."""
    mesh = Mesh.rectangle(4.0, 1.0, 12, 3)
    rng = np.random.default_rng(2)
    x = (mesh.points + 0.03 * rng.standard_normal(mesh.points.shape)).ravel()
    v = rng.standard_normal(x.shape)
    model = get_model(mesh, mat)
    p = model.params(mat)
    T = model.hessian_pattern.matrix(model.third_data(x, p, v)).toarray()
    err = [np.abs(T - (model.hessian(x + h * v, p) - model.hessian(x - h * v, p)).toarray() / (2 * h)).max()
           for h in (1e-4, 1e-5)]
    assert 80 < err[0] / err[1] < 120 and err[1] < 1e-6 * np.abs(T).max()


# ------------------------------------------------------------------------------------ presets and input
# Engineering stress (kPa) at 25, 50, ..., 300 % engineering strain: the rows at t = 1.1, 2.2, ..., 13.2 s
# (columns "Engineering Strain", "Engineering Stress (MPa)") of Tensile-Tests-Data/<file>.csv in
# github.com/LucMarechal/Soft-Robotics-Materials-Database, commit 0f67d88995fe159072f80f8849fe15f776b27af8,
# the data of Marechal et al., Soft Robotics 8(3), 284-297 (2021), doi:10.1089/soro.2019.0115 (ASTM D412,
# 450 mm/min).
_STRAIN = np.arange(1, 13) * 0.25
_MARECHAL = {  # preset: (file, stresses)
    "ecoflex-00-30": ("Ecoflex 00-30", [8.56, 16.89, 22.88, 29.72, 34.51, 40.08, 46.66, 52.39, 59.24, 65.93,
                                        72.99, 80.15]),
    "ecoflex-00-50": ("Ecoflex 00-50", [12.26, 22.775, 32.07, 40.95, 50.38, 59.51, 68.745, 79.005, 90.195,
                                        101.295, 113.2, 125.775]),
    "dragon-skin-10": ("Dragon Skin 10 MEDIUM", [26.4267, 52.9967, 82.2933, 112.963, 149.83, 190.583, 233.527,
                                                 272.79, 313.973, 355.973, 400.147, 444.76]),
    "dragon-skin-20": ("Dragon Skin 20", [72.147, 151.073, 232.767, 318.36, 410.47, 509.237, 612.93, 722.257,
                                          835.687, 952.813, 1071.973, 1194.473]),
    "dragon-skin-30": ("Dragon Skin 30", [110.873, 213.917, 322.07, 437.123, 560.21, 689.383, 822.907, 959.47,
                                          1098.137, 1238.697, 1382.733, 1529.49]),
}


@pytest.mark.parametrize("name", list(_MARECHAL))
def test_presets_are_the_stated_fit_of_their_source(name):
    """Each Yeoh preset is the relative least-squares fit of the incompressible uniaxial nominal stress to its
    source's rows (rounded to three significant figures), and the sheet reproduces those rows through its own
    closed form within the module's stated bounds: 5.5 % from 50 to 300 % strain, 8.2 % at 25 %. The
    Neo-Hookean alternative has the same small-strain modulus."""
    stress = np.array(_MARECHAL[name][1]) * 1e3
    lam = 1.0 + _STRAIN
    x, g = lam ** 2 + 2.0 / lam - 3.0, 2.0 * (lam - lam ** -2)
    A = np.stack([g, 2 * g * x, 3 * g * x * x], 1) / stress[:, None]
    fit = np.linalg.lstsq(A, np.ones(len(stress)), rcond=None)[0]
    assert SILICONES[name] == tuple(float(f"{c:.3g}") for c in fit)
    m = silicone(name, thickness=1e-3)
    assert isinstance(m, Yeoh) and m.thickness == 1e-3 and m.C1 == SILICONES[name][0]
    err = np.array([_uniaxial(m, 1.0 + e)[0] / m.thickness for e in _STRAIN]) / stress - 1.0
    assert np.abs(err[1:]).max() < 0.055 and 0.0 < err[0] < 0.082
    nh = silicone(name.upper().replace("-", " "), law="neo-hookean")
    assert isinstance(nh, NeoHookean) and nh.plane == "stress" and nh.nu == 0.5
    assert nh.E == pytest.approx(m.E, rel=1e-14) and nh.mu == pytest.approx(2 * m.C1, rel=1e-14)


def test_sylgard_preset_is_its_youngs_modulus():
    # 1.32 MPa: the low end of 1.32-2.97 MPa (curing at 25-200 C), Johnston et al., J. Micromech. Microeng.
    # 24(3), 035017 (2014), abstract
    m = silicone("Sylgard_184")
    assert m.E == pytest.approx(1.32e6, rel=1e-12) and m.C2 == m.C3 == 0.0


@pytest.mark.parametrize("make, err, match", [
    (lambda: NeoHookean(1.0, 0.5), ValueError, r"nu \(Poisson's ratio\) must lie in \(-1, 0.5\) in plane strain "
                                               r"\(nu = 0.5, incompressible, needs plane='stress'\)"),
    (lambda: NeoHookean(1.0, 0.3, plane="plane"), ValueError, "plane must be 'strain'"),
    (lambda: NeoHookean(1.0, 0.3, plane=1), TypeError, "plane must be 'strain' or 'stress', got int"),
    (lambda: NeoHookean(1.0, -0.2, plane="stress"), ValueError, r"must lie in \[0, 0.5\] for a plane-stress"),
    (lambda: NeoHookean(1.0, 0.51, plane="stress"), ValueError, r"must lie in \[0, 0.5\]"),
    (lambda: LinearElastic(1.0, 0.6, plane="stress"), ValueError, r"must lie in \(-1, 0.5\]"),
    (lambda: Yeoh(0.0, 1.0), ValueError, r"C1 \(Yeoh\) must be > 0"),
    (lambda: Yeoh(1.0, "a"), TypeError, r"C2 \(Yeoh\) must be a real number"),
    (lambda: Yeoh(1.0, 0.0, float("inf")), ValueError, r"C3 \(Yeoh\) must be finite"),
    (lambda: Yeoh(1.0, thickness=0.0), ValueError, "thickness"),
    (lambda: MooneyRivlin(-1.0, 0.5), ValueError, r"C10 \+ C01 \(half the shear modulus\) must be > 0"),
    (lambda: silicone("ecoflex"), ValueError, "unknown silicone 'ecoflex'.*; known: ecoflex-00-30, ecoflex-00-50, "
                                              "dragon-skin-10, dragon-skin-20, dragon-skin-30, sylgard-184"),
    (lambda: silicone(30), TypeError, "name must be a string"),
    (lambda: silicone("ecoflex-00-30", law="ogden"), ValueError, "law must be one of yeoh, neo-hookean"),
    (lambda: silicone("ecoflex-00-30", thickness=-1.0), ValueError, "thickness"),
])
def test_bad_input_is_refused_at_the_door(make, err, match):
    with pytest.raises(err, match=match):
        make()


@pytest.mark.parametrize("mat", ALL, ids=lambda m: m.kind[:24])
def test_records_and_scene_tables_read_back(mat, tmp_path):
    """``material_dict`` (design.json, summary.json) and ``material_table`` (a scene file's [material]) read
    back as the same material; an old record (kind, E, nu, thickness) is plane strain."""
    assert material_from_dict(json.loads(json.dumps(material_dict(mat)))) == mat
    scene = _finger()
    scene["material"] = material_table(mat)
    (tmp_path / "s.json").write_text(json.dumps(scene))
    assert load_scene(tmp_path / "s.json").material == mat
    assert material_from_dict({"kind": "neo-hookean", "E": 2.0, "nu": 0.3, "thickness": 0.5}) == \
        NeoHookean(2.0, 0.3, 0.5)


def _finger() -> dict:
    return tomllib.loads((Path(__file__).parent / "data" / "finger.toml").read_text())


def test_scene_file_silicone_preset(tmp_path):
    scene = _finger()
    scene["material"] = {"silicone": "dragon-skin-10", "thickness": 2e-3}
    (tmp_path / "s.json").write_text(json.dumps(scene))
    assert load_scene(tmp_path / "s.json").material == silicone("dragon-skin-10", 2e-3)
    bad = dict(scene, material={"silicone": "dragon-skin-10", "nu": 0.4})
    (tmp_path / "b.json").write_text(json.dumps(bad))
    with pytest.raises(ValueError, match=r"material\.nu: a silicone preset takes only a thickness"):
        load_scene(tmp_path / "b.json")
    bad["material"] = {"model": "yeoh", "C2": 1.0}
    (tmp_path / "b.json").write_text(json.dumps(bad))
    with pytest.raises(ValueError, match=r"material\.C1: a yeoh material needs C1"):
        load_scene(tmp_path / "b.json")


# ------------------------------------------------------------------------------------ solves
@pytest.mark.parametrize("mat", SHEETS, ids=lambda m: m.kind[:24])
def test_solve_external_with_each_sheet(mat):
    """A strip pulled and sheared at one end: IPOPT (numeric callbacks) and the Newton backend both succeed
    and find the same minimum; at the same small-strain modulus the sheets' strokes agree at small load."""
    mesh = Mesh.rectangle(4.0, 1.0, 8, 2)
    left = np.flatnonzero(mesh.points[:, 0] < 1e-9)
    right = np.flatnonzero(mesh.points[:, 0] > 4 - 1e-9)
    drag = (right, mesh.points[right] + [1.0, 0.3])
    a = solve_external(mesh, mat, left, drag)
    b = solve_external(mesh, mat, left, drag, backend="newton")
    assert a.success and b.success
    assert b.energy == pytest.approx(a.energy, rel=1e-9)
    assert np.abs(a.x - b.x).max() < 1e-6
    assert a.energy > 0 and mesh.jacobians(a.x).min() > 0


def test_silicone_in_si_units_matches_the_unit_problem():
    """A Dragon Skin strip 40 x 10 mm, 2 mm thick, in metres and pascals, is the same problem as its
    dimensionless copy (Yeoh constants scaled by a power of two, the same kind): the same shape, the energy
    in joules."""
    mat = silicone("dragon-skin-30", thickness=2e-3)
    mesh = Mesh.rectangle(0.04, 0.01, 8, 2)
    u = Units(mesh, mat)
    assert u.unit_material.kind == mat.kind and u.unit_material.thickness == mat.thickness / 2.0 ** -9
    left = np.flatnonzero(mesh.points[:, 0] < 1e-12)
    right = np.flatnonzero(mesh.points[:, 0] > 0.04 - 1e-12)
    res = solve_external(mesh, mat, left, (right, mesh.points[right] + [0.01, 0.0]))
    ref = solve_external(Mesh.rectangle(4.0, 1.0, 8, 2), Yeoh(1.0, mat.C2 / mat.C1, mat.C3 / mat.C1), left,
                         (right, Mesh.rectangle(4.0, 1.0, 8, 2).points[right] + [1.0, 0.0]))
    assert res.success and ref.success
    assert np.abs(res.x / 0.01 - ref.x).max() < 1e-7
    # energy scales as C1 t L^2 (C1 in Pa, t and the 0.01 m length in m)
    assert res.energy == pytest.approx(ref.energy * mat.C1 * 2e-3 * 0.01 ** 2, rel=1e-7)


@pytest.mark.parametrize("derivatives", ["numeric", "casadi"])
def test_design_recovers_a_contraction_of_a_compressible_sheet(derivatives):
    """The design NLP on a compressible plane-stress sheet, with numpy callbacks (closed forms) or the
    CasADi graph (the out-of-plane stretch's Newton iterations differentiated symbolically, IPOPT's exact
    Hessian), recovers the contraction that made the target."""
    from mdsr_opt import Muscle, design_contractions, solve_internal

    mesh = Mesh.rectangle(4.0, 1.0, 16, 4)
    mat, mus = NeoHookean(1.0, 0.45, plane="stress"), [Muscle(range(1, 16))]
    target = solve_internal(mesh, mat, mus, [0.2])
    assert target.success
    res = design_contractions(mesh, mat, mus, target.x, derivatives=derivatives)
    assert res.success and abs(float(np.ravel(res.contractions)[0]) - 0.2) < 1e-6


class _DetSheet:
    """An incompressible Neo-Hookean sheet stated independently, with CasADi's ``det`` and ``trace`` and no
    closed forms: a material of another kind (``kind``, ``params``, ``psi_expr`` only)."""

    kind = "test-det-sheet"
    E, nu, thickness = 3.0, 0.5, 1.0
    params = np.array([1.0, 0.0])

    @staticmethod
    def psi_expr(F, p):
        import casadi as ca

        return p[0] / 2 * (ca.trace(ca.mtimes(F.T, F)) + ca.det(F) ** -2 - 3)


def test_a_symbolic_material_matches_the_closed_form_sheet_and_newton_refuses_it_by_name():
    mesh = Mesh.rectangle(4.0, 1.0, 8, 2)
    left = np.flatnonzero(mesh.points[:, 0] < 1e-9)
    right = np.flatnonzero(mesh.points[:, 0] > 4 - 1e-9)
    drag = (right, mesh.points[right] + [1.0, 0.3])
    a = solve_external(mesh, _DetSheet(), left, drag)
    b = solve_external(mesh, NeoHookean(3.0, 0.5, plane="stress"), left, drag)
    assert a.success and b.success and np.abs(a.x - b.x).max() < 1e-9
    assert a.energy == pytest.approx(b.energy, rel=1e-12)
    with pytest.raises(ValueError, match="got 'test-det-sheet'; use backend='ipopt'"):
        solve_external(mesh, _DetSheet(), left, drag, backend="newton")
