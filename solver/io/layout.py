"""The results directory, known in one place: the files a run writes there, the CSV columns, what
``--overwrite`` removes and how a directory is prepared before a run.

A results directory holds (docs/guide/outputs.md)::

    solution.xdmf          the XDMF series of the fields (solver/io/xdmf.py), its data in
    fields/mesh.h5         the mesh, written once
    fields/levels_*.h5     the levels, up to 100 a chunk
    contact.xdmf           Γ_C as a facet mesh with the contact results (scenes with contact; solver/io/contact_series.py),
                           its data in fields/contact_mesh.h5 and fields/contact_levels_*.h5
    timeseries.csv         one row a level (TIMESERIES_COLUMNS and the scene's own)
    contact.csv            the contact results along Γ_C at each written level (PROFILE_COLUMNS; scenes with contact)
    config.toml            the resolved scene
    tables/*.csv           the rows of the tables the scene read from CSV files (config.toml refers to them)
    checkpoint.h5          the last checkpoint (``--restart`` continues from it)
    plan.json              what a tolerance chose (runs with accuracy.tolerance)
    mesh.xdmf, mesh.h5     the mesh a tolerance chose, with its boundary tags

The command line and :mod:`solver.api` prepare a directory with :func:`prepare` and name the files through
:class:`ResultsDir`; the writers (:mod:`solver.io.results`) take their paths from it. Nothing here imports
dolfinx or MPI: the readers (:mod:`solver.post`) use it too.
"""

from __future__ import annotations

import tempfile
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

from solver.config.scene import TABLES
from solver.errors import OutputDirectoryError, UsageError

if TYPE_CHECKING:
    from mpi4py import MPI

SOLUTION = "solution.xdmf"
FIELDS = "fields"
FIELD_PATTERNS = ("mesh.h5", "levels_*.h5", "contact_mesh.h5", "contact_levels_*.h5")  # the series' data in fields/
TIMESERIES = "timeseries.csv"
CONTACT = "contact.csv"
CONTACT_SERIES = "contact.xdmf"
CONFIG = "config.toml"
CHECKPOINT = "checkpoint.h5"
PLAN = "plan.json"
PLAN_MESH = ("mesh.xdmf", "mesh.h5")
# the files a run writes at the top of the directory, in the order --help lists them
TOP_FILES = (SOLUTION, CONTACT_SERIES, TIMESERIES, CONTACT, CONFIG, CHECKPOINT, PLAN, *PLAN_MESH)
TABLE_PATTERN = "*.csv"  # in tables/: the copies of the tables read from files (solver.config.scene.dumps_referring)

TIMESERIES_COLUMNS = (
    "step", "t", "newton_iterations", "linear_solves", "factorizations", "residual", "contact_force",
    "contact_length", "max_penetration", "zeta_min", "zeta_max", "zeta_raw_min", "zeta_raw_max", "zeta_clipped",
    "strain_norm", "zeta_norm", "time_damage", "time_memory", "time_displacement", "time_diagnostics", "time_output",
    "wall_time",
)
# with solver.linear resolving to "iterative": the Krylov iterations of the level's displacement solves (summed
# over its Newton iterations) and of its damage solve; they follow TIMESERIES_COLUMNS, before the scene's own
KRYLOV_COLUMNS = ("krylov_iterations", "damage_krylov_iterations")
# with time.adaptive: each level's step, its estimated local time error and the trial steps rejected before it
STEP_COLUMNS = ("k", "error_estimate", "rejected")
PROFILE_COLUMNS = ("step", "t", "part", "s", "x", "y", "z", "gap", "u_normal", "penetration", "pressure")


def timeseries_columns(model: Any, sensors: tuple = ()) -> tuple[str, ...]:
    """The columns of timeseries.csv for ``model`` (a :class:`solver.run.model.Model`), in the file's order: the
    fixed ones, the Krylov counts with the iterative solver, the diagnostics' (peak pressure, reactions), then each
    sensor's (a tolerance's error estimates)."""
    return (TIMESERIES_COLUMNS + (KRYLOV_COLUMNS if model.linear == "iterative" else ())
            + (STEP_COLUMNS if model.cfg.time.adaptive else ())
            + model.mech.diagnostics.columns + tuple(c for s in sensors for c in s.columns))


def listing() -> str:
    """The files a run writes, as ``--help`` lists them."""
    return ", ".join((SOLUTION, *(f"{FIELDS}/{p}" for p in FIELD_PATTERNS[:2]), CONTACT_SERIES,
                      *(f"{FIELDS}/{p}" for p in FIELD_PATTERNS[2:]), *TOP_FILES[2:], f"{TABLES}/{TABLE_PATTERN}"))


