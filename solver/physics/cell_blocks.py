"""A linear form of cell integrals assembled a block of cells at a time.

dolfinx 0.5.2's ``assemble_vector`` packs the coefficients of every cell of the form into one array before it
assembles (cells x the coefficients' dofs per cell: 71 MiB for the damage source's u and zeta on 584,016 P1
tetrahedra), at every assembly. :class:`CellBlockForm` compiles the same integrand once, over a subdomain, and
builds one form per block of :data:`BLOCK` owned cells (a cell tag each, the compiled code shared), so that only one
block's coefficients are packed at a time. The blocks run in cell order and each block's cells are in order, so
every entry of the vector receives the same contributions in the same order as in the one-form assembly: the same
vector, bit for bit (tests/physics/test_cell_blocks.py).
"""

from __future__ import annotations

import functools
import operator

import numpy as np
import ufl
from dolfinx import fem
from dolfinx import mesh as dmesh
from dolfinx.fem import petsc as fpetsc
from mpi4py import MPI
from petsc4py import PETSc

BLOCK = 65536  # owned cells a block (u and zeta of a P1 tetrahedron: 8 MiB of packed coefficients a block)


class CellBlockForm:
    """``form`` on ``mesh`` (a linear form whose integrals are all over every cell, ``dx`` with any metadata) as
    one compiled form per block of ``block`` owned cells (default :data:`BLOCK`); any other form, or a mesh of one
    block, stays one form (``compiled``, where the caller has compiled ``form`` already). The number of blocks is the
    same on every rank (forms are compiled collectively): a rank with fewer cells has empty blocks."""

    def __init__(self, mesh: dmesh.Mesh, form: ufl.Form, block: int | None = None, compiled=None) -> None:
        block = BLOCK if block is None else block
        integrals = form.integrals()
        tdim = mesh.topology.dim
        owned = mesh.topology.index_map(tdim).size_local
        blocks = mesh.comm.allreduce(-(-owned // block), op=MPI.MAX)
        every_cell = all(i.integral_type() == "cell" and i.subdomain_id() == "everywhere" for i in integrals)
        if not every_cell or blocks <= 1:
            self.forms = [fem.form(form) if compiled is None else compiled]
            return
        self.forms = []
        for b in range(blocks):
            cells = np.arange(min(b * block, owned), min((b + 1) * block, owned), dtype=np.int32)
            tags = dmesh.meshtags(mesh, tdim, cells, np.ones(len(cells), dtype=np.int32))
            parts = [i.integrand() * ufl.Measure("dx", domain=mesh, subdomain_data=tags, metadata=i.metadata())(1)
                     for i in integrals]
            self.forms.append(fem.form(functools.reduce(operator.add, parts)))

    def assemble(self, b: PETSc.Vec) -> None:
        """b += the form, block by block (local: no ghost update)."""
        for form in self.forms:
            fpetsc.assemble_vector(b, form)
