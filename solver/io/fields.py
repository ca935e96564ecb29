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
from dolfinx import fem

from solver.config import MaterialConfig, OutputConfig
from solver.errors import OutputError, UsageError
from solver.io.contact_series import ContactSeries
from solver.io.xdmf import DolfinxRows, FieldSpec, SeriesError, Vector3, XDMFSeries, dolfinx_layout, tensor6
from solver.laws.memory import pairs
from solver.physics.material import lame, von_mises_array
from solver.physics.memory_source import StrainMap, strain_table

KINDS = {"displacement": ("Node", "Vector"), "damage": ("Node", "Scalar"), "stress": ("Cell", "Tensor6"),
         "elastic_stress": ("Cell", "Tensor6"), "von_mises": ("Cell", "Scalar"), "von_mises_elastic": ("Cell", "Scalar"),
         "stress_zz": ("Cell", "Scalar"), "elastic_stress_zz": ("Cell", "Scalar"), "contact_pressure": ("Node", "Scalar"),
         "gap": ("Node", "Scalar"), "penetration": ("Node", "Scalar")}
CONTACT_FIELDS = ("contact_pressure", "gap", "penetration")
PLANE_STRAIN_ONLY = ("stress_zz", "elastic_stress_zz")


class CellStresses:
    """Cell averages of A eps(u) and of sigma = A eps(u) + M on the owned cells, with nothing assembled per level.

    eps(u) is linear in u: its independent components at points of each cell come from a table of the scalar
    basis gradients (:class:`solver.physics.memory_source.StrainMap`, 12 doubles per P1 tetrahedron, where the
    assembled matrix of cell averages held 72 entries of 12 bytes). With memory the history's own source gives
    them at its rule's points (the strain of u_n it keeps for the next commit: no product and no table of the
    writer's own); without, a table at the cells' centroids. The cell average is the rule's weighted mean of the
    point values, exact for a P1 or P2 u on affine cells (eps is then constant or linear in a cell), and
    A eps = lambda tr(eps) I + 2 mu eps follows per cell. The memory M lives at the same points: on affine cells
    its L2 projection onto constants with that rule is the weighted mean of its point values. Rows are in the local
    order of the owned cells (that of :func:`solver.io.xdmf.dolfinx_layout`). In plane strain,
    sigma_33 = lambda tr eps(u) + M_33 per cell as well (:meth:`out_of_plane`).
    """

    def __init__(self, model, material: MaterialConfig) -> None:
        mesh = model.geo.mesh
        self.d = d = mesh.geometry.dim
        self.u, self.history = model.u, model.history
        self.lame_lambda, self.lame_mu = lame(material.E, material.nu, material.model)
        self.plane_strain = material.model == "plane_strain" and d == 2
        self._trace: np.ndarray | None = None
        self.pairs = pairs(d)  # xx, yy[, zz], then xy[, yz, xz]: the sources' order
        imap = mesh.topology.index_map(mesh.topology.dim)
        n_cells, n_all = imap.size_local, imap.size_local + imap.num_ghosts
        if self.history is not None:
            rule = model.rule
            npts = len(rule.weights)
            self.npts = npts
            self.q_weights = (rule.weights / rule.weights.sum())[None, :, None]
            dofmap = self.history.M.function_space.dofmap.list.array.reshape(n_all, npts)
            self._strain_points = dofmap[:n_cells]  # (owned cell, point) -> the rule's point (M's and the source's)
            self._strain = self.history.H.strain
            if self.plane_strain:  # M_33 is a scalar at the same points
                self._points_zz = self.history.M33.function_space.dofmap.list.array.reshape(n_all, npts)[:n_cells]
        else:
            E = _centroid_strains(model.u, n_cells)
            self._strain_points = np.arange(n_cells)[:, None]
            self._strain = lambda: (E @ self.u.x.array).reshape(len(self.pairs), -1)
        self.n_cells = n_cells
        # one point per cell, the cells' own in order (P1, a one-point rule, serial or not): blocks of the arrays are
        # slices, no gathers
        self._in_order = self._strain_points.shape[1] == 1 and np.array_equal(self._strain_points[:, 0],
                                                                                np.arange(n_cells))
        self._eps = self._memory = self._memory_zz = None
        self._scratch: np.ndarray | None = None  # von_mises_plane's work arrays (a block's cells)

    def prepare(self) -> None:
        """Read the level: eps(u) at the points (the source's kept array, read only) and the memory tensors.
        :meth:`elastic` over all cells calls it; blocks of cells (``rows``) need it first."""
        self._eps = self._strain()
        if self.history is None:
            return
        weight = self.history.current_weight
        w = float(weight.value) if weight is not None else 0.0
        # the implicit trapezoid keeps the past in M; sigma_n also holds its current term (k/2) g(0) H(u_n, zeta_n)
        self._memory = self.history.M.x.array if w == 0.0 else self.history.M.x.array + w * self.history.H()
        if self.plane_strain:
            zz = self.history.out_of_plane
            self._memory_zz = zz.M.x.array if w == 0.0 else zz.M.x.array + w * zz.H()

    def release(self) -> None:
        """Drop what :meth:`prepare` read: the level's strain (the source's kept array, replaced by the next level's:
        held here beside it, two strains would be alive at each level's end) and the memory tensors."""
        self._eps = self._memory = self._memory_zz = self._trace = None

    def elastic(self, rows: slice | None = None) -> np.ndarray:
        """A eps(u) per owned cell (``rows``: a block of them, after :meth:`prepare`), rows of d*d (row-major)."""
        if rows is None:
            self.prepare()
            rows = slice(None)
        e = self._strains(rows)
        d = self.d
        s = np.empty((e.shape[1], d, d))
        trace = e[:d].sum(axis=0)
        self._trace = trace
        for k, (i, j) in enumerate(self.pairs):
            if i == j:
                s[:, i, i] = 2.0 * self.lame_mu * e[k] + self.lame_lambda * trace
            else:
                s[:, i, j] = s[:, j, i] = 2.0 * self.lame_mu * e[k]
        return s.reshape(len(s), d * d)

    def _strains(self, rows: slice) -> np.ndarray:
        """eps(u)'s independent components averaged over each cell of ``rows``: (component, cell)."""
        eps = self._eps
        if self._in_order:
            return eps[:, : self.n_cells][:, rows]
        points = self._strain_points[rows]
        if points.shape[1] == 1:
            return np.take(eps, points[:, 0], axis=1)
        return (eps[:, points] * self.q_weights[:, :, 0]).sum(axis=2)

    def von_mises_plane(self, rows: slice, out: tuple[np.ndarray, np.ndarray] | None = None
                        ) -> tuple[np.ndarray, np.ndarray]:
        """(von Mises of sigma, of A eps(u)) per cell of ``rows`` in plane stress (2-D, after :meth:`prepare`), from
        the components: the values of :func:`von_mises_array` of :meth:`total` and :meth:`elastic`, the same
        operations on the same numbers, without the d x d tensors. ``out``: the two arrays to fill (else new ones).
        The operations run in place, in work arrays kept between levels (no temporaries a level)."""
        e = self._strains(rows)
        m = e.shape[1]
        if self._scratch is None or self._scratch.shape[1] != m:
            self._scratch = np.empty((4, m))
        a, b, c, tmp = self._scratch
        vm, elastic = (np.empty(m), np.empty(m)) if out is None else out
        two_mu, lam = 2.0 * self.lame_mu, self.lame_lambda
        np.add(e[0], e[1], out=c)  # the trace e[:2].sum(axis=0): e[0] + e[1]
        np.multiply(lam, c, out=tmp)
        np.multiply(two_mu, e[0], out=a)
        a += tmp
        np.multiply(two_mu, e[1], out=b)
        b += tmp
        np.multiply(two_mu, e[2], out=c)
        _plane_von_mises(a, b, c, tmp, elastic)
        if self.history is None:
            if out is not None:
                vm[...] = elastic
                return vm, elastic
            return elastic, elastic
        mem = self._cell_average(self._memory, self._strain_points, 4, rows)  # rows of xx, xy, yx, yy
        a += mem[:, 0]
        b += mem[:, 3]
        c += mem[:, 1]
        return _plane_von_mises(a, b, c, tmp, vm), elastic

    def total(self, elastic: np.ndarray, rows: slice | None = None) -> np.ndarray:
        """sigma = A eps(u) + (cell average of M), given A eps(u) of the same cells."""
        if self.history is None:
            return elastic
        return elastic + self._cell_average(self._memory, self._strain_points, self.d * self.d, rows)

    def out_of_plane(self, rows: slice | None = None) -> tuple[np.ndarray, np.ndarray]:
        """(sigma_33, (A eps)_33) per owned cell in plane strain, after :meth:`elastic` of the same cells: eps_33 = 0,
        so (A eps)_33 = lambda tr eps(u), and sigma_33 adds the cell average of the memory's M_33."""
        elastic = self.lame_lambda * self._trace
        if self.history is None:
            return elastic, elastic
        return elastic + self._cell_average(self._memory_zz, self._points_zz, 1, rows)[:, 0], elastic

    def _cell_average(self, memory: np.ndarray, points: np.ndarray, width: int, rows: slice | None) -> np.ndarray:
        """Cell averages of a memory tensor at the rule's points (rows of ``width``)."""
        if self._in_order:
            return memory.reshape(-1, width)[: self.n_cells][slice(None) if rows is None else rows]
        points = points[slice(None) if rows is None else rows]
        M = np.take(memory.reshape(-1, width), points.ravel(), axis=0)
        if self.npts == 1:  # one point per cell: the average is the value
            return M
        return (M.reshape(-1, self.npts, width) * self.q_weights).sum(axis=1)


