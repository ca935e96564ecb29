"""How often pvbatch under the private Xvfb crashes: the same render many times, several at once, with the virtual
display's options as shipped and with the server's reset on last close (the options without ``-noreset``).

    python scripts/paraview_renders.py [--renders 8] [--at-once 3] [--name paraview_renders]

Makes a tiny 3-D result (example1_3d, 3 x 3 x 3, two steps), then for each variant runs ``--at-once`` loops of
``--renders`` renders (``python -m solver paraview``'s ``main`` in a new process each, the variant's options set in
it), and counts the renders whose first attempt crashed (the "retrying" line) and those that failed after the retry.
Writes NAME.json and NAME.md under benchmarks/results.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
RENDER = ("import sys; import solver.post.paraview as spv; spv.XVFB_OPTIONS = tuple(sys.argv[1].split()); "
          "sys.exit(spv.main(sys.argv[2:]))")


def _loop(options: str, results: Path, png: Path, renders: int) -> list[tuple[int, bool]]:
    out = []
    for i in range(renders):
        res = subprocess.run([sys.executable, "-c", RENDER, options, str(results), "--output", f"{png}_{i}.png",
                              "--size", "600", "400"], cwd=ROOT, capture_output=True, text=True, timeout=600)
        out.append((res.returncode, "retrying once" in res.stderr))
    return out


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--renders", type=int, default=8)
    p.add_argument("--at-once", type=int, default=3)
    p.add_argument("--name", default="paraview_renders")
    args = p.parse_args(argv)
    sys.path.insert(0, str(ROOT))
    import solver.post.paraview as spv

    shipped = " ".join(spv.XVFB_OPTIONS)
    variants = {"shipped": shipped, "with reset": " ".join(o for o in spv.XVFB_OPTIONS if o != "-noreset")}
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        results = Path(tmp) / "r"
        subprocess.run([sys.executable, "-m", "solver", "run", "configs/example1_3d.toml", "--output", str(results),
                        "--no-progress", "--set", "time.T=0.1", "--set", "time.k=0.05", "--set", "mesh.nx=3",
                        "--set", "mesh.ny=3", "--set", "mesh.nz=3"], cwd=ROOT, check=True, capture_output=True)
        for name, options in variants.items():
            with ThreadPoolExecutor(args.at_once) as pool:
                futures = [pool.submit(_loop, options, results, Path(tmp) / f"{name[0]}{j}", args.renders)
                           for j in range(args.at_once)]
                loops = [f.result() for f in futures]
            runs = [r for loop in loops for r in loop]
            rows.append({"variant": name, "options": options, "renders": len(runs),
                         "first_attempt_crashed": sum(retried for _, retried in runs),
                         "failed": sum(code != 0 for code, _ in runs)})
            print(rows[-1], flush=True)
    out = ROOT / "benchmarks" / "results"
    (out / f"{args.name}.json").write_text(json.dumps(rows, indent=1) + "\n")
    lines = [f"# pvbatch under the private Xvfb: {args.at_once} loops at once, {args.renders} renders each",
             "", f"`python scripts/paraview_renders.py --renders {args.renders} --at-once {args.at_once}`", "",
             "| Xvfb options | renders | first attempt crashed | failed after the retry |", "|---|---|---|---|"]
    lines += [f"| `{r['options']}` ({r['variant']}) | {r['renders']} | {r['first_attempt_crashed']} | {r['failed']} |"
              for r in rows]
    (out / f"{args.name}.md").write_text("\n".join(lines) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
