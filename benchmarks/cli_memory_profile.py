"""Where the CLI run's memory goes: the resident set after each set-up stage and the largest arrays it keeps.

``python benchmarks/cli_memory_profile.py --n 46 --steps 4`` runs ``solver run configs/example1_3d.toml`` in this
process (the same ``--set`` as benchmarks/cli_memory.py: iterative solver, k = 0.02, a checkpoint every 2 levels),
with the set-up's stages (mesh, damage, quadrature rule, memory source, history, mechanics, writers), each level
and each checkpoint wrapped, and each level's parts (memory commit, damage step, displacement solve, written
level): after each it prints the resident set (``/proc/self/status`` VmRSS), the run's peak so far, the peak since
the row above (VmHWM, reset at each row through ``/proc/self/clear_refs``: where the peak comes), glibc malloc's
bytes in use and free (mallinfo2) and, with ``--trace``, tracemalloc's current and peak (numpy's arrays; PETSc's own
memory does not show there). After the run it lists what the model still holds: every numpy array and scipy sparse matrix
reachable from it (by attribute path), every PETSc Mat (MatInfo's memory) and Vec, largest first.
Written to ``OUT/NAME.md`` (default benchmarks/results/cli_memory_profile.md). One process; nothing else heavy
beside it.
"""

from __future__ import annotations

import argparse
import ctypes
import functools
import gc
import math
import os
import subprocess
import sys
import tempfile
import time
import tracemalloc
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))  # this checkout's solver (the editable install may point at another)
SCENE = ROOT / "configs" / "example1_3d.toml"
MIB = 2.0 ** 20
LOG: list[str] = []
SNAPS: list = []  # the last stage's tracemalloc snapshot (--trace)
DIFFS: list[str] = []  # the largest changes of traced memory between stages, by line (--trace)


def status() -> tuple[float, float]:
    """VmRSS and VmHWM in MiB."""
    out = {}
    with open("/proc/self/status") as f:
        for line in f:
            if line.startswith(("VmRSS:", "VmHWM:")):
                out[line[:5]] = int(line.split()[1]) / 1024.0
    return out["VmRSS"], out["VmHWM"]


class _MallInfo2(ctypes.Structure):
    _fields_ = [(name, ctypes.c_size_t) for name in
                "arena ordblks smblks hblks hblkhd usmblks fsmblks uordblks fordblks keepcost".split()]


def heap() -> tuple[float, float, float]:
    """glibc's malloc: bytes in use (heap and mmapped) and free in the heap (allocated from the system, not in use:
    what a later malloc reuses before the resident set grows), MiB; NaN without glibc's mallinfo2."""
    try:
        libc = ctypes.CDLL("libc.so.6")
        libc.mallinfo2.restype = _MallInfo2
        m = libc.mallinfo2()
    except (OSError, AttributeError):
        return math.nan, math.nan, math.nan
    return (m.uordblks + m.hblkhd) / MIB, m.fordblks / MIB, m.hblkhd / MIB


PEAK = [0.0]  # the run's VmHWM so far (the kernel's is reset at each row)


def note(label: str) -> None:
    """A row: VmRSS, the run's peak so far, the peak since the last row (VmHWM, then reset by
    ``/proc/self/clear_refs``: when the peak came), malloc's bytes in use and free."""
    rss, hwm = status()
    PEAK[0] = max(PEAK[0], hwm)
    try:
        with open("/proc/self/clear_refs", "w") as f:
            f.write("5")  # VmHWM := VmRSS
    except OSError:
        pass
    used, free, _ = heap()
    line = f"| {label} | {rss:,.0f} | {PEAK[0]:,.0f} | {hwm:,.0f} | {used:,.0f} | {free:,.0f} |"
    if tracemalloc.is_tracing():
        cur, peak = tracemalloc.get_traced_memory()
        line += f" {cur / MIB:,.0f} | {peak / MIB:,.0f} |"
    LOG.append(line)
    print(line, flush=True)
    if tracemalloc.is_tracing():
        snap = tracemalloc.take_snapshot().filter_traces([tracemalloc.Filter(False, tracemalloc.__file__)])
        if SNAPS:
            for stat in snap.compare_to(SNAPS[-1], "traceback")[:5]:
                if abs(stat.size_diff) >= 2 * MIB:
                    DIFFS.append(f"| {label} | {stat.size_diff / MIB:+,.1f} | {where(stat.traceback)} |")
        SNAPS[:] = [snap]


