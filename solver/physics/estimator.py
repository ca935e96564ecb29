"""A posteriori estimate of the displacement error of a level, residual based, cell by cell.

For the displacement problem of a level (docs/model.md §3.2: elasticity, the memory stress
M, the body force f, tractions t on Γ_N and the normal compliance p on Γ_C), with
σ_h = A ε(u_h) + M, the classical residual estimator is

    η_K² = h_K² ‖div σ_h + f‖²_K + ½ Σ_{E ⊂ ∂K interior} h_E ‖[σ_h n]‖²_E
           + Σ_{E ⊂ ∂K ∩ Γ_N} h_E ‖σ_h n − t‖²_E + Σ_{E ⊂ ∂K ∩ Γ_C} h_E ‖σ_h n + p(u_ν − g) ν‖²_E
           + Σ_{E ⊂ ∂K free} h_E ‖σ_h n‖²_E,

and ‖ε(u − u_h)‖ ≤ C η with a constant C that the theory leaves open: it is measured
(calibrated) against the error of solutions whose reference is known, not assumed.
η is the estimator's indicator (``indicator`` in solver/run/accuracy; ``eta`` in config/damage
is the damage's truncation, another quantity).

The estimate is assembled as one vector against the piecewise constants (one test function
per cell), so that η_K² comes out per cell in one assembly, in parallel as in serial. The
memory stress M lives at quadrature points and has no facet values, so σ_h uses its L2
projection Π M onto discontinuous tensors of degree p − 1, cell by cell (exact for P1,
where M is one value per cell; zero at t = 0). Without it the residual of a later level
measures the memory stress itself, not the discretization error.

The contact pressure in the Γ_C residual is the discrete problem's own: λ_h in the traces of
the degree-p Lagrange space on Γ_C with (λ_h, ψ)_Γ_C = Σ_q p(u_ν − g) ψ w_q, the compliance
at the contact quadrature points, for every trace ψ (:class:`ContactPressure`). The discrete
equations hold with λ_h in place of p, which the pointwise p(u_ν − g) does not: at the edge
of the contact zone a facet has points on both sides, p jumps there from σ_νν to 0 within one
facet, and with P2 the pointwise residual doubled η at the levels where the zone's edge
crossed a point (configs/hard.toml, η 0.0078 → 0.0147 → 0.0078 over three levels).
"""

from __future__ import annotations

import numpy as np
import ufl
from dolfinx import fem
from dolfinx.fem import petsc as fpetsc
from mpi4py import MPI
from petsc4py import PETSc

from solver.config import BoundaryConfig, MaterialConfig
from solver.mesh.geometry import Geometry
from solver.physics.contact import compliance, gap_function, penetration
from solver.physics.material import elasticity, strain
from solver.physics.quadrature import ContactRule, contact_rule, facet_type


class _Projection:
    """A field kept as the solution of a fixed SPD system A x = b(L), b reassembled from the form ``rhs`` at each
    :meth:`update`; A is solved by CG to 1e-14 with the given preconditioner (both are mass matrices)."""

    def _init_solver(self, A: PETSc.Mat, rhs: fem.Form, target: fem.Function, pc: str) -> None:
        self.rhs, self.target = rhs, target
        self.b = fpetsc.create_vector(rhs)
        self.ksp = PETSc.KSP().create(target.function_space.mesh.comm)
        self.ksp.setOperators(A)
        self.ksp.setType("cg")
        self.ksp.getPC().setType(pc)
        self.ksp.setTolerances(rtol=1e-14, atol=1e-300)

    def update(self) -> None:
        with self.b.localForm() as local:
            local.set(0.0)
        fpetsc.assemble_vector(self.b, self.rhs)
        self.b.ghostUpdate(addv=PETSc.InsertMode.ADD, mode=PETSc.ScatterMode.REVERSE)
        self.ksp.solve(self.b, self.target.vector)
        self.target.x.scatter_forward()


