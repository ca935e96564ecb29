"""A fine reference solution of any degree and time order, and the paper's error of any run against it.

The error is the paper's norm (docs/model.md §3.6),

    max over the run's levels of ||eps(u_n^ref - u_n)||_L2 + ||zeta_n^ref - zeta_n||_L2,

evaluated on the reference mesh: each run's fields are interpolated onto the reference's
dofs by a sparse matrix (the run's basis at the reference's dof points), which is exact
when the meshes nest and the run's degree is at most the reference's. Levels are compared
where the run and the reference share a time. Serial (the reference is one process).
"""

from __future__ import annotations

import hashlib
import os
import time
from pathlib import Path

import numpy as np
import scipy.sparse as sp


def _locate(mesh, points: np.ndarray):
    """The cell holding each point (2-D affine triangles), the cell's Jacobian (columns: edges) and the point's
    reference coordinates; raises ValueError if a point lies outside this process's cells."""
    from dolfinx import geometry

    tdim = mesh.topology.dim
    pts = np.zeros((len(points), 3))
    pts[:, : points.shape[1]] = points
    tree = geometry.BoundingBoxTree(mesh, tdim)
    colliding = geometry.compute_colliding_cells(mesh, geometry.compute_collisions(tree, pts), pts)
    offsets = colliding.offsets
    if np.any(np.diff(offsets) == 0):
        raise ValueError("a point lies outside the mesh")
    cells = colliding.array[offsets[:-1]]
    gdofs = mesh.geometry.dofmap.array.reshape(-1, tdim + 1)[cells]
    X = mesh.geometry.x[gdofs][:, :, :2]  # (point, vertex, xy)
    J = np.stack([X[:, 1] - X[:, 0], X[:, 2] - X[:, 0]], axis=2)
    ref = np.linalg.solve(J, (pts[:, :2] - X[:, 0])[:, :, None])[:, :, 0]
    return cells, J, ref


def _tabulated(V, points: np.ndarray, derivatives: int):
    """V's element basis (and its reference derivatives up to ``derivatives``) at located points, with what a
    sparse matrix over V's local nodes needs: (cells' Jacobians, table (deriv, point, local dof), rows, cols,
    number of columns)."""
    import basix

    cells, J, ref = _locate(V.mesh, points)
    element = basix.create_element(basix.ElementFamily.P, basix.CellType.triangle, V.ufl_element().degree(),
                                   basix.LagrangeVariant.gll_warped)
    tab = element.tabulate(derivatives, ref)[:, :, :, 0]
    ndofs = tab.shape[2]
    cols = V.dofmap.list.array.reshape(-1, ndofs)[cells].ravel()
    rows = np.repeat(np.arange(len(points)), ndofs)
    size = V.dofmap.index_map.size_local + V.dofmap.index_map.num_ghosts
    return J, tab, rows, cols, size


def interpolation_matrix(V, points: np.ndarray) -> sp.csr_matrix:
    """Rows: points; columns: the nodes of V (a Lagrange space on affine triangles, this process; for a vector
    space the matrix acts on each component: P @ u.reshape(-1, bs)).

    Each point is located in a cell of V's mesh (bounding-box tree), mapped to the reference
    triangle, and V's element basis is tabulated there.
    """
    _, tab, rows, cols, size = _tabulated(V, points, 0)
    P = sp.csr_matrix((tab[0].ravel(), (rows, cols)), shape=(len(points), size))
    P.eliminate_zeros()
    return P


def gradient_matrices(V, points: np.ndarray) -> tuple[sp.csr_matrix, sp.csr_matrix]:
    """(Dx, Dy): rows: points; columns: the nodes of V (a Lagrange space on affine triangles); Dx @ u gives
    du/dx at the points (componentwise for a vector space, as :func:`interpolation_matrix`)."""
    J, tab, rows, cols, size = _tabulated(V, points, 1)
    Jinv_T = np.transpose(np.linalg.inv(J), (0, 2, 1))  # grad_x = J^{-T} grad_X
    grads = np.einsum("pij,jpd->ipd", Jinv_T, tab[1:])  # (x/y, point, local dof)
    return tuple(sp.csr_matrix((grads[i].ravel(), (rows, cols)), shape=(len(points), size)) for i in range(2))


