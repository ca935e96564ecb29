"""The command line as a user meets it: exit codes, one-line errors, no silent overwrite, MPI."""

import os
import subprocess

import numpy as np
import pytest
from conftest import ROOT
from conftest import run_cli as cli

from solver.post.results import read_csv, read_results

pytestmark = pytest.mark.serial  # each test starts its own processes


SMALL = ["--set", "mesh.nx=4", "--set", "mesh.ny=4", "--set", "time.k=0.5", "--no-progress"]


@pytest.mark.parametrize("nproc", [1, 2])
def test_bad_value_is_one_line_exit_2(tmp_path, nproc):
    out = tmp_path / "o"
    res = cli(["run", "configs/example1.toml", "--set", "material.E=-3", "--output", str(out)], nproc)
    assert res.returncode == 2
    # exactly one message (rank 0), whatever mpirun itself adds about the exit code
    ours = [ln for ln in res.stderr.splitlines() if ln.startswith(("error", "failed", "scene"))]
    assert ours == ["error: --set material.E=-3: material.E = -3.0: must be > 0"], res.stderr
    if nproc == 1:
        assert res.stderr.strip() == ours[0]
    assert "Traceback" not in res.stderr and not out.exists()


def test_incompatible_interval_refused_before_output(tmp_path):
    out = tmp_path / "o"
    res = cli(["run", "configs/example1.toml", "--set", "boundary.bottom.interval=[0.0, 0.3]",
               "--output", str(out), *SMALL])
    assert res.returncode == 2 and "boundary.bottom.interval" in res.stderr and not out.exists()


@pytest.mark.slow
def test_check_and_no_overwrite(tmp_path):
    res = cli(["check", "configs/example1.toml"])
    assert res.returncode == 0 and ": ok — " in res.stdout and res.stderr == ""
    out = tmp_path / "o"
    assert cli(["run", "configs/example1.toml", "--output", str(out), *SMALL]).returncode == 0
    before = (out / "timeseries.csv").read_bytes()
    res = cli(["run", "configs/example1.toml", "--output", str(out), *SMALL, "--set", "time.k=0.25"])
    assert res.returncode == 2 and "--overwrite" in res.stderr
    assert (out / "timeseries.csv").read_bytes() == before
    res = cli(["run", "configs/example1.toml", "--output", str(out), *SMALL, "--set", "time.k=0.25", "--overwrite"])
    assert res.returncode == 0 and (out / "timeseries.csv").read_bytes() != before


@pytest.mark.parametrize("nproc", [1, 2])
def test_a_power_kernel_run_reports_its_terms_and_error(tmp_path, nproc):
    """The log's line and config.toml's first line give the sum of exponentials' terms and kernel error; the
    scene written there reads back (the line is a comment)."""
    out = tmp_path / "o"
    scene = tmp_path / "power.toml"
    text = (ROOT / "configs/example1.toml").read_text()
    old = 'kernel = "constant"   # G = zeta Phi_L(A eps(u))\nweights = [1.0]\n'
    assert old in text
    scene.write_text(text.replace(old, 'kernel = "power"\ncoefficient = 1.0\nexponent = 0.5\n'))
    res = cli(["run", str(scene), "--output", str(out), *SMALL, "--set", "time.k=0.25"], nproc)
    assert res.returncode == 0, res.stderr
    line = next(ln for ln in (res.stdout + res.stderr).splitlines() if ln.startswith("memory:"))
    terms = int(line.split(" as ")[1].split()[0])
    error = float(line.split("max relative kernel error ")[1].split()[0])
    assert 1 <= terms <= 64 and error <= 1e-8 and "lags [0.25, 1]" in line
    head = (out / "config.toml").read_text().splitlines()[0]
    assert head.startswith("# memory.kernel = 'power' runs as") and f"{terms} exponential term(s)" in head
    assert cli(["check", str(out / "config.toml")]).returncode == 0


