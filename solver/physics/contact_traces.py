"""The contact results on Γ_C as fields (docs/contact.md): the pressure λ_h, the normal displacement, the gap
and the penetration, in the traces on Γ_C of the degree-p Lagrange space (zero off Γ_C).

λ_h is the discrete problem's own pressure (as the estimator's :class:`estimator.ContactPressure`):

    (λ_h, ψ)_Γ_C = Σ_parts Σ_q p(u_ν − g)(x_q) ψ(x_q) w_q    for every trace ψ,

the compliance at the contact term's quadrature points. Taking ψ = Σ_i ψ_i = 1 on Γ_C gives
∫_Γ_C λ_h ds = the contact force of the discrete equations, exactly (to the CG tolerance). u_ν is
the same projection of u·ν (exact for P1 on a straight part, where u·ν is P1 itself), g is the gap at
the trace's nodes, and the penetration u_ν − g. The boundary mass matrix is assembled and its Γ_C block
factored once: an update is an assembly and a triangular solve pair on the Γ_C dofs.
"""

from __future__ import annotations

import numpy as np
import ufl
from dolfinx import fem, la
from dolfinx.fem import petsc as fpetsc
from mpi4py import MPI
from petsc4py import PETSc

from solver.config import BoundaryConfig
from solver.mesh.geometry import Geometry
from solver.physics.contact import compliance, penetration
from solver.physics.gap import gap_function, gap_values


