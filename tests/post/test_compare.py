"""solver.post.compare: two results directories of the same run agree; a changed value is found and named."""

import shutil

import h5py
import numpy as np
import pytest

from solver import api
from solver.config import from_dict
from solver.post.compare import compare_runs

SCENE = {"mesh": {"nx": 4, "ny": 4}, "time": {"T": 0.3, "k": 0.1}}


@pytest.fixture()
def twins(comm, shared_tmp):
    a, b = shared_tmp / "a", shared_tmp / "b"
    api.run(from_dict(SCENE), a, comm=comm)
    api.run(from_dict(SCENE), b, comm=comm)
    return a, b


def test_the_same_run_twice_is_the_same(twins):
    diff = compare_runs(*twins)
    assert diff.same and diff.levels == 4 and diff.written == 4 and diff.worst < 1e-13, diff.differences


@pytest.mark.serial
def test_a_changed_node_value_or_row_is_named(twins, tmp_path):
    a, b = twins
    c = tmp_path / "c"
    shutil.copytree(a, c)
    text = (c / "timeseries.csv").read_text().splitlines()
    head, row = text[0].split(","), text[2].split(",")
    col = head.index("zeta_min")
    row[col] = repr(float(row[col]) * (1 + 1e-9))
    (c / "timeseries.csv").write_text("\n".join([*text[:2], ",".join(row), *text[3:]]) + "\n")
    diff = compare_runs(c, b)
    assert not diff.same and diff.differences[0].startswith("timeseries.csv step 1 zeta_min")
    shutil.rmtree(c)
    shutil.copytree(a, c)
    for h5 in sorted((c / "fields").glob("*.h5")):
        with h5py.File(h5, "r+") as f:
            names = _datasets(f, "damage")
            if names:
                f[names[-1]][0] = np.asarray(f[names[-1]][0]) + 1e-6
                break
    diff = compare_runs(c, b)
    assert not diff.same and any(d.startswith("damage at t = ") for d in diff.differences), diff.differences


def _datasets(f: h5py.File, part: str) -> list[str]:
    names: list[str] = []
    f.visititems(lambda n, o: names.append(n) if isinstance(o, h5py.Dataset) and part in n else None)
    return names