@pytest.mark.parametrize("nproc", [1, 2])
def test_solver_failure_stops_cleanly(tmp_path, nproc):
    """Example 3 unloads at t = 0.55 (6 Newton iterations at k = 0.05); with max_it = 4 and no fallback that step
    fails (the default damped fallback solves it: tests/solvers/test_damped_newton.py)."""
    out = tmp_path / "o"
    res = cli(["run", "configs/example3.toml", "--output", str(out), "--no-progress", "--set", "time.k=0.05",
               "--set", "solver.max_it=4", "--set", "solver.newton_fallback=false", "--set", "output.checkpoint_every=5",
               "--set", "output.every=2"], nproc)
    assert res.returncode == 1
    msg = [ln for ln in res.stderr.splitlines() if ln.startswith("failed:")]
    assert len(msg) == 1 and "Traceback" not in res.stderr
    assert "step 11, t = 0.55: displacement solve failed: SNES DIVERGED_MAX_IT, 4 iterations" in msg[0]
    assert "last residuals [" in msg[0]
    # everything written so far is kept and readable: rows 0..10, levels up to 0.5, the checkpoint of step 10
    rows = read_csv(out / "timeseries.csv")
    assert [int(r["step"]) for r in rows] == list(range(11))
    assert read_results(out)["times"][-1] == pytest.approx(0.5)
    import h5py

    with h5py.File(out / "checkpoint.h5") as h5:
        assert h5.attrs["step"] == 10


# on 2 ranks the default factorization is redundant: its options carry the redundant_ prefix
@pytest.mark.parametrize("nproc,option,value,reason", [
    (1, "mech_ksp_type", "nonsense", "Unable to find requested KSP type nonsense"),
    (2, "mech_ksp_type", "nonsense", "Unable to find requested KSP type nonsense"),
    (1, "mech_pc_factor_mat_solver_type", "nonsense", "Could not locate solver type nonsense"),
    (2, "mech_redundant_pc_factor_mat_solver_type", "nonsense", "Could not locate solver type nonsense"),
    (1, "mech_snes_max_it", "abc", "Input string abc has no integer value"),
    (1, "damage_ksp_type", "nonsense", "Unable to find requested KSP type nonsense"),
])
def test_petsc_option_petsc_rejects_is_one_line_exit_2(tmp_path, nproc, option, value, reason):
    """An option PETSc rejects is bad input like any other: one line naming it, exit 2, nothing written."""
    out = tmp_path / "o"
    res = cli(["run", "configs/example1.toml", "--output", str(out), *SMALL,
               "--set", f"solver.petsc_options.{option}={value}"], nproc)
    assert res.returncode == 2, res.stderr
    ours = [ln for ln in res.stderr.splitlines() if ln.startswith("error")]
    assert len(ours) == 1 and "Traceback" not in res.stderr and "PETSC ERROR" not in res.stderr
    assert ours[0].startswith(f"error: solver.petsc_options.{option} = '{value}': PETSc rejects it: ")
    assert reason in ours[0] and not out.exists()
    if nproc == 1:
        assert res.stderr.strip() == ours[0]


FULL_DISK = ["run", "configs/example1.toml", "--no-progress", "--set", "mesh.nx=16", "--set", "mesh.ny=16",
             "--set", "time.T=0.1", "--set", "time.k=0.001", "--set", "output.checkpoint_every=10",
             "--set", 'output.fields=["displacement", "damage", "stress", "elastic_stress", "von_mises", "von_mises_elastic"]']