class ContactTraces:
    """λ_h, u_ν, g and u_ν − g on Γ_C as functions of the degree-p Lagrange space (:meth:`update` per level)."""

    def __init__(self, geo: Geometry, u: fem.Function, parts: tuple[BoundaryConfig, ...], degree: int,
                 pressure_floor: float = 0.0) -> None:
        mesh = geo.mesh
        self.geo, self.parts, self.comm = geo, parts, geo.comm
        self.pressure_floor = pressure_floor  # pressures within it of the peak (or all, below it) tie
        p = u.function_space.ufl_element().degree()
        S = fem.FunctionSpace(mesh, ("Lagrange", p))
        self.pressure = fem.Function(S, name="contact_pressure")
        self.normal_displacement = fem.Function(S, name="normal_displacement")
        self.gap = fem.Function(S, name="gap")
        self.penetration = fem.Function(S, name="penetration")
        lam, psi = ufl.TrialFunction(S), ufl.TestFunction(S)
        n = ufl.FacetNormal(mesh)
        fdim = mesh.topology.dim - 1
        x = S.tabulate_dof_coordinates()
        self.x = x
        self._order: dict[str, tuple[np.ndarray, np.ndarray]] | None = None  # rank 0: the profile's order (once)
        n_local = S.dofmap.index_map.size_local
        self.part_dofs = {}  # per part: its owned dofs
        for part in parts:
            dofs = fem.locate_dofs_topological(S, fdim, geo.facets(part.name))
            self.gap.x.array[dofs] = gap_values(part, x[dofs])
            self.part_dofs[part.name] = dofs[dofs < n_local]
        self.on = np.unique(np.concatenate([fem.locate_dofs_topological(S, fdim, geo.facets(q.name)) for q in parts]))
        mass = sum(lam * psi * geo.ds(geo.tags[q.name], metadata={"quadrature_degree": 2 * p}) for q in parts)
        A = fpetsc.assemble_matrix(fem.form(mass))
        A.assemble()
        # only the Γ_C block is factored: the rows off Γ_C are empty (the right-hand sides vanish there too); the
        # whole matrix, with 1 on the diagonal off Γ_C, fills like a volume Laplacian (docs/developer/design-notes.md)
        marker = fem.Function(S)  # the owned dofs on Γ_C: also those whose Γ_C facets are all on another rank
        marker.x.array[self.on] = 1.0
        marker.x.scatter_reverse(la.ScatterMode.add)
        owned_on = np.flatnonzero(marker.x.array[:n_local]).astype(np.int32)
        self.is_on = PETSc.IS().createGeneral(S.dofmap.index_map.local_to_global(owned_on).astype(PETSc.IntType),
                                              comm=self.comm)
        A_on = A.createSubMatrix(self.is_on, self.is_on)
        A.destroy()

        def ds(q):
            return geo.ds(geo.tags[q.name], metadata={"quadrature_degree": degree})

        self.rhs = {
            self.pressure: fem.form(sum(compliance(penetration(u, n, gap_function(q, geo, degree)), q) * psi * ds(q)
                                        for q in parts)),
            self.normal_displacement: fem.form(sum(ufl.dot(u, n) * psi * ds(q) for q in parts)),
        }
        self.b = fpetsc.create_vector(self.rhs[self.pressure])
        # factored once (the Γ_C block): each level's λ_h is one triangular solve pair
        self.ksp = PETSc.KSP().create(self.comm)
        self.ksp.setOperators(A_on)
        self.ksp.setType("preonly")
        pc = self.ksp.getPC()
        pc.setType("cholesky")
        pc.setFactorSolverType("mumps" if self.comm.size > 1 else "petsc")
        self.ksp.setUp()

    def update_pressure(self) -> None:
        """λ_h at the current u (every level: the peak-pressure columns read it)."""
        self._solve(self.pressure)

    def update(self) -> None:
        """λ_h and u_ν at the current u; the penetration u_ν − g on Γ_C (the levels that are written)."""
        self._solve(self.pressure)
        self.update_normal()

    def update_normal(self) -> None:
        """u_ν and the penetration u_ν − g on Γ_C at the current u (λ_h is left as it is)."""
        self._solve(self.normal_displacement)
        self.penetration.x.array[:] = 0.0
        self.penetration.x.array[self.on] = self.normal_displacement.x.array[self.on] - self.gap.x.array[self.on]

    def _solve(self, target: fem.Function) -> None:
        """(target, psi)_{Γ_C} = the target's right-hand side (a triangular solve pair of the factored mass matrix)."""
        with self.b.localForm() as local:
            local.set(0.0)
        fpetsc.assemble_vector(self.b, self.rhs[target])
        self.b.ghostUpdate(addv=PETSc.InsertMode.ADD, mode=PETSc.ScatterMode.REVERSE)
        b_on, x_on = self.b.getSubVector(self.is_on), target.vector.getSubVector(self.is_on)
        self.ksp.solve(b_on, x_on)
        self.b.restoreSubVector(self.is_on, b_on)
        target.vector.restoreSubVector(self.is_on, x_on)  # off Γ_C the target stays 0
        target.x.scatter_forward()

    def peak(self) -> tuple[float, np.ndarray]:
        """The largest λ_h over Γ_C and the point where it sits, the same on every rank and for any partition.

        Points whose λ_h is within max(1e-9 |peak|, ``pressure_floor``) of the peak tie, and the first of them
        (smallest x, then y, then z) is the one named: a flat top, or a level without contact (λ_h at round-off
        everywhere), would otherwise name whichever point a partition's round-off puts first.
        """
        owned = np.concatenate(list(self.part_dofs.values()))
        values = self.pressure.x.array[owned]
        value = self.comm.allreduce(float(values.max()) if len(owned) else -np.inf, op=MPI.MAX)
        tol = max(1e-9 * abs(value), self.pressure_floor)
        near = self.x[owned[values >= value - tol]]
        first = tuple(near[np.lexsort(near.T[::-1])[0]]) if len(near) else (np.inf, np.inf, np.inf)
        return value, np.array(min(self.comm.allgather(first)))

    def profile(self) -> list[tuple[str, np.ndarray]] | None:
        """Per part on rank 0 (None elsewhere): rows (s, x, y, z, gap, u_ν, u_ν − g, λ_h) of its nodes in order
        along the part (sorted by the coordinate that varies most; s the arc length from the first)."""
        a = self.pressure.x.array
        if self._order is None:  # the nodes' order along each part and their s: the geometry's, found once
            self._order = self._profile_order() or {}  # {} on the other ranks: found (a collective call, once)
        local = {name: np.column_stack([self.gap.x.array[d], self.normal_displacement.x.array[d],
                                        self.penetration.x.array[d], a[d]]) for name, d in self.part_dofs.items()}
        gathered = self.comm.gather(local, root=0)
        if self.comm.rank != 0:
            return None
        out = []
        for part in self.parts:
            order, head = self._order[part.name]
            rows = np.concatenate([g[part.name] for g in gathered]).reshape(-1, 4)[order]
            out.append((part.name, np.column_stack([head, rows])))
        return out

    def _profile_order(self) -> dict[str, tuple[np.ndarray, np.ndarray]] | None:
        """Per part on rank 0 (None elsewhere): the order of its gathered nodes along it (sorted by the coordinate that
        varies most, ties by x, then y, then z) and the columns (s, x, y, z) of its nodes in that order."""
        gathered = self.comm.gather({name: self.x[d] for name, d in self.part_dofs.items()}, root=0)
        if self.comm.rank != 0:
            return None
        out = {}
        for part in self.parts:
            x = np.concatenate([g[part.name] for g in gathered]).reshape(-1, 3)
            order = np.lexsort(x[:, 2::-1].T) if len(x) else np.zeros(0, dtype=np.intp)
            axis = int(np.argmax(np.ptp(x, axis=0))) if len(x) else 0
            order = order[np.argsort(x[order, axis], kind="stable")]
            x = x[order]
            s = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(x, axis=0), axis=1))])[: len(x)]
            out[part.name] = (order, np.column_stack([s, x]))
        return out