class PointwiseError:
    """The paper's error of a run on any mesh against a reference on another (serial, 2-D).

    The integrals run over the judged run's own cells, with a degree-``q`` rule: eps(u_h) and
    zeta_h there are polynomials, and the reference's strain and damage are evaluated at the
    same points (located in the reference mesh). Nothing is interpolated onto a mesh that
    does not hold the function exactly, so meshes need not nest (adapted meshes do not). It
    is exact where the reference is smooth in a judged cell; where the reference's strain
    jumps inside one (a finer reference), the rule integrates a discontinuity: against the
    exact error of nested meshes this measured 0.3-0.6 % of the error
    (tests/test_reference.py).
    """

    def __init__(self, V_ref, Z_ref, model, q: int = 4) -> None:
        import basix
        import ufl
        from dolfinx import fem

        mesh = model.geo.mesh
        X, w = basix.make_quadrature(basix.CellType.triangle, q)
        n_cells = mesh.topology.index_map(2).size_local
        self.cells = np.arange(n_cells, dtype=np.int32)
        nodes = mesh.geometry.dofmap.array.reshape(-1, 3)[:n_cells]
        x = mesh.geometry.x[:, :2][nodes]  # (cell, vertex, xy)
        J = np.stack([x[:, 1] - x[:, 0], x[:, 2] - x[:, 0]], axis=2)
        pts = x[:, 0][:, None, :] + np.einsum("cij,qj->cqi", J, X)
        self.W = (w[None, :] * np.abs(np.linalg.det(J))[:, None]).ravel()
        flat = pts.reshape(-1, 2)
        self.Dx, self.Dy = gradient_matrices(V_ref, flat)
        self.eps = fem.Expression(ufl.sym(ufl.grad(model.u)), X)
        self.nq = len(w)
        self.model = model
        self.Pz = self.zeta = None
        if model.damage is not None and Z_ref is not None:
            self.Pz = interpolation_matrix(Z_ref, flat)
            self.zeta = fem.Expression(model.damage.zeta, X)

    def __call__(self, u_ref: np.ndarray, zeta_ref: np.ndarray | None) -> tuple[float, float]:
        """(||eps(u_ref - u)||, ||zeta_ref - zeta||) for the judged model's current fields."""
        u = u_ref.reshape(-1, 2)
        gx, gy = self.Dx @ u, self.Dy @ u  # (point, component): d u_i / dx, d u_i / dy
        e_ref = np.stack([gx[:, 0], 0.5 * (gy[:, 0] + gx[:, 1]), 0.5 * (gy[:, 0] + gx[:, 1]), gy[:, 1]], axis=1)
        e_h = self.eps.eval(self.cells).reshape(-1, 4)
        d = e_ref - e_h
        eu = float(np.sqrt(max(np.einsum("p,pi,pi->", self.W, d, d), 0.0)))
        ez = 0.0
        if self.Pz is not None and zeta_ref is not None:
            dz = self.Pz @ zeta_ref - self.zeta.eval(self.cells).ravel()
            ez = float(np.sqrt(max(np.einsum("p,p,p->", self.W, dz, dz), 0.0)))
        return eu, ez


def scheme_fingerprint() -> str:
    """A hash of the solver's physics sources: a cached solution is reused only by the code that computed it."""
    here = Path(__file__).resolve().parent
    skip = {"bench.py", "study.py", "plots.py", "paraview.py", "paraview_script.py", "post.py", "cli.py",
            "discretizations.py", "reference.py", "convergence.py", "estimator.py", "estimator_study.py"}
    h = hashlib.sha256()
    for path in sorted(here.rglob("*.py")):
        if path.name not in skip:
            h.update(path.read_bytes())
    return h.hexdigest()


def _petsc_to_scipy(A) -> sp.csr_matrix:
    ai, aj, av = A.getValuesCSR()
    return sp.csr_matrix((av, aj, ai), shape=A.getSize())


