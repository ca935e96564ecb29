"""Newton iterations per level on the moving-contact scenes, two trees one after the other (docs/model.md §4).

    python benchmarks/moving_contact_iterations.py --base CHECKOUT_OF_THE_BASE [--out PATH_WITHOUT_SUFFIX]

Each scene is run under the default settings (``auto``) at P2, order 2, with ``python -m solver run`` of the base
tree then of this one (each tree on PYTHONPATH, cwd its root), scene after scene, on the same machine in the same
run: configs/moving_contact.toml at n = 32 and configs/hard.toml at n = 48. Writes OUT.csv (scene, tree, total
Newton iterations, largest on a level, the levels above 10 as level:iterations) from each run's timeseries.csv and
prints it. Iteration counts only: no timing is compared here.
"""

from __future__ import annotations

import argparse
import csv
import os
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
P2 = ["discretization.u_degree=2", "discretization.zeta_degree=2", "time.order=2", "output.xdmf=false"]
SCENES = {"moving_contact_n32": ("configs/moving_contact.toml", 32), "hard_n48": ("configs/hard.toml", 48)}


def run(tree: Path, scene: str, n: int, out: Path) -> list[int]:
    """The Newton iterations of every level of ``scene`` at n by the solver of ``tree``."""
    sets = [*P2, f"mesh.nx={n}", f"mesh.ny={n}", f"output.directory='{out}'"]
    cmd = [sys.executable, "-m", "solver", "run", str(tree / scene)]
    for s in sets:
        cmd += ["--set", s]
    subprocess.run(cmd, cwd=tree, env={**os.environ, "PYTHONPATH": str(tree)}, check=True, capture_output=True)
    with open(out / "timeseries.csv", newline="") as f:
        return [int(row["newton_iterations"]) for row in csv.DictReader(f)]


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--base", required=True, help="a checkout of the base tree")
    parser.add_argument("--out", default=str(ROOT / "benchmarks" / "results" / "moving_contact_iterations_runs"))
    args = parser.parse_args()
    work = Path(tempfile.mkdtemp(prefix="moving_contact_"))
    rows = []
    for name, (scene, n) in SCENES.items():
        for tree, src in (("base", Path(args.base).resolve()), ("this", ROOT)):
            its = run(src, scene, n, work / f"{name}_{tree}")
            above = " ".join(f"{i}:{k}" for i, k in enumerate(its) if k > 10)
            rows.append({"scene": name, "tree": tree, "total": sum(its), "largest": max(its), "above_10": above})
            print(rows[-1], flush=True)
    with open(f"{args.out}.csv", "w", newline="") as f:
        w = csv.DictWriter(f, list(rows[0]))
        w.writeheader()
        w.writerows(rows)
    return 0


if __name__ == "__main__":
    sys.exit(main())