def where(tb) -> str:
    """The innermost three frames of a traceback in this checkout (or the innermost frame), innermost first."""
    frames = [f for f in reversed(tb) if f.filename.startswith(str(ROOT))][:3] or [tb[-1]]
    return " < ".join(f"{f.filename.replace(str(ROOT) + '/', '')}:{f.lineno}" for f in frames)


def wrap(module, name: str, label: str | None = None) -> None:
    """Note the resident set after each call of ``module.name``."""
    fn = getattr(module, name)

    @functools.wraps(fn)
    def noted(*args, **kwargs):
        out = fn(*args, **kwargs)
        extra = ""
        if name == "step":
            extra = f" {args[1]}"
        note(f"after {label or name}{extra}")
        return out

    setattr(module, name, noted)


def mat_mib(A) -> float:
    """An AIJ matrix's arrays (values 8 B and column index 4 B per allocated entry, 16 B per row; PETSc's MatInfo
    memory is 0 without its malloc log)."""
    try:
        info = A.getInfo()
        return (12 * info["nz_allocated"] + 16 * A.getLocalSize()[0]) / MIB
    except Exception:  # noqa: BLE001  (a shell or a type without MatInfo)
        return 0.0


def solvers() -> list[tuple[float, str]]:
    """Every KSP alive (gc) with its operator and, for a multigrid preconditioner, its hierarchy's operators and
    interpolations: (MiB, what)."""
    from petsc4py import PETSc

    out = []
    objects = gc.get_objects()
    ksps = [o for o in objects if isinstance(o, PETSc.KSP)]
    ksps += [o.getKSP() for o in objects if isinstance(o, PETSc.SNES)]
    for ksp in ksps:
        try:
            A = ksp.getOperators()[0]
            pc = ksp.getPC()
            kind, prefix = pc.getType(), ksp.getOptionsPrefix()
            line = f"KSP {prefix} ({kind}) operator {A.getSize()}: {mat_mib(A):,.1f} MiB"
            total = 0.0
            if kind in ("gamg", "mg", "ml") and pc.getMGLevels() > 0:
                parts = []
                for level in range(pc.getMGLevels()):
                    Al = pc.getMGSmoother(level).getOperators()[0]
                    m = mat_mib(Al) if level < pc.getMGLevels() - 1 else 0.0  # the finest is the operator
                    if level > 0:
                        m += mat_mib(pc.getMGInterpolation(level))
                    total += m
                    parts.append(f"{Al.getSize()[0]}")
                line += f"; hierarchy ({' / '.join(parts)} rows): coarse operators and interpolations {total:,.1f} MiB"
            out.append((mat_mib(A) + total, line))
        except Exception as exc:  # noqa: BLE001
            out.append((0.0, f"KSP: {exc}"))
    return sorted(out, reverse=True)


