"""The fields a run writes for ParaView: u, zeta and cell-wise stresses (docs/model.md §5 for what the paper shows).

XDMF cannot hold quadrature functions, so the stresses sigma = A eps(u) + M and A eps(u)
are written as DG0 cell averages (the exact L2 projection onto piecewise constants),
with their von Mises values. ``output.fields`` chooses which are written; only the cell
averages those need are computed. The series itself is :class:`solver.xdmf.XDMFSeries`.
"""

from __future__ import annotations

from pathlib import Path

from dolfinx import fem

from .config import MaterialConfig, OutputConfig
from .errors import OutputError, UsageError
from .io import CellAverage, von_mises_array
from .material import elasticity, strain
from .xdmf import DolfinxRows, FieldSpec, SeriesError, XDMFSeries, dolfinx_layout, tensor6, vector3

KINDS = {"displacement": ("Node", "Vector"), "damage": ("Node", "Scalar"), "stress": ("Cell", "Tensor6"),
         "elastic_stress": ("Cell", "Tensor6"), "von_mises": ("Cell", "Scalar"), "von_mises_elastic": ("Cell", "Scalar")}


class Outputs:
    """Owns the written fields and the XDMF series of a run (``outdir`` None: nothing is written).

    ``expected_levels`` sizes the series' files; ``keep_until`` (a restart) keeps the levels
    already written up to that time and appends after them.
    """

    def __init__(self, model, material: MaterialConfig, output: OutputConfig, outdir: Path | None,
                 expected_levels: int | None = None, keep_until: float | None = None) -> None:
        mesh = model.geo.mesh
        self.d = mesh.geometry.dim
        self.series = None
        self.names = [f for f in output.fields if f != "damage" or model.damage is not None]
        if outdir is None or not self.names:
            return
        self.model = model
        want = set(self.names)
        T0 = fem.TensorFunctionSpace(mesh, ("DG", 0))
        S0 = fem.FunctionSpace(mesh, ("DG", 0))
        sig_el = elasticity(strain(model.u), material.E, material.nu, material.model)
        self.averages = []  # (tensor, its von Mises or None): only what the chosen fields need
        self.cell: dict[str, fem.Function] = {}
        for tensor, scalar, sig in (("stress", "von_mises", sig_el + model.history.M if model.history is not None else sig_el),
                                    ("elastic_stress", "von_mises_elastic", sig_el)):
            if want & {tensor, scalar}:
                T = fem.Function(T0, name=tensor)
                # the paper's figures: memory balances the load, so "relaxes" / "not stress-free" are about A eps(u)
                V = fem.Function(S0, name=scalar) if scalar in want else None
                self.averages.append((CellAverage(sig, T, model.rule.dx), T, V))
                self.cell[tensor] = T
                if V is not None:
                    self.cell[scalar] = V
        self.rows = DolfinxRows(mesh)
        specs = [FieldSpec(name, *KINDS[name]) for name in self.names]
        try:
            self.series = XDMFSeries(outdir, dolfinx_layout(mesh), specs, output.precision, expected_levels, keep_until)
        except SeriesError as exc:
            raise (UsageError(f"--restart: {exc}") if keep_until is not None else OutputError(str(exc))) from None

    def update_cell_fields(self) -> None:
        """Cell averages of the stresses the written fields need, and their von Mises values."""
        for avg, tensor, scalar in self.averages:
            avg.update()
            if scalar is not None:
                n = scalar.function_space.dofmap.index_map.size_local
                scalar.x.array[:n] = von_mises_array(tensor.x.array[: n * self.d * self.d], self.d)

    def _rows(self, name: str):
        if name == "displacement":
            return vector3(self.rows.rows(self.model.u))
        if name == "damage":
            return self.rows.rows(self.model.damage.zeta)
        rows = self.rows.rows(self.cell[name])
        return tensor6(rows, self.d) if name in ("stress", "elastic_stress") else rows

    def write(self, t: float) -> None:
        """Write level t (no-op without a series); a failed write raises OutputError (everything before it stays)."""
        if self.series is None:
            return
        self.update_cell_fields()
        try:
            self.series.write(t, {name: self._rows(name) for name in self.names})
        except SeriesError as exc:
            raise OutputError(str(exc)) from None

    def close(self) -> None:
        if self.series is not None:
            self.series.close()
