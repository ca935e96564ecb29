"""Command line: python -m solver {run,check,plot,paraview} ...; runs under mpirun.

The studies and benchmarks behind the published figures are ``python -m studies`` in a checkout.

Bad input gives one line on stderr (rank 0 only) and exit code 2; a failed
solve exits 1 with the step, time and reason; results are never overwritten
without ``--overwrite``.
"""

from __future__ import annotations

import argparse
import importlib.util
import logging
import shlex
import signal
import sys
import time
from pathlib import Path
from typing import NoReturn

from mpi4py import MPI

from solver import __version__
from solver.config import load
from solver.config.accuracy import tolerance
from solver.config.fields import Ctx
from solver.config.memory import FITTED_KERNELS
from solver.errors import InputError, Interrupted, SolveFailure, UsageError
from solver.io import layout
from solver.run import formcache

log = logging.getLogger("solver")


def _setup_logging(comm: MPI.Comm, verbose: bool) -> None:
    """Our messages on rank 0 only; the form compiler's build chatter only with --verbose."""
    log.handlers.clear()
    handler = logging.StreamHandler(sys.stderr)
    handler.setFormatter(logging.Formatter("%(message)s"))
    log.addHandler(handler)
    log.propagate = False
    log.setLevel(logging.INFO if comm.rank == 0 else logging.ERROR)
    import ffcx  # noqa: F401  (calls logging.basicConfig() on import)

    # the JIT's distutils resets the root level to INFO at every compile: filter at the handler
    for h in logging.getLogger().handlers:
        h.setLevel(logging.DEBUG if verbose else logging.WARNING)
    formcache.show_compiler_output(verbose)


class OneLineParser(argparse.ArgumentParser):
    """An argparse parser whose mistakes are one line on stderr and exit code 2, like every other bad input.

    ``argv`` (set before parsing) lets a message add what was probably meant: ``--set time.k 0.01`` leaves
    ``0.01`` unrecognized, where ``--set time.k=0.01`` was meant."""

    argv: list[str] = []

    def error(self, message: str) -> NoReturn:
        hint = ""
        if message.startswith("unrecognized arguments"):
            loose = [v for o, v in zip(self.argv, self.argv[1:]) if o == "--set" and "=" not in v]
            if loose:
                at = self.argv.index(loose[0])
                value = self.argv[at + 1] if at + 1 < len(self.argv) else "VALUE"
                hint = f" (--set takes SECTION.KEY=VALUE as one word: --set {loose[0]}={value})"
        if MPI.COMM_WORLD.rank == 0:  # under mpirun, one line, not one per rank
            sys.stderr.write(f"error: {self.prog}: {message}{hint}; see {self.prog} --help\n")
        self.exit(2)


def _parser(argv: list[str] | None = None) -> argparse.ArgumentParser:
    OneLineParser.argv = list(argv or [])
    p = OneLineParser(prog="solver", description=__doc__.splitlines()[0])
    p.add_argument("--version", action="version", version=f"solver {__version__}")
    sub = p.add_subparsers(dest="command", required=True)

    r = sub.add_parser("run", help="run a scene and write its results")
    r.add_argument("config", help="scene file (TOML)")
    r.add_argument("--output", "-o", help="results directory (default: the scene's output.directory)")
    r.add_argument("--set", dest="overrides", action="append", default=[], metavar="SECTION.KEY=VALUE",
                   help="override a scene value, e.g. --set mesh.nx=64 --set time.k=0.002 (repeatable)")
    r.add_argument("--tolerance", metavar="TOL",
                   help="bound on the paper's error norm (accuracy.tolerance): the solver chooses mesh, degree and step")
    mode = r.add_mutually_exclusive_group()
    mode.add_argument("--overwrite", action="store_true",
                      help="replace earlier results in the output directory: removes only the files a run writes "
                           f"({layout.listing()}); anything else there is kept")
    mode.add_argument("--restart", action="store_true",
                      help="continue the run in the output directory from its last checkpoint")
    r.add_argument("--no-progress", action="store_true", help="no progress bar")
    r.add_argument("--verbose", "-v", action="store_true")

    sub.add_parser("plot", help="PNG pictures of a results directory (see plot --help)", add_help=False)
    sub.add_parser("paraview", help="render with ParaView's pvbatch (see paraview --help)", add_help=False)

    c = sub.add_parser("check", help="validate a scene without running it")
    c.add_argument("config")
    c.add_argument("--set", dest="overrides", action="append", default=[], metavar="SECTION.KEY=VALUE")
    return p