@dataclass(frozen=True)
class ResultsDir:
    """The paths of a results directory's files (nothing is read or made here)."""

    path: Path

    @property
    def solution(self) -> Path:
        return self.path / SOLUTION

    @property
    def contact_series(self) -> Path:
        """Γ_C's own dataset (contact.xdmf)."""
        return self.path / CONTACT_SERIES

    @property
    def timeseries(self) -> Path:
        return self.path / TIMESERIES

    @property
    def contact(self) -> Path:
        return self.path / CONTACT

    @property
    def config(self) -> Path:
        return self.path / CONFIG

    @property
    def checkpoint(self) -> Path:
        return self.path / CHECKPOINT

    @property
    def plan(self) -> Path:
        return self.path / PLAN

    @property
    def plan_mesh(self) -> Path:
        """The tolerance's mesh (mesh.xdmf; its data in mesh.h5 beside it)."""
        return self.path / PLAN_MESH[0]

    def written(self) -> list[Path]:
        """The files of the directory that a run writes (and ``--overwrite`` removes); nothing else there is
        touched."""
        found = [self.path / f for f in TOP_FILES if (self.path / f).is_file()]
        fields = self.path / FIELDS
        if fields.is_dir():
            found += sorted(p for pattern in FIELD_PATTERNS for p in fields.glob(pattern) if p.is_file())
        tables = self.path / TABLES
        if tables.is_dir():
            found += sorted(p for p in tables.glob(TABLE_PATTERN) if p.is_file())
        return found

    def remove_written(self) -> None:
        """Remove :meth:`written` (and fields/, tables/ if that leaves them empty)."""
        for target in self.written():
            target.unlink()
        for folder in (self.path / FIELDS, self.path / TABLES):
            if folder.is_dir() and not any(folder.iterdir()):
                folder.rmdir()


@dataclass(frozen=True)
class Wording:
    """How a caller names its options in a refusal: the command line's flags or the Python interface's arguments."""

    output: str
    overwrite: str
    restart: str | None  # None: the caller cannot restart


CLI = Wording("--output", "--overwrite", "--restart")
API = Wording("output", "overwrite=True", None)


def prepare(comm: MPI.Comm, directory: Path, overwrite: bool = False, restart: bool = False, dry: bool = False,
            wording: Wording = CLI) -> None:
    """Check the results directory and make it (rank 0; every rank raises the same
    :class:`OutputDirectoryError`).

    Earlier results are refused unless ``overwrite`` (then :meth:`ResultsDir.written` is removed) or ``restart``
    (then the checkpoint must be there). ``dry``: only the refusals, nothing made or removed (before a planning
    that may refuse the tolerance: a refused run leaves nothing behind)."""
    problem = None
    if comm.rank == 0:
        problem = _problem(ResultsDir(Path(directory)), overwrite, restart, dry, wording)
    problem = comm.bcast(problem, root=0)
    if problem is not None:
        message, kind, existing = problem
        raise OutputDirectoryError(message, Path(directory), kind, existing)


def check_writable(directory: Path, what: str) -> None:
    """Refuse (:class:`UsageError`, one line) a directory this process cannot make or write a file in: what
    ``solver plot`` and ``solver paraview`` check before drawing. ``what`` names it for the user."""
    if directory.exists() and not directory.is_dir():
        raise UsageError(f"{what}: cannot write there (Not a directory)")
    try:
        directory.mkdir(parents=True, exist_ok=True)
        tempfile.TemporaryFile(dir=directory).close()  # mode bits do not tell root, a read-only mount, an ACL
    except OSError as exc:
        raise UsageError(f"{what}: cannot write there ({exc.strerror or exc})") from None


def _problem(out: ResultsDir, overwrite: bool, restart: bool, dry: bool,
             wording: Wording) -> tuple[str, str, tuple[str, ...]] | None:
    """What refuses ``out`` as (message, problem, existing), or None once it is made (rank 0)."""
    where = f"{wording.output} {out.path}"
    try:
        if out.path.exists() and not out.path.is_dir():
            return f"{where}: exists and is not a directory", "not a directory", ()
        if restart:
            if not out.checkpoint.exists():
                return (f"{wording.restart}: {out.checkpoint} does not exist (nothing to restart from)",
                        "no checkpoint", ())
        elif out.path.is_dir():
            existing = out.written()
            if existing and not overwrite:
                names = tuple(sorted({f"{p.parent.name}/" if p.parent != out.path else p.name for p in existing}))
                how = f"pass {wording.overwrite} to replace them, "
                how += f"{wording.restart} to continue them, " if wording.restart else ""
                return (f"{where}: holds earlier results ({', '.join(names)}); {how}or choose another directory",
                        "earlier results", names)
            if existing and not dry:
                out.remove_written()
        if not dry:
            out.path.mkdir(parents=True, exist_ok=True)
            tempfile.TemporaryFile(dir=out.path).close()  # can we write in it? (mode bits do not tell root)
    except OSError as exc:
        return f"{where}: cannot write there ({exc.strerror or exc})", "cannot write", ()
    return None
