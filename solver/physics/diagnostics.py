"""Per-level diagnostics of the displacement: contact force and zone, penetration, the peak of the contact
pressure (:class:`contact_traces.ContactTraces`) and where it sits, ||eps(u)||, reactions.

Functionals of the contact term are integrated with the same facet rule as the term
itself; ||eps(u)||_L2 from the strain at the memory points where the scene has memory (that
strain is the next commit's, so the norm is one pass over the points), else sqrt(u . G u) with
the strain Gram matrix G assembled once.
"""

from __future__ import annotations

import logging
from collections.abc import Callable

import numpy as np
import ufl
from dolfinx import fem, la
from dolfinx.fem import petsc as fpetsc
from dolfinx.mesh import meshtags
from mpi4py import MPI
from petsc4py import PETSc

from solver.config import BoundaryConfig
from solver.config.boundary import AXES
from solver.mesh.geometry import Geometry
from solver.physics import contact
from solver.physics.contact_points import ContactPoints
from solver.physics.contact_traces import ContactTraces
from solver.physics.displacement import DisplacementProblem
from solver.physics.gap import ReachableError, segment_errors
from solver.physics.material import strain
from solver.physics.operators import Operators
from solver.physics.quadrature import ContactRule


def dirichlet_rows_form(ops: Operators, constrained: np.ndarray) -> fem.Form:
    """The bulk form sigma(du) : eps(w) over the cells that hold a Dirichlet dof on any rank (``constrained``: the
    owned ones, unrolled local indices). Its matrix has K_full's Dirichlet rows whole and nothing far from them,
    a few per cent of K's nonzeros (docs/developer/design-notes.md)."""
    V = ops.du.ufl_function_space()
    mesh = V.mesh
    tdim = mesh.topology.dim
    bs = V.dofmap.index_map_bs
    marker = la.create_petsc_vector(V.dofmap.index_map, bs)  # 1 on the constrained dofs, ghosts included
    with marker.localForm() as m:
        m.array[constrained] = 1.0
    marker.ghostUpdate(addv=PETSc.InsertMode.INSERT, mode=PETSc.ScatterMode.FORWARD)
    with marker.localForm() as m:
        at_node = m.array.reshape(-1, bs).any(axis=1)
    marker.destroy()
    owned = mesh.topology.index_map(tdim).size_local
    cell_nodes = V.dofmap.list.array.reshape(-1, V.dofmap.dof_layout.num_dofs)[:owned]
    cells = np.flatnonzero(at_node[cell_nodes].any(axis=1)).astype(np.int32)
    tags = meshtags(mesh, tdim, cells, np.ones(len(cells), dtype=np.int32))
    return fem.form(ops.stress_work * ufl.Measure("dx", domain=mesh, subdomain_data=tags)(1))


class Reactions:
    """The force each Dirichlet part exerts on the body to hold it, per prescribed component.

    R = K_full u + j(u) + B M_n (+ the trapezoid's implicit memory term) - (f_n, w): the residual
    with no Dirichlet row replaced, so on a Dirichlet dof it is the force the support must add
    for equilibrium. Summed over the dofs the part carries (:class:`operators.Dirichlet`). Only
    K_full's Dirichlet rows are needed: they are assembled over the cells that touch a Dirichlet
    dof alone and kept, so neither the set-up nor the product pays for the rest of K.
    """

    def __init__(self, problem: DisplacementProblem) -> None:
        self.problem = problem
        self.comm = problem.u.function_space.mesh.comm
        ops = problem.ops
        self.dirichlet = ops.dirichlet
        self.columns = self.dirichlet.columns
        self._K: PETSc.Mat | None = None  # K_full's Dirichlet rows, assembled at the first use (:attr:`K`)
        self.contact_form = problem.contact.residual_form if problem.contact is not None else None

    @property
    def K(self) -> PETSc.Mat:
        """K_full's Dirichlet rows (local row j is the owned dof constrained[j]), from the cells at those dofs; made
        at the first use, not at the build (a model solved once without a row does not pay for them). Collective."""
        if self._K is None:
            self._rows()
        return self._K

    def _rows(self) -> None:
        ops = self.problem.ops
        constrained = self.dirichlet.constrained
        K = fpetsc.assemble_matrix(dirichlet_rows_form(ops, constrained))  # no Dirichlet rows or columns removed
        K.assemble()
        start, end = K.getOwnershipRange()
        rows = PETSc.IS().createGeneral((constrained + start).astype(PETSc.IntType), comm=self.comm)
        cols = PETSc.IS().createStride(end - start, start, 1, comm=self.comm)
        self._K = K.createSubMatrix(rows, cols)
        K.destroy()
        self.Ku = self._K.createVecLeft()
        self.position = {key: np.searchsorted(constrained, dofs) for key, dofs in self.dirichlet.dofs.items()}
        self.R = ops.b.duplicate()

    def row(self) -> dict[str, float]:
        K = self.K
        ops, R = self.problem.ops, self.R
        with R.localForm() as r:
            r.set(0.0)
        for form in (self.contact_form, self.problem.Fm):
            if form is not None:
                fpetsc.assemble_vector(R, form)
        R.ghostUpdate(addv=PETSc.InsertMode.ADD, mode=PETSc.ScatterMode.REVERSE)
        if ops.memory_force is not None:
            R.axpy(1.0, ops.memory_force)
        R.axpy(-1.0, ops.loads)
        K.mult(self.problem.u.vector, self.Ku)
        values, Ku = R.array_r, self.Ku.array_r
        local = np.array([values[dofs].sum() + Ku[self.position[key]].sum() for key, dofs in self.dirichlet.dofs.items()])
        total = self.comm.allreduce(local, op=MPI.SUM) if len(local) else local
        return dict(zip(self.dirichlet.dofs, (float(v) for v in total)))


