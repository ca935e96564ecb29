"""What a big gap table costs the whole command: Example 1 with a constant gap against the same gap as a table of
``--rows`` rows, given inline in the scene and as a CSV file, each ``solver run`` timed from start to exit.

The three runs alternate (constant, inline, CSV, constant, ...) for ``--rounds`` rounds on the noisy shared machine;
the report gives each table run's ratio to the constant run of its round (median, min–max) and the largest
difference of the written fields (displacement, damage) between a table run and the constant one, relative to the
field's largest value. Writes ``NAME.json`` and ``NAME.md`` to ``--output``.

    python scripts/table_speed.py --rows 100001 --n 16 --steps 20 --rounds 7
"""

from __future__ import annotations

import argparse
import json
import os
import shlex
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]


def _scenes(tmp: Path, rows: int) -> dict[str, Path]:
    """Example 1's scene with its gap 0 as a number, as an inline table and as a CSV file of ``rows`` rows."""
    base = (ROOT / "configs" / "example1.toml").read_text()
    assert "gap = 0.0\n" in base
    s = np.linspace(0.0, 1.0, rows).tolist()
    (tmp / "profile.csv").write_text("x,g\n" + "".join(f"{a!r},0.0\n" for a in s))
    table = "[" + ", ".join(f"[{a!r}, 0.0]" for a in s) + "]"
    out = {"constant": tmp / "constant.toml", "inline": tmp / "inline.toml", "csv": tmp / "csv.toml"}
    out["constant"].write_text(base)
    out["inline"].write_text(base.replace("gap = 0.0\n", f"gap = {table}\n"))
    out["csv"].write_text(base.replace("gap = 0.0\n", 'gap = {file = "profile.csv", columns = ["x", "g"]}\n'))
    return out


def _once(scene: Path, out: Path, sets: list[str]) -> float:
    cmd = [sys.executable, "-m", "solver", "run", str(scene), "--output", str(out), "--overwrite", "--no-progress",
           *(a for s in sets for a in ("--set", s))]
    t0 = time.perf_counter()
    subprocess.run(cmd, env={**os.environ, "PYTHONPATH": str(ROOT)}, cwd=ROOT, check=True, capture_output=True)
    return time.perf_counter() - t0


def _difference(a: Path, b: Path) -> float:
    """Largest |a − b| over the written displacement and damage at every level, relative to max |a|."""
    from solver.post.results import read_results

    ra, rb = read_results(a), read_results(b)
    worst = 0.0
    for field in ("displacement", "damage"):
        fa, fb = ra["fields"][field], rb["fields"][field]
        assert list(fa) == list(fb), field
        scale = max(float(np.abs(v).max()) for v in fa.values()) or 1.0
        worst = max(worst, max(float(np.abs(fa[t] - fb[t]).max()) for t in fa) / scale)
    return worst


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rows", type=int, default=100_001)
    ap.add_argument("--n", type=int, default=16)
    ap.add_argument("--steps", type=int, default=20)
    ap.add_argument("--rounds", type=int, default=7)
    ap.add_argument("--name", default="gap_table_cli")
    ap.add_argument("--output", type=Path, default=ROOT / "benchmarks" / "results")
    args = ap.parse_args(argv)
    k = 0.01
    sets = [f"mesh.nx={args.n}", f"mesh.ny={args.n}", f"time.k={k}", f"time.T={args.steps * k}"]
    with tempfile.TemporaryDirectory() as tmpdir:
        tmp = Path(tmpdir)
        scenes = _scenes(tmp, args.rows)
        for name, scene in scenes.items():  # the form cache warm for all
            _once(scene, tmp / f"out_{name}", sets)
        times: dict[str, list[float]] = {name: [] for name in scenes}
        for r in range(args.rounds):
            for name, scene in scenes.items():
                times[name].append(_once(scene, tmp / f"out_{name}", sets))
            print(f"round {r + 1}: " + ", ".join(f"{n} {t[-1]:.2f} s" for n, t in times.items()), flush=True)
        diffs = {name: _difference(tmp / "out_constant", tmp / f"out_{name}") for name in ("inline", "csv")}
    rows = {}
    for name in ("inline", "csv"):
        pairs = [a / b for a, b in zip(times[name], times["constant"], strict=True)]
        rows[name] = {"median_s": statistics.median(times[name]), "ratio_median": statistics.median(pairs),
                      "ratio_min": min(pairs), "ratio_max": max(pairs), "difference": diffs[name]}
    result = {"rows": args.rows, "n": args.n, "steps": args.steps, "rounds": args.rounds,
              "constant_median_s": statistics.median(times["constant"]), "times": times, "tables": rows}
    args.output.mkdir(parents=True, exist_ok=True)
    (args.output / f"{args.name}.json").write_text(json.dumps(result, indent=1))
    lines = [f"# A {args.rows}-row gap table against a constant gap: the whole `solver run`", "",
             "`python scripts/table_speed.py " + shlex.join(argv if argv is not None else sys.argv[1:]) + "`", "",
             f"Example 1 at n = {args.n}, {args.steps} steps (its default outputs: every level written), "
             f"{args.rounds} alternated rounds (constant, inline, CSV); constant gap: median "
             f"{result['constant_median_s']:.2f} s.", "",
             "| gap | median (s) | ratio to the constant gap's run (min–max) | largest field difference |",
             "|---|---|---|---|"]
    for name, row in rows.items():
        lines.append(f"| {name} table | {row['median_s']:.2f} | {row['ratio_median']:.3f} "
                     f"({row['ratio_min']:.2f}–{row['ratio_max']:.2f}) | {row['difference']:.1e} |")
    (args.output / f"{args.name}.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines[-3:]))
    return 0


if __name__ == "__main__":
    sys.exit(main())