class Outputs:
    """Owns the written fields and the XDMF series of a run (``outdir`` None: nothing is written).

    ``keep_until`` (a restart) keeps the levels already written up to that time and appends after them.
    """

    BLOCK = 65536  # cells a block of the cell fields: 5 MB of each of its temporaries in 3-D

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
        self._vector3 = Vector3()  # the displacement's rows padded to 3 components, in an array kept between levels
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
        """The chosen cell fields on the owned cells: stresses as d*d rows, von Mises values (and sigma_33 beside a
        plane-strain tensor). Computed in blocks of ``BLOCK`` cells: only the written arrays are whole."""
        want, out = set(self.names), {}
        if self.stresses is None:
            return out
        st = self.stresses
        n, d = st.n_cells, self.d
        tensors = [f for f in ("stress", "elastic_stress") if f in want]
        for name in want & {"von_mises", "von_mises_elastic", "stress_zz", "elastic_stress_zz"}:
            out[name] = np.empty(n)
        for name in tensors:
            out[name] = np.empty((n, d * d))
            if st.plane_strain:
                out[name + "_zz"] = np.empty(n)
        st.prepare()
        try:
            self._cell_blocks(st, out, tensors, want)
        finally:
            st.release()
        return out

    def _cell_blocks(self, st: CellStresses, out: dict[str, np.ndarray], tensors: list[str], want: set[str]) -> None:
        """Fill ``out`` block by block (after ``st.prepare()``)."""
        n, d = st.n_cells, self.d
        plane = d == 2 and not st.plane_strain and not tensors and want & {"von_mises", "von_mises_elastic"}
        for start in range(0, n, self.BLOCK):
            rows = slice(start, min(start + self.BLOCK, n))
            if plane:  # the von Mises values alone, from the components, into the written arrays
                sigma, elastic = (out[name][rows] if name in out else np.empty(rows.stop - rows.start)
                                  for name in ("von_mises", "von_mises_elastic"))
                st.von_mises_plane(rows, (sigma, elastic))
                continue
            block = {"elastic_stress": st.elastic(rows)}
            if want & {"stress", "von_mises"}:
                block["stress"] = st.total(block["elastic_stress"], rows)
            zz = {"stress": None, "elastic_stress": None}
            if st.plane_strain:
                zz["stress"], zz["elastic_stress"] = st.out_of_plane(rows)
                block["stress_zz"], block["elastic_stress_zz"] = zz["stress"], zz["elastic_stress"]
            for tensor, scalar in (("stress", "von_mises"), ("elastic_stress", "von_mises_elastic")):
                if scalar in want:
                    block[scalar] = von_mises_array(block[tensor], d, zz[tensor])
            for name, values in out.items():
                values[rows] = block[name]

    def write(self, t: float, left: int | None = None) -> None:
        """Write level t (no-op without a series); a failed write raises OutputError (everything before it stays).
        ``left``: the levels written up to the next flush or close, this one included (None: not known; see
        :meth:`XDMFSeries.write`)."""
        if self.contact is not None:
            try:
                self.contact.write(t, left)
            except SeriesError as exc:
                raise OutputError(str(exc), exc.t) from None
        if self.series is None:
            return
        cells = self.cell_fields()
        values = {}
        for name in self.names:
            if name == "displacement":
                values[name] = self._vector3(self.rows.rows(self._node_fields[name]()))
            elif name == "damage" or name in CONTACT_FIELDS:
                values[name] = self.rows.rows(self._node_fields[name]())
            else:
                values[name] = (tensor6(cells[name], self.d, cells.get(name + "_zz")) if name in ("stress", "elastic_stress")
                                else cells[name])
        try:
            self.series.write(t, values, left)
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


