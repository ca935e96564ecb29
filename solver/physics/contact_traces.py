"""The contact results on Γ_C as fields (docs/guide/contact.md): the pressure, the normal displacement, the gap and
the penetration, as P1 functions that are nonzero on Γ_C only, recovered from the contact term's quadrature points.

The law acts at the points x_q where the contact term is integrated, with the exact gap: p_q = p(u_ν − g)(x_q).
Each field is reported at a vertex i of Γ_C as the lumped-mass (row-sum) L² projection onto P1 of its values at
those points:

    f_i = Σ_q φ_i(x_q) w_q f_q / m_i,    m_i = Σ_q φ_i(x_q) w_q = ∫_Γ_C φ_i ds,

a weighted mean with nonnegative weights (the P1 hats are ≥ 0), so

- the pressure is ≥ 0 by construction (a mean of the law's values), zero where no point in the vertex's
  facets is in contact, and Σ_i m_i p_i = Σ_q w_q p_q: its integral with the lumped mass is the contact force
  of the discrete equations, exactly;
- u_ν and g are the means of u·ν and of the exact gap at the points, so u_ν − g is the mean of the
  penetration r = u_ν − g where the law acts (not the interpolation error of the gap between the nodes);
- the penetration reported is the mean of r₊ = max(r, 0) where that is positive (the vertex's pressure is then
  positive: for the linear law p_i = r₊,i / μ), else the mean of r (≤ 0, a separation): a positive pressure
  never sits beside a negative penetration.

One boundary assembly a level (the three means share it); the gap's mean and m are assembled once. P2
displacements are reported at the vertices (the recovery is onto P1 on Γ_C).
"""

from __future__ import annotations

import numpy as np
import ufl
from dolfinx import fem
from dolfinx.fem import petsc as fpetsc
from mpi4py import MPI
from petsc4py import PETSc

from solver.config import BoundaryConfig
from solver.mesh.geometry import Geometry
from solver.physics.contact import compliance, contact_ds, penetration
from solver.physics.gap import gap_function
from solver.physics.quadrature import ContactRule


def _assemble(form: fem.Form) -> PETSc.Vec:
    """A vector form assembled, summed over ranks into the owned entries and copied to the ghosts."""
    b = fpetsc.create_vector(form)
    with b.localForm() as local:
        local.set(0.0)
    fpetsc.assemble_vector(b, form)
    b.ghostUpdate(addv=PETSc.InsertMode.ADD, mode=PETSc.ScatterMode.REVERSE)
    b.ghostUpdate(addv=PETSc.InsertMode.INSERT, mode=PETSc.ScatterMode.FORWARD)
    return b


