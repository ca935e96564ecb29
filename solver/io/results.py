"""A run written to a results directory: the fields, the CSV time series, checkpoints and restart.

:func:`run` drives :func:`solver.run.stepper.levels` and writes what it yields into the files
:mod:`solver.io.layout` names: ``solution.xdmf`` + ``fields/`` (sigma_n = A eps(u_n) + M_n and the rest,
:mod:`solver.io.fields`), ``timeseries.csv`` (one row a level), ``contact.csv`` (the contact results along Γ_C at
each written level, :mod:`solver.io.contact_profile`; scenes with contact), ``config.toml`` (the resolved
scene; a first comment line gives the terms and kernel error of a tabulated or power kernel's sum of exponentials)
and ``checkpoint.h5`` every ``output.checkpoint_every`` levels. The directory is prepared before
(:func:`solver.io.layout.prepare`).
"""

from __future__ import annotations

import time
from collections.abc import Callable
from pathlib import Path

from mpi4py import MPI

from solver.config.scene import dumps_referring
from solver.config.tables import write_copy
from solver.errors import Interrupted, OutputError, SolveFailure
from solver.io import checkpoint
from solver.io.contact_profile import ProfileWriter
from solver.io.fields import Outputs
from solver.io.files import on_rank0, write_text_atomic
from solver.io.layout import ResultsDir, timeseries_columns
from solver.io.timeseries import CSVWriter
from solver.run.adaptive import StepController, output_times
from solver.run.model import Model
from solver.run.stepper import levels, writes_level, written_levels


def run(model: Model, outdir: Path | None = None, on_step: Callable[[dict], None] | None = None,
        restart: bool = False, sensors: tuple = (), stop: Callable[[], int] | None = None) -> list[dict]:
    """Run the model's scene; write results to ``outdir`` (None: nothing written). Returns the rows.

    With ``restart``, the state is loaded from ``outdir``'s checkpoint and the run continues
    after it: the CSV keeps its rows up to the checkpoint, the XDMF series its levels up to
    it, and the new levels are appended. A write that fails (a full disk) stops the run with
    an OutputError that knows the step; what was written before stays readable.

    ``sensors``: as for :func:`solver.run.stepper.levels`; their columns go to the CSV too.

    ``stop``: asked after every level (a signal's number, 0 to go on; the ranks agree by a max-reduction):
    when it answers, the run ends there as if that level were the last written one (series, CSV, and a
    checkpoint of that level) and raises :class:`Interrupted`, which ``--restart`` continues.
    """
    cfg, comm = model.cfg, model.comm
    steps = cfg.time.steps
    clock = StepController(model) if cfg.time.adaptive else None
    start, part, keep, keep_until = 0, 0, None, None
    if restart:
        ckpt = checkpoint.read(outdir, model, clock)
        start, part, keep_until = ckpt.step + 1, ckpt.part, ckpt.t
        if comm.rank == 0:
            keep = _csv_lines_until(ResultsDir(outdir).timeseries, ckpt.step)
    writers = _Writers(model, outdir, sensors, keep, keep_until, start - 1 if restart else None)
    rows: list[dict] = []
    finished, interrupted = False, None
    try:
        for row in levels(model, start, sensors, clock=clock):
            n = row["step"]
            last = row["t"] >= cfg.time.T if clock is not None else n == steps
            try:
                writers.level(row, last)
                rows.append(row)
                if writers.every_ckpt and not last and n % writers.every_ckpt == 0:
                    writers.out.flush()  # a checkpoint never runs ahead of the listed series
                    checkpoint.write(outdir, model, n, row["t"], part, clock)
            except SolveFailure as exc:
                raise _located(exc, n, row["t"], cfg.time.k) from None
            if on_step is not None:
                on_step(row)
            signum = comm.allreduce(stop(), op=MPI.MAX) if stop is not None and not last else 0
            if signum:
                interrupted = _stop_here(writers.out, outdir, model, n, row["t"], part, signum, clock)
                break
        try:
            writers.out.close()
        except SolveFailure as exc:
            raise _located(exc, steps, steps * cfg.time.k, cfg.time.k) from None
        finished = True
    finally:
        writers.close(finished)
    if interrupted is not None:
        raise interrupted
    return rows