def _plane_von_mises(a: np.ndarray, b: np.ndarray, c: np.ndarray, tmp: np.ndarray, out: np.ndarray) -> np.ndarray:
    """sqrt(a a + b b - a b + 3 c c) into ``out``, the operations of :func:`von_mises_array`'s plane formula in its
    order (((a a + b b) - a b) + (3 c) c), in place (``tmp`` a work array): the same values to the last bit."""
    np.multiply(a, a, out=out)
    np.multiply(b, b, out=tmp)
    out += tmp
    np.multiply(a, b, out=tmp)
    out -= tmp
    np.multiply(3, c, out=tmp)
    tmp *= c
    out += tmp
    return np.sqrt(out, out=out)


def _centroid_strains(u: fem.Function, n_cells: int) -> StrainMap:
    """eps(u)'s independent components at the centroids of the first ``n_cells`` local cells (their averages for a
    P1 or P2 u on affine cells), as a table of the scalar basis gradients there."""
    d = u.function_space.mesh.geometry.dim
    cells = np.arange(n_cells, dtype=np.int32)
    grad, nodes, bs, size_v = strain_table(u, np.full((1, d), 1.0 / (d + 1)), cells)
    return StrainMap(grad, nodes, bs, cells[:, None], n_cells, size_v, pairs(d))


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