ZONE = 1e-3  # the pressure above this fraction of the peak: the contact zone, as the gap table warning judges it


class DisplacementDiagnostics:
    """What the time series reports about u at each level (all values the same on every rank)."""

    def __init__(self, geo: Geometry, u: fem.Function, parts: tuple[BoundaryConfig, ...], degree: int | ContactRule,
                 points: ContactPoints | None, reactions: Reactions | None = None,
                 strain_norm: Callable[[], float] | None = None, pressure_floor: float = 0.0) -> None:
        self.geo, self.u, self.points, self.reactions = geo, u, points, reactions
        self._point_norm = strain_norm  # ||eps(u)|| at the memory points (memory.PointStrainNorm), if exact there
        self.has_contact = bool(parts)
        self.force_form = fem.form(contact.force(u, geo, parts, degree)) if parts else None
        self.length_form = fem.form(contact.active_length(u, geo, parts, degree)) if parts else None
        self.parts, self._degree, self._floor = parts, degree, pressure_floor
        self._traces: ContactTraces | None = None
        self._warned = False
        self._tables: dict[str, ReachableError] | None = None
        self.peak_columns = ("peak_pressure",) + tuple(f"peak_pressure_{a}" for a in "xyz"[: geo.dim]) if parts else ()
        self._gram = None

    # the traces and the Gram matrix are made at their first use, not at the build: a model solved once and
    # never asked for a row (the accuracy planner's t = 0 solves) does not pay for them
    @property
    def traces(self) -> ContactTraces | None:
        """The contact traces on Γ_C (None without contact), made at the first use."""
        if self._traces is None and self.parts:
            self._traces = ContactTraces(self.geo, self.u, self.parts, self._degree, self._floor)
        return self._traces

    @property
    def gram(self) -> PETSc.Mat:
        """(eps(du), eps(w)), the strain norm's matrix, assembled at the first use."""
        if self._gram is None:
            V = self.u.function_space
            du, w = ufl.TrialFunction(V), ufl.TestFunction(V)
            self._gram = fpetsc.assemble_matrix(fem.form(ufl.inner(strain(du), strain(w)) * ufl.dx))
            self._gram.assemble()
            self._work = self._gram.createVecLeft()
        return self._gram

    @property
    def tables(self) -> dict[str, ReachableError]:
        """The linear gap tables the contact can reach (made once, not per level)."""
        if self._tables is None:
            self._tables = _reachable_tables(self.traces, self.parts) if self.parts else {}
        return self._tables

    def _integral(self, form) -> float:
        return 0.0 if form is None else self.geo.comm.allreduce(fem.assemble_scalar(form), op=MPI.SUM)

    def contact_force(self) -> float:
        """Total normal contact force int p(u_nu - g) ds."""
        return self._integral(self.force_form)

    def contact_length(self) -> float:
        """Length (area) of the zone where u_nu > g, at the facet quadrature points."""
        return self._integral(self.length_form)

    def max_penetration(self) -> float:
        """Largest u_nu - g: over the contact quadrature points in 2-D; in 3-D the largest penetration of the contact
        profile (the traces' recovery from those points, :meth:`ContactTraces.max_penetration`); 0 without contact."""
        if self.points is not None:
            return self.points.max_penetration(self.u.x.array)
        if self.traces is not None:
            return self.traces.max_penetration()
        return 0.0

    def strain_norm(self) -> float:
        """||eps(u)||_L2: at the memory points where given, else sqrt(u . G u)."""
        if self._point_norm is not None:
            return self._point_norm()
        gram = self.gram
        gram.mult(self.u.vector, self._work)
        return float(np.sqrt(max(self._work.dot(self.u.vector), 0.0)))

    @property
    def columns(self) -> tuple[str, ...]:
        """The peak pressure and the reaction columns (the fixed ones are io.CSV_COLUMNS)."""
        return self.peak_columns + (self.reactions.columns if self.reactions is not None else ())

    def peak(self) -> dict[str, float]:
        """The largest contact pressure over Γ_C and its point (the traces as :meth:`row` updated them)."""
        value, x = self.traces.peak()
        if not self._warned and value > 0 and self.tables:
            self._warned = _warn_coarse_tables(self.parts, self._zone_errors(value), value)
        return dict(zip(self.peak_columns, (value, *(float(c) for c in x[: self.geo.dim]))))

    def _zone_errors(self, peak: float) -> dict[str, float]:
        """Per linear gap table: its largest interpolation error where the body is in contact at this level: over the
        segments within the part's extent whose lower gap is at most the largest gap under the contact zone.

        The zone is the trace nodes where the reported pressure > ZONE × the peak: a vertex's pressure is the mean
        over its facets' quadrature points, so the zone found reaches one node beyond the true one (on the safe
        side); u_ν − g at the nodes is no signal (it is the table's own chord error, of either sign)."""
        traces = self.traces
        out = {}
        for part in self.parts:
            if part.name not in self.tables:
                out[part.name] = 0.0
                continue
            dofs = traces.part_dofs[part.name]
            g = traces.gap.x.array[dofs[traces.pressure.x.array[dofs] > ZONE * peak]]
            reach = self.geo.comm.allreduce(float(g.max()) if len(g) else -np.inf, op=MPI.MAX)
            out[part.name] = self.tables[part.name].up_to(reach)
        return out

    def row(self) -> dict[str, float]:
        if self.traces is not None:
            self.traces.update()  # pressure, u_ν, penetration: one boundary assembly
        out = {"contact_force": self.contact_force(), "contact_length": self.contact_length(),
               "max_penetration": self.max_penetration(), "strain_norm": self.strain_norm()}
        if self.traces is not None:
            out.update(self.peak())
        if self.reactions is not None:
            out.update(self.reactions.row())
        return out


