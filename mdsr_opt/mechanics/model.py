"""Energies of a mesh, made once per topology and reused for every scene.

The total energy is

``E(x; p) = sum_e t A_e Psi(F_e(x)) + sum_edges k_ij/2 (|x_j - x_i| - r_ij l0_ij)^2 + sum_cables K_c/2 (L_c(x) - R_c)^2``

with all node coordinates ``x`` (2n, interleaved ``x0, y0, x1, y1, ...``) as variables. Scenes differ
only in numbers: fixed nodes become equal bounds (IPOPT turns them into parameters), per-edge spring
stiffness ``k`` and rest-length factor ``r`` are parameters (zero stiffness where no muscle runs), and
sliding cables carry their stiffness and target length as parameters.

Two evaluations of the same energy:

* numeric (models without sliding cables, of a material with closed forms, as every material of
  :mod:`mdsr_opt.body.material` has:
  :attr:`EnergyModel.is_numeric`): :meth:`~EnergyModel.energy`, :meth:`~EnergyModel.gradient` and
  :meth:`~EnergyModel.hessian` in vectorised numpy (:class:`~mdsr_opt.mechanics.newton.NewtonEnergy`,
  scattered by :class:`~mdsr_opt.mechanics.assembly.HessianPattern`); IPOPT takes them through CasADi callbacks
  (:func:`~mdsr_opt.mechanics.assembly.ipopt_functions`). Making the model costs a few array operations.
* symbolic (``x``, ``p``, ``f_fn``, ``grad_fn``, ``hess_fn``, ``hess_lag_fn``, ``hess_lag_full_fn``: for
  the design NLP, the constrained models, the other backends, and every model the numeric path does not
  cover), built on first use: each term is one small SX function of a few nodes (a triangle, an edge, a
  cable) whose gradient and Hessian CasADi differentiates symbolically; ``Function.map`` evaluates them
  over all terms and constant sparse matrices scatter them into the global gradient and the upper
  triangle of the global Hessian. Building is linear in the mesh size and needs no symbolic
  differentiation of the global graph, but costs several solves on small meshes.

Both evaluate the same statements, each written once: the material's density
(:meth:`~mdsr_opt.body.material.NeoHookean.density`) and the spring energy
(:func:`~mdsr_opt.mechanics.segments.spring_energy`). The symbolic model differentiates them with CasADi
and is the reference; the numeric one evaluates their closed-form derivatives, which tests check against it
(energy, gradient, Hessian and third derivative at random states, for every material with and without
muscle springs) and against finite differences.

Example
-------
>>> from mdsr_opt import Mesh, NeoHookean
>>> from mdsr_opt.mechanics.model import get_model
>>> mesh = Mesh.rectangle(2.0, 1.0, 4, 2)
>>> model = get_model(mesh, NeoHookean(1.0, 0.3))
>>> float(model.energy(mesh.points, model.params(NeoHookean(1.0, 0.3))))
0.0
"""

from __future__ import annotations

import numbers
import time
from dataclasses import dataclass

import casadi as ca
import numpy as np
import scipy.sparse as sp

from ..body.material import numeric_law
from ..body.muscles import label_of
from .segments import spring_energy
from .assembly import HessianPattern
from .newton import NewtonEnergy

__all__ = ["EnergyModel", "TermFamily", "get_model", "spring_parameters", "to_dm"]


def to_dm(S: sp.spmatrix) -> ca.DM:
    """A scipy sparse matrix as a CasADi DM with the same sparsity (``ca.DM(S)`` itself converts entry by
    entry, milliseconds for a few thousand entries)."""
    S = sp.csc_matrix(S, dtype=float)
    S.sort_indices()
    spars = ca.Sparsity(S.shape[0], S.shape[1], S.indptr.astype(np.int64).tolist(),
                        S.indices.astype(np.int64).tolist())
    return ca.DM(spars, S.data.tolist())


@dataclass
class _Term:
    """One family of energy terms: an SX function of ``d`` local dofs, mapped over ``N`` instances."""

    name: str
    dofs: np.ndarray  # (N, d) global dof indices
    data: np.ndarray  # (N, nd) per-instance constants or per-instance parameters (see param_slice)
    W: ca.Function  # (xloc, data, glob) -> scalar
    WG: ca.Function  # -> (scalar, grad d)
    H: ca.Function  # -> vec(hess) d*d


