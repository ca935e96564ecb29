"""The fixed operators of the displacement problem (docs/model.md §3.3), assembled once; the level's
forms as a whole are declared in :mod:`level`.

    K u = (A eps(u), eps(w))                    bulk stiffness, with the Dirichlet rows as identity
    b_n = (f0_n, w) + (f2_n, w)_{Gamma_N} - B M_n - K_{.D} g_n     loads at t_n, memory, lifting

B = (S, eps(w)) maps a tensor field S in the memory's quadrature space to nodal forces;
it is assembled once, so the memory term of each level is one sparse product.
Dirichlet values g_n (``clamped``: zero; ``displacement``: per component, possibly moving)
enter only through b_n: K has its Dirichlet columns removed, so their coupling
-K_{.D} g_n (the lifting) is part of b_n, the Dirichlet rows of b_n hold g_n, and
F(u) = K u + j(u) - b_n is the residual of the problem with u = g_n on the Dirichlet dofs.
The carried residual F_0 = F(u_{n-1}) + b_{n-1} - b_n (:mod:`displacement`) therefore
stays exact when g moves: on a Dirichlet row it gives u_{n-1} - g_n.
"""

from __future__ import annotations

import numpy as np
import ufl
from dolfinx import cpp, fem
from dolfinx.fem import petsc as fpetsc
from mpi4py import MPI
from petsc4py import PETSc

from solver.config import BodyForceConfig, BoundaryConfig, MaterialConfig
from solver.errors import RigidMotionError
from solver.mesh.geometry import Geometry
from solver.physics.material import elasticity, strain
from solver.physics.memory_source import MemoryForce


def assemble_without_diagonal(M: PETSc.Mat, form, bcs) -> None:
    """M = the form, with the clamped rows and columns zero and no unit diagonal: a term to add to K,
    whose own diagonal already holds the boundary condition."""
    M.zeroEntries()
    cpp.fem.petsc.assemble_matrix(M, form, cpp.fem.pack_constants(form), cpp.fem.pack_coefficients(form), bcs)
    M.assemble()


def clamped_conditions(geo: Geometry, V: fem.FunctionSpace, clamped: tuple[BoundaryConfig, ...]) -> list:
    """u = 0 on every clamped part (one condition on the union of their dofs)."""
    if not clamped:
        return []
    fdim = geo.mesh.topology.dim - 1
    dofs = np.unique(np.concatenate(
        [fem.locate_dofs_topological(V, fdim, geo.facets(p.name)) for p in clamped]
    )).astype(np.int32)
    return [fem.dirichletbc(np.zeros(geo.mesh.geometry.dim, dtype=PETSc.ScalarType), dofs, V)]


class Dirichlet:
    """The Dirichlet conditions of the scene: ``clamped`` parts (u = 0) and ``displacement`` parts
    (u_i = g_i(t) on the components that are not free, one condition per part and component on
    the sub-space V.sub(i), its value a Constant updated by :meth:`update`).

    The displacement parts come first and the clamped union last, so where parts share a node
    the clamped value wins, and so does its reaction (``dofs``: per (part, component) the owned
    dofs whose reaction the part carries, each dof counted once).
    """

    def __init__(self, geo: Geometry, V: fem.FunctionSpace, parts: tuple[BoundaryConfig, ...]) -> None:
        fdim = geo.mesh.topology.dim - 1
        d = geo.mesh.geometry.dim
        bs = V.dofmap.index_map_bs
        owned = V.dofmap.index_map.size_local * bs
        self.parts = tuple(p for p in parts if p.dirichlet)
        self.inhomogeneous = any(p.inhomogeneous for p in self.parts)
        self.bcs: list = []
        self._values: list[tuple[BoundaryConfig, int, fem.Constant]] = []
        owner: dict[int, tuple[str, int]] = {}
        for p in (q for q in self.parts if q.role == "displacement"):
            for i, fixed in enumerate(p.fixed(d)):
                if not fixed:
                    continue
                dofs = fem.locate_dofs_topological(V.sub(i), fdim, geo.facets(p.name))  # unrolled indices
                value = fem.Constant(geo.mesh, PETSc.ScalarType(0.0))
                self.bcs.append(fem.dirichletbc(value, dofs, V.sub(i)))
                self._values.append((p, i, value))
                owner.update((int(k), (p.name, i)) for k in dofs)
        clamped = tuple(q for q in self.parts if q.role == "clamped")
        self.bcs += clamped_conditions(geo, V, clamped)
        for p in clamped:
            nodes = fem.locate_dofs_topological(V, fdim, geo.facets(p.name))  # blocked indices
            owner.update((int(k) * bs + i, (p.name, i)) for k in nodes for i in range(d))
        self.columns = tuple(f"reaction_{p.name}_{'xyz'[i]}" for p in self.parts
                             for i, fixed in enumerate(p.fixed(d)) if fixed)
        by_key: dict[tuple[str, int], list[int]] = {}
        for dof, key in owner.items():
            if dof < owned:
                by_key.setdefault(key, []).append(dof)
        self.dofs = {f"reaction_{name}_{'xyz'[i]}": np.array(sorted(by_key.get((name, i), [])), dtype=np.int32)
                     for name, i in ((p.name, i) for p in self.parts for i, f in enumerate(p.fixed(d)) if f)}
        self.constrained = np.array(sorted(k for k in owner if k < owned), dtype=np.int32)
        self.bs = bs

    def update(self, t: float) -> None:
        """Set the prescribed values of time t."""
        for part, i, value in self._values:
            value.value = part.displacement_at(t, len(part.displacement))[i]


