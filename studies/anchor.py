"""The plain-elasticity anchor of the scaling benchmark: one linear-elasticity solve with plain dolfinx.

What any 3-D solver of this problem must pay at least: the unit cube of 3-D Example 1 (the same
``create_box`` tetrahedra, E, nu, clamped at x = 0, traction (-10, 0, -10) at x = 1), without contact, memory
or damage, solved as dolfinx's ``demo_elasticity.py`` does: CG with GAMG and the six rigid motions as
near-nullspace, rtol 1e-8, or MUMPS's Cholesky (the solver's ICNTL(14)). Written without the solver's modules
on purpose, so that an overhead of the solver cannot hide in its own yardstick.

    -div sigma(u) = 0 in the cube,  sigma = 2 mu_L eps(u) + lambda_L tr(eps(u)) I,
    u = 0 on x = 0,  sigma n = (-10, 0, -10) on x = 1,  sigma n = 0 elsewhere.

``python -m studies.anchor N SOLVER`` prints the case's figures as one JSON line (rank 0); run each case in
its own process so that its peak memory is its own.
"""

from __future__ import annotations

import json
import resource
import statistics
import sys
import time
from contextlib import ExitStack

import numpy as np

E, NU, TRACTION = 100.0, 0.3, (-10.0, 0.0, -10.0)  # configs/example1_3d.toml
SOLVERS = ("gamg", "mumps")
SOLVES = 3  # solves timed from a zero guess; the median is reported


def _options(solver: str) -> dict[str, str]:
    if solver == "gamg":  # demo_elasticity.py
        return {"ksp_type": "cg", "ksp_rtol": "1e-8", "pc_type": "gamg", "pc_gamg_coarse_eq_limit": "1000",
                "mg_levels_ksp_type": "chebyshev", "mg_levels_pc_type": "jacobi", "mg_levels_esteig_ksp_type": "cg"}
    return {"ksp_type": "preonly", "pc_type": "cholesky", "pc_factor_mat_solver_type": "mumps",
            "mat_mumps_icntl_14": "50"}


def _rigid_motions(V):
    """The six rigid motions of the cube, orthonormalized: GAMG's near-nullspace (demo_elasticity.py)."""
    from dolfinx import la
    from petsc4py import PETSc

    index_map, bs = V.dofmap.index_map, V.dofmap.index_map_bs
    basis = [la.create_petsc_vector(index_map, bs) for _ in range(6)]
    dofs = [V.sub(i).dofmap.list.array for i in range(3)]  # component i's entries of the blocked vector
    x = V.tabulate_dof_coordinates()
    blocks = V.dofmap.list.array
    x0, x1, x2 = x[blocks, 0], x[blocks, 1], x[blocks, 2]
    with ExitStack() as stack:  # the local forms hold the ghosts too
        arrays = [np.asarray(stack.enter_context(b.localForm())) for b in basis]
        for i in range(3):
            arrays[i][dofs[i]] = 1.0  # translations
        for a, (i, xi), (j, xj) in ((3, (0, -x1), (1, x0)), (4, (0, x2), (2, -x0)), (5, (2, x1), (1, -x2))):
            arrays[a][dofs[i]] = xi  # rotations
            arrays[a][dofs[j]] = xj
    la.orthonormalize(basis)
    return PETSc.NullSpace().create(vectors=basis)


def run_case(n: int, solver: str) -> dict:
    """Build, assemble and solve the n x n x n cube; figures the same on every rank (times are rank 0's)."""
    import ufl
    from dolfinx import fem, mesh
    from dolfinx.fem.petsc import apply_lifting, assemble_matrix, assemble_vector, set_bc
    from mpi4py import MPI
    from petsc4py import PETSc

    comm = MPI.COMM_WORLD
    comm.barrier()
    t0 = time.perf_counter()
    msh = mesh.create_box(comm, [np.zeros(3), np.ones(3)], [n, n, n], cell_type=mesh.CellType.tetrahedron)
    V = fem.VectorFunctionSpace(msh, ("Lagrange", 1))
    mu, lmbda = E / (2 * (1 + NU)), E * NU / ((1 + NU) * (1 - 2 * NU))
    u, v = ufl.TrialFunction(V), ufl.TestFunction(V)

    def sigma(w):
        return 2 * mu * ufl.sym(ufl.grad(w)) + lmbda * ufl.tr(ufl.sym(ufl.grad(w))) * ufl.Identity(3)

    right = mesh.locate_entities_boundary(msh, 2, lambda x: np.isclose(x[0], 1.0))
    tags = mesh.meshtags(msh, 2, right, np.full(len(right), 1, dtype=np.int32))
    ds = ufl.Measure("ds", domain=msh, subdomain_data=tags)
    a = fem.form(ufl.inner(sigma(u), ufl.sym(ufl.grad(v))) * ufl.dx)
    L = fem.form(ufl.inner(fem.Constant(msh, np.array(TRACTION)), v) * ds(1))
    left = fem.locate_dofs_topological(V, 2, mesh.locate_entities_boundary(msh, 2, lambda x: np.isclose(x[0], 0.0)))
    bc = fem.dirichletbc(np.zeros(3), left, V)
    A = assemble_matrix(a, bcs=[bc])
    A.assemble()
    b = assemble_vector(L)
    apply_lifting(b, [a], bcs=[[bc]])
    b.ghostUpdate(addv=PETSc.InsertMode.ADD, mode=PETSc.ScatterMode.REVERSE)
    set_bc(b, [bc])
    if solver == "gamg":
        A.setNearNullSpace(_rigid_motions(V))
    ksp = PETSc.KSP().create(comm)
    ksp.setOptionsPrefix("anchor_")
    opts = PETSc.Options()
    for k, val in _options(solver).items():
        opts[f"anchor_{k}"] = val
    ksp.setOperators(A)
    ksp.setFromOptions()
    comm.barrier()
    t1 = time.perf_counter()
    ksp.setUp()  # the factorization, or the AMG hierarchy
    comm.barrier()
    t2 = time.perf_counter()
    x = b.duplicate()
    times, its = [], []
    for _ in range(SOLVES):
        x.set(0.0)
        comm.barrier()
        t = time.perf_counter()
        ksp.solve(b, x)
        comm.barrier()
        times.append(time.perf_counter() - t)
        its.append(ksp.getIterationNumber())
    if ksp.getConvergedReason() <= 0:
        raise RuntimeError(f"anchor n={n} {solver}: KSP diverged ({ksp.getConvergedReason()})")
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0  # MiB (Linux: KiB)
    return {"n": n, "solver": solver, "nproc": comm.size, "dofs": V.dofmap.index_map.size_global * 3,
            "assemble_s": t1 - t0, "setup_s": t2 - t1, "solve_s": float(statistics.median(times)),
            "iterations": int(statistics.median(its)), "norm_u": x.norm(),
            "peak_mib_max": comm.allreduce(peak, op=MPI.MAX), "peak_mib_sum": comm.allreduce(peak, op=MPI.SUM)}


if __name__ == "__main__":
    if len(sys.argv) != 3 or sys.argv[2] not in SOLVERS or not sys.argv[1].isdigit():
        print(f"usage: python -m studies.anchor N {{{','.join(SOLVERS)}}}", file=sys.stderr)
        raise SystemExit(2)
    result = run_case(int(sys.argv[1]), sys.argv[2])
    from mpi4py import MPI

    if MPI.COMM_WORLD.rank == 0:
        print(json.dumps(result))