def _make_term(name, d, data_sizes, ng, energy_of):
    """SX functions ``(xl, *data, glob) -> W``, ``-> (W, grad)``, ``-> vec(Hessian)`` of one term.

    Each per-instance datum is its own input (a row per datum when mapped), so the mapped call takes
    rows of constants or slices of ``p`` without concatenating them in MX.
    """
    xl = ca.SX.sym("xl", d)
    dl = [ca.SX.sym(f"d{i}", k) for i, k in enumerate(data_sizes)]
    gl = ca.SX.sym("gl", ng)
    w = energy_of(xl, dl, gl)
    g = ca.gradient(w, xl)
    h = ca.hessian(w, xl)[0]
    args = [xl, *dl, gl]
    return (ca.Function(f"{name}_W", args, [w]),
            ca.Function(f"{name}_WG", args, [w, g]),
            ca.Function(f"{name}_H", args, [ca.vec(ca.densify(h))]))


def _element_energy(psi_expr):
    def energy(xe, dl, mat):
        dmi, area = dl
        Ds = ca.horzcat(xe[2:4] - xe[0:2], xe[4:6] - xe[0:2])
        F = ca.mtimes(Ds, ca.reshape(dmi, 2, 2))
        return area * psi_expr(F, mat)
    return energy


def _spring_energy(xs, dl, _g):
    l0, k, r = dl
    return spring_energy(ca.sqrt(ca.sumsqr(xs[2:4] - xs[0:2])), k, r * l0)


@dataclass(frozen=True)
class TermFamily:
    """One family of energy terms, described by numbers (see :meth:`EnergyModel.term_families`).

    Attributes
    ----------
    name : str
    dofs : (N, d) int ndarray
        Global dof indices of each of the ``N`` instances.
    W : casadi.Function
        SX function ``(xl (d), *data, glob) -> w`` of one term.
    data : tuple
        Per datum input of ``W``: its ``(nd, N)`` constants, or None where it is read from ``p``.
    data_index : tuple
        Per datum input: ``(nd, N)`` indices into ``p``, or None where it is constant.
    glob_index : (ng,) int ndarray
        Indices into ``p`` of the input shared by all instances.
    """

    name: str
    dofs: np.ndarray
    W: ca.Function
    data: tuple
    data_index: tuple
    glob_index: np.ndarray

    def inputs(self, p, rows=None) -> list:
        """The data and shared inputs of the mapped ``W`` over instances ``rows`` (all when None), for a
        parameter vector ``p`` (a CasADi column: DM, SX or MX)."""
        N = self.dofs.shape[0]
        rows = np.arange(N) if rows is None else np.asarray(rows, dtype=np.int64)
        out = []
        for const, idx in zip(self.data, self.data_index):
            if const is not None:
                out.append(ca.DM(np.asarray(const)[:, rows]))
            else:
                sel = np.asarray(idx)[:, rows]
                out.append(ca.reshape(p[sel.ravel(order="F").tolist()], sel.shape[0], sel.shape[1]))
        out.append(p[self.glob_index.tolist()] if len(self.glob_index) else type(p)(0, 1))
        return out


