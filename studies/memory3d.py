"""Where the memory of a 3-D run goes: resident set by stage, the arrays and PETSc matrices the model holds.

``python -m studies.memory3d N [SOLVER]`` builds 3-D Example 1 on the n x n x n box (one process), runs level 0
and two steps as the CLI does (its outputs and a checkpoint; ``--no-outputs``: the levels alone), and reports per
displacement dof: the resident set after the imports, after build_model, after each level and its writing
(VmRSS; VmHWM the peak), the numpy/scipy arrays reachable from the model (largest
first), and every PETSc matrix alive (nonzeros x 12 bytes + row pointers). The plain-elasticity anchor
(studies/anchor.py) of the same size is the yardstick: run it beside, ``python -m studies.anchor N gamg``.
Written to ``benchmarks/results/memory_3d.md`` with ``--output``.
"""

from __future__ import annotations

import argparse
import gc
import sys
from pathlib import Path

import numpy as np

from studies import REPO as ROOT


def _status(key: str) -> float:
    """A /proc/self/status entry in MiB (VmRSS: resident now, VmHWM: its peak)."""
    with open("/proc/self/status") as f:
        for line in f:
            if line.startswith(key + ":"):
                return int(line.split()[1]) / 1024.0
    return float("nan")


def _allocated(a: np.ndarray) -> int:
    """Bytes of the buffer an array keeps alive: its base's, for a view (a slice keeps all of its base)."""
    while isinstance(a.base, np.ndarray):
        a = a.base
    return a.nbytes


def arrays_held(obj, path: str = "model", seen: set | None = None, depth: int = 0) -> dict[str, int]:
    """Bytes of the numpy arrays, scipy sparse matrices and dolfinx Function arrays reachable from the
    solver's objects (attributes, lists, dicts), by attribute path."""
    import scipy.sparse as sp
    from dolfinx import fem

    seen = set() if seen is None else seen
    if id(obj) in seen or depth > 6:
        return {}
    seen.add(id(obj))
    if isinstance(obj, np.ndarray):
        return {path: _allocated(obj)}
    if sp.issparse(obj):
        return {path: sum(_allocated(getattr(obj, a)) for a in ("data", "indices", "indptr", "row", "col") if hasattr(obj, a))}
    if isinstance(obj, fem.Function):
        return {path + ".x": _allocated(obj.x.array)}
    items = (enumerate(obj) if isinstance(obj, (list, tuple)) else obj.items() if isinstance(obj, dict)
             else vars(obj).items() if type(obj).__module__.startswith("solver") and hasattr(obj, "__dict__") else ())
    out: dict[str, int] = {}
    for k, o in items:
        out.update(arrays_held(o, f"{path}[{k!r}]" if not hasattr(obj, "__dict__") else f"{path}.{k}", seen, depth + 1))
    return out


def petsc_matrices() -> list[tuple[str, tuple[int, int], int]]:
    """(type, size, bytes) of every assembled AIJ matrix alive in this process."""
    from petsc4py import PETSc

    out = []
    for o in gc.get_objects():
        if isinstance(o, PETSc.Mat):
            try:
                info, size = o.getInfo(), o.getSize()
                out.append((o.getType(), size, int(info["nz_allocated"] * 12 + size[0] * 4)))
            except PETSc.Error:
                continue
    return out


