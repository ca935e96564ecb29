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

from solver.mesh.transfer import gradient_matrices, interpolation_matrix, petsc_to_scipy


class PointwiseError:
    """The paper's error of a run on any mesh against a reference on another (serial; triangles or tetrahedra).

    The integrals run over the judged run's own cells, with a degree-``q`` rule: eps(u_h) and
    zeta_h there are polynomials, and the reference's strain and damage are evaluated at the
    same points (located in the reference mesh). Nothing is interpolated onto a mesh that
    does not hold the function exactly, so meshes need not nest (adapted meshes do not). It
    is exact where the reference is smooth in a judged cell; where the reference's strain
    jumps inside one (a finer reference), the rule integrates a discontinuity: against the
    exact error of nested meshes this measured 0.3-0.6 % of the error
    (tests/studies/test_fine_reference.py).
    """

    def __init__(self, V_ref, Z_ref, model, q: int = 4) -> None:
        import basix
        import ufl
        from dolfinx import fem

        mesh = model.geo.mesh
        dim = mesh.topology.dim
        self.dim = dim
        X, w = basix.make_quadrature(basix.CellType.triangle if dim == 2 else basix.CellType.tetrahedron, q)
        n_cells = mesh.topology.index_map(dim).size_local
        self.cells = np.arange(n_cells, dtype=np.int32)
        nodes = mesh.geometry.dofmap.array.reshape(-1, dim + 1)[:n_cells]
        x = mesh.geometry.x[:, :dim][nodes]  # (cell, vertex, coordinate)
        J = np.stack([x[:, i] - x[:, 0] for i in range(1, dim + 1)], axis=2)
        pts = x[:, 0][:, None, :] + np.einsum("cij,qj->cqi", J, X)
        self.W = (w[None, :] * np.abs(np.linalg.det(J))[:, None]).ravel()
        flat = pts.reshape(-1, dim)
        self.D = gradient_matrices(V_ref, flat)
        self.eps = fem.Expression(ufl.sym(ufl.grad(model.u)), X)
        self.nq = len(w)
        self.model = model
        self.Pz = self.zeta = None
        if Z_ref is not None:  # a judged model without damage (accuracy.simplify left it out) has zeta = zeta0
            self.Pz = interpolation_matrix(Z_ref, flat)
            self.zeta = fem.Expression(model.damage.zeta, X) if model.damage is not None else None
            self.zeta0 = model.cfg.damage.zeta0

    def __call__(self, u_ref: np.ndarray, zeta_ref: np.ndarray | None) -> tuple[float, float]:
        """(||eps(u_ref - u)||, ||zeta_ref - zeta||) for the judged model's current fields."""
        dim = self.dim
        u = u_ref.reshape(-1, dim)
        g = np.stack([D @ u for D in self.D], axis=2)  # (point, component i, derivative j): d u_i / d x_j
        e_ref = (0.5 * (g + np.transpose(g, (0, 2, 1)))).reshape(-1, dim * dim)
        e_h = self.eps.eval(self.cells).reshape(-1, dim * dim)
        d = e_ref - e_h
        eu = float(np.sqrt(max(np.einsum("p,pi,pi->", self.W, d, d), 0.0)))
        ez = 0.0
        if self.Pz is not None and zeta_ref is not None:
            z_h = self.zeta.eval(self.cells).ravel() if self.zeta is not None else self.zeta0
            dz = self.Pz @ zeta_ref - z_h
            ez = float(np.sqrt(max(np.einsum("p,p,p->", self.W, dz, dz), 0.0)))
        return eu, ez


def scheme_fingerprint() -> str:
    """A hash of the solver's physics sources: a cached solution is reused only by the code that computed it."""
    import solver

    here = Path(solver.__file__).resolve().parent
    skip = {"cli.py", "estimator.py"}
    h = hashlib.sha256()
    for path in sorted(here.rglob("*.py")):
        if path.name not in skip and "post" not in path.relative_to(here).parts:
            h.update(path.read_bytes())
    return h.hexdigest()


class FineReference:
    """The reference run, stored at every level (a memory-mapped cache), and the norms of its spaces."""

    def __init__(self, cfg_path: Path, overrides: list[str], n: int, k: float, cache: Path, log=print) -> None:
        import dolfinx.fem.petsc  # noqa: F401
        import ufl
        from dolfinx import fem
        from mpi4py import MPI

        from solver.config import dumps, load
        from solver.io.results import run
        from solver.run.model import build_model

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
        self.strain_gram, self.mass_zeta = petsc_to_scipy(E), petsc_to_scipy(Mz)
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
        return float(np.sqrt(max(du @ (self.strain_gram @ du), 0.0))), float(np.sqrt(max(dz @ (self.mass_zeta @ dz), 0.0)))

    def measure(self, overrides: list[str], n: int, k: float) -> dict:
        """Run the scene at (n, k) with ``overrides`` and return its error record and time-loop seconds."""
        from mpi4py import MPI

        from solver.config import load
        from solver.errors import SolveFailure
        from solver.io.results import run
        from solver.run.model import build_model

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