def allowed_penetration(part: BoundaryConfig, pressure: float) -> float:
    """The penetration r at which the part's law reaches ``pressure`` (p(r) = pressure; linear: mu p)."""
    return part.contact_law.inverse(pressure)


def _reachable_tables(traces: ContactTraces, parts: tuple[BoundaryConfig, ...]) -> dict[str, ReachableError]:
    """Per linear gap table: its segments' errors within the part's extent along the table's coordinate (the extent
    of the part's trace nodes, the same on every rank)."""
    out = {}
    for part in parts:
        if not len(segment_errors(part)[0]):
            continue
        x = traces.x[traces.part_dofs[part.name], AXES.index(part.gap_coordinate)]
        lo = traces.comm.allreduce(float(x.min()) if len(x) else np.inf, op=MPI.MIN)
        hi = traces.comm.allreduce(float(x.max()) if len(x) else -np.inf, op=MPI.MAX)
        out[part.name] = ReachableError(part, lo, hi)
    return out


def _warn_coarse_tables(parts: tuple[BoundaryConfig, ...], errors: dict[str, float], pressure: float) -> bool:
    """One line per linear gap table whose interpolation error (where the body can be in contact) exceeds the
    penetration the law allows at the peak pressure: the body then follows the table's kinks (docs/contact.md).
    Whether it warned."""
    warned = False
    for part in parts:
        err, allowed = errors[part.name], allowed_penetration(part, pressure)
        if err > allowed:
            warned = True
            logging.getLogger("solver").warning(
                "warning: boundary.%s: the gap table's interpolation error (~%.2g) is %.0f times the penetration "
                "its law allows at the peak pressure %.3g (%.2g): the pressure will follow the table's kinks; "
                "sample it finer or set gap_interpolation = \"cubic\"", part.name, err, err / allowed, pressure,
                allowed)
    return warned


class DamageDiagnostics:
    """Range and L2 norm of zeta at each level (a constant zeta0 when the scene has no damage)."""

    def __init__(self, mesh, damage, zeta0: float) -> None:
        self.comm = mesh.comm
        self.zeta = damage.zeta if damage is not None else None
        self.zeta0 = zeta0
        if self.zeta is not None:  # ||zeta||^2 = zeta . M zeta, with the mass matrix assembled once
            Z = self.zeta.function_space
            z, xi = ufl.TrialFunction(Z), ufl.TestFunction(Z)
            self.mass = fpetsc.assemble_matrix(fem.form(z * xi * ufl.dx))
            self.mass.assemble()
            self._work = self.mass.createVecLeft()
        else:
            area = self.comm.allreduce(fem.assemble_scalar(fem.form(1.0 * ufl.dx(domain=mesh))), op=MPI.SUM)
            self._constant_norm = zeta0 * float(np.sqrt(area))

    def zeta_range(self) -> tuple[float, float]:
        if self.zeta is None:
            return self.zeta0, self.zeta0
        n = self.zeta.function_space.dofmap.index_map.size_local
        a = self.zeta.x.array[:n]
        return (self.comm.allreduce(float(a.min()) if n else np.inf, op=MPI.MIN),
                self.comm.allreduce(float(a.max()) if n else -np.inf, op=MPI.MAX))

    def zeta_norm(self) -> float:
        if self.zeta is None:
            return self._constant_norm
        self.mass.mult(self.zeta.vector, self._work)
        return float(np.sqrt(max(self._work.dot(self.zeta.vector), 0.0)))
