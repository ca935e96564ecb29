"""The pure parts of the bench command: the median timer and the Markdown table."""

import pytest
from mpi4py import MPI

from studies.bench import _median_time, _table


def test_median_time_calls_once_to_warm_up_then_reps_times():
    calls = []
    t = _median_time(lambda: calls.append(1), MPI.COMM_SELF, reps=5)
    assert len(calls) == 6 and t >= 0.0


def test_table_has_a_row_per_case_and_the_speedup_section():
    case = {"n": 32, "nproc": 1, "dofs_u": 2178, "step_ms": 2.0, "ratio": 1.25, "newton_per_step": 1.0,
            "factorizations_per_step": 0.0, "peak_mib_max": 150.0, "floor_ms": {"total": 1.6},
            "split_ms": {"damage": 0.5, "memory": 0.3, "displacement": 0.9, "diagnostics": 0.2, "output": 0.1}}
    text = _table({"sizes": [case], "speedup": {32: {"serial_ms": 2.0, "parallel_ms": 1.6, "speedup": 1.25,
                                                      "max_diff": 1e-15}}})
    rows = [ln for ln in text.splitlines() if ln.startswith("| 32 |")]
    assert len(rows) == 2
    assert "| 2.00 | 0.50 | 0.30 | 0.90 | 0.20 | 1.60 | 1.25 | 0.10 |" in rows[0]  # output apart from the step
    assert "mpirun -n 2" in text
    with pytest.raises(KeyError):
        _table({"sizes": [{"n": 1}]})


def test_discretization_table_reports_the_source_apart_from_the_floor():
    """The floor is unchanged; one memory-source evaluation is a column of its own with its own ratio."""
    case = {"kernel": "p2-order1", "n": 64, "dofs_u": 33282, "step_ms": 9.0, "ratio": 2.0, "ratio_with_source": 1.5,
            "floor_ms": {"total": 4.5, "memory_source": 1.5},
            "split_ms": {"damage": 1.0, "memory": 1.2, "displacement": 5.0, "diagnostics": 0.8, "output": 0.0}}
    text = _table({"sizes": [], "discretizations": [case]})
    assert "| p2-order1 | 64 | 33282 | 9.00 | 1.00 | 1.20 | 5.00 | 4.50 | 2.00 | 1.50 | 1.50 |" in text