def _stopped_by_full_disk(res, out, step: int | None = None) -> None:
    """Exit 1 with one line naming the step and the reason; everything listed before is complete and readable."""
    assert res.returncode == 1, res.stderr[-2000:]
    msg = [ln for ln in res.stderr.splitlines() if ln.startswith("failed:")]
    assert len(msg) == 1 and "Traceback" not in res.stderr, res.stderr[-2000:]
    assert "writing results failed: No space left on device" in msg[0], msg[0]
    if step is not None:
        assert msg[0].startswith(f"failed: step {step}, t = {step * 0.001:.6g}: "), msg[0]
    got = read_results(out)
    n = len(got["times"])
    assert n >= 2 and got["times"] == pytest.approx([0.001 * i for i in range(n)], rel=0, abs=1e-15)
    for values in got["fields"].values():
        assert len(values) == n and all(np.all(np.isfinite(v)) for v in values.values())
    rows = read_csv(out / "timeseries.csv")  # complete rows only
    assert [int(r["step"]) for r in rows] == list(range(len(rows))) and len(rows) >= n - 1
    return got


@pytest.mark.parametrize("nproc", [1, 2])
def test_full_disk_injected_stops_like_a_failed_solve(tmp_path, nproc):
    """The data write of the 6th level (step 5) fails with ENOSPC half-way (tests/faults.py): exit 1, step and
    reason, levels 0-4 listed (the open chunk's complete levels), intact and equal to a run that was not stopped."""
    out, ref = tmp_path / "o", tmp_path / "ref"
    assert cli([*FULL_DISK, "--set", "time.T=0.01", "--output", str(ref)], nproc).returncode == 0
    got = _stopped_by_full_disk(cli([*FULL_DISK, "--output", str(out)], nproc, fault="enospc:data:6"), out, step=5)
    assert len(got["times"]) == 5
    want = read_results(ref)
    for name, values in got["fields"].items():
        for t, v in values.items():
            assert np.allclose(v, want["fields"][name][t], rtol=1e-10, atol=1e-12), (name, t)


def test_full_disk_on_a_small_file_system(tmp_path):
    """A real full disk: a 2 MiB tmpfs (root only; elsewhere the injected test above stands for it)."""
    mnt = tmp_path / "small"
    mnt.mkdir()
    if os.geteuid() != 0 or subprocess.run(["mount", "-t", "tmpfs", "-o", "size=2m", "tmpfs", str(mnt)],
                                           capture_output=True).returncode != 0:
        pytest.skip("cannot mount a small tmpfs here (needs root)")
    try:
        res = cli([*FULL_DISK, "--output", str(mnt / "o")])
        _stopped_by_full_disk(res, mnt / "o")
    finally:
        subprocess.run(["umount", str(mnt)], check=True)


def test_output_directory_that_cannot_be_written(tmp_path):
    """One line, exit 2, before any computation writes: a path through a file, and a read-only directory."""
    blocker = tmp_path / "file"
    blocker.write_text("x")
    res = cli(["run", "configs/example1.toml", "--output", str(blocker / "o"), *SMALL])
    assert res.returncode == 2 and res.stderr.strip() == f"error: --output {blocker / 'o'}: cannot write there (Not a directory)"
    ro = tmp_path / "ro"
    ro.mkdir()
    if os.geteuid() == 0:  # root writes through mode bits: make a read-only file system
        if subprocess.run(["mount", "-t", "tmpfs", "-o", "ro,size=1m", "tmpfs", str(ro)], capture_output=True).returncode:
            pytest.skip("cannot mount a read-only tmpfs here")
    else:
        ro.chmod(0o555)
    try:
        res = cli(["run", "configs/example1.toml", "--output", str(ro / "o"), *SMALL])
        assert res.returncode == 2 and "Traceback" not in res.stderr
        reason = "Read-only file system" if os.geteuid() == 0 else "Permission denied"
        assert res.stderr.strip() == f"error: --output {ro / 'o'}: cannot write there ({reason})", res.stderr
    finally:
        subprocess.run(["umount", str(ro)], capture_output=True) if os.geteuid() == 0 else ro.chmod(0o755)


NO_CONTACT = ["--set", 'boundary.bottom={role="traction", traction=[0.0, 0.0]}']


