"""How many forms FFCx compiles when a parameter users sweep changes between runs from Python, and what reaches stderr.

    python scripts/sweep_compilations.py [--output FILE]

Example 1 at 4 x 4, k = 0.25, run from solver.api with three values of each parameter (the contact compliance, E,
nu, the memory truncation L, the kernel weight, the traction): the C compilations of the second and third runs (0:
the forms compiled once) and the lines written to stderr. Run it in a fresh FFCx cache (XDG_CACHE_HOME=...) to
see the first run compile too (from a worktree other than the installed one: PYTHONPATH=. as well).
Figures: benchmarks/results/sweep_compilations.json (and _main_dfcb6a6.json, the tree before forms held them as
constants).
"""

from __future__ import annotations

import argparse
import contextlib
import json
import os
import sys
import tempfile
import time
from pathlib import Path

import ffcx.codegeneration.jit as jit

COUNT = {"n": 0}
_compile = jit._compile_objects


def _counted(*args, **kwargs):
    COUNT["n"] += 1
    return _compile(*args, **kwargs)


jit._compile_objects = _counted  # before the solver is imported: its quiet compile wraps this one

SWEEPS = {
    "boundary.bottom.mu": [{"boundary": {"bottom": {"mu": v}}} for v in (1e-8, 2e-8, 4e-8)],
    "material.E": [{"material": {"E": v}} for v in (100.0, 150.0, 200.0)],
    "material.nu": [{"material": {"nu": v}} for v in (0.3, 0.25, 0.2)],
    "memory.L": [{"memory": {"L": v}} for v in (1000.0, 500.0, 250.0)],
    "memory.weights": [{"memory": {"weights": [v]}} for v in (1.0, 0.5, 0.25)],
    "boundary.right.traction": [{"boundary": {"right": {"traction": [v, v]}}} for v in (-10.0, -5.0, -20.0)],
}


@contextlib.contextmanager
def _stderr_captured():
    """File descriptor 2 into a temporary file for the block (what any writer, gcc included, puts on stderr); the
    yielded list holds its text once the block is left."""
    text: list[str] = []
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "stderr"
        sys.stderr.flush()
        saved = os.dup(2)
        with open(path, "w") as fh:
            os.dup2(fh.fileno(), 2)
            try:
                yield text
            finally:
                sys.stderr.flush()
                os.dup2(saved, 2)
                os.close(saved)
        text.append(path.read_text())


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--output", type=Path, help="write the figures as JSON here")
    args = p.parse_args()
    from solver import api

    root = Path(__file__).resolve().parents[1]
    base = api.load(root / "configs" / "example1.toml").replace({"mesh": {"nx": 4, "ny": 4}, "time": {"k": 0.25}})
    out = {}
    for name, changes in SWEEPS.items():
        counts, times = [], []
        with _stderr_captured() as err:
            for change in changes:
                before, t0 = COUNT["n"], time.perf_counter()
                api.run(base.replace(change))
                counts.append(COUNT["n"] - before)
                times.append(round(time.perf_counter() - t0, 2))
        out[name] = {"compilations_per_run": counts, "seconds_per_run": times,
                     "stderr_lines": len("".join(err).splitlines())}
        print(f"{name}: compilations per run {counts}, seconds {times}, stderr lines "
              f"{out[name]['stderr_lines']}", flush=True)
    if args.output:
        args.output.write_text(json.dumps(out, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