def _progress(comm: MPI.Comm, steps: int, enabled: bool, T: float | None = None):
    """The progress display: of the levels, or (``T`` given: adaptive steps) of the time."""
    if comm.rank != 0 or not enabled:
        return None, lambda row: None
    if not sys.stderr.isatty():
        return None, _log_lines(steps) if T is None else _log_time(T)
    from tqdm import tqdm  # only for a terminal's bar

    if T is not None:
        bar = tqdm(total=T, unit="s", dynamic_ncols=True, file=sys.stderr, mininterval=0.2,
                   bar_format="{l_bar}{bar}| t={n:.4g}/{total:.4g} [{elapsed}<{remaining}{postfix}]")
    else:
        bar = tqdm(total=steps + 1, unit="step", dynamic_ncols=True, file=sys.stderr, mininterval=0.2)

    def update(row: dict) -> None:
        if T is not None:
            bar.set_postfix_str(f"level {row['step']} k={row['k']:.3g} newton={row['newton_iterations']} "
                                f"zeta_min={row['zeta_min']:.4f}", refresh=False)
            bar.update(row["t"] - bar.n)
            return
        bar.set_postfix_str(f"t={row['t']:.4g} newton={row['newton_iterations']} zeta_min={row['zeta_min']:.4f}", refresh=False)
        bar.update(1)

    return bar, update


def _log_time(T: float):
    """Progress of an adaptive run for a log: one line every 10 % of the time."""
    done = [0]

    def update(row: dict) -> None:
        tenth = int(10 * row["t"] / T + 1e-9)
        if tenth > done[0]:
            done[0] = tenth
            log.info("%3d%% t=%.4g level %d k=%.3g newton=%d zeta_min=%.4f", 10 * tenth, row["t"], row["step"],
                     row["k"], row["newton_iterations"], row["zeta_min"])

    return update


def _log_lines(steps: int):
    """Progress for a log (stderr not a terminal): one whole line every 10 % of the levels, no redraws."""
    total, done = steps + 1, [0]

    def update(row: dict) -> None:
        before, done[0] = done[0], done[0] + 1
        if done[0] * 10 // total > before * 10 // total or done[0] == total:
            log.info("%3d%% level %d/%d: t=%.4g newton=%d zeta_min=%.4f", 100 * done[0] // total, done[0], total,
                     row["t"], row["newton_iterations"], row["zeta_min"])

    return update


WARN_OUTPUT_BYTES = 2 * 1024**3  # check warns above this estimate of a run's output


def _output_estimate(cfg, geo) -> tuple[int, int]:
    """(levels written, bytes) a run of cfg writes: each written level holds every chosen field (cells or nodes
    times components at the output precision) and every level a CSV row of about 400 bytes."""
    from solver.io.fields import KINDS
    from solver.run.stepper import writes_level

    d, steps = cfg.dim, cfg.time.steps
    levels = sum(writes_level(n, steps, cfg.output.every) for n in range(steps + 1)) if cfg.output.xdmf else 0
    nodes = geo.mesh.topology.index_map(0).size_global
    cells = geo.mesh.topology.index_map(d).size_global
    comps = {"Vector": 3, "Scalar": 1, "Tensor6": 6}
    per_level = sum((nodes if KINDS[f][0] == "Node" else cells) * comps[KINDS[f][1]] for f in cfg.output.fields)
    width = 4 if cfg.output.precision == "single" else 8
    return levels, levels * per_level * width + 400 * (steps + 1)


