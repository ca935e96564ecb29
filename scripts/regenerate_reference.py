"""Rewrite tests/data/example1_reference.json from the current code (after an intended change of the scheme).

    .venv/bin/python scripts/regenerate_reference.py [--check]

With --check it only prints the largest relative difference to the stored values.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))

import regression  # noqa: E402
from mpi4py import MPI  # noqa: E402

from solver.config import load  # noqa: E402
from solver.io.results import run  # noqa: E402
from solver.run.model import build_model


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--check", action="store_true", help="compare only; write nothing")
    args = p.parse_args()
    model = build_model(load(regression.SCENE, regression.OVERRIDES), MPI.COMM_WORLD)
    new = regression.quantities(model, run(model))
    old = regression.load() if regression.PATH.exists() else {}
    for key, value in new.items():
        was = old.get(key)
        vals, olds = (value, was) if isinstance(value, list) else ([value], [was] if was is not None else None)
        rel = max(abs(a - b) / max(abs(b), 1e-300) for a, b in zip(vals, olds)) if olds else float("nan")
        print(f"{key:14s} {value}  (relative change {rel:.1e})")
    if not args.check and MPI.COMM_WORLD.rank == 0:
        regression.PATH.write_text(json.dumps(new, indent=1) + "\n")
        print(f"wrote {regression.PATH}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
