"""Do two trees give the same results? Runs a matrix of scenes and methods through the CLI, then compares.

A refactoring must leave every result as it was: the time series, the contact profile and the written fields
of each case, to a relative tolerance (1e-12 by default), serially and on 2 ranks. The cases are the shipped
scenes at small sizes with every contact method that applies (``fixed_point`` and ``penalty_duality`` are 2-D).

    python scripts/same_results.py run --out /tmp/after [--nproc 2] [--only hard]
    python scripts/same_results.py run --out /tmp/before --src CHECKOUT_OF_THE_BASE   # the base's code
    python scripts/same_results.py compare /tmp/before /tmp/after [--rtol 1e-12] [--results-only]

``run`` runs each case with ``python -m solver run`` of ``--src`` (this tree by default, the interpreter being
this one); ``compare`` prints a row per case and exits 1 if any differs or is missing. Timings are not compared.
"""

from __future__ import annotations

import argparse
import csv
import os
import subprocess
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
P2 = ["discretization.u_degree=2", "discretization.zeta_degree=2", "time.order=2"]
SMALL_2D = ["mesh.nx=8", "mesh.ny=8"]
# scene file, overrides, 2-D (the point-based methods apply)
SCENES: dict[str, tuple[str, list[str], bool]] = {
    "example1": ("example1.toml", [*SMALL_2D, "time.k=0.02"], True),
    "example1_p2": ("example1.toml", [*SMALL_2D, *P2, "time.k=0.05"], True),
    # a soft foundation, where the fixed-point methods converge
    "example1_soft": ("example1.toml", [*SMALL_2D, "time.k=0.05", "boundary.bottom.mu=1.0", "solver.max_it=200"], True),
    "limited": ("example1.toml", [*SMALL_2D, "time.k=0.05", "boundary.bottom.law='limited_penetration'",
                                  "boundary.bottom.mu=1e-6", "boundary.bottom.depth=1e-7", "boundary.bottom.mu_stiff=1e-10"],
                True),
    "trapezoid": ("example1.toml", [*SMALL_2D, "time.k=0.05", "memory.rule='trapezoid'"], True),
    "plane_strain": ("example1.toml", [*SMALL_2D, "time.k=0.05", "material.model='plane_strain'"], True),
    "example2": ("example2.toml", [*SMALL_2D, "time.T=0.2"], True),
    "example3": ("example3.toml", [*SMALL_2D, "time.T=0.2"], True),
    "hard": ("hard.toml", ["time.T=0.6", "time.k=0.02"], True),
    "hard_p2": ("hard.toml", [*P2, "time.T=0.5", "time.k=0.025"], True),
    "load_cycle": ("load_cycle.toml", [*SMALL_2D, "time.T=0.5"], True),
    "foundation": ("foundation.toml", ["time.T=0.2"], True),
    "example1_3d": ("example1_3d.toml", ["mesh.nx=4", "mesh.ny=4", "mesh.nz=4", "time.T=0.2"], False),
    "column3d": ("column3d.toml", ["time.T=0.1"], False),
}
METHODS = ["newton", "newton_energy", "newton_condensed", "auto", "fixed_point", "penalty_duality"]
POINT_METHODS = {"fixed_point", "penalty_duality"}
TIMING = ("time_", "wall_time")


def cases(only: list[str], methods: list[str] | None = None) -> dict[str, tuple[str, list[str]]]:
    out = {}
    for name, (scene, sets, planar) in SCENES.items():
        if only and not any(o in name for o in only):
            continue
        for method in methods or METHODS:
            if method in POINT_METHODS and not planar:
                continue
            out[f"{name}-{method}"] = (scene, [*sets, f"solver.method='{method}'", "output.every=5"])
    return out


def run(args: argparse.Namespace) -> int:
    src = Path(args.src).resolve()
    env = {**os.environ, "PYTHONPATH": str(src)}
    launch = [sys.executable] if args.nproc == 1 else ["mpirun", "-n", str(args.nproc), sys.executable]
    failed = 0
    for name, (scene, sets) in cases(args.only, args.methods).items():
        out = Path(args.out) / name
        cmd = [*launch, "-m", "solver", "run", str(src / "configs" / scene), "--output", str(out), "--overwrite",
               "--no-progress", *(a for s in sets for a in ("--set", s))]
        done = subprocess.run(cmd, env=env, cwd=src, capture_output=True, text=True)
        status = "ok" if done.returncode == 0 else f"exit {done.returncode}: {done.stderr.strip().splitlines()[-1:]}"
        failed += done.returncode != 0
        out.mkdir(parents=True, exist_ok=True)
        (out / "exit_code").write_text(str(done.returncode))
        (out / "last_error").write_text(done.stderr.strip().splitlines()[-1] if done.returncode else "")
        print(f"{name}: {status}", flush=True)
    return 0 if failed == 0 else 1


def _csv(path: Path) -> dict[str, np.ndarray]:
    if not path.exists():
        return {}
    with path.open() as f:
        rows = list(csv.DictReader(f))
    if {"x", "y", "z"} <= set(rows[0] if rows else ()):
        # a profile's points in a fixed order: ranks gather points of equal s (a 3-D face) in any order
        rows.sort(key=lambda r: (float(r["step"]), r["part"], *(round(float(r[c]), 9) for c in "xyz")))
    cols = {}
    for key in rows[0] if rows else []:
        try:
            cols[key] = np.array([float(r[key]) for r in rows])
        except ValueError:
            cols[key] = np.array([r[key] for r in rows])
    return cols