def measure(n: int, linear: str, outputs: bool = True) -> dict:
    """The stages, arrays and matrices of one run (level 0 and two steps of k = 0.02). ``outputs``: run as the CLI
    does (:func:`solver.io.results.run` into a temporary directory: solution.xdmf, contact.xdmf, the CSVs and a
    checkpoint after level 1); else the solver's levels alone, nothing written."""
    import shutil
    import tempfile

    from mpi4py import MPI

    from solver.config import load
    from solver.io.launch import directed
    from solver.io.layout import prepare
    from solver.io.results import run
    from solver.run.model import build_model
    from solver.run.stepper import levels

    stages = {"imports": _status("VmRSS")}
    cfg = load(ROOT / "configs" / "example1_3d.toml", [f"mesh.nx={n}", f"mesh.ny={n}", f"mesh.nz={n}", "time.k=0.02",
                                                        "time.T=0.04", f"output.xdmf={str(outputs).lower()}",
                                                        "output.checkpoint_every=1", f"solver.linear='{linear}'"])
    tmp = Path(tempfile.mkdtemp(prefix="memory3d_")) if outputs else None
    try:
        if tmp is not None:
            cfg = directed(cfg, tmp)
        model = build_model(cfg, MPI.COMM_SELF)
        stages["build_model"] = _status("VmRSS")
        if tmp is not None:
            prepare(MPI.COMM_SELF, tmp, True, False)

            def written(row: dict) -> None:
                stages[f"level {row['step']} (written)"] = _status("VmRSS")

            run(model, tmp, on_step=written)
        else:
            for i, _ in enumerate(levels(model)):
                stages[f"level {i}"] = _status("VmRSS")
        stages["peak (VmHWM)"] = _status("VmHWM")
    finally:
        if tmp is not None:
            shutil.rmtree(tmp, ignore_errors=True)
    return {"n": n, "solver": model.linear, "outputs": outputs,
            "dofs": model.u.function_space.dofmap.index_map.size_global * 3,
            "stages_mib": stages, "arrays": arrays_held(model), "matrices": petsc_matrices()}


def report(m: dict, output: str = "benchmarks/results") -> str:
    dofs = m["dofs"]
    per = lambda mib: f"{mib * 2 ** 20 / dofs:,.0f}"  # noqa: E731
    flag = "" if m.get("outputs", False) else " --no-outputs"
    lines = [f"# Memory of 3-D Example 1, n = {m['n']} ({dofs:,} dofs), {m['solver']}, one process", "",
             f"Command: `python -m studies.memory3d {m['n']} {m['solver']}{flag} --output {output}`"
             + (" (the CLI's writing: solution.xdmf, contact.xdmf, the CSVs, a checkpoint after level 1)." if not flag
                else " (nothing written)."), "",
             "| stage | resident (MiB) | growth over the previous stage (B/dof) |", "|---|---|---|"]
    prev = None
    for stage, mib in m["stages_mib"].items():
        lines.append(f"| {stage} | {mib:,.0f} | {per(mib - prev) if prev is not None and 'peak' not in stage else '-'} |")
        prev = mib
    arrays = sorted(m["arrays"].items(), key=lambda kv: -kv[1])
    lines += ["", f"Arrays reachable from the model: {sum(v for _, v in arrays) / dofs:,.0f} B/dof in all.", "",
              "| array | MiB | B/dof |", "|---|---|---|"]
    lines += [f"| `{k}` | {v / 2 ** 20:.1f} | {v / dofs:,.0f} |" for k, v in arrays if v / dofs >= 5]
    mats = m["matrices"]
    lines += ["", f"PETSc matrices alive: {sum(b for *_, b in mats) / dofs:,.0f} B/dof in all "
              "(nonzeros x 12 B + row pointers; the preconditioner's own hierarchy is not a Mat object of Python's).", "",
              "| type | size | B/dof |", "|---|---|---|"]
    lines += [f"| {t} | {s[0]:,} x {s[1]:,} | {b / dofs:,.0f} |" for t, s, b in sorted(mats, key=lambda x: -x[2])]
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m studies.memory3d", description=__doc__.splitlines()[0])
    p.add_argument("n", type=int, help="box size (3 (n+1)^3 dofs)")
    p.add_argument("solver", nargs="?", default="iterative", choices=["iterative", "mumps", "petsc"])
    p.add_argument("--no-outputs", action="store_true", help="the solver's levels alone, nothing written")
    p.add_argument("--output", default=None, help="directory for memory_3d.md (default: print only)")
    a = p.parse_args(argv)
    if a.n < 1:
        print(f"error: n {a.n}: must be >= 1", file=sys.stderr)
        return 2
    text = report(measure(a.n, a.solver, not a.no_outputs), a.output or "DIR")
    print(text)
    if a.output:
        Path(a.output, "memory_3d.md").write_text(text)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