def cmd_check(args: argparse.Namespace, comm: MPI.Comm) -> int:
    """``solver check``: validate the scene against its mesh and print what a run would compute and write."""
    from dolfinx import fem

    from solver.mesh.geometry import build
    from solver.physics.operators import Dirichlet, check_rigid_motions

    cfg = load(args.config, args.overrides)
    # building the geometry also checks boundary names and intervals against the mesh,
    # and the Dirichlet parts against the rigid motions
    geo = build(comm, cfg.mesh, cfg.boundaries, cfg.dim)
    V = fem.VectorFunctionSpace(geo.mesh, ("CG", 1))
    check_rigid_motions(geo, V, Dirichlet(geo, V, cfg.boundaries))
    physics = ["elasticity"]
    if cfg.body_force.f:
        physics.append("body force")
    moving = [p.name for p in cfg.dirichlet if p.role == "displacement"]
    if moving:
        physics.append("displacement(" + ",".join(moving) + ")")
    if cfg.contact:
        physics.append("contact(" + ",".join(f"{p.name}:{p.law}" for p in cfg.contact) + ")")
    if cfg.memory.kernel in FITTED_KERNELS:
        fit = cfg.memory.fit(cfg.time.k, cfg.time.steps)
        physics.append(f"memory({cfg.memory.kernel} as {fit.terms} exponential terms, error {fit.error:.1e})")
    elif cfg.memory.kernel != "none":
        physics.append(f"memory({cfg.memory.kernel})")
    if cfg.damage.enabled:
        physics.append("damage")
    disc = cfg.discretization
    levels, size = _output_estimate(cfg, geo)
    if size > WARN_OUTPUT_BYTES:
        log.warning("warning: a run writes about %.1f GB (%d levels at output.every = %d): raise output.every, or "
                    "leave fields out with output.fields", size / 1e9, levels, cfg.output.every)
    if comm.rank == 0:  # the answer goes to stdout (warnings and errors to stderr)
        print(f"{args.config}: ok — {' + '.join(physics)}; u P{disc.u_degree}, zeta P{disc.zeta_degree}, "
              f"{cfg.time.steps} steps of k = {cfg.time.k:g} (order {cfg.time.order}); writes about "
              f"{size / 1e6:.3g} MB ({levels} levels)")
    return 0


def _scene(args: argparse.Namespace):
    """The scene with its ``--set`` overrides, and ``--tolerance`` as accuracy.tolerance (checked like the scene
    key, before the scene is read)."""
    if args.tolerance is None:
        return load(args.config, args.overrides)
    try:
        value = float(args.tolerance)
    except ValueError:
        raise UsageError(f"--tolerance {args.tolerance}: must be a number strictly between 0 and 1") from None
    value = tolerance(Ctx("--tolerance"), "tolerance", value)
    return load(args.config, args.overrides).replace({"accuracy": {"tolerance": value}}, label="--tolerance")


def cmd_run(args: argparse.Namespace, comm: MPI.Comm) -> int:
    """``solver run``: launch the scene in its results directory, run it with a progress display, report."""
    cfg = _scene(args)
    if args.output is not None and not args.output.strip():
        raise UsageError(f"--output {args.output!r}: empty; give a directory (or leave --output out to use the "
                         f"scene's output.directory = {cfg.output.directory!r})")
    outdir = Path(cfg.output.directory if args.output is None else args.output)
    from solver.io.launch import launch
    from solver.io.results import run

    formcache.install()  # compiled forms opened by file name, not found by listing FFCx's cache (start-up)
    start = time.perf_counter()
    # a restart's scene, then the model (geometry problems), then the directory: refusals before any file is made
    launched = launch(cfg, comm, outdir, args.overwrite, args.restart, args.overrides)
    cfg, model, plan, sensors = launched.config, launched.model, launched.plan, launched.sensors
    log.info("scene %s: %d cells, %d steps, %d process(es)", args.config, model.geo.num_cells(), cfg.time.steps,
             comm.size)
    fit = model.history.kernel_fit if model.history is not None else None
    if fit is not None:
        log.info("memory: the %s kernel as %s", cfg.memory.kernel, fit.summary())
    bar, update = _progress(comm, cfg.time.steps, not args.no_progress, cfg.time.T if cfg.time.adaptive else None)
    stop = _StopOnSignal()
    try:
        rows = run(model, outdir, on_step=update, restart=args.restart, sensors=sensors, stop=stop)
    except Interrupted as exc:
        if bar is not None:
            bar.close()
        how = shlex.join(["python", "-m", "solver", "run", args.config, "--output", str(outdir),
                          *(a for o in args.overrides for a in ("--set", o)), "--restart"])
        log.info("stopped by %s at the end of step %d (t = %g): results and a checkpoint up to there in %s; "
                 "continue with: %s", signal.Signals(exc.signal).name, exc.step, exc.t, outdir, how)
        return 128 + exc.signal
    finally:
        stop.restore()
        if bar is not None:
            bar.close()
    _report(rows, time.perf_counter() - start, plan, sensors, model, outdir)
    return 0