class MemoryProjection(_Projection):
    """Π M: the L2 projection of a quadrature-point tensor M onto discontinuous tensors of ``degree``, cell by
    cell (the mass matrix is block diagonal: one exact block-Jacobi solve)."""

    def __init__(self, M: fem.Function, dx, degree: int) -> None:
        mesh = M.function_space.mesh
        S = fem.TensorFunctionSpace(mesh, ("DG", degree))
        self.PM = fem.Function(S, name="memory_projected")
        s, t = ufl.TrialFunction(S), ufl.TestFunction(S)
        A = fpetsc.assemble_matrix(fem.form(ufl.inner(s, t) * ufl.dx))
        A.assemble()
        self._init_solver(A, fem.form(ufl.inner(M, t) * dx), self.PM, "bjacobi")


class ContactPressure(_Projection):
    """λ_h: the contact pressure of the discrete problem, as a trace on Γ_C of the degree-p Lagrange space.

    (λ_h, ψ)_Γ_C = Σ_parts ∫ p(u_ν − g) ψ ds with the contact term's quadrature, for every ψ of the
    space; the boundary mass matrix (with 1 on the diagonal of the dofs off Γ_C, where λ_h = 0) is
    assembled once, so an update is one assembly and one CG solve."""

    def __init__(self, geo: Geometry, u: fem.Function, parts: tuple[BoundaryConfig, ...],
                 contact_degree: int | ContactRule | None) -> None:
        mesh = geo.mesh
        degree = u.function_space.ufl_element().degree()
        S = fem.FunctionSpace(mesh, ("Lagrange", degree))
        self.pressure = fem.Function(S, name="contact_pressure")
        lam, psi = ufl.TrialFunction(S), ufl.TestFunction(S)
        n = ufl.FacetNormal(mesh)
        fdim = mesh.topology.dim - 1
        on = np.unique(np.concatenate([geo.facet_tags.find(geo.tags[p.name]) for p in parts])).astype(np.int32)
        off = np.setdiff1d(np.arange(S.dofmap.index_map.size_local + S.dofmap.index_map.num_ghosts, dtype=np.int32),
                           fem.locate_dofs_topological(S, fdim, on))
        zero = fem.Constant(mesh, 0.0)  # a cell term of zeros: every dof's diagonal is in the pattern
        mass = sum(lam * psi * geo.ds(geo.tags[p.name], metadata={"quadrature_degree": 2 * degree}) for p in parts)
        A = fpetsc.assemble_matrix(fem.form(mass + zero * lam * psi * ufl.dx),
                                   bcs=[fem.dirichletbc(fem.Function(S), off)])
        A.assemble()
        # None: FFCx's estimated degree, the gap at degree 2's points; else the contact term's rule
        qd = {} if contact_degree is None else contact_rule(contact_degree).metadata(facet_type(mesh))
        gap_rule = 2 if contact_degree is None else contact_degree
        # b is zero off Γ_C (the traces of those dofs' basis functions vanish); Jacobi-preconditioned CG on the
        # boundary mass matrix converges in a few tens of iterations
        L = fem.form(sum(compliance(penetration(u, n, gap_function(p, geo, gap_rule)), p) * psi
                         * geo.ds(geo.tags[p.name], metadata=qd) for p in parts))
        self._init_solver(A, L, self.pressure, "jacobi")