class ContactTraces:
    """The contact pressure, u_ν, g and the penetration on Γ_C as P1 functions (:meth:`update` per level)."""

    def __init__(self, geo: Geometry, u: fem.Function, parts: tuple[BoundaryConfig, ...], degree: int | ContactRule,
                 pressure_floor: float = 0.0) -> None:
        mesh = geo.mesh
        self.geo, self.parts, self.comm = geo, parts, geo.comm
        self.pressure_floor = pressure_floor  # pressures within it of the peak (or all, below it) tie
        S = fem.FunctionSpace(mesh, ("Lagrange", 1))
        self.pressure = fem.Function(S, name="contact_pressure")
        self.normal_displacement = fem.Function(S, name="normal_displacement")
        self.gap = fem.Function(S, name="gap")
        self.penetration = fem.Function(S, name="penetration")
        self.x = S.tabulate_dof_coordinates()
        fdim = mesh.topology.dim - 1
        self._order: dict[str, tuple[np.ndarray, np.ndarray]] | None = None  # rank 0: the profile's order (once)
        n_local = S.dofmap.index_map.size_local
        self.n_local = n_local
        self.part_dofs = {}  # per part: its owned dofs
        for part in parts:
            dofs = fem.locate_dofs_topological(S, fdim, geo.facets(part.name))
            self.part_dofs[part.name] = dofs[dofs < n_local]
        n = ufl.FacetNormal(mesh)

        def ds(q):
            return contact_ds(geo, q, degree)

        psi = ufl.TestFunction(S)
        self.mass = _assemble(fem.form(sum(psi * ds(q) for q in parts))).array_r.copy()
        self.on = np.flatnonzero(self.mass > 0).astype(np.int32)  # local (ghosts too) vertices of Γ_C
        self._inv_mass = 1.0 / self.mass[self.on]
        gaps = {q.name: gap_function(q, geo, degree) for q in parts}
        held = {name: fem.Constant(mesh, float(g)) if isinstance(g, (int, float)) else g  # 0 * psi would vanish
                for name, g in gaps.items()}
        self.gap.x.array[self.on] = _assemble(fem.form(sum(held[q.name] * psi * ds(q) for q in parts))).array_r[
            self.on] * self._inv_mass
        # the three means of a level in one assembly: p(r), r₊ and u·ν against the components of a P1 3-vector
        S3 = fem.VectorFunctionSpace(mesh, ("Lagrange", 1), dim=3)
        w = ufl.TestFunction(S3)
        terms = []
        for q in parts:
            r = penetration(u, n, gaps[q.name])
            terms.append((compliance(r, q) * w[0] + ufl.max_value(r, 0.0) * w[1] + ufl.dot(u, n) * w[2]) * ds(q))
        self.form = fem.form(sum(terms))
        self.b = fpetsc.create_vector(self.form)

    def update(self) -> None:
        """The pressure, u_ν and the penetration at the current u (one boundary assembly)."""
        b = self.b
        with b.localForm() as local:
            local.set(0.0)
        fpetsc.assemble_vector(b, self.form)
        b.ghostUpdate(addv=PETSc.InsertMode.ADD, mode=PETSc.ScatterMode.REVERSE)
        b.ghostUpdate(addv=PETSc.InsertMode.INSERT, mode=PETSc.ScatterMode.FORWARD)
        with b.localForm() as local:
            means = local.array_r.reshape(-1, 3)[self.on] * self._inv_mass[:, None]
        pressure, plus, normal = means.T
        self.pressure.x.array[self.on] = pressure
        self.normal_displacement.x.array[self.on] = normal
        self.penetration.x.array[self.on] = np.where(plus > 0, plus, normal - self.gap.x.array[self.on])

    def lumped_force(self) -> float:
        """Σ_i m_i p_i over Γ_C: the reported pressure's integral with the lumped mass (= the contact force)."""
        owned = self.on[self.on < self.n_local]
        return self.comm.allreduce(float(self.mass[owned] @ self.pressure.x.array[owned]), op=MPI.SUM)

    def max_penetration(self) -> float:
        """The largest reported penetration over Γ_C (-inf without Γ_C vertices anywhere)."""
        owned = self.on[self.on < self.n_local]
        return self.comm.allreduce(float(self.penetration.x.array[owned].max()) if len(owned) else -np.inf,
                                   op=MPI.MAX)

    def peak(self) -> tuple[float, np.ndarray]:
        """The largest pressure over Γ_C and the point where it sits, the same on every rank and for any partition.

        Points whose pressure is within max(1e-9 |peak|, ``pressure_floor``) of the peak tie, and the first of them
        (smallest x, then y, then z) is the one named: a flat top, or a level without contact (0 everywhere),
        would otherwise name whichever point a partition puts first.
        """
        owned = np.concatenate(list(self.part_dofs.values()))
        values = self.pressure.x.array[owned]
        value = self.comm.allreduce(float(values.max()) if len(owned) else -np.inf, op=MPI.MAX)
        tol = max(1e-9 * abs(value), self.pressure_floor)
        near = self.x[owned[values >= value - tol]]
        first = tuple(near[np.lexsort(near.T[::-1])[0]]) if len(near) else (np.inf, np.inf, np.inf)
        return value, np.array(min(self.comm.allgather(first)))

    def profile(self) -> list[tuple[str, np.ndarray]] | None:
        """Per part on rank 0 (None elsewhere): rows (s, x, y, z, gap, u_ν, penetration, pressure) of its vertices in
        order along the part (sorted by the coordinate that varies most; s the arc length from the first)."""
        a = self.pressure.x.array
        if self._order is None:  # the nodes' order along each part and their s: the geometry's, found once
            self._order = self._profile_order() or {}  # {} on the other ranks: found (a collective call, once)
        local = {name: np.column_stack([self.gap.x.array[d], self.normal_displacement.x.array[d],
                                        self.penetration.x.array[d], a[d]]) for name, d in self.part_dofs.items()}
        gathered = self.comm.gather(local, root=0) if self.comm.size > 1 else [local]  # no pickling alone
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
