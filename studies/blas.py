"""Which BLAS this process runs on, so that no speed figure is reported silently on netlib's reference BLAS.

Every MUMPS factorization, dense numpy product and LAPACK call goes through the ``libblas.so.3`` the dynamic
loader picked (Debian's alternatives, or ``LD_LIBRARY_PATH``). On the reference BLAS a 107k-dof MUMPS Cholesky
is about 8x slower than on OpenBLAS (issue 30), so a benchmark names the library it ran on and refuses to run
on the reference one unless told to (``--allow-reference-blas``).

The library is read from ``/proc/self/maps`` after numpy and PETSc are loaded (they bring in BLAS), resolved
through its symbolic links; for OpenBLAS its configuration string and thread count come from the library itself.
"""

from __future__ import annotations

import ctypes
import os
import re
import sys
from dataclasses import asdict, dataclass

# a mapped file that is a BLAS: its basename (libblas.so.3, libopenblas.so.0, libmkl_rt.so, libblis.so.4, ...)
_BLAS_FILE = re.compile(r"lib(open)?blas[a-z0-9_]*[.-]|libmkl_rt|libblis|libflexiblas")
# what each kind is called in the reports; "reference" is netlib's (Debian's libblas3)
KINDS = ("openblas", "mkl", "blis", "flexiblas", "reference", "unknown")
ALLOW_FLAG = "--allow-reference-blas"


@dataclass(frozen=True)
class BlasInfo:
    """The BLAS a process runs on: kind (one of KINDS), the resolved library files, OpenBLAS's config and threads."""

    kind: str
    libraries: tuple[str, ...]
    config: str = ""
    threads: int | None = None

    def label(self) -> str:
        """One line for a report: e.g. 'openblas (OpenBLAS 0.3.21 DYNAMIC_ARCH ..., 1 thread)'."""
        extra = ", ".join(x for x in (self.config, f"{self.threads} thread(s)" if self.threads else "") if x)
        where = ", ".join(self.libraries) or "no BLAS mapped"
        return f"{self.kind} ({extra}; {where})" if extra else f"{self.kind} ({where})"

    def as_dict(self) -> dict:
        return asdict(self)


def classify(path: str) -> str:
    """The kind of a resolved BLAS library file (its real path, links followed)."""
    name = path.lower()
    for kind in ("openblas", "mkl", "blis", "flexiblas"):
        if kind in name:
            return kind
    # Debian's netlib BLAS: /usr/lib/<triplet>/blas/libblas.so.3.x (Fedora etc.: /usr/lib64/libblas.so.3.x)
    if re.search(r"/libblas\.so(\.\d+)*$", name):
        return "reference"
    return "unknown"


def mapped_blas(maps: str) -> tuple[str, ...]:
    """The BLAS library files named in a /proc/<pid>/maps text, links resolved, in order of first mapping."""
    seen: dict[str, None] = {}
    for line in maps.splitlines():
        parts = line.split(maxsplit=5)
        if len(parts) == 6 and parts[5].startswith("/") and _BLAS_FILE.search(os.path.basename(parts[5])):
            seen.setdefault(os.path.realpath(parts[5]), None)
    return tuple(seen)


def _openblas_details(path: str) -> tuple[str, int | None]:
    """OpenBLAS's own configuration string and thread count (empty, None if it does not export them)."""
    try:
        lib = ctypes.CDLL(path)
        lib.openblas_get_config.restype = ctypes.c_char_p
        return lib.openblas_get_config().decode().strip(), int(lib.openblas_get_num_threads())
    except (OSError, AttributeError):
        return "", None


def detect(load: bool = True) -> BlasInfo:
    """The BLAS of this process. ``load``: import numpy and petsc4py first (what the solver's runs load)."""
    if load:
        import numpy  # noqa: F401
        from petsc4py import PETSc  # noqa: F401
    with open("/proc/self/maps") as f:
        libs = mapped_blas(f.read())
    kinds = [classify(p) for p in libs]
    # an optimized library anywhere wins the name: OpenBLAS's libblas.so.3 is that library, and a process
    # may also map netlib's CBLAS wrapper beside it; reference only when nothing else is there
    kind = next((k for k in KINDS if k in kinds), "unknown")
    config, threads = ("", None)
    if kind == "openblas":
        config, threads = _openblas_details(libs[kinds.index("openblas")])
    return BlasInfo(kind, libs, config, threads)


def require_optimized(info: BlasInfo, allow: bool, what: str) -> bool:
    """False (and one line on stderr) when ``info`` is the reference BLAS and ``allow`` is not set."""
    if info.kind != "reference" or allow:
        return True
    print(f"error: {what}: the BLAS is netlib's reference BLAS ({', '.join(info.libraries)}), about 8x slower than "
          f"OpenBLAS for factorizations; install the project with `make install` (Debian's libopenblas0-serial), "
          f"or pass {ALLOW_FLAG} to measure on it anyway (the reports then say so)", file=sys.stderr)
    return False