class ResidualEstimator:
    """η_K² of the displacement ``u`` on every owned cell (:meth:`cells`) and η (:meth:`total`).

    ``loads`` gives, per traction part, the traction constant the operators update each level
    (so the estimate is that of the level just solved); clamped and displacement parts carry
    no residual.
    """

    def __init__(self, geo: Geometry, u: fem.Function, material: MaterialConfig,
                 boundaries: tuple[BoundaryConfig, ...], tractions: dict[str, fem.Constant], degree: int,
                 body_force: fem.Constant | None = None, memory: MemoryProjection | None = None,
                 contact_degree: int | ContactRule | None = None) -> None:
        mesh = geo.mesh
        self.geo = geo
        V0 = fem.FunctionSpace(mesh, ("DG", 0))
        v = ufl.TestFunction(V0)
        n = ufl.FacetNormal(mesh)
        h = ufl.CellDiameter(mesh)
        sigma = elasticity(strain(u), material.E, material.nu, material.model)
        contact = tuple(p for p in boundaries if p.role == "contact")
        pressure = ContactPressure(geo, u, contact, contact_degree) if contact else None
        self.memory, self.pressure = memory, pressure
        if memory is not None:
            sigma = sigma + memory.PM
        md = {"quadrature_degree": degree}
        dx, dS = ufl.dx(metadata=md), ufl.dS(metadata=md)

        div_term = None
        if u.function_space.ufl_element().degree() > 1 or body_force is not None:  # P1: div sigma_h = 0 in a cell
            R = ufl.div(sigma) if body_force is None else ufl.div(sigma) + body_force
            div_term = h**2 * ufl.inner(R, R) * v * dx
        jump = ufl.jump(sigma, n)
        interior = ufl.avg(h) * ufl.inner(jump, jump) * ufl.avg(v) * dS
        form = interior if div_term is None else interior + div_term

        # exterior facets: everywhere sigma n, then each tagged part replaces its share by its own residual
        traction = ufl.dot(sigma, n)
        form = form + h * ufl.inner(traction, traction) * v * ufl.ds(metadata=md)
        for part in boundaries:
            ds = geo.ds(geo.tags[part.name], metadata=md)
            form = form - h * ufl.inner(traction, traction) * v * ds
            if part.role == "traction":
                r = traction - tractions[part.name]
            elif part.role == "contact":
                # the discrete problem's pressure lambda_h: p(u_nu - g) itself is controlled only at the contact
                # term's points (p = r_+/mu, 1/mu ~ 1e10, anywhere else on a facet would count that as a residual)
                r = traction + pressure.pressure * n
            else:  # Dirichlet: no residual
                continue
            form = form + h * ufl.inner(r, r) * v * ds
        self.form = fem.form(form)
        self.vec = fpetsc.create_vector(self.form)
        n_cells = mesh.topology.index_map(mesh.topology.dim).size_local
        self.cell_dofs = V0.dofmap.list.array[:n_cells]  # one dof per cell (owned cells own their dof)

    def cells(self) -> np.ndarray:
        """η_K² of the owned cells, in the mesh's local cell order."""
        if self.memory is not None:
            self.memory.update()
        if self.pressure is not None:
            self.pressure.update()
        with self.vec.localForm() as local:
            local.set(0.0)
        fpetsc.assemble_vector(self.vec, self.form)
        self.vec.ghostUpdate(addv=PETSc.InsertMode.ADD, mode=PETSc.ScatterMode.REVERSE)
        return np.maximum(self.vec.array_r[self.cell_dofs], 0.0)

    def total(self, eta2: np.ndarray | None = None) -> float:
        """η = (Σ_K η_K²)^{1/2} over all ranks."""
        eta2 = self.cells() if eta2 is None else eta2
        return float(np.sqrt(self.geo.comm.allreduce(float(eta2.sum()), op=MPI.SUM)))


def estimator_for(model) -> ResidualEstimator:
    """The estimator of a built model's displacement problem (its tractions as the operators hold them)."""
    cfg = model.cfg
    ops = model.mech.ops
    tractions = {part.name: f for part, f in ops.tractions}
    degree = 2 * cfg.discretization.u_degree + 2
    body_force = ops.f0 if ops.body_force is not None else None
    memory = None
    if model.history is not None:
        memory = MemoryProjection(model.history.M, model.rule.dx, cfg.discretization.u_degree - 1)
    return ResidualEstimator(model.geo, model.u, cfg.material, cfg.boundaries, tractions, degree, body_force, memory,
                             ContactRule.of(cfg))


def dorfler(eta2: np.ndarray, theta: float, comm: MPI.Comm) -> np.ndarray:
    """Dörfler marking: the owned cells (a boolean mask) with the largest η_K² whose sum is at least
    θ Σ η_K², over all ranks (a global threshold found by bisection on the value)."""
    total = comm.allreduce(float(eta2.sum()), op=MPI.SUM)
    if total == 0.0:
        return np.zeros(len(eta2), dtype=bool)
    lo, hi = 0.0, comm.allreduce(float(eta2.max(initial=0.0)), op=MPI.MAX)
    for _ in range(60):  # the largest threshold whose cells above it carry theta of the total
        mid = 0.5 * (lo + hi)
        if comm.allreduce(float(eta2[eta2 >= mid].sum()), op=MPI.SUM) >= theta * total:
            lo = mid
        else:
            hi = mid
    return eta2 >= lo
