"""The 3-D sphere's first contact under other Newton strategies: how many Jacobian solves each takes to the stiff law's
solution (docs/model.md §4, "The 3-D sphere"; benchmarks/results/first_contact_strategies.md).

    python benchmarks/first_contact_strategies.py [--h 0.03] [--strategies plain energy ...] [--max 60] [--trace]
        [--out benchmarks/results/first_contact_strategies]

The scene is benchmarks/first_contact.py's sphere (radius 2 pressed 0.015 into the quarter block, P1, mu = 1e-8) on
meshes/hertz3d.py's mesh graded to ``h``. Each strategy starts from the level's start (u = 0, no contact) and counts
every solve with the Jacobian J = K + s C (each a MUMPS Cholesky factorization: every stage of a path counts); it
stops where ||F|| <= solver.rtol * scale (the solver's test) or after ``--max`` solves. Strategies:

- ``plain``: semismooth Newton's full steps (the set of each iterate);
- ``energy``: each Newton step shortened to the minimum of the level's energy on its line where it changes the
  active set (damped_newton.line_minimum);
- ``path`` / ``path_energy``: the compliance path of solvers/continuation.py (the contact term at stiffness ratios
  1, 10, 100, two steps each), then the stiff law by full steps / by steps with the line search;
- ``path_accept``: the path, then the full step where it lowers the energy (the energy's difference computed from
  the residuals and the contact energy (1/2mu) int (u_nu - g)_+^2), else the line search;
- ``path_superset``: the path, then the line search on steps solved with the Jacobian of the points within
  ``--eps`` of contact (a superset of the active set) for ``--eps-steps`` steps, then the exact one;
- ``predicted`` / ``predicted_energy``: the solve without contact, then the start lifted by half the largest overlap
  (the zone of Hertz's a^2 = R d, not the overlap's 2 R d), then full steps / steps with the line search.

Writes OUT.csv (h, strategy, solves, converged, residual, contact force, seconds; rows of other sizes and strategies
kept) and OUT.md (its table), and prints each solve with ``--trace``. One process, serial.
"""

from __future__ import annotations

import argparse
import csv
import importlib.util
import sys
import tempfile
import time
from pathlib import Path

import ufl
from dolfinx import fem
from mpi4py import MPI
from petsc4py import PETSc

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "benchmarks"))

from first_contact import sphere  # noqa: E402

from solver.config import from_dict  # noqa: E402
from solver.physics.contact import gap_function, penetration  # noqa: E402
from solver.physics.quadrature import ContactRule, facet_type  # noqa: E402
from solver.run.model import build_model  # noqa: E402
from solver.solvers.continuation import RATIOS, STAGE_ITERATIONS, contact_stiffness_ratio  # noqa: E402
from solver.solvers.damped_newton import line_minimum  # noqa: E402

STRATEGIES = ("plain", "energy", "path", "path_energy", "path_accept", "path_superset", "predicted",
              "predicted_energy")


class Level:
    """The sphere's first level with its own MUMPS solver and counters."""

    def __init__(self, msh: Path, trace: bool) -> None:
        self.model = build_model(from_dict(sphere(str(msh))), MPI.COMM_WORLD)
        self.problem = problem = self.model.mech.problem
        self.contact = problem.contact
        self.scale = problem.begin_level(0.0)
        self.tol = self.model.cfg.solver.rtol * self.scale
        self.ratio = contact_stiffness_ratio(problem)
        u = problem.u
        self.x, self.F, self.d, self.y, self.G, self.j = (u.vector.copy() for _ in range(6))
        ksp = PETSc.KSP().create(MPI.COMM_WORLD)
        ksp.setType("preonly")
        ksp.getPC().setType("cholesky")
        ksp.getPC().setFactorSolverType("mumps")
        self.ksp = ksp
        self.solves, self.trace = 0, trace
        part = self.model.mech.physics.parts[0]
        geo, rule = self.model.geo, ContactRule.of(self.model.cfg)
        r = penetration(u, ufl.FacetNormal(geo.mesh), gap_function(part, geo, rule))
        ds = geo.ds(geo.tags[part.name], metadata=rule.metadata(facet_type(geo.mesh)))
        self._energy = fem.form(self.contact.scale * ufl.max_value(r, 0.0) ** 2 / (2.0 * part.contact_law.mu) * ds)

    def set_scale(self, s: float) -> None:
        self.contact.scale.value = PETSc.ScalarType(s)
        self.contact.forget()

    def residual(self) -> float:
        self.problem.evaluate(self.x, self.F)
        return self.F.norm()

    def _contact_energy(self, v: PETSc.Vec, F: PETSc.Vec) -> tuple[float, float]:
        """(d . (K v - b), the contact energy at v); F = F(v)."""
        self.problem.evaluate(v, F)
        with self.j.localForm() as local:
            local.set(0.0)
        self.contact.add_residual(self.j)
        energy = MPI.COMM_WORLD.allreduce(fem.assemble_scalar(self._energy), op=MPI.SUM)
        return F.dot(self.d) - self.j.dot(self.d), energy

    def energy_change(self) -> float:
        """E(x + d) - E(x), the quadratic part from the residuals (no O(1/mu) cancellation)."""
        a, ex = self._contact_energy(self.x, self.F)
        self.y.waxpy(1.0, self.d, self.x)
        b, ey = self._contact_energy(self.y, self.G)
        self.problem.evaluate(self.x, self.F)
        return 0.5 * (a + b) + ey - ex

    def step(self, search: str = "none", eps: float = 0.0, label: str = "") -> None:
        """One Newton step from x: J at x (or at x lowered by eps: the points within eps of contact), then x += lam d."""
        problem = self.problem
        f0 = self.residual()
        if eps > 0.0:
            self.x.copy(self.y)
            self.y.array.reshape(-1, 3)[:, 2] -= eps  # the contact face is z = 0, its outer normal -e_z
            problem.update_jacobian(self.y)
        else:
            problem.update_jacobian(self.x)
        self.ksp.setOperators(problem.J, problem.J)
        self.ksp.solve(self.F, self.d)
        self.d.scale(-1.0)
        self.solves += 1
        lam = 1.0
        if search != "none":
            slope = self.F.dot(self.d)
            full = search == "accept" and self.energy_change() < 0.0
            if not full:
                lam = line_minimum(problem, self.x, self.d, self.y, self.G, slope, False)
        self.x.axpy(lam, self.d)
        if self.trace:
            print(f"  {label:8s} solve {self.solves:3d} |F| {f0:.3e} -> {self.residual():.3e} lam {lam:.3g} "
                  f"|d| {self.d.norm():.3e}", flush=True)

    def stiff(self, limit: int, search: str = "none", eps: float = 0.0, eps_steps: int = 0) -> None:
        """Steps on the level's own law until the solver's test or ``limit`` solves."""
        self.set_scale(1.0)
        k = 0
        while self.solves < limit and self.residual() > self.tol:
            self.step(search, eps if k < eps_steps else 0.0, "stiff")
            k += 1

    def path(self, search: str = "none") -> None:
        for r in RATIOS:
            self.set_scale(r / self.ratio)
            for _ in range(STAGE_ITERATIONS):
                self.step(search, label=f"s={r:g}")

    def predicted(self) -> None:
        """The solve without contact, then the start lifted by half the largest overlap (Hertz's zone)."""
        self.step(label="free")
        uz = self.x.array.reshape(-1, 3)[:, 2]
        depth = MPI.COMM_WORLD.allreduce(float(-uz.min()) if uz.size else 0.0, op=MPI.MAX)
        uz += 0.5 * depth


