"""The damage step's right-hand side assembled as one form and a block of cells at a time, side by side.

``python benchmarks/damage_rhs_blocks.py --n 32 --rounds 7`` builds 3-D Example 1's damage step (configs/example1_3d.toml
on the n x n x n box, u a smooth field) and times, alternated in each round, dolfinx's one-form assembly of its source
(``fpetsc.assemble_vector(b, damage.rhs_form)``: every cell's coefficients packed at once) and the blocked one the
step uses (``damage.rhs_blocks.assemble(b)``, :mod:`solver.physics.cell_blocks`); it checks the two vectors are equal
bit for bit and reports the median ratio blocked / one form and its range. Written to ``OUT/damage_rhs_blocks.md``
(default benchmarks/results). One process; run nothing else heavy beside it.
"""

from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))  # this checkout's solver


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python benchmarks/damage_rhs_blocks.py", description=__doc__.splitlines()[0])
    p.add_argument("--n", type=int, default=32)
    p.add_argument("--rounds", type=int, default=7)
    p.add_argument("--out", default=str(ROOT / "benchmarks" / "results"))
    a = p.parse_args(argv)

    import numpy as np
    from dolfinx.fem import petsc as fpetsc
    from mpi4py import MPI

    from solver.config import load
    from solver.run.model import build_model

    cfg = load(ROOT / "configs" / "example1_3d.toml", [f"mesh.nx={a.n}", f"mesh.ny={a.n}", f"mesh.nz={a.n}",
                                                       "solver.linear='iterative'"])
    model = build_model(cfg, MPI.COMM_WORLD)
    model.u.interpolate(lambda x: np.vstack([0.01 * x[0] * x[1], 0.02 * np.sin(x[2]), -0.01 * x[0] ** 2]))
    damage = model.damage
    one, blocked = damage.b.duplicate(), damage.b.duplicate()
    times: dict[str, list[float]] = {"one form": [], "blocks": []}
    for _ in range(a.rounds):
        for name, vec, assemble in (("one form", one, lambda v: fpetsc.assemble_vector(v, damage.rhs_form)),
                                    ("blocks", blocked, damage.rhs_blocks.assemble)):
            with vec.localForm() as local:
                local.set(0.0)
            t0 = time.perf_counter()
            assemble(vec)
            times[name].append(time.perf_counter() - t0)
    same = bool(np.array_equal(one.array, blocked.array))
    ratios = [b / o for b, o in zip(times["blocks"], times["one form"])]
    cells = model.geo.mesh.topology.index_map(3).size_global
    commit = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=ROOT, capture_output=True,
                            text=True).stdout.strip()
    text = "\n".join([
        "# The damage source assembled as one form and in blocks of cells", "",
        f"Command: `python benchmarks/damage_rhs_blocks.py --n {a.n} --rounds {a.rounds}` "
        f"({time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())}, commit {commit}, load average "
        f"{' '.join(f'{x:.1f}' for x in os.getloadavg())}).", "",
        f"3-D Example 1's damage step on the {a.n}^3 box ({cells:,} tetrahedra, {len(damage.rhs_blocks.forms)} blocks "
        "of at most 65,536 cells), alternated in each round; median [min, max].", "",
        "| assembly | time (ms) |", "|---|---|",
        *(f"| {k} | {1e3 * statistics.median(v):,.1f} [{1e3 * min(v):,.1f}, {1e3 * max(v):,.1f}] |"
          for k, v in times.items()),
        "", f"Blocks / one form: **{statistics.median(ratios):.2f}** [{min(ratios):.2f}, {max(ratios):.2f}]; "
        f"the two vectors equal bit for bit: {same}.", ""])
    out = Path(a.out)
    out.mkdir(parents=True, exist_ok=True)
    (out / "damage_rhs_blocks.md").write_text(text)
    print(text)
    return 0 if same else 1


if __name__ == "__main__":
    raise SystemExit(main())
