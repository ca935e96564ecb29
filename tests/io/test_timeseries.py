"""Writers: von Mises of arrays, CSV rows (one system call each), atomic small files (cell stresses: test_outputs)."""

import numpy as np
import pytest

from solver.io.files import write_text_atomic
from solver.io.timeseries import CSV_COLUMNS, CSVWriter
from solver.physics.material import von_mises_array


def test_von_mises_array_plane_and_3d():
    s2 = np.array([[3.0, 1.0], [1.0, -2.0]]).ravel()
    assert von_mises_array(s2, 2)[0] == pytest.approx(np.sqrt(9 + 4 + 6 + 3))
    uniaxial = np.diag([5.0, 0.0, 0.0]).ravel()
    assert von_mises_array(uniaxial, 3)[0] == pytest.approx(5.0)
    assert von_mises_array(np.eye(3).ravel(), 3)[0] == pytest.approx(0.0, abs=1e-14)  # hydrostatic


def _row(step: int) -> dict:
    return {c: (step if c == "step" else 0.5 * step) for c in CSV_COLUMNS}


def test_csv_writer_keeps_rows_and_appends_whole_lines(tmp_path, comm):
    if comm.size > 1:
        pytest.skip("rank 0 writes; the file path is per rank here")
    path = tmp_path / "t.csv"
    w = CSVWriter(path, comm)
    w.write(_row(0))
    w.write(_row(1))
    w.close()
    lines = path.read_text().splitlines()
    assert lines[0] == ",".join(CSV_COLUMNS) and len(lines) == 3
    assert lines[2].split(",")[:2] == ["1", "0.5"]
    w = CSVWriter(path, comm, keep=[lines[1] + "\n"])  # a restart keeps rows up to its checkpoint
    w.write(_row(5))
    w.close()
    assert [ln.split(",")[0] for ln in path.read_text().splitlines()[1:]] == ["0", "5"]


def test_write_text_atomic_leaves_no_temporary(tmp_path):
    path = tmp_path / "config.toml"
    write_text_atomic(path, "a = 1\n")
    write_text_atomic(path, "a = 2\n")
    assert path.read_text() == "a = 2\n" and [p.name for p in tmp_path.iterdir()] == ["config.toml"]