class EnergyModel:
    """Energy, gradient and Hessian of one mesh topology: numeric methods and (built on first use) CasADi
    Functions; see the module docstring.

    Parameters
    ----------
    mesh : Mesh
    material : NeoHookean | LinearElastic | Yeoh | MooneyRivlin
        Only its kind (``psi_expr``, its law) is baked in; its numbers are parameters.
    cables : sequence of node paths, optional
        Sliding cables (one spring on each whole path). Empty for the per-segment spring model, which
        needs no rebuild when muscles change.
    expand : bool
        Expand the mapped MX graphs to SX (faster evaluation, slower build).

    Parameter vector ``p`` = ``[material params (2), k (n_edges), r (n_edges), K (n_cables),
    R (n_cables)]``; see :meth:`params`.

    ``build_time`` counts the numeric set-up, plus the symbolic graph's build once something uses it.
    """

    def __init__(self, mesh, material, cables=(), expand: bool = False):
        t0 = time.perf_counter()
        self.mesh = mesh
        self.material_kind = material.kind
        #: the material (the first of its kind): its closed forms evaluate the numeric model (see
        #: :func:`numeric_law`); they take the numbers from ``p``, never from the material
        self.material_law = material
        self._psi_expr = material.psi_expr
        self._expand = bool(expand)
        self.cables = tuple(tuple(int(v) for v in c) for c in cables)
        n, m = mesh.n_nodes, mesh.n_triangles
        E = mesh.edges
        self.n_dof = 2 * n
        self.n_edges = len(E)
        self.n_params = 2 + 2 * self.n_edges + 2 * len(self.cables)
        tri = mesh.triangles
        self.elem_dofs = np.stack([2 * tri, 2 * tri + 1], axis=2).reshape(m, 6)
        self.edge_dofs = np.stack([2 * E, 2 * E + 1], axis=2).reshape(len(E), 4)
        elem_data = np.column_stack([np.transpose(mesh.Dm_inv, (0, 2, 1)).reshape(m, 4), mesh.areas])
        self._elem_data = [elem_data[:, :4].T.copy(), elem_data[:, 4:].T.copy()]
        #: energy, gradient and Hessian evaluate in vectorised numpy (no symbolic graph needed)
        self.is_numeric = not self.cables and numeric_law(material)
        self._solvers: dict = {}
        self.build_time = time.perf_counter() - t0

    # ------------------------------------------------------------------ symbolic model, built on first use
    def _terms(self) -> dict:
        """The per-term SX functions (cheap: a few small functions)."""
        t = self.__dict__.get("_term_fns")
        if t is None:
            t = {"elem": _make_term("elem", 6, [4, 1], 2, _element_energy(self._psi_expr)),
                 "spring": _make_term("spring", 4, [1, 1, 1], 0, _spring_energy)}
            for c, path in enumerate(self.cables):
                def cable_energy(xl, dl, _g, k=len(path)):
                    K, R = dl
                    L = 0
                    for i in range(k - 1):
                        L += ca.sqrt(ca.sumsqr(xl[2 * i + 2:2 * i + 4] - xl[2 * i:2 * i + 2]))
                    return spring_energy(L, K, R)

                t[f"cable{c}"] = _make_term(f"cable{c}", 2 * len(path), [1, 1], 0, cable_energy)
            self.__dict__["_term_fns"] = t
        return t

    @property
    def element_functions(self):
        """``(W, WG, H)`` SX functions of one triangle."""
        return self._terms()["elem"]

    @property
    def spring_functions(self):
        """``(W, WG, H)`` SX functions of one edge spring."""
        return self._terms()["spring"]

    @property
    def cable_functions(self):
        """Per cable, its ``(W, WG, H)`` SX functions."""
        return tuple(self._terms()[f"cable{c}"] for c in range(len(self.cables)))

    def _graph(self) -> dict:
        """The symbolic model over the whole mesh (MX): built on the first use of ``x``, ``p``, ``f_fn``,
        ``grad_fn``, ``hess_fn``, ``hess_lag_fn`` or ``hess_lag_full_fn``, and its time added to
        ``build_time``."""
        g = self.__dict__.get("_graph_fns")
        if g is None:
            t0 = time.perf_counter()
            g = _build_graph(self)
            self.__dict__["_graph_fns"] = g
            self.build_time += time.perf_counter() - t0
        return g

    x = property(lambda self: self._graph()["x"], doc="MX symbol of the coordinates (2n).")
    p = property(lambda self: self._graph()["p"], doc="MX symbol of the parameters.")
    f_fn = property(lambda self: self._graph()["f_fn"], doc="CasADi Function ``(x, p) -> energy``.")
    grad_fn = property(lambda self: self._graph()["grad_fn"], doc="``(x, p) -> (energy, gradient)``.")
    hess_fn = property(lambda self: self._graph()["hess_fn"], doc="``(x, p) -> upper Hessian``.")
    hess_lag_fn = property(lambda self: self._graph()["hess_lag_fn"],
                           doc="``(x, p, lam_f, lam_g) -> lam_f * upper Hessian``.")
    hess_lag_full_fn = property(lambda self: self._graph()["hess_lag_full_fn"],
                                doc="``(x, p, lam_f, lam_g) -> lam_f * Hessian`` (full symmetric).")

    @property
    def hess_sparsity(self) -> ca.Sparsity:
        """Sparsity of the upper triangle of the Hessian."""
        return self._graph()["hess_sparsity"]

    # ------------------------------------------------------------------ parameters
    def params(self, material, springs: tuple[np.ndarray, np.ndarray] | None = None,
               cables: tuple[np.ndarray, np.ndarray] | None = None) -> np.ndarray:
        """Assemble ``p`` from a material, optional per-edge ``(k, r)`` and per-cable ``(K, R)``."""
        if material.kind != self.material_kind:
            raise ValueError(f"this model was built for a {self.material_kind} material, got {material.kind}")
        p = np.zeros(self.n_params)
        p[0:2] = material.params
        ne, nc = self.n_edges, len(self.cables)
        p[2 + ne:2 + 2 * ne] = 1.0
        if springs is not None:
            p[2:2 + ne] = springs[0]
            p[2 + ne:2 + 2 * ne] = springs[1]
        if nc:
            if cables is None:
                raise ValueError("this model has cables: pass their (K, R)")
            p[2 + 2 * ne:2 + 2 * ne + nc] = cables[0]
            p[2 + 2 * ne + nc:] = cables[1]
        return p

    # ------------------------------------------------------------------ numeric evaluation
    def numeric(self, p):
        """The vectorised numpy energy (:class:`~mdsr_opt.mechanics.newton.NewtonEnergy`) at parameters ``p``
        (the last one is kept). Only for models with :attr:`is_numeric`."""
        p = np.asarray(p, dtype=float).ravel()
        cached = self.__dict__.get("_numeric")
        if cached is not None and np.array_equal(cached[0], p):
            return cached[1]
        en = NewtonEnergy(self, p, geometry=cached[1] if cached is not None else None)
        self.__dict__["_numeric"] = (p.copy(), en)
        return en

    @property
    def hessian_pattern(self):
        """:class:`~mdsr_opt.mechanics.assembly.HessianPattern` of the mesh, with where each element and edge
        block entry lands (made on first use)."""
        pat = self.__dict__.get("_hessian_pattern")
        if pat is None:
            pat = HessianPattern(self.mesh.n_nodes, self.mesh.edges)
            # in the (d, d, N) layout of NewtonEnergy's blocks
            pat.elem_pos = pat.positions(self.mesh.triangles).reshape(-1)
            pat.edge_pos = pat.positions(self.mesh.edges).reshape(16, -1)
            self.__dict__["_hessian_pattern"] = pat
        return pat

    def hessian_data(self, x, p) -> np.ndarray:
        """The values of the full symmetric Hessian in the CSC order of :attr:`hessian_pattern` (numeric
        models only)."""
        en = self.numeric(p)
        return self._pattern_data(en, *en.hessian_blocks(np.asarray(x, dtype=float).reshape(-1)))

    def projected_hessian_data(self, x, p) -> np.ndarray:
        """As :meth:`hessian_data`, each element's and spring's term projected to positive semi-definite
        (:meth:`~mdsr_opt.mechanics.newton.NewtonEnergy.element_blocks`): a positive semi-definite matrix."""
        en = self.numeric(p)
        return self._pattern_data(en, *en.element_blocks(np.asarray(x, dtype=float).reshape(-1), True)[1:])

    def _pattern_data(self, en, He, Hs) -> np.ndarray:
        """Element blocks (6, 6, m) and the springs' of ``en`` (4, 4, s) summed in :attr:`hessian_pattern`'s order."""
        pat = self.hessian_pattern
        data = self._elem_scatter @ He.ravel()
        if len(Hs):
            data += np.bincount(pat.edge_pos[:, en.spring_on].ravel(), weights=Hs.ravel(), minlength=pat.nnz)
        return data

    @property
    def _elem_scatter(self) -> sp.csr_matrix:
        """The 0/1 matrix (nnz, 36 m) summing the element blocks' raveled (6, 6, m) entries into
        :attr:`hessian_pattern`'s order (made on first use): a sparse product scatters them several times
        faster than ``np.bincount`` on fine meshes, and the design NLP assembles many Hessians per mesh."""
        S = self.__dict__.get("_elem_scatter_matrix")
        if S is None:
            pat = self.hessian_pattern
            k = len(pat.elem_pos)  # one entry per column: built as CSC, converted without sorting in Python
            S = sp.csc_matrix((np.ones(k), pat.elem_pos, np.arange(k + 1)), shape=(pat.nnz, k)).tocsr()
            self.__dict__["_elem_scatter_matrix"] = S
        return S

    def third_data(self, x, p, v) -> np.ndarray:
        """The values of ``D^3 E(x)[v]`` (the Hessian's derivative along ``v``, symmetric) in the CSC order
        of :attr:`hessian_pattern` (numeric models only; see
        :meth:`~mdsr_opt.mechanics.newton.NewtonEnergy.third_blocks`)."""
        en = self.numeric(p)
        return self._pattern_data(en, *en.third_blocks(x, v))

    def free_ordering(self, free) -> np.ndarray:
        """A fill-reducing ordering of the free coordinates (indices into them, ``free`` a mask over 2n):
        approximate minimum degree of the node graph (CasADi's ``Sparsity.amd``, made once per mesh), each
        node's two coordinates together. A sparse factorisation in this order (SuperLU ``NATURAL``) has the
        fill of SuperLU's own minimum degree ordering without its cost (about 60 % of a factorisation at
        30k nodes)."""
        free = np.asarray(free, dtype=bool)
        cache = self.__dict__.setdefault("_free_orderings", {})
        key = free.tobytes()
        if key not in cache:
            node_order = self.__dict__.get("_node_order")
            if node_order is None:
                pat = self.hessian_pattern
                n = self.mesh.n_nodes
                S = ca.Sparsity(n, n, pat.node_colptr.tolist(), pat.node_rows.tolist())
                node_order = self.__dict__["_node_order"] = np.asarray(S.amd(), dtype=np.int64)
            dof = np.stack([2 * node_order, 2 * node_order + 1], axis=1).ravel()
            newidx = np.full(self.n_dof, -1, dtype=np.int64)
            newidx[free] = np.arange(int(free.sum()))
            o = newidx[dof]
            if len(cache) >= 8:
                cache.pop(next(iter(cache)))
            cache[key] = o[o >= 0]
        return cache[key]

    def energy(self, x, p) -> float:
        """The energy at ``x`` (non-finite where a Neo-Hookean triangle is inverted)."""
        if self.is_numeric:
            with np.errstate(all="ignore"):
                return float(self.numeric(p).energy(np.asarray(x, float).reshape(-1)))
        return float(self.f_fn(np.asarray(x, float).reshape(-1), p))

    def gradient(self, x, p) -> np.ndarray:
        """The energy gradient (2n,) at ``x``."""
        if self.is_numeric:
            with np.errstate(all="ignore"):
                return self.numeric(p).gradient(np.asarray(x, float).reshape(-1))
        return np.asarray(self.grad_fn(np.asarray(x, float).reshape(-1), p)[1]).ravel()

    def hessian(self, x, p) -> sp.csc_matrix:
        """The full symmetric Hessian as a scipy CSC matrix."""
        if self.is_numeric:
            with np.errstate(all="ignore"):
                return self.hessian_pattern.matrix(self.hessian_data(x, p))
        v = np.asarray(self.hess_fn(np.asarray(x, float).reshape(-1), p).nonzeros())
        if not hasattr(self, "_full_pattern"):
            self._full_pattern = _symmetric_pattern(self.hess_sparsity)
        indptr, indices, src = self._full_pattern
        return sp.csc_matrix((v[src], indices, indptr), shape=(self.n_dof, self.n_dof))

    def term_families(self) -> list["TermFamily"]:
        """The energy's term families (elements, edge springs, each cable) as :class:`TermFamily` records.

        Each record gives the instances' dofs, the per-term SX energy function and where its inputs come
        from (constants, or entries of ``p``), so that other derived quantities (third derivatives,
        derivatives with respect to parameters) can be assembled term by term like the model's own
        gradient and Hessian.
        """
        ne, nc = self.n_edges, len(self.cables)
        e = np.arange(ne)
        out = [TermFamily("elem", self.elem_dofs, self.element_functions[0], tuple(self._elem_data),
                          (None, None), np.array([0, 1])),
               TermFamily("spring", self.edge_dofs, self.spring_functions[0],
                          (self.mesh.edge_lengths[None, :].copy(), None, None),
                          (None, (2 + e)[None, :], (2 + ne + e)[None, :]), np.zeros(0, dtype=np.int64))]
        for c, path in enumerate(self.cables):
            v = np.asarray(path)
            dofs = np.stack([2 * v, 2 * v + 1], axis=1).reshape(1, 2 * len(v))
            out.append(TermFamily(f"cable{c}", dofs, self.cable_functions[c][0], (None, None),
                                  (np.array([[2 + 2 * ne + c]]), np.array([[2 + 2 * ne + nc + c]])),
                                  np.zeros(0, dtype=np.int64)))
        return out

    def solver(self, backend: str, options: dict, factory):
        """``(solver, seconds spent building it now)``: built by ``factory(self)`` on first use, then cached
        (later calls report 0 s, so timings count each build once)."""
        key = (backend, repr(sorted(options.items())))
        if key in self._solvers:
            return self._solvers[key], 0.0
        t0 = time.perf_counter()
        s = factory(self)
        self._solvers[key] = s
        return s, time.perf_counter() - t0


