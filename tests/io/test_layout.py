"""The results directory (solver/io/layout.py): every file a run writes is named there, --overwrite removes exactly
those, refusals are typed errors with fields, and the time series' columns are the CSV's header."""

import pytest
from conftest import solve

from solver.config import from_dict
from solver.errors import OutputDirectoryError
from solver.io import checkpoint, layout
from solver.io.layout import API, CLI, ResultsDir, prepare, timeseries_columns

# a contact scene that writes every file of a plain run: the series, the profile, a checkpoint
SCENE = {"mesh": {"nx": 4, "ny": 4}, "time": {"T": 0.3, "k": 0.1}, "output": {"checkpoint_every": 1}}


def _files(directory) -> set[str]:
    return {str(p.relative_to(directory)) for p in directory.rglob("*") if p.is_file()}


def test_every_file_a_run_writes_is_known_and_overwrite_removes_them_all(comm, shared_tmp):
    if comm.rank == 0:  # a gap table from a file: its copy goes to tables/
        (shared_tmp / "profile.csv").write_text("x,g\n0,0\n0.5,0\n1,0\n")
    comm.barrier()
    gap = {"gap": {"file": "profile.csv"}, "gap_coordinate": "x", "role": "contact", "mu": 1e-10}
    cfg = from_dict({**SCENE, "boundary": {"left": {"role": "clamped"}, "bottom": gap}}, base=shared_tmp)
    model, _ = solve(cfg, comm, shared_tmp)
    comm.barrier()
    if comm.rank == 0:
        written = _files(shared_tmp) - {"profile.csv"}
        assert {"solution.xdmf", "timeseries.csv", "contact.csv", "config.toml", "checkpoint.h5",
                "fields/mesh.h5", "fields/levels_000000.h5", "tables/boundary.bottom.gap.csv"} <= written, written
        assert {str(p.relative_to(shared_tmp)) for p in ResultsDir(shared_tmp).written()} == written
        header = (shared_tmp / layout.TIMESERIES).read_text().splitlines()[0].split(",")
        assert tuple(header) == timeseries_columns(model)
        profile = (shared_tmp / layout.CONTACT).read_text().splitlines()[0].split(",")
        assert tuple(profile) == layout.PROFILE_COLUMNS
        (shared_tmp / "notes.txt").write_text("mine")  # a user's file beside the results
        (shared_tmp / "fields" / "mine.h5").write_text("mine")
    comm.barrier()
    prepare(comm, shared_tmp, overwrite=True)
    if comm.rank == 0:
        assert _files(shared_tmp) == {"notes.txt", "fields/mine.h5", "profile.csv"}


def test_the_writers_use_the_layouts_names():
    assert checkpoint.NAME == layout.CHECKPOINT
    assert layout.listing().split(", ") == ["solution.xdmf", "fields/mesh.h5", "fields/levels_*.h5", "contact.xdmf",
                                            "fields/contact_mesh.h5", "fields/contact_levels_*.h5", "timeseries.csv",
                                            "contact.csv", "config.toml", "checkpoint.h5", "plan.json", "mesh.xdmf",
                                            "mesh.h5", "tables/*.csv"]


def _earlier(comm, directory, *names) -> None:
    if comm.rank == 0:
        directory.mkdir(parents=True, exist_ok=True)
        for name in names:
            (directory / name).parent.mkdir(exist_ok=True)
            (directory / name).write_text("old")
    comm.barrier()


@pytest.mark.parametrize("wording,how", [(CLI, "pass --overwrite to replace them, --restart to continue them, or"),
                                         (API, "pass overwrite=True to replace them, or")])
def test_earlier_results_are_refused_with_their_names(comm, shared_tmp, wording, how):
    out = shared_tmp / "o"
    _earlier(comm, out, "contact.csv", "fields/levels_000000.h5")
    with pytest.raises(OutputDirectoryError) as err:
        prepare(comm, out, wording=wording)
    assert err.value.problem == "earlier results" and err.value.directory == out
    assert err.value.existing == ("contact.csv", "fields/")
    assert str(err.value) == f"{wording.output} {out}: holds earlier results (contact.csv, fields/); {how} choose " \
                             "another directory"
    prepare(comm, out, overwrite=True, dry=True)  # dry: refusals only, nothing removed
    if comm.rank == 0:
        assert (out / "contact.csv").exists()


def test_a_restart_needs_the_checkpoint_and_a_file_is_no_directory(comm, shared_tmp):
    _earlier(comm, shared_tmp, "timeseries.csv", "blocker")
    with pytest.raises(OutputDirectoryError) as err:
        prepare(comm, shared_tmp, restart=True)
    assert err.value.problem == "no checkpoint"
    assert str(err.value) == f"--restart: {shared_tmp / 'checkpoint.h5'} does not exist (nothing to restart from)"
    with pytest.raises(OutputDirectoryError) as err:
        prepare(comm, shared_tmp / "blocker")
    assert err.value.problem == "not a directory"
    with pytest.raises(OutputDirectoryError) as err:
        prepare(comm, shared_tmp / "blocker" / "o")
    assert err.value.problem == "cannot write" and str(err.value).endswith("cannot write there (Not a directory)")