def check_rigid_motions(geo: Geometry, V: fem.FunctionSpace, dirichlet: Dirichlet) -> None:
    """Raise :class:`RigidMotionError` if a rigid motion vanishes on every Dirichlet dof: K is then singular.

    The rigid motions (d translations and d(d-1)/2 rotations about the centre of the mesh) are
    taken at the constrained dofs; a direction in their span that is zero there is free.
    """
    comm = geo.comm
    d = geo.mesh.geometry.dim
    x = V.tabulate_dof_coordinates()[:, :d]
    n_owned = V.dofmap.index_map.size_local
    lo, hi = np.full(d, np.inf), np.full(d, -np.inf)
    if n_owned:
        lo, hi = x[:n_owned].min(axis=0), x[:n_owned].max(axis=0)
    comm.Allreduce(MPI.IN_PLACE, lo, op=MPI.MIN)
    comm.Allreduce(MPI.IN_PLACE, hi, op=MPI.MAX)
    centre, size = (lo + hi) / 2, max(float(np.max(hi - lo)), 1e-300)
    nodes, comps = np.divmod(dirichlet.constrained, dirichlet.bs)
    y = (x[nodes] - centre) / size
    modes = rigid_modes(y, comps, d)  # (dofs, modes)
    gram = comm.allreduce(modes.T @ modes, op=MPI.SUM)
    w, v = np.linalg.eigh(gram)
    free = [v[:, j] for j in range(len(w)) if w[j] <= 1e-10 * max(w[-1], 1.0)]
    if free:
        raise RigidMotionError([_describe(m, centre, size, d) for m in free])


def rigid_modes(y: np.ndarray, comps: np.ndarray, d: int) -> np.ndarray:
    """Values of the rigid motions at dofs (point y, component c): translations, then rotations."""
    cols = [(comps == i).astype(float) for i in range(d)]
    pairs = [(0, 1)] if d == 2 else [(1, 2), (2, 0), (0, 1)]
    for a, b in pairs:  # rotation in the (a, b) plane: u_a = -y_b, u_b = y_a
        cols.append(np.where(comps == a, -y[:, b], 0.0) + np.where(comps == b, y[:, a], 0.0))
    return np.column_stack(cols) if len(y) else np.zeros((0, len(cols)))


def _describe(m: np.ndarray, centre: np.ndarray, size: float, d: int) -> str:
    m = m / np.abs(m).max()
    if d == 2 and abs(m[2]) > 1e-8:  # u = t + c (-(y - y0), x - x0) is a rotation about a point
        t, c = m[:2], m[2]
        p = centre + size * np.round(np.array([-t[1] / c, t[0] / c]), 9) + 0.0  # no -0 or 1e-17 in the message
        return f"rotation about ({p[0]:.6g}, {p[1]:.6g})"
    if np.abs(m[d:]).max() < 1e-8:
        return "translation along (" + ", ".join(f"{v:.3g}" for v in m[:d]) + ")"
    return "rigid motion (translation, rotation) = (" + ", ".join(f"{v:.3g}" for v in m) + ")"