def test_overwrite_by_a_scene_without_contact_leaves_no_contact_profile(tmp_path):
    """--overwrite removes every file a run writes: a contact.csv left behind would be plotted as the new run's."""
    out = tmp_path / "o"
    assert cli(["run", "configs/example1.toml", "--output", str(out), *SMALL]).returncode == 0
    assert (out / "contact.csv").is_file()
    res = cli(["run", "configs/example1.toml", "--output", str(out), *SMALL, *NO_CONTACT])
    assert res.returncode == 2 and "contact.csv" in res.stderr  # named among the earlier results
    res = cli(["run", "configs/example1.toml", "--output", str(out), *SMALL, *NO_CONTACT, "--overwrite"])
    assert res.returncode == 0, res.stderr
    assert (out / "timeseries.csv").is_file() and not (out / "contact.csv").exists()


def test_run_help_lists_the_files_of_the_layout():
    from solver.io import layout

    res = cli(["run", "--help"])
    assert res.returncode == 0 and layout.listing() in " ".join(res.stdout.split())
    assert all(name in layout.listing() for name in layout.TOP_FILES)


@pytest.mark.parametrize("nproc", [1, 2])
@pytest.mark.parametrize("argv, line", [
    (["run", "configs/example1.toml", "--set", "time.k", "0.01"],
     "error: solver: unrecognized arguments: 0.01 (--set takes SECTION.KEY=VALUE as one word: --set time.k=0.01); "
     "see solver --help"),
    (["run", "configs/example1.toml", "--overwrite", "--restart"],
     "error: solver run: argument --restart: not allowed with argument --overwrite; see solver run --help"),
])
def test_command_line_mistakes_are_one_line_exit_2(tmp_path, argv, line, nproc):
    res = cli([*argv, "--output", str(tmp_path / "o")], nproc)
    assert res.returncode == 2
    ours = [ln for ln in res.stderr.splitlines() if ln.startswith("error")]
    assert ours == [line], res.stderr
    assert "usage:" not in res.stderr and not (tmp_path / "o").exists()


def test_help_has_no_markup():
    res = cli(["--help"])
    assert res.returncode == 0 and "``" not in res.stdout and "python -m solver" in res.stdout


@pytest.mark.parametrize("nproc", [1, 2])
def test_a_gap_table_from_a_file_is_copied_beside_the_results_and_runs_again(tmp_path, nproc):
    """A scene whose gap is a CSV file (relative to the scene) runs; its results folder holds config.toml and the
    table's copy it refers to; ``solver run DIR/config.toml`` runs the same scene to the same numbers; a
    restart from DIR/config.toml into DIR is accepted (the same scene)."""
    scene = tmp_path / "in" / "scene.toml"
    scene.parent.mkdir()
    s = np.linspace(0.0, 1.0, 2001)
    (scene.parent / "profile.csv").write_text("x,g\n" + "".join(f"{a!r},{1e-4 * a * a!r}\n" for a in s))
    text = open("configs/example1.toml").read().replace("gap = 0.0\n", 'gap = {file = "profile.csv"}\n')
    scene.write_text(text)
    first, again = tmp_path / "first", tmp_path / "again"
    args = [*SMALL, "--set", "output.checkpoint_every=1"]
    assert cli(["run", str(scene), "--output", str(first), *args], nproc).returncode == 0
    assert (first / "tables" / "boundary.bottom.gap.csv").read_text() == (scene.parent / "profile.csv").read_text()
    assert 'gap = {file = "tables/boundary.bottom.gap.csv"}' in (first / "config.toml").read_text()
    res = cli(["run", str(first / "config.toml"), "--output", str(again), *args], nproc)
    assert res.returncode == 0, res.stderr
    a, b = read_csv(first / "timeseries.csv"), read_csv(again / "timeseries.csv")
    for column in ("contact_force", "zeta_min", "strain_norm"):
        assert [r[column] for r in a] == [r[column] for r in b], column
    res = cli(["run", str(first / "config.toml"), "--output", str(first), "--restart", *args], nproc)
    assert res.returncode == 0, res.stderr