def _report(rows: list[dict], seconds: float, plan, sensors: tuple, model, outdir: Path) -> None:
    """The closing lines of a run: where it ended, the tolerance's estimate, where the results are."""
    last = rows[-1]
    log.info("done in %.1f s: t = %g, zeta_min = %.6g, contact force = %.6g", seconds,
             last["t"], last["zeta_min"], last["contact_force"])
    if plan is not None:
        largest = sensors[0].largest
        log.info("estimated error %.3e (space %.3e, time %.3e; max over levels) for tolerance %.3e: P%d, order %d, "
                 "k = %g, %d cells", largest.total, largest.space, largest.time, plan.tolerance, plan.degree,
                 plan.order, plan.k, model.geo.num_cells())
        for ingredient in plan.ingredients:
            log.info("  %s", ingredient.line(plan.tolerance))
        if largest.total > plan.tolerance:
            log.info("warning: the estimate over the run is above the tolerance (the growth measured on the start "
                     "mesh was too small); run again with a smaller tolerance")
    paraview = layout.SOLUTION + (f" and {layout.CONTACT_SERIES}" if (Path(outdir) / layout.CONTACT_SERIES).is_file() else "")
    log.info("results in %s (%s for ParaView, %s, %s)", outdir, paraview, layout.TIMESERIES, layout.CONFIG)


class _StopOnSignal:
    """SIGINT (Ctrl-C) and SIGTERM (a scheduler's warning before the time limit) ask the run to stop at the end
    of the current level (:func:`solver.io.results.run`'s ``stop``); a second one stops at once. mpirun kills
    its ranks on SIGINT/SIGTERM itself but forwards SIGUSR1: under mpirun send SIGUSR1 to mpirun, or the
    signal to the ranks (as a batch scheduler does)."""

    SIGNALS = (signal.SIGINT, signal.SIGTERM, signal.SIGUSR1)

    def __init__(self) -> None:
        self.signum = 0
        self.previous = {s: signal.signal(s, self._handle) for s in self.SIGNALS}

    def _handle(self, signum: int, frame) -> None:
        if self.signum:
            raise KeyboardInterrupt  # the second: now (main() reports it in one line)
        self.signum = signum

    def __call__(self) -> int:
        return self.signum

    def restore(self) -> None:
        for s, handler in self.previous.items():
            signal.signal(s, handler)


def _installed(module: str) -> bool:
    try:
        return importlib.util.find_spec(module) is not None
    except ValueError:  # already imported as None (how a test hides a module)
        return False


def main(argv: list[str] | None = None) -> int:
    comm = MPI.COMM_WORLD
    argv = sys.argv[1:] if argv is None else argv
    _setup_logging(comm, "-v" in argv or "--verbose" in argv)
    if argv[:1] == ["paraview"]:
        from solver.post.paraview import main as paraview_main

        return paraview_main(argv[1:])
    if argv[:1] == ["plot"]:
        missing = [m for m in ("matplotlib", "pyvista") if not _installed(m)]
        if missing and sys.prefix == sys.base_prefix:  # not a virtual environment: not the project's Python
            print(f"error: plot needs {' and '.join(missing)}, which this Python ({sys.executable}) does not see: "
                  "run the project's environment, .venv/bin/python -m solver plot (make install makes it)",
                  file=sys.stderr)
            return 2
        if missing:
            print(f"error: plot needs {' and '.join(missing)}, which this installation leaves out (a slim image, or "
                  "make install PLOTS=0): install the plotting extra (make install PLOTS=1), or plot with the full "
                  "image", file=sys.stderr)
            return 2
        from solver.post.plots import main as plot_main

        return plot_main(argv[1:])
    args = _parser(argv).parse_args(argv)
    try:
        if args.command == "check":
            return cmd_check(args, comm)
        return cmd_run(args, comm)
    except InputError as exc:
        if comm.rank == 0:
            print(f"error: {exc}", file=sys.stderr)
        return 2
    except SolveFailure as exc:
        if comm.rank == 0:
            print(f"failed: {exc}", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        if comm.rank == 0:
            print("stopped at once (a second interrupt): the results up to the last checkpoint are kept; "
                  "continue with --restart", file=sys.stderr)
        return 128 + signal.SIGINT