class FineReference:
    """The reference run, stored at every level (a memory-mapped cache), and the norms of its spaces."""

    def __init__(self, cfg_path: Path, overrides: list[str], n: int, k: float, cache: Path, log=print) -> None:
        import dolfinx.fem.petsc  # noqa: F401
        import ufl
        from dolfinx import fem
        from mpi4py import MPI

        from .config import dumps, load
        from .stepper import build_model, run

        self.cfg_path, self.overrides, self.n, self.k, self.cache = Path(cfg_path), list(overrides), n, k, cache
        cfg = load(cfg_path, [*overrides, f"mesh.nx={n}", f"mesh.ny={n}", f"time.k={k}", "output.xdmf=false"])
        self.cfg = cfg
        model = build_model(cfg, MPI.COMM_SELF)
        self.model = model
        V, Z = model.u.function_space, model.damage.V
        self.nu, self.nz = model.u.x.array.size, model.damage.zeta.x.array.size
        key = hashlib.sha256((dumps(cfg).split("\n", 1)[1] + scheme_fingerprint()).encode()).hexdigest()[:16]
        cache.mkdir(parents=True, exist_ok=True)
        path = cache / f"fine-reference-{n}-{k}-{key}.npy"
        self.cached = path.exists()
        self.seconds = 0.0
        if not self.cached:
            tmp = path.with_suffix(f".{os.getpid()}.tmp.npy")
            data = np.lib.format.open_memmap(tmp, mode="w+", dtype=np.float64,
                                             shape=(cfg.time.steps + 1, self.nu + self.nz))

            def store(row):
                data[row["step"], : self.nu] = model.u.x.array
                data[row["step"], self.nu:] = model.damage.zeta.x.array

            t0 = time.perf_counter()
            run(model, on_step=store)
            self.seconds = time.perf_counter() - t0
            data.flush()
            del data
            os.replace(tmp, path)
        self.data = np.load(path, mmap_mode="r")
        log(f"reference {cfg.discretization} order {cfg.time.order} n={n} k={k}: {cfg.time.steps + 1} levels"
            + (" (from cache)" if self.cached else f" ({self.seconds:.1f} s)"))
        du, w = ufl.TrialFunction(V), ufl.TestFunction(V)
        E = fem.petsc.assemble_matrix(fem.form(ufl.inner(ufl.sym(ufl.grad(du)), ufl.sym(ufl.grad(w))) * ufl.dx))
        E.assemble()
        z, xi = ufl.TrialFunction(Z), ufl.TestFunction(Z)
        Mz = fem.petsc.assemble_matrix(fem.form(z * xi * ufl.dx))
        Mz.assemble()
        self.E, self.Mz = _petsc_to_scipy(E), _petsc_to_scipy(Mz)
        self.u_points = V.tabulate_dof_coordinates()[:, :2]  # one row per node
        self.z_points = Z.tabulate_dof_coordinates()[:, :2]

    def level(self, t: float) -> int | None:
        """The reference level at time t, if t is one of its times."""
        m = t / self.k
        return int(round(m)) if abs(m - round(m)) < 1e-9 and round(m) < len(self.data) else None

    def error(self, u: np.ndarray, zeta: np.ndarray, step: int) -> tuple[float, float]:
        """(||eps(u_ref - u)||, ||zeta_ref - zeta||) with u, zeta already on the reference's dofs."""
        du = self.data[step, : self.nu] - u
        dz = self.data[step, self.nu:] - zeta
        return float(np.sqrt(max(du @ (self.E @ du), 0.0))), float(np.sqrt(max(dz @ (self.Mz @ dz), 0.0)))

    def measure(self, overrides: list[str], n: int, k: float) -> dict:
        """Run the scene at (n, k) with ``overrides`` and return its error record and time-loop seconds."""
        from mpi4py import MPI

        from .config import load
        from .errors import SolveFailure
        from .stepper import build_model, run

        cfg = load(self.cfg_path, [*self.overrides, *overrides, f"mesh.nx={n}", f"mesh.ny={n}", f"time.k={k}",
                                   "output.xdmf=false"])
        model = build_model(cfg, MPI.COMM_SELF)
        Pu = interpolation_matrix(model.u.function_space, self.u_points)
        Pz = interpolation_matrix(model.damage.V, self.z_points)
        d = 2
        errs: list[tuple[float, float, float]] = []
        loop = [0.0]

        def compare(row):
            loop[0] += row["wall_time"]
            step = self.level(row["t"])
            if step is None:
                return
            u = (Pu @ model.u.x.array.reshape(-1, d)).ravel()
            eu, ez = self.error(u, Pz @ model.damage.zeta.x.array, step)
            errs.append((row["t"], eu, ez))

        failure = None
        try:
            run(model, on_step=compare)
        except SolveFailure as exc:
            failure = exc
        e = np.array(errs) if errs else np.full((1, 3), np.nan)
        total = e[:, 1] + e[:, 2]
        m = int(np.nanargmax(total)) if np.isfinite(total).any() else 0
        return {"n": n, "k": k, "u_degree": cfg.discretization.u_degree, "zeta_degree": cfg.discretization.zeta_degree,
                "order": cfg.time.order, "error": float(total[m]), "error_u": float(e[m, 1]),
                "error_zeta": float(e[m, 2]), "t_max": float(e[m, 0]), "error_T": float(total[-1]),
                "levels_compared": len(errs), "loop_seconds": loop[0], "failure": failure,
                "dofs_u": model.u.x.array.size}