class _Writers:
    """What a run writes at a level: the fields (XDMF), the contact profile, the CSV row; config.toml at the start.

    ``keep``/``keep_until``/``profile_until``: a restart's CSV lines, series levels and profile levels to keep."""

    def __init__(self, model: Model, outdir: Path | None, sensors: tuple, keep: list[str] | None,
                 keep_until: float | None, profile_until: int | None) -> None:
        cfg, comm = model.cfg, model.comm
        self.comm, self.steps, self.every = comm, cfg.time.steps, cfg.output.every
        self.marks = set(output_times(cfg)) if cfg.time.adaptive else set()  # the times an adaptive run writes
        self.adaptive = cfg.time.adaptive  # its levels are not the scene's steps: its chunks sized as before
        files = ResultsDir(outdir) if outdir is not None else None
        if files is not None:
            fit = model.history.kernel_fit if model.history is not None else None
            head = f"# memory.kernel = {cfg.memory.kernel!r} runs as {fit.summary()}\n" if fit is not None else ""
            on_rank0(comm, lambda: _write_scene(files, cfg, head))
        self.out = Outputs(model, cfg.material, cfg.output, outdir if cfg.output.xdmf else None, keep_until)
        columns = timeseries_columns(model, sensors)
        self.csv = CSVWriter(files.timeseries, comm, keep=keep, columns=columns) if files is not None else None
        traces = model.mech.diagnostics.traces
        self.profile = (ProfileWriter(files.contact, comm, traces, profile_until)
                        if files is not None and traces is not None else None)
        self.every_ckpt = cfg.output.checkpoint_every if outdir is not None else 0

    def level(self, row: dict, last: bool) -> None:
        """Write level ``row["step"]`` where it is written (``last``: the run's last level); its output time goes
        to the row."""
        n, t0 = row["step"], time.perf_counter()
        if writes_level(n, n if last else -1, self.every) or row["t"] in self.marks:
            self.out.write(row["t"], None if self.adaptive else self.left(n))
            if self.profile is not None:
                self.profile.write(n, row["t"])
        row["time_output"] = time.perf_counter() - t0
        row["wall_time"] += row["time_output"]
        if self.csv is not None:
            on_rank0(self.comm, lambda: self.csv.write(row))

    def left(self, n: int) -> int:
        """The levels written from level n (a written one) to the next checkpoint (its flush) or the run's last
        level, both included: a chunk of the series opened at n is then full when that flush closes it."""
        k = self.every_ckpt
        stop = min(-(-n // k) * k, self.steps) if k else self.steps
        return written_levels(n, stop, self.steps, self.every)

    def close(self, finished: bool) -> None:
        self.out.close(quiet=not finished)
        if self.csv is not None:
            self.csv.close()
        if self.profile is not None:
            self.profile.close()


def _write_scene(files: ResultsDir, cfg, head: str = "") -> None:
    """config.toml, the resolved scene (after ``head``, comment lines), and the copies of the tables it read from
    files, which it refers to (tables/: ``solver run DIR/config.toml`` runs the same scene)."""
    text, tables = dumps_referring(cfg)
    for name, (rows, as_file) in tables.items():
        path = files.path / name
        path.parent.mkdir(exist_ok=True)
        write_copy(rows, path, as_file)
    write_text_atomic(files.config, head + text)


def _stop_here(out: Outputs, outdir: Path | None, model: Model, n: int, t: float, part: int,
               signum: int, clock: StepController | None = None) -> Interrupted:
    """End an interrupted run at level n: the series written up to it and a checkpoint of it."""
    out.flush()
    if outdir is not None:
        checkpoint.write(outdir, model, n, t, part, clock)
    return Interrupted(signum, n, t, outdir is not None)


def _located(exc: SolveFailure, n: int, t: float, k: float) -> SolveFailure:
    """The failure at level n, or, for a failed write that names its level (OutputError.level_t), at that level."""
    if isinstance(exc, OutputError) and exc.level_t is not None:
        return exc.at(round(exc.level_t / k), exc.level_t)
    return exc.at(n, t)


def _csv_lines_until(path: Path, step: int) -> list[str]:
    """The data lines of a timeseries.csv with step <= ``step``, as written (complete lines only)."""
    lines = path.read_text().splitlines(keepends=True)[1:] if path.exists() else []
    return [ln for ln in lines if ln.endswith("\n") and int(ln.split(",", 1)[0]) <= step]