def _build_graph(model) -> dict:
    """The MX model of the whole mesh: each term family's SX functions mapped over its instances and
    scattered by constant sparse matrices into the global gradient and the upper triangle of the Hessian."""
    mesh = model.mesh
    n = mesh.n_nodes
    ne, nc = model.n_edges, len(model.cables)
    x = ca.MX.sym("x", 2 * n)
    p = ca.MX.sym("p", model.n_params)
    mat = p[0:2]
    k_e = p[2:2 + ne]
    r_e = p[2 + ne:2 + 2 * ne]
    K_c = p[2 + 2 * ne:2 + 2 * ne + nc]
    R_c = p[2 + 2 * ne + nc:]
    terms = model._terms()
    # family: (dofs, W/WG/H functions, list of data rows (each nd_i x N), global params)
    fam = [(model.elem_dofs, *terms["elem"], [ca.DM(v) for v in model._elem_data], mat),
           (model.edge_dofs, *terms["spring"], [ca.DM(mesh.edge_lengths).T, k_e.T, r_e.T], ca.MX(0, 1))]
    for c, path in enumerate(model.cables):
        v = np.asarray(path)
        dofs = np.stack([2 * v, 2 * v + 1], axis=1).reshape(1, 2 * len(v))
        fam.append((dofs, *terms[f"cable{c}"], [K_c[c], R_c[c]], ca.MX(0, 1)))

    # global Hessian sparsity (upper triangle) from all families
    rows, cols, srcs = [], [], []
    for dofs, *_r in fam:
        N, d = dofs.shape
        rr = np.broadcast_to(dofs[:, None, :], (N, d, d)).reshape(-1)  # vec(H) col-major: entry (i, j)
        cc = np.broadcast_to(dofs[:, :, None], (N, d, d)).reshape(-1)  # at j*d + i -> row dofs[i]
        keep = rr <= cc
        rows.append(rr[keep])
        cols.append(cc[keep])
        srcs.append(np.nonzero(keep)[0])
    allr, allc = np.concatenate(rows), np.concatenate(cols)
    pattern = sp.csc_matrix((np.ones(len(allr)), (allr, allc)), shape=(2 * n, 2 * n))
    pattern.sum_duplicates()
    pattern.sort_indices()
    nnz = pattern.nnz
    hess_sparsity = ca.Sparsity(2 * n, 2 * n, pattern.indptr.tolist(), pattern.indices.tolist())
    # CSC position lookup: key = col * 2n + row
    col_of_nz = np.repeat(np.arange(2 * n), np.diff(pattern.indptr))
    keys = col_of_nz.astype(np.int64) * (2 * n) + pattern.indices
    order = np.argsort(keys)

    W_tot, G_tot, H_tot = 0, 0, 0
    W_only = 0
    for fi, (dofs, W, WG, H, data, glob) in enumerate(fam):
        N, d = dofs.shape
        X = ca.reshape(x[dofs.reshape(-1).tolist()], d, N)
        Wm, WGm, Hm = (f.map(N, "serial") for f in (W, WG, H))
        W_only += ca.sum2(Wm(X, *data, glob))
        w, g = WGm(X, *data, glob)
        W_tot += ca.sum2(w)
        Sg = sp.csr_matrix((np.ones(N * d), (dofs.reshape(-1), np.arange(N * d))), shape=(2 * n, N * d))
        G_tot += ca.mtimes(to_dm(Sg), ca.vec(g))
        k = np.searchsorted(keys[order], cols[fi].astype(np.int64) * (2 * n) + rows[fi])
        nzpos = order[k]
        Sh = sp.csr_matrix((np.ones(len(nzpos)), (nzpos, srcs[fi])), shape=(nnz, N * d * d))
        H_tot += ca.mtimes(to_dm(Sh), ca.vec(Hm(X, *data, glob)))
    Hmx = ca.MX(hess_sparsity, H_tot)
    lam_f = ca.MX.sym("lam_f")
    lam_g = ca.MX.sym("lam_g", 0)
    out = {"x": x, "p": p, "hess_sparsity": hess_sparsity,
           "f_fn": ca.Function("energy", [x, p], [W_only], ["x", "p"], ["f"]),
           "grad_fn": ca.Function("grad_f", [x, p], [W_tot, G_tot], ["x", "p"], ["f", "grad"]),
           "hess_fn": ca.Function("energy_hess", [x, p], [Hmx], ["x", "p"], ["H"]),
           "hess_lag_fn": ca.Function("hess_lag", [x, p, lam_f, lam_g], [lam_f * Hmx],
                                      ["x", "p", "lam_f", "lam_g"], ["hess"])}
    # full symmetric version for solvers that require it (sqpmethod)
    Hfull = Hmx + ca.triu(Hmx, False).T
    out["hess_lag_full_fn"] = ca.Function("hess_lag_full", [x, p, lam_f, lam_g], [lam_f * Hfull],
                                          ["x", "p", "lam_f", "lam_g"], ["hess"])
    if model._expand:
        for key in ("f_fn", "grad_fn", "hess_fn", "hess_lag_fn", "hess_lag_full_fn"):
            out[key] = out[key].expand()
    return out