def report_line(info: dict | None) -> str:
    """The line a report opens with: the BLAS its figures were measured on (loudly if the reference one)."""
    if not info:
        return "BLAS: not recorded (measured before the benchmarks named their BLAS)."
    b = BlasInfo(info["kind"], tuple(info["libraries"]), info.get("config", ""), info.get("threads"))
    if b.kind == "reference":
        return f"**BLAS: netlib's reference BLAS** ({', '.join(b.libraries)}): factorizations and dense products are " \
               f"several times slower than on OpenBLAS ({ALLOW_FLAG})."
    return f"BLAS: {b.label()}."


# ----------------------------------------------------------------------------------------------- comparison
# ``python -m studies bench --blas DIR ...`` (or ``python -m studies.blas compare DIR ...``): the same work on
# each BLAS, alternated, in fresh processes whose loader finds the library in DIR first (LD_LIBRARY_PATH;
# "system" = the alternatives' choice): a dense numpy product and the plain-elasticity MUMPS Cholesky of
# studies/anchor.py. Written to blas.md / blas.json.
PRODUCT = ("import time, numpy as np; a = np.random.default_rng(0).random((1500, 1500)); a @ a; t = time.perf_counter(); "
           "a @ a; print(time.perf_counter() - t)")


def _run_on(directory: str, cmd: list[str], env_extra: dict[str, str]) -> str:
    import subprocess

    env = dict(os.environ, **env_extra)
    if directory != "system":
        env["LD_LIBRARY_PATH"] = os.pathsep.join(x for x in (directory, env.get("LD_LIBRARY_PATH", "")) if x)
    res = subprocess.run(cmd, capture_output=True, text=True, env=env, check=True)
    return res.stdout.strip().splitlines()[-1]


def compare(directories: list[str], n: int, reps: int, threads: str | None) -> list[dict]:
    """Median product and factorization times per library, runs alternated A B A B over ``reps`` rounds."""
    import json
    import statistics

    env = {"OPENBLAS_NUM_THREADS": threads} if threads else {}
    probe = [sys.executable, "-c", "import json; from studies.blas import detect; print(json.dumps(detect().as_dict()))"]
    rows = [{"directory": d, "blas": json.loads(_run_on(d, probe, env)), "product_s": [], "factor_s": []}
            for d in directories]
    for _ in range(reps):
        for row in rows:
            row["product_s"].append(float(_run_on(row["directory"], [sys.executable, "-c", PRODUCT], env)))
            case = json.loads(_run_on(row["directory"], [sys.executable, "-m", "studies.anchor", str(n), "mumps"], env))
            row["factor_s"].append(case["setup_s"])
            row.update(dofs=case["dofs"], norm_u=case["norm_u"])
    for row in rows:
        row["product_median_s"] = statistics.median(row["product_s"])
        row["factor_median_s"] = statistics.median(row["factor_s"])
    return rows


def compare_table(rows: list[dict], n: int, reps: int, threads: str | None) -> str:
    base = rows[0]
    lines = [f"# BLAS against BLAS: one process, {reps} alternated rounds, medians", "",
             f"Command: `python -m studies.blas compare --n {n} --reps {reps} "
             f"{'--threads ' + threads + ' ' if threads else ''}DIR ...`. Dense product: numpy 1500 x 1500 @ 1500 x 1500. "
             f"Factorization: MUMPS Cholesky of the plain elasticity cube n = {n} ({rows[0].get('dofs', 0):,} dofs, "
             "studies/anchor.py, ICNTL(14) = 50, default ordering). Ratios to the first row.", "",
             "| BLAS | threads | product (s) | ratio | factorization (s) | ratio | all runs: product; factorization (s) "
             "| norm of u |", "|---|---|---|---|---|---|---|---|"]
    for r in rows:
        b = r["blas"]
        name = b["kind"] + (f" ({os.path.basename(r['directory'])})" if r["directory"] != "system" else " (system)")
        runs = ", ".join(f"{x:.3g}" for x in r["product_s"]) + "; " + ", ".join(f"{x:.3g}" for x in r["factor_s"])
        lines.append(f"| {name} | {b.get('threads') or 1} | {r['product_median_s']:.3g} "
                     f"| {r['product_median_s'] / base['product_median_s']:.2f} | {r['factor_median_s']:.3g} "
                     f"| {r['factor_median_s'] / base['factor_median_s']:.2f} | {runs} | {r['norm_u']:.15g} |")
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    import argparse
    import json
    from pathlib import Path

    p = argparse.ArgumentParser(prog="python -m studies bench --blas", description="the same work on several BLAS")
    p.add_argument("command", choices=["compare"], help=argparse.SUPPRESS)
    p.add_argument("directories", nargs="+", help="directories holding a libblas.so.3 (system: the installed choice)")
    p.add_argument("--n", type=int, default=22, help="cube size of the factorization (3 (n+1)^3 dofs)")
    p.add_argument("--reps", type=int, default=3)
    p.add_argument("--threads", default=None, help="OPENBLAS_NUM_THREADS for every run (default: the library's own)")
    p.add_argument("--output", default=None, help="directory for blas.md and blas.json (default: print only)")
    a = p.parse_args(argv)
    rows = compare(a.directories, a.n, a.reps, a.threads)
    text = compare_table(rows, a.n, a.reps, a.threads)
    print(text)
    if a.output:
        Path(a.output, "blas.md").write_text(text)
        Path(a.output, "blas.json").write_text(json.dumps(rows, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
