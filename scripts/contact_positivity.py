"""The reported contact pressure on the shipped scenes: its smallest value over Γ_C against its peak at every written
level, and its lumped integral against the contact force (contact.csv, timeseries.csv).

    python scripts/contact_positivity.py [--quick] [--out benchmarks/results/contact_positivity.md]

Runs each of configs/{example1,example2,example3,hard,load_cycle,example1_3d,column3d}.toml (``--quick``: coarser
meshes and fewer levels for the costly ones) in a temporary directory with every level written, then reads the
files back. The issue's target: min p >= -1e-8 x peak at every level.
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from solver.post.results import read_csv, read_profile  # noqa: E402

SCENES = ("example1", "example2", "example3", "hard", "load_cycle", "example1_3d", "column3d")
QUICK = {"hard": ["time.T=0.2"], "load_cycle": ["time.T=0.5"],
         "example1_3d": ["mesh.nx=6", "mesh.ny=6", "mesh.nz=6", "time.T=0.2"], "column3d": ["time.T=0.2"]}


def measure(scene: str, quick: bool) -> dict:
    """Run one scene (every level written) and read its pressure back."""
    sets = ["output.every=1", "output.xdmf=false"] + (QUICK.get(scene, []) if quick else [])
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "r"
        cmd = [sys.executable, "-m", "solver", "run", f"configs/{scene}.toml", "--output", str(out), "--no-progress"]
        for s in sets:
            cmd += ["--set", s]
        start = time.perf_counter()
        res = subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True)
        if res.returncode != 0:
            raise RuntimeError(f"{scene}: {res.stderr[-2000:]}")
        rows = {int(r["step"]): r for r in read_csv(out / "timeseries.csv")}
        profile = read_profile(out / "contact.csv")
    worst, levels, peak_max = np.inf, set(), 0.0
    by_level: dict[int, list] = {}
    for (step, _), cols in profile.items():
        by_level.setdefault(step, []).append(cols)
    for step, parts in by_level.items():
        p = np.concatenate([c["pressure"] for c in parts])
        peak = float(p.max())
        levels.add(step)
        peak_max = max(peak_max, peak)
        if peak > 0:
            worst = min(worst, float(p.min()) / peak)
    return {"scene": scene, "sets": " ".join(sets[2:]) or "-", "levels": len(levels), "peak": peak_max,
            "worst": worst, "force": max(r["contact_force"] for r in rows.values()), "seconds": time.perf_counter() - start}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="coarser meshes and fewer levels for the costly scenes")
    ap.add_argument("--out", type=Path, default=ROOT / "benchmarks" / "results" / "contact_positivity.md")
    ap.add_argument("--scenes", nargs="*", default=list(SCENES))
    args = ap.parse_args(argv)
    lines = ["| scene | overrides | written levels | largest peak | min p / peak (worst level) | largest force | run (s) |",
             "|---|---|---|---|---|---|---|"]
    ok = True
    for scene in args.scenes:
        r = measure(scene, args.quick)
        ok &= r["worst"] >= -1e-8
        lines.append(f"| {r['scene']} | {r['sets']} | {r['levels']} | {r['peak']:.4g} | {r['worst']:.3g} | "
                     f"{r['force']:.4g} | {r['seconds']:.0f} |")
        print(lines[-1], flush=True)
    text = (f"# Reported contact pressure: min over Γ_C / peak, every written level\n\n"
            f"`python scripts/contact_positivity.py{' --quick' if args.quick else ''}`\n\n" + "\n".join(lines) + "\n\n"
            f"Target min p >= -1e-8 x peak: {'met' if ok else 'NOT met'} on every scene and level.\n")
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(text)
    print(f"wrote {args.out}")
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
