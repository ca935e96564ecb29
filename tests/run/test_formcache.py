"""The in-process memo of compiled forms: a model built again asks the disk cache for nothing, and is the same."""

import numpy as np

from solver.config import from_dict
from solver.run import formcache
from solver.run.model import build_model
from solver.run.stepper import Stepper


def test_a_second_build_reads_no_disk_cache_and_gives_the_same_level(comm, monkeypatch):
    cfg = from_dict({"mesh": {"nx": 4, "ny": 4}, "time": {"T": 0.2, "k": 0.1}, "discretization": {"u_degree": 2}})
    first = build_model(cfg, comm)
    rows_first = [Stepper(first).step(n) for n in range(3)]
    assert formcache.kept() > 0
    asked = []
    disk = formcache._disk_lookup
    monkeypatch.setattr(formcache, "_disk_lookup", lambda *a: asked.append(a[0]) or disk(*a))
    second = build_model(cfg, comm)
    rows_second = [Stepper(second).step(n) for n in range(3)]
    assert asked == []  # every form of the second build came from the memo
    assert np.array_equal(first.u.x.array, second.u.x.array)
    assert [r["strain_norm"] for r in rows_first] == [r["strain_norm"] for r in rows_second]


def test_a_module_not_in_the_memo_is_looked_up_on_disk(monkeypatch):
    asked = []
    monkeypatch.setattr(formcache, "_disk_lookup", lambda *a: asked.append(a[0]) or (None, None))
    assert formcache._lookup("libffcx_forms_not_compiled_yet", ["form_x"], "/nonexistent", 1) == (None, None)
    assert asked == ["libffcx_forms_not_compiled_yet"]
    assert ("libffcx_forms_not_compiled_yet", ("form_x",), "/nonexistent") not in formcache._found
