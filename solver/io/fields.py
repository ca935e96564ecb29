"""The fields a run writes for ParaView: u, zeta and cell-wise stresses (docs/model.md §5 for what the paper shows).

XDMF cannot hold quadrature functions, so the stresses sigma = A eps(u) + M and A eps(u)
are written as cell averages (the L2 projection onto piecewise constants), with their von
Mises values. ``output.fields`` chooses which are written; only what those need is
computed. The series itself is :class:`solver.io.xdmf.XDMFSeries`. P2 fields
(``discretization.u_degree`` or ``zeta_degree`` = 2) are written as their P1 interpolants on
the mesh, their exact values at the vertices: ParaView shows the vertex values the solver
computed and interpolates linearly in between.

The contact results ``contact_pressure`` (λ_h, the discrete problem's pressure), ``gap`` (g) and
``penetration`` (u_ν − g) are vertex fields of the whole mesh that are zero off Γ_C
(:class:`solver.physics.contact_traces.ContactTraces`): one mesh in the file, so ParaView shows them
over the deformed body with the rest. Scenes with contact also write Γ_C as a dataset of its own,
``contact.xdmf`` (:mod:`solver.io.contact_series`), whatever ``output.fields`` lists.

In plane strain the out-of-plane stress sigma_33 = lambda tr eps(u) + M_33 (docs/model.md
§2) is part of the stress: the von Mises values include it, and ``stress_zz`` /
``elastic_stress_zz`` write it (requested in ``output.fields``; plane strain only).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import ufl
from dolfinx import fem
from dolfinx.fem import petsc as fpetsc

from solver.config import MaterialConfig, OutputConfig
from solver.errors import OutputError, UsageError
from solver.io.contact_series import ContactSeries
from solver.io.xdmf import DolfinxRows, FieldSpec, RowMap, SeriesError, XDMFSeries, dolfinx_layout, tensor6, vector3
from solver.physics.material import lame, strain, von_mises_array

KINDS = {"displacement": ("Node", "Vector"), "damage": ("Node", "Scalar"), "stress": ("Cell", "Tensor6"),
         "elastic_stress": ("Cell", "Tensor6"), "von_mises": ("Cell", "Scalar"), "von_mises_elastic": ("Cell", "Scalar"),
         "stress_zz": ("Cell", "Scalar"), "elastic_stress_zz": ("Cell", "Scalar"), "contact_pressure": ("Node", "Scalar"),
         "gap": ("Node", "Scalar"), "penetration": ("Node", "Scalar")}
CONTACT_FIELDS = ("contact_pressure", "gap", "penetration")
PLANE_STRAIN_ONLY = ("stress_zz", "elastic_stress_zz")


class CellStresses:
    """Cell averages of A eps(u) and of sigma = A eps(u) + M on the owned cells, with nothing assembled per level.

    For P1 displacements eps(u) is constant on each cell: its independent components are read
    from the memory source's kept strain at the cell's first point (:meth:`strain`), or are one
    sparse product B u with B assembled once (rows scaled by 1/|K|; 12 entries per triangle),
    and A eps = lambda tr(eps) I + 2 mu eps follows per cell. The memory M lives at the points
    of the quadrature rule that integrates it everywhere else; on affine cells its L2
    projection onto constants with that rule is the weighted mean of its point values. Rows
    are in the local order of the owned cells (that of :func:`solver.io.xdmf.dolfinx_layout`).
    In plane strain, sigma_33 = lambda tr eps(u) + M_33 per cell as well (:meth:`out_of_plane`).
    """

    def __init__(self, model, material: MaterialConfig) -> None:
        mesh = model.geo.mesh
        self.d = d = mesh.geometry.dim
        self.u, self.history = model.u, model.history
        self.lame_lambda, self.lame_mu = lame(material.E, material.nu, material.model)
        self.plane_strain = material.model == "plane_strain" and d == 2
        self._trace: np.ndarray | None = None
        self.pairs = [(i, i) for i in range(d)] + ([(0, 1)] if d == 2 else [(0, 1), (1, 2), (0, 2)])
        E0 = fem.VectorFunctionSpace(mesh, ("DG", 0), dim=len(self.pairs))
        eps = strain(ufl.TrialFunction(model.u.function_space))
        components = ufl.as_vector([eps[i, j] for i, j in self.pairs])
        self.strain_components = fpetsc.assemble_matrix(fem.form(ufl.inner(components, ufl.TestFunction(E0)) * ufl.dx))
        self.strain_components.assemble()
        S0 = fem.FunctionSpace(mesh, ("DG", 0))
        vol = fpetsc.assemble_vector(fem.form(ufl.TestFunction(S0) * ufl.dx))  # local cell volumes, no sharing
        scale = self.strain_components.createVecLeft()
        n_dofs = E0.dofmap.index_map.size_local
        scale.array[:] = np.repeat(1.0 / vol.array_r[:n_dofs], len(self.pairs))
        self.strain_components.diagonalScale(L=scale)
        self.out = self.strain_components.createVecLeft()
        imap = mesh.topology.index_map(mesh.topology.dim)
        n_cells, n_all = imap.size_local, imap.size_local + imap.num_ghosts
        self.cells = RowMap(E0.dofmap.list.array.reshape(n_all, -1)[:n_cells, 0], len(self.pairs))  # one dof per cell
        if self.history is not None:
            rule = model.rule
            npts = len(rule.weights)
            self.npts = npts
            self.points = RowMap(self.history.M.function_space.dofmap.list.array.reshape(n_all, npts)[:n_cells], d * d)
            self.q_weights = (rule.weights / rule.weights.sum())[None, :, None]
            if self.plane_strain:  # M_33 is a scalar at the same points
                self.points_zz = RowMap(self.history.M33.function_space.dofmap.list.array.reshape(n_all, npts)[:n_cells], 1)
        self._kept = None  # (components, points): where the source's kept strain holds each owned cell's components
        source = self.history.H if self.history is not None else None
        if (model.u.function_space.ufl_element().degree() == 1 and hasattr(source, "kept_strain")
                and getattr(source, "Q", None) is self.history.M.function_space):
            q = self.history.M.function_space.dofmap.list.array.reshape(n_all, self.npts)[:n_cells, 0]
            order = [source.pairs.index(p) for p in self.pairs]  # the same components, 3-D off-diagonals reordered
            self._kept = (np.asarray(order)[:, None], np.asarray(q, dtype=np.intp)[None, :])

    def strain(self) -> np.ndarray:
        """The independent strain components of u per owned cell, (cells, components) in ``pairs``' order.

        For P1 displacements eps(u) is constant on each cell: when the memory source has kept u's strain at its
        points (the level's strain norm computed it), it is read from there at each cell's first point, with no
        product (that product was a third of a written level's time: docs/benchmarks/speed.md); else B u."""
        if self._kept is not None:
            eps = self.history.H.kept_strain()
            if eps is not None:
                return eps[self._kept[0], self._kept[1]].T
        self.strain_components.mult(self.u.vector, self.out)
        return self.cells.take(self.out.array_r)

    def elastic(self) -> np.ndarray:
        """A eps(u) per owned cell, rows of d*d (row-major)."""
        e = self.strain()
        d = self.d
        s = np.empty((len(e), d, d))
        trace = e[:, 0] + e[:, 1] if d == 2 else e[:, 0] + e[:, 1] + e[:, 2]  # sum(axis=1) bit for bit, faster
        self._trace = trace
        for k, (i, j) in enumerate(self.pairs):
            if i == j:
                s[:, i, i] = 2.0 * self.lame_mu * e[:, k] + self.lame_lambda * trace
            else:
                s[:, i, j] = s[:, j, i] = 2.0 * self.lame_mu * e[:, k]
        return s.reshape(len(e), d * d)

    def total(self, elastic: np.ndarray) -> np.ndarray:
        """sigma = A eps(u) + (cell average of M), given A eps(u)."""
        if self.history is None:
            return elastic
        return elastic + self._cell_average(self.history.M.x.array, self.history.H, self.points, self.d * self.d)

    def out_of_plane(self) -> tuple[np.ndarray, np.ndarray]:
        """(sigma_33, (A eps)_33) per owned cell in plane strain, after :meth:`elastic`: eps_33 = 0, so
        (A eps)_33 = lambda tr eps(u), and sigma_33 adds the cell average of the memory's M_33."""
        elastic = self.lame_lambda * self._trace
        if self.history is None:
            return elastic, elastic
        zz = self.history.out_of_plane
        return elastic + self._cell_average(zz.M.x.array, zz.H, self.points_zz, 1)[:, 0], elastic

    def _cell_average(self, memory: np.ndarray, source, points: RowMap, width: int) -> np.ndarray:
        """Cell averages of a memory tensor at the rule's points (rows of ``width``)."""
        weight = self.history.current_weight
        if weight is not None and float(weight.value) != 0.0:
            # the implicit trapezoid keeps the past in M; sigma_n also holds its current term (k/2) g(0) H(u_n, zeta_n)
            memory = memory + float(weight.value) * source()
        M = points.take(memory)
        if self.npts == 1:  # one point per cell: the average is the value
            return M
        return (M.reshape(-1, self.npts, width) * self.q_weights).sum(axis=1)


class Outputs:
    """Owns the written fields and the XDMF series of a run (``outdir`` None: nothing is written).

    ``keep_until`` (a restart) keeps the levels already written up to that time and appends after them.
    """

    def __init__(self, model, material: MaterialConfig, output: OutputConfig, outdir: Path | None,
                 keep_until: float | None = None) -> None:
        mesh = model.geo.mesh
        self.d = mesh.geometry.dim
        self.series = None
        self.contact = None  # contact.xdmf: Γ_C's own dataset (scenes with contact)
        plane_strain = material.model == "plane_strain" and self.d == 2
        traces = model.mech.diagnostics.traces
        self.names = [f for f in output.fields if (f != "damage" or model.damage is not None)
                      and (f not in PLANE_STRAIN_ONLY or plane_strain) and (f not in CONTACT_FIELDS or traces)]
        if outdir is None:
            return
        if traces is not None:
            self.contact = self._open(lambda: ContactSeries(outdir, model.geo, traces, _vertex_values(model.u),
                                                            output.precision, keep_until), keep_until)
        if not self.names:
            return
        self.model = model
        self.rows = DolfinxRows(mesh)
        self._node_fields = {"displacement": _vertex_values(model.u)}
        if model.damage is not None:
            self._node_fields["damage"] = _vertex_values(model.damage.zeta)
        if traces is not None:  # updated by the level's diagnostics
            for name in CONTACT_FIELDS:
                self._node_fields[name] = _vertex_values(getattr(traces, "pressure" if name == "contact_pressure" else name))
        self.stresses = (CellStresses(model, material) if set(self.names) - {"displacement", "damage", *CONTACT_FIELDS}
                         else None)
        specs = [FieldSpec(name, *KINDS[name]) for name in self.names]
        self.series = self._open(lambda: XDMFSeries(outdir, dolfinx_layout(mesh), specs, output.precision, keep_until),
                                 keep_until)

    @staticmethod
    def _open(make, keep_until: float | None):
        """A series made by ``make``; its failure as a UsageError (a restart that cannot continue it) or OutputError."""
        try:
            return make()
        except SeriesError as exc:
            raise (UsageError(f"--restart: {exc}") if keep_until is not None else OutputError(str(exc))) from None

    def _series(self) -> list:
        return [s for s in (self.series, self.contact) if s is not None]

    def cell_fields(self) -> dict[str, np.ndarray]:
        """The chosen cell fields on the owned cells: stresses as d*d rows, von Mises values."""
        want, out = set(self.names), {}
        if self.stresses is None:
            return out
        elastic = self.stresses.elastic()
        if want & {"stress", "von_mises"}:
            out["stress"] = self.stresses.total(elastic)
        out["elastic_stress"] = elastic
        zz = {"stress": None, "elastic_stress": None}
        if self.stresses.plane_strain:
            zz["stress"], zz["elastic_stress"] = self.stresses.out_of_plane()
            out["stress_zz"], out["elastic_stress_zz"] = zz["stress"], zz["elastic_stress"]
        for tensor, scalar in (("stress", "von_mises"), ("elastic_stress", "von_mises_elastic")):
            if scalar in want:
                out[scalar] = von_mises_array(out[tensor], self.d, zz[tensor])
        return out

    def write(self, t: float) -> None:
        """Write level t (no-op without a series); a failed write raises OutputError (everything before it stays)."""
        if self.contact is not None:
            try:
                self.contact.write(t)
            except SeriesError as exc:
                raise OutputError(str(exc), exc.t) from None
        if self.series is None:
            return
        cells = self.cell_fields()
        values = {}
        for name in self.names:
            if name == "displacement":
                values[name] = vector3(self.rows.rows(self._node_fields[name]()))
            elif name == "damage" or name in CONTACT_FIELDS:
                values[name] = self.rows.rows(self._node_fields[name]())
            else:
                values[name] = (tensor6(cells[name], self.d, cells.get(name + "_zz")) if name in ("stress", "elastic_stress")
                                else cells[name])
        try:
            self.series.write(t, values)
        except SeriesError as exc:
            raise OutputError(str(exc), exc.t) from None

    def flush(self) -> None:
        """List every level written so far in the series (before a checkpoint); raise a failed write's OutputError."""
        for series in self._series():
            try:
                series.flush()
            except SeriesError as exc:
                raise OutputError(str(exc), exc.t) from None

    def close(self, quiet: bool = False) -> None:
        """Finish the series; ``quiet``: a failure is not raised (another one is already on its way)."""
        failure = None
        for series in self._series():
            try:
                series.close()
            except SeriesError as exc:
                failure = failure or exc
        if failure is not None and not quiet:
            raise OutputError(str(failure), failure.t) from None


def _vertex_values(f: fem.Function):
    """A callable giving f itself if P1, else a P1 function holding f's values at the vertices (updated per call)."""
    if f.function_space.ufl_element().degree() == 1:
        return lambda: f
    el = f.function_space.ufl_element()
    mesh = f.function_space.mesh
    V1 = (fem.VectorFunctionSpace(mesh, ("CG", 1), dim=el.value_shape()[0]) if el.value_shape()
          else fem.FunctionSpace(mesh, ("CG", 1)))
    out = fem.Function(V1, name=f.name)

    def update() -> fem.Function:
        out.interpolate(f)
        return out

    return update