def _fields(folder: Path) -> dict[str, np.ndarray]:
    import h5py

    out: dict[str, np.ndarray] = {}
    for path in sorted(folder.glob("**/*.h5")):
        if path.name == "checkpoint.h5":
            continue
        with h5py.File(path, "r") as f:
            f.visititems(lambda key, obj, p=path: out.__setitem__(f"{p.relative_to(folder)}:{key}", obj[()])
                         if isinstance(obj, h5py.Dataset) else None)
    return out


def _worst(a: np.ndarray, b: np.ndarray, scale: float | None = None) -> float:
    """Largest difference relative to the quantity's scale (by default its largest magnitude in the base)."""
    if a.shape != b.shape:
        return np.inf
    if a.dtype.kind not in "fiu":
        return 0.0 if np.array_equal(a, b) else np.inf
    a, b = a.astype(float), b.astype(float)
    if not np.array_equal(np.isnan(a), np.isnan(b)):
        return np.inf
    a, b = np.nan_to_num(a, nan=0.0), np.nan_to_num(b, nan=0.0)
    scale = max(np.abs(b).max(initial=0.0) if scale is None else scale, np.finfo(float).tiny)
    return float(np.abs(a - b).max(initial=0.0) / scale)


def _shared_scale(cols: dict[str, np.ndarray], key: str) -> float | None:
    """The scale a column is measured against where its own would mislead: a point's coordinates and a vector's
    components share theirs (a coordinate or component that is zero up to round-off varies from run to run on 2
    ranks), and the forces of a level share one (reactions, the contact force, the final residual, a force norm)."""
    stem, _, last = key.rpartition("_")
    if key in ("x", "y", "z"):
        group = ["x", "y", "z"]
    elif key.startswith("reaction_") or key in ("contact_force", "residual"):
        group = [k for k in cols if k.startswith("reaction_") or k in ("contact_force", "residual")]
    elif last in ("x", "y", "z"):
        group = [f"{stem}_{c}" for c in "xyz"]
    else:
        return None
    parts = [cols[k] for k in group if k in cols and cols[k].dtype.kind == "f"]
    return max(float(np.nanmax(np.abs(p), initial=0.0)) for p in parts) if parts else None


# the solver's own counters and its final residual: what a change of method changes while the results stay
SOLVER_COUNTS = ("newton_iterations", "linear_solves", "factorizations", "krylov_iterations", "residual")


def compare_case(base: Path, new: Path, skip: tuple[str, ...] = ()) -> tuple[float, str]:
    """(the worst relative difference, where) of one case; inf where something is missing or shaped otherwise."""
    for folder in (base, new):
        if not (folder / "exit_code").exists():
            return np.inf, f"{folder} did not run"
    codes = [(f / "exit_code").read_text() for f in (base, new)]
    if codes != ["0", "0"]:  # a failure is the same result where both fail with the same message
        errors = [(f / "last_error").read_text() for f in (base, new)]
        same = codes[0] == codes[1] and errors[0] == errors[1]
        return (0.0 if same else np.inf), f"exit {codes[0]} / {codes[1]}: {errors[1][:80]}"
    worst, where = 0.0, ""
    for name in ("timeseries.csv", "contact.csv"):
        a, b = _csv(new / name), _csv(base / name)
        if set(a) != set(b):
            return np.inf, f"{name}: columns {sorted(set(a) ^ set(b))}"
        for key in b:
            if key.startswith(TIMING) or key in skip:
                continue
            if key == "s" and "z" in b and np.any(b["z"] != 0.0):
                continue  # "s along the part" on a 3-D face depends on the order ranks gather its points in
            d = _worst(a[key], b[key], _shared_scale(b, key))
            if d > worst:
                worst, where = d, f"{name}:{key}"
    fa, fb = _fields(new), _fields(base)
    if set(fa) != set(fb):
        return np.inf, f"fields {sorted(set(fa) ^ set(fb))[:4]}"
    for key in fb:
        d = _worst(fa[key], fb[key])
        if d > worst:
            worst, where = d, key
    return worst, where


def compare(args: argparse.Namespace) -> int:
    base, new = Path(args.base), Path(args.new)
    names = sorted({p.name for p in base.iterdir() if p.is_dir()} | {p.name for p in new.iterdir() if p.is_dir()})
    ran = [n for n in names if (base / n / "exit_code").exists() and (new / n / "exit_code").exists()]
    bad = 0
    for name in ran:
        worst, where = compare_case(base / name, new / name, SOLVER_COUNTS if args.results_only else ())
        ok = worst <= args.rtol
        bad += not ok
        print(f"{'same' if ok else 'DIFFERS'}  {name:36s} {worst:9.2e}  {where}")
    missing = sorted(set(names) - set(ran))
    print(f"{len(ran) - bad} same, {bad} differ (rtol {args.rtol:g}); {len(missing)} run in one folder only")
    return 0 if bad == 0 and ran and not (args.all and missing) else 1


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    sub = parser.add_subparsers(dest="command", required=True)
    r = sub.add_parser("run", help="run the cases into --out")
    r.add_argument("--out", required=True)
    r.add_argument("--src", default=str(ROOT), help="the tree whose solver runs (default: this one)")
    r.add_argument("--nproc", type=int, default=1)
    r.add_argument("--only", nargs="*", default=[], help="cases whose name contains one of these")
    r.add_argument("--methods", nargs="*", choices=METHODS, help="only these methods (default: every one)")
    c = sub.add_parser("compare", help="compare two --out folders")
    c.add_argument("base")
    c.add_argument("new")
    c.add_argument("--rtol", type=float, default=1e-12)
    c.add_argument("--all", action="store_true", help="fail where a case ran in one folder only")
    c.add_argument("--results-only", action="store_true",
                   help="leave out the solver's counters and final residual (a change of method: the same results)")
    args = parser.parse_args(argv)
    return run(args) if args.command == "run" else compare(args)


if __name__ == "__main__":
    sys.exit(main())