class Operators:
    """Dirichlet conditions, K, B and the load form; ``b`` is the current right-hand side, ``b_prev`` the last one.

    ``pattern_extra`` (a bilinear UFL form in the same ``arguments``) widens K's sparsity, so that
    terms with a wider stencil (the contact Jacobian) can be added to copies of K in place.
    """

    def __init__(self, geo: Geometry, arguments: tuple, material: MaterialConfig, dirichlet: Dirichlet,
                 tractions: tuple[BoundaryConfig, ...], history=None, pattern_extra=None,
                 body_force: BodyForceConfig | None = None) -> None:
        mesh = geo.mesh
        d = mesh.geometry.dim
        self.du, self.w = arguments  # (trial, test): shared with the other terms of the same forms
        self.dirichlet = dirichlet
        self.bcs = dirichlet.bcs

        # loads: tractions (time-dependent constants on their facets); a zero term keeps the form valid without any
        self.tractions = [(p, fem.Constant(mesh, np.zeros(d, dtype=PETSc.ScalarType))) for p in tractions]
        zero = fem.Constant(mesh, np.zeros(d, dtype=PETSc.ScalarType))
        load = sum((ufl.inner(f, self.w) * geo.ds(geo.tags[p.name]) for p, f in self.tractions),
                ufl.inner(zero, self.w) * geo.ds)
        # the body force f0(t), a time-dependent constant over the body
        self.body_force = body_force if body_force is not None and body_force.f else None
        self.f0 = fem.Constant(mesh, np.zeros(d, dtype=PETSc.ScalarType))
        if self.body_force is not None:
            load = load + ufl.inner(self.f0, self.w) * ufl.dx
        self.load_ufl = load  # l_n(w) = (f0_n, w) + (f2_n, w)_{Gamma_N}, its constants set by assemble_rhs
        self.load_form = fem.form(load)
        self.history = history
        # (M_n, eps(w)) over the memory's points: the definition of B M_n, which MemoryForce forms without assembly
        self.memory_ufl = (ufl.inner(history.M, strain(self.w)) * history.rule.dx) if history is not None else None
        # B M = (M, eps(w)) from the source's strain operator (tested equal to the assembled coupling)
        self._memory_force = MemoryForce(history.rule, history.H) if history is not None else None

        # sigma(du) : eps(w), the bulk integrand (Reactions integrates it over the cells at the Dirichlet dofs alone)
        self.stress_work = ufl.inner(elasticity(strain(self.du), material.E, material.nu, material.model),
                                     strain(self.w))
        self.bulk = self.stress_work * ufl.dx
        pattern = self.bulk if pattern_extra is None else self.bulk + pattern_extra
        self.bulk_form = fem.form(self.bulk)
        self.K = fpetsc.create_matrix(fem.form(pattern))
        fpetsc.assemble_matrix(self.K, self.bulk_form, self.bcs)
        self.K.assemble()

        self.b = fpetsc.create_vector(self.load_form)
        self.b_prev = self.b.duplicate()
        self._work = self.b.duplicate()  # B M_n after assemble_rhs
        self.loads = self.b.duplicate()  # (f_n, w) after assemble_rhs, Dirichlet rows included (for reactions)
        self._lift = self.b.duplicate()

    @property
    def memory_operator(self) -> MemoryForce | None:
        """The operator that forms B M from the source's strain operator (None without memory)."""
        return self._memory_force

    @property
    def memory_force(self) -> PETSc.Vec | None:
        """B M_n of the last :meth:`assemble_rhs` (None without memory)."""
        return self._work if self.history is not None else None

    def assemble_rhs(self, t: float) -> None:
        """b_n: loads at t, minus the memory term B M_n and the Dirichlet lifting K_{.D} g_n; g_n on the
        Dirichlet rows (the previous b is kept as ``b_prev``)."""
        self.b, self.b_prev = self.b_prev, self.b
        for part, f in self.tractions:
            f.value[:] = part.traction_at(t)
        if self.body_force is not None:
            self.f0.value[:] = self.body_force.at(t)
        self.dirichlet.update(t)
        with self.b.localForm() as b:
            b.set(0.0)
        fpetsc.assemble_vector(self.b, self.load_form)
        self.b.ghostUpdate(addv=PETSc.InsertMode.ADD, mode=PETSc.ScatterMode.REVERSE)
        self.b.copy(self.loads)
        if self._memory_force is not None:
            self._memory_force(self.history.M, self._work)
            self.b.axpy(-1.0, self._work)
        if self.dirichlet.inhomogeneous:
            with self._lift.localForm() as v:
                v.set(0.0)
            fpetsc.apply_lifting(self._lift, [self.bulk_form], bcs=[self.bcs])  # -K_{.D} g_n
            self._lift.ghostUpdate(addv=PETSc.InsertMode.ADD, mode=PETSc.ScatterMode.REVERSE)
            self.b.axpy(1.0, self._lift)
        fpetsc.set_bc(self.b, self.bcs)
