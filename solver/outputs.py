"""The fields a run writes for ParaView: u, zeta and cell-wise stresses (docs/model.md §5 for what the paper shows).

XDMF cannot hold quadrature functions, so the stresses sigma = A eps(u) + M and A eps(u)
are written as DG0 cell averages (the exact L2 projection onto piecewise constants),
with their von Mises values. P2 fields (``discretization.u_degree`` or ``zeta_degree`` = 2)
are written as their P1 interpolants on the mesh (their values at the vertices): ParaView
shows the vertex values exactly, never a field the solver did not compute.
"""

from __future__ import annotations

from pathlib import Path

from dolfinx import fem

from .config import MaterialConfig
from .io import CellAverage, XDMFWriter, von_mises_array
from .material import elasticity, strain


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
        self.xdmf = None
        self._p1: list[tuple[fem.Function, fem.Function]] = []  # (solver field, its P1 interpolant)
        if outdir is not None:
            zeta = [model.damage.zeta] if model.damage is not None else []
            written = [self._vertex_values(f) for f in (model.u, *zeta)]
            funcs = [*written, self.stress, self.elastic_stress, self.von_mises, self.von_mises_elastic]
            self.xdmf = XDMFWriter(outdir, mesh, funcs, part=part, prefix=prefix)

    def _vertex_values(self, f: fem.Function) -> fem.Function:
        """f itself if P1, else a P1 function of the same name that takes f's vertex values at each write."""
        if f.function_space.ufl_element().degree() == 1:
            return f
        el = f.function_space.ufl_element()
        mesh = f.function_space.mesh
        V1 = (fem.VectorFunctionSpace(mesh, ("CG", 1), dim=el.value_shape()[0]) if el.value_shape()
              else fem.FunctionSpace(mesh, ("CG", 1)))
        out = fem.Function(V1, name=f.name)
        self._p1.append((f, out))
        return out

    def update_cell_fields(self) -> None:
        for f, out in self._p1:
            out.interpolate(f)
        self.avg_el.update()
        self.avg.update()
        n = self.von_mises.function_space.dofmap.index_map.size_local
        for tensor, scalar in ((self.stress, self.von_mises), (self.elastic_stress, self.von_mises_elastic)):
            scalar.x.array[:n] = von_mises_array(tensor.x.array[: n * self.d * self.d], self.d)
            scalar.x.scatter_forward()

    def write(self, t: float) -> None:
        """Write level t (no-op without a writer)."""
        if self.xdmf is not None:
            self.update_cell_fields()
            self.xdmf.write(t)

    def close(self) -> None:
        if self.xdmf is not None:
            self.xdmf.close()