def _symmetric_pattern(upper: ca.Sparsity):
    """CSC pattern of the full symmetric matrix and, per entry, the index of its upper-triangle value."""
    colind = np.asarray(upper.colind())
    row = np.asarray(upper.row())
    col = np.repeat(np.arange(upper.size2()), np.diff(colind))
    nz = np.arange(len(row))
    off = row != col
    R = np.concatenate([row, col[off]])
    C = np.concatenate([col, row[off]])
    S = np.concatenate([nz, nz[off]])
    order = np.lexsort((R, C))
    counts = np.bincount(C, minlength=upper.size2())
    indptr = np.concatenate([[0], np.cumsum(counts)])
    return indptr, R[order], S[order]


def get_model(mesh, material, cables=(), expand: bool = False) -> EnergyModel:
    """The cached :class:`EnergyModel` of ``mesh`` for the material's kind (and cables, if any)."""
    cache = mesh.__dict__.setdefault("_model_cache", {})
    key = (material.kind, tuple(tuple(int(v) for v in c) for c in cables), bool(expand))
    if key not in cache:
        cache[key] = EnergyModel(mesh, material, cables, expand=expand)
    return cache[key]


def spring_parameters(mesh, muscles, contractions, stiffness) -> tuple[np.ndarray, np.ndarray]:
    """Per-edge ``(k, r)`` of the per-segment ("dummy spring") muscle model.

    Each muscle segment on edge ``e`` adds ``k_s/2 (l_e - (1 - a_c) l0_e)^2``; muscles sharing an edge
    combine exactly into one spring with summed stiffness and stiffness-weighted mean factor.
    ``stiffness`` is one absolute ``k_s`` for every segment, or a sequence with one array of per-segment
    stiffnesses per muscle (see :func:`mdsr_opt.mechanics.constraints.segment_spring_parameters`, which states
    the stiffness per unit rest length so the model does not depend on the mesh).
    """
    k = np.zeros(len(mesh.edges))
    kr = np.zeros(len(mesh.edges))
    scalar = isinstance(stiffness, numbers.Real) or (isinstance(stiffness, np.ndarray) and stiffness.ndim == 0)
    for c, (mus, a) in enumerate(zip(muscles, contractions)):
        ks = np.full(len(mus.segments), float(stiffness)) if scalar else np.asarray(stiffness[c], dtype=float)
        if ks.shape != (len(mus.segments),):
            raise ValueError(f"stiffness[{c}] must have one value per segment ({len(mus.segments)}), "
                             f"got shape {ks.shape}")
        e = mesh.edge_rows(mus.segments[:, 0], mus.segments[:, 1])
        if (e < 0).any():
            raise ValueError(f"muscle {label_of(muscles, c)} leaves the mesh: a segment is not a mesh edge")
        np.add.at(k, e, ks)  # unbuffered: a row given twice adds up twice
        np.add.at(kr, e, ks * (1.0 - a))
    r = np.where(k > 0, kr / np.where(k > 0, k, 1.0), 1.0)
    return k, r
