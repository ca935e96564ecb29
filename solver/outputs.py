"""The fields a run writes for ParaView: u, zeta and cell-wise stresses (docs/model.md §5 for what the paper shows).

XDMF cannot hold quadrature functions, so the stresses sigma = A eps(u) + M and A eps(u)
are written as DG0 cell averages (the exact L2 projection onto piecewise constants),
with their von Mises values; in plane strain also sigma_33 (``stress_zz``, ``elastic_stress_zz``),
which the von Mises values then include.
"""

from __future__ import annotations

from pathlib import Path

from dolfinx import fem

from .config import MaterialConfig
from .io import CellAverage, XDMFWriter, von_mises_array
from .material import elasticity, out_of_plane_stress, strain


class Outputs:
    """Owns the written fields and the XDMF writer of a run (None: nothing is written)."""

    def __init__(self, model, material: MaterialConfig, outdir: Path | None, part: int = 0,
                 prefix: list | None = None) -> None:
        mesh = model.geo.mesh
        self.d = mesh.geometry.dim
        T0 = fem.TensorFunctionSpace(mesh, ("DG", 0))
        self.stress = fem.Function(T0, name="stress")
        self.elastic_stress = fem.Function(T0, name="elastic_stress")
        S0 = fem.FunctionSpace(mesh, ("DG", 0))
        self.von_mises = fem.Function(S0, name="von_mises")
        # the paper's figures: memory balances the load, so "relaxes" / "not stress-free" are about A eps(u)
        self.von_mises_elastic = fem.Function(S0, name="von_mises_elastic")
        sig_el = elasticity(strain(model.u), material.E, material.nu, material.model)
        sig = sig_el + model.history.M if model.history is not None else sig_el
        self.avg_el = CellAverage(sig_el, self.elastic_stress, model.rule.dx)
        self.avg = CellAverage(sig, self.stress, model.rule.dx)
        # plane strain: sigma_33 = lambda tr eps(u) + M_33 (and its elastic part), for von Mises and written
        self.zz: list[fem.Function] = []
        self.avg_zz: list[CellAverage] = []
        if material.model == "plane_strain":
            s33_el = out_of_plane_stress(strain(model.u), material.E, material.nu)
            s33 = s33_el + model.history.M33 if model.history is not None else s33_el
            self.zz = [fem.Function(S0, name="stress_zz"), fem.Function(S0, name="elastic_stress_zz")]
            self.avg_zz = [CellAverage(s33, self.zz[0], model.rule.dx), CellAverage(s33_el, self.zz[1], model.rule.dx)]
        self.xdmf = None
        if outdir is not None:
            zeta = [model.damage.zeta] if model.damage is not None else []
            funcs = [model.u, *zeta, self.stress, self.elastic_stress, self.von_mises, self.von_mises_elastic, *self.zz]
            self.xdmf = XDMFWriter(outdir, mesh, funcs, part=part, prefix=prefix)

    def update_cell_fields(self) -> None:
        self.avg_el.update()
        self.avg.update()
        for avg in self.avg_zz:
            avg.update()
        n = self.von_mises.function_space.dofmap.index_map.size_local
        zz = [f.x.array[:n] for f in self.zz] or [None, None]
        for tensor, scalar, s33 in ((self.stress, self.von_mises, zz[0]), (self.elastic_stress, self.von_mises_elastic, zz[1])):
            scalar.x.array[:n] = von_mises_array(tensor.x.array[: n * self.d * self.d], self.d, s33)
            scalar.x.scatter_forward()

    def write(self, t: float) -> None:
        """Write level t (no-op without a writer)."""
        if self.xdmf is not None:
            self.update_cell_fields()
            self.xdmf.write(t)

    def close(self) -> None:
        if self.xdmf is not None:
            self.xdmf.close()