def run(strategy: str, msh: Path, limit: int, eps: float, eps_steps: int, trace: bool) -> dict:
    t = time.perf_counter()
    level = Level(msh, trace)
    if strategy in ("plain", "energy"):
        level.stiff(limit, "line" if strategy == "energy" else "none")
    elif strategy.startswith("path"):
        search = {"path": "none", "path_energy": "line", "path_accept": "line", "path_superset": "line"}[strategy]
        level.path(search)
        level.stiff(limit, "accept" if strategy == "path_accept" else search,
                    eps if strategy == "path_superset" else 0.0, eps_steps)
    else:
        level.predicted()
        level.stiff(limit, "line" if strategy == "predicted_energy" else "none")
    residual = level.residual()
    force = level.model.mech.diagnostics.row()["contact_force"]
    return {"strategy": strategy, "solves": level.solves, "converged": residual <= level.tol,
            "residual": residual, "contact_force": force, "seconds": time.perf_counter() - t}


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--h", type=float, default=0.03, help="mesh size at the contact")
    parser.add_argument("--strategies", nargs="*", default=list(STRATEGIES), choices=STRATEGIES)
    parser.add_argument("--max", type=int, default=60, help="solves at most")
    parser.add_argument("--eps", type=float, default=1e-7, help="path_superset's distance to contact")
    parser.add_argument("--eps-steps", type=int, default=10, help="path_superset's steps on the superset")
    parser.add_argument("--trace", action="store_true", help="print every solve")
    parser.add_argument("--out", default=str(ROOT / "benchmarks" / "results" / "first_contact_strategies"))
    args = parser.parse_args()
    msh = Path(tempfile.mkdtemp(prefix="strategies_")) / "hertz3d.msh"
    if MPI.COMM_WORLD.rank == 0:
        spec = importlib.util.spec_from_file_location("hertz3d_mesh", ROOT / "meshes" / "hertz3d.py")
        mesher = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(mesher)
        mesher.write(msh, args.h, size=2.0)
    MPI.COMM_WORLD.barrier()
    rows = []
    for strategy in args.strategies:
        print(f"{strategy} (h = {args.h})", flush=True)
        rows.append({"h": args.h, **run(strategy, msh, args.max, args.eps, args.eps_steps, args.trace)})
        print(rows[-1], flush=True)
    keys = ["h", "strategy", "solves", "converged", "residual", "contact_force", "seconds"]
    out = Path(f"{args.out}.csv")
    old = list(csv.DictReader(out.open())) if out.exists() else []
    old = [r for r in old if not (float(r["h"]) == args.h and r["strategy"] in args.strategies)]
    with out.open("w", newline="") as f:
        w = csv.DictWriter(f, keys)
        w.writeheader()
        for r in [*old, *rows]:
            w.writerow({k: r.get(k, "") for k in keys})
    table = list(csv.DictReader(out.open()))
    lines = ["# The 3-D sphere's first contact under other Newton strategies", "",
             "Written by `python benchmarks/first_contact_strategies.py --h H` (its docstring says what each strategy is).",
             "Solves: Jacobian solves from the level's start (each a factorization; every stage of a path counts), at",
             "most the run's `--max`; converged: ||F|| <= rtol * scale.", "",
             "| h | strategy | solves | converged | residual | contact force | seconds |", "|---|---|---|---|---|---|---|"]
    lines += [f"| {r['h']} | {r['strategy']} | {r['solves']} | {r['converged']} | {float(r['residual']):.2e} | "
              f"{float(r['contact_force']):.10e} | {float(r['seconds']):.0f} |" for r in table]
    Path(f"{args.out}.md").write_text("\n".join(lines) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
