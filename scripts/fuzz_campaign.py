"""A longer fuzz campaign over the scene loader, the command line and the result directories handed to plot and
paraview (issue 32); the test suite runs the same properties (tests/fuzzing.py, tests/fuzzing_results.py) with a
bounded number of examples.

    python scripts/fuzz_campaign.py --examples 2000 [--run] [--plot-examples N] [--paraview-examples M]
        [--properties scene,cli,plot,paraview] [--seed 1] [--output benchmarks/results/fuzz.json]

Every input is tried (defects are collected, not stopped at); prints and writes how many inputs were tried,
their outcomes and each distinct defect (first line)."""

from __future__ import annotations

import argparse
import json
import os
import sys
import tempfile
import time
from collections import Counter
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path[:0] = [str(ROOT), str(ROOT / "tests")]

from fuzzing import OVERRIDES, Defect, call_cli, check_one_line, scene_property, scenes  # noqa: E402
from fuzzing_results import DAMAGE_LISTS, PlotWorker, make_base, paraview_command, plot_command, results_property  # noqa: E402
from hypothesis import HealthCheck, given, seed, settings  # noqa: E402


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--examples", type=int, default=2000, help="inputs per property (scenes; command lines)")
    p.add_argument("--seed", type=int, default=1, help="hypothesis seed (a campaign is repeatable)")
    p.add_argument("--run", action="store_true", help="also run the tiny valid scenes (slower)")
    p.add_argument("--plot-examples", type=int, default=None, help="damaged result directories for plot "
                   "(default: --examples)")
    p.add_argument("--paraview-examples", type=int, default=30, help="damaged result directories for paraview "
                   "(each valid one starts ParaView: a few seconds)")
    p.add_argument("--properties", default="scene,cli,plot,paraview", help="which properties, comma-separated")
    p.add_argument("--output", type=Path, help="write the figures as JSON here")
    args = p.parse_args(argv)
    chosen = set(args.properties.split(","))
    outcomes: Counter = Counter()
    defects: dict[str, str] = {}
    harness: dict[str, str] = {}
    conf = settings(max_examples=args.examples, deadline=None, database=None, suppress_health_check=list(HealthCheck))

    def record(kind: str, fn) -> None:
        try:
            outcomes[f"{kind}:{fn()}"] += 1
        except Defect as exc:
            outcomes[f"{kind}:defect"] += 1
            first = str(exc).splitlines()[0] if str(exc) else repr(exc)
            key = first.split(": ", 2)[-1][:160]
            defects.setdefault(key, " | ".join(str(exc).splitlines())[:3000])  # what the user saw, on one line
        except Exception as exc:  # noqa: BLE001  (a bug of the fuzzer itself: counted apart, the campaign goes on)
            outcomes[f"{kind}:harness_error"] += 1
            harness.setdefault(f"{type(exc).__name__}: {exc}"[:300], kind)

    @seed(args.seed)
    @conf
    @given(doc=scenes(), overrides=OVERRIDES)
    def scene_case(doc, overrides):
        with tempfile.TemporaryDirectory() as tmp:
            record("scene", lambda: scene_property(doc, overrides, Path(tmp), run=args.run))

    from test_fuzz import ARGS

    @seed(args.seed)
    @conf
    @given(argv=ARGS)
    def cli_case(argv):
        if argv[:1] == ["run"] and "configs/example1.toml" in argv and "--tolerance" not in argv:
            argv = [*argv, "--set", "nosuch.key=1"]

        def one() -> str:
            with tempfile.TemporaryDirectory() as tmp:
                code, _, err = call_cli([a if a != "/" else tmp for a in argv])
            check_one_line(code, err, f"solver {argv!r}")
            return "ok" if code == 0 else "refused"

        record("cli", one)

    start = time.perf_counter()
    os.chdir(ROOT)
    if "scene" in chosen:
        scene_case()
    if "cli" in chosen:
        cli_case()
    with tempfile.TemporaryDirectory() as tmp:
        base = make_base(Path(tmp))
        for name in ("plot", "paraview"):
            if name in chosen:
                results_campaign(name, base, args, record)
    figures = {"examples_per_property": args.examples, "seed": args.seed, "run": args.run,
               "plot_examples": args.plot_examples or args.examples, "paraview_examples": args.paraview_examples,
               "properties": sorted(chosen),
               "inputs_tried": sum(outcomes.values()), "outcomes": dict(sorted(outcomes.items())),
               "defects": len(defects), "defect_messages": list(defects.values()),
               "harness_errors": [f"{kind}: {msg}" for msg, kind in harness.items()],
               "seconds": round(time.perf_counter() - start, 1)}
    text = json.dumps(figures, indent=1, ensure_ascii=False)
    print(text)
    if args.output:
        args.output.parent.mkdir(parents=True, exist_ok=True)
        args.output.write_text(text + "\n")
    return 1 if defects or harness else 0


def results_campaign(name: str, base: Path, args, record) -> None:
    """Damaged copies of the base results directory handed to ``solver plot`` (in a dolfinx-free worker process)
    or ``solver paraview`` (as a user runs it)."""
    worker = PlotWorker()
    command = plot_command(worker) if name == "plot" else paraview_command
    examples = (args.plot_examples or args.examples) if name == "plot" else args.paraview_examples
    conf = settings(max_examples=examples, deadline=None, database=None, suppress_health_check=list(HealthCheck))

    @seed(args.seed)
    @conf
    @given(damages=DAMAGE_LISTS)
    def case(damages):
        with tempfile.TemporaryDirectory() as tmp:
            record(name, lambda: results_property(base, damages, Path(tmp), command))

    try:
        case()
    finally:
        worker.close()


if __name__ == "__main__":
    sys.exit(main())