def holdings(root, limit: int = 40) -> list[tuple[float, str, str]]:
    """(MiB, attribute path, kind) of the numpy arrays, scipy sparse matrices and PETSc objects reachable from
    ``root`` (each object once, under the first path found; breadth first)."""
    import scipy.sparse as sp
    from petsc4py import PETSc

    seen: set[int] = set()
    found: list[tuple[float, str, str]] = []
    queue = [(root, "model")]
    while queue:
        nxt = []
        for obj, path in queue:
            if id(obj) in seen or obj is None or isinstance(obj, (int, float, str, bytes, bool, type)):
                continue
            seen.add(id(obj))
            if isinstance(obj, np.ndarray):
                data = obj.__array_interface__["data"][0]
                if (obj.base is None or not isinstance(obj.base, np.ndarray)) and data not in seen:
                    seen.add(data)  # its own memory, or a C++ object's (listed once, under the first path)
                    found.append((obj.nbytes / MIB, path, f"ndarray {obj.dtype} {obj.shape}"))
                continue
            if sp.issparse(obj):
                nbytes = sum(getattr(obj, a).nbytes for a in ("data", "indices", "indptr", "row", "col")
                             if hasattr(obj, a))
                found.append((nbytes / MIB, path, f"sparse {obj.format} {obj.shape} nnz {obj.nnz}"))
                continue
            if isinstance(obj, PETSc.Mat):
                found.append((mat_mib(obj), path, f"PETSc Mat {obj.getType()} {obj.getSize()}"))
                continue
            if isinstance(obj, PETSc.Vec):
                found.append((obj.getLocalSize() * 8 / MIB, path, f"PETSc Vec {obj.getSize()}"))
                continue
            if isinstance(obj, PETSc.KSP):
                continue
            if isinstance(obj, dict):
                items = [(v, f"{path}[{k!r}]") for k, v in obj.items()]
            elif isinstance(obj, (list, tuple, set, frozenset)):
                items = [(v, f"{path}[{i}]") for i, v in enumerate(obj)]
            else:
                items = []
                d = getattr(obj, "__dict__", None)
                if d is not None:
                    items += [(v, f"{path}.{k}") for k, v in d.items()]
                for k in getattr(type(obj), "__slots__", ()):
                    if hasattr(obj, k):
                        items.append((getattr(obj, k), f"{path}.{k}"))
                if type(obj).__module__.startswith("dolfinx") and hasattr(obj, "x"):
                    try:
                        items.append((obj.x.array, f"{path}.x.array"))
                    except Exception:
                        pass
            nxt.extend(items)
        queue = nxt
    found.sort(reverse=True)
    return found[:limit]


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python benchmarks/cli_memory_profile.py", description=__doc__.splitlines()[0])
    p.add_argument("--n", type=int, default=46)
    p.add_argument("--steps", type=int, default=4)
    p.add_argument("--checkpoint-every", type=int, default=2)
    p.add_argument("--trace", action="store_true", help="tracemalloc too (slower; numpy's allocations)")
    p.add_argument("--set", action="append", default=[], help="more --set for the run")
    p.add_argument("--out", default=str(ROOT / "benchmarks" / "results"))
    p.add_argument("--name", default="cli_memory_profile")
    a = p.parse_args(argv)
    if a.trace:
        tracemalloc.start(8)
    note("start")
    import solver.cli as cli
    import solver.io.checkpoint as checkpoint
    import solver.io.results as results
    import solver.run.model as model_mod
    import solver.run.stepper as stepper

    note("imports")
    for name, label in (("build", "mesh (geometry.build)"), ("make_damage", "damage"), ("QuadratureRule", "rule"),
                        ("MemorySource", "memory source"), ("make_history", "history"),
                        ("build_mechanics", "mechanics")):
        wrap(model_mod, name, label)
    for name in ("Outputs", "CSVWriter", "ProfileWriter"):
        wrap(results, name)
    wrap(checkpoint, "write", "checkpoint")
    wrap(stepper.Stepper, "step", "level")
    import solver.io.fields as fields
    import solver.run.scheme as scheme

    for cls in (scheme.FirstOrderScheme, scheme.SecondOrderScheme):  # a level's parts, where the class has its own
        for name, label in (("memory", "memory commit"), ("damage", "damage step"),
                            ("displacement", "displacement solve")):
            if name in vars(cls):
                wrap(cls, name, label)
    wrap(fields.Outputs, "write", "written level")
    kept = {}
    build_model = model_mod.build_model

    def build_and_keep(*args, **kwargs):
        m = build_model(*args, **kwargs)
        kept["model"] = m
        core = getattr(m.mech.solver, "core", None)
        if core is not None:  # the resident set at the start of each Krylov solve (after its preconditioner's set-up)
            solves = [0]

            def monitor(ksp, its, rnorm):
                if its == 0:
                    solves[0] += 1
                    note(f"Krylov solve {solves[0]} begins")
            core.ksp.setMonitor(monitor)
        return m

    import solver.io.launch as launch
    launch.build_model = build_and_keep
    n, k = a.n, 0.02
    sets = [f"mesh.nx={n}", f"mesh.ny={n}", f"mesh.nz={n}", f"time.k={k}", f"time.T={k * a.steps}",
            "solver.linear='iterative'", f"output.checkpoint_every={a.checkpoint_every}", *a.set]
    t0 = time.perf_counter()
    with tempfile.TemporaryDirectory(dir=ROOT / "benchmarks") as tmp:
        code = cli.main(["run", str(SCENE), "--output", str(Path(tmp) / "run"), "--overwrite", "--no-progress",
                         *(x for s in sets for x in ("--set", s))])
    wall = time.perf_counter() - t0
    note("run returned")
    top = []
    if a.trace:
        snap = tracemalloc.take_snapshot()
        top = snap.statistics("traceback")[:15]
    gc.collect()
    held = holdings(kept["model"])
    ksps = solvers()
    commit = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=ROOT, capture_output=True,
                            text=True).stdout.strip()
    dofs = 3 * (n + 1) ** 3
    lines = [f"# Where the CLI run's memory goes (n = {n}, {dofs:,} dofs)", "",
             f"Command: `python benchmarks/cli_memory_profile.py --n {n} --steps {a.steps} --checkpoint-every "
             f"{a.checkpoint_every}{' --trace' if a.trace else ''}"
             f"{''.join(f' --set {s}' for s in a.set)}` ({time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())}, "
             f"commit {commit}, load average {' '.join(f'{x:.1f}' for x in os.getloadavg())}; exit {code}, "
             f"{wall:.0f} s).", "",
             "Resident set (VmRSS) after each stage, the run's peak so far, the peak since the row above (VmHWM, "
             "reset at each row through /proc/self/clear_refs: where the peak comes), and glibc malloc's bytes in use "
             "and free in its heap (mallinfo2: freed memory the process keeps and reuses), MiB"
             + (" (tracemalloc: numpy's and Python's allocations, current and peak)" if a.trace else "") + ":", "",
             "| after | VmRSS | peak so far | peak since the row above | malloc in use | malloc free |"
             + (" traced | traced peak |" if a.trace else ""),
             "|---|---|---|---|---|---|" + ("---|---|" if a.trace else ""), *LOG, "",
             "What the model holds after the run (reachable arrays and PETSc objects, largest first; a PETSc Mat as 12 B "
             "per allocated entry and 16 B per row; a preconditioner's hierarchy is listed below):", "",
             "| MiB | where | what |", "|---|---|---|",
             *(f"| {mib:,.1f} | `{path}` | {what} |" for mib, path, what in held), "",
             "The linear solvers alive after the run (a Mat as 12 B per allocated entry and 16 B per row):", "",
             *(f"- {line}" for _, line in ksps)]
    if DIFFS:
        lines += ["", "tracemalloc: the largest changes of live allocations in each stage, by line:", "",
                  "| stage | MiB | line |", "|---|---|---|", *DIFFS]
    if top:
        lines += ["", "tracemalloc's largest live allocations at the end, by line:", "", "| MiB | line |", "|---|---|",
                  *(f"| {s.size / MIB:,.1f} | {where(s.traceback)} |" for s in top)]
    text = "\n".join(lines) + "\n"
    out = Path(a.out)
    out.mkdir(parents=True, exist_ok=True)
    (out / f"{a.name}.md").write_text(text)
    print(text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
