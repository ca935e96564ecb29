"""The in-process memo of compiled forms: a model built again asks the disk cache for nothing, and is the same."""

import numpy as np
import pytest

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
    other = build_model(cfg.replace({"mesh": {"nx": 5, "ny": 3}}, "test"), comm)  # another mesh: nothing compiled
    Stepper(other).step(0)
    assert asked == []


def test_a_module_not_in_the_memo_is_looked_up_on_disk(monkeypatch):
    asked = []
    monkeypatch.setattr(formcache, "_disk_lookup", lambda *a: asked.append(a[0]) or (None, None))
    assert formcache._lookup("libffcx_forms_not_compiled_yet", ["form_x"], "/nonexistent", 1) == (None, None)
    assert asked == ["libffcx_forms_not_compiled_yet"]
    assert ("libffcx_forms_not_compiled_yet", ("form_x",), "/nonexistent") not in formcache._found


@pytest.mark.serial  # starts its own process
def test_from_a_cold_cache(tmp_path):
    """Issue 32, item 15: in a fresh image (an empty FFCx cache) the test above failed every time. Three causes:
    the second build looked up on disk the modules the first had compiled (the memo keeps them now),
    Geometry.measure compiled a form named after each mesh (no form now), and FFCx marks a mesh's coordinate
    element equispaced in place when it first compiles a form on it, so forms made after that were named
    otherwise than in a build that found everything in the cache (geometry.equispaced marks it at creation).
    Run it with an empty cache directory of its own."""
    import os
    import subprocess
    import sys

    from conftest import ROOT

    env = dict(os.environ, XDG_CACHE_HOME=str(tmp_path / "cache"))
    res = subprocess.run([sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider",
                          "tests/run/test_formcache.py::test_a_second_build_reads_no_disk_cache_and_gives_the_same_level"],
                         cwd=ROOT, env=env, capture_output=True, text=True, timeout=1800)
    assert res.returncode == 0, res.stdout[-3000:]
    assert (tmp_path / "cache" / "fenics").is_dir()  # it did compile into the fresh cache


def test_the_measure_of_a_boundary_part_compiles_nothing(comm, monkeypatch):
    """Geometry.measure from coordinates: no form, so a new mesh compiles nothing for it."""
    import ffcx.codegeneration.jit as ffcx_jit

    from solver.config import from_dict as scene
    from solver.mesh.geometry import build

    cfg = scene({"mesh": {"nx": 3, "ny": 5}})
    compiled = []
    monkeypatch.setattr(ffcx_jit, "compile_forms", lambda *a, **k: compiled.append(a) or None)
    geo = build(comm, cfg.mesh, cfg.boundaries, cfg.dim)
    assert compiled == []
    assert abs(geo.measure("bottom") - 1.0) < 1e-14 and abs(geo.measure("left") - 1.0) < 1e-14


def test_a_compiled_module_is_opened_by_name_without_listing_the_cache(comm, monkeypatch):
    """Issue 30, start-up: a module FFCx compiled in an earlier process is loaded from its file, not found by FFCx's
    lookup (which lists the whole cache directory each time); the model is the same."""
    cfg = from_dict({"mesh": {"nx": 4, "ny": 4}, "time": {"T": 0.2, "k": 0.1}})
    first = build_model(cfg, comm)  # compiles (or finds) every module once
    rows_first = [Stepper(first).step(n) for n in range(3)]
    asked = []
    disk = formcache._disk_lookup
    monkeypatch.setattr(formcache, "_found", {})  # as in a new process: nothing in memory
    monkeypatch.setattr(formcache, "_disk_lookup", lambda *a: asked.append(a[0]) or disk(*a))
    second = build_model(cfg, comm)
    rows_second = [Stepper(second).step(n) for n in range(3)]
    assert asked == []
    assert formcache.kept() > 0
    assert np.array_equal(first.u.x.array, second.u.x.array)
    assert [r["strain_norm"] for r in rows_first] == [r["strain_norm"] for r in rows_second]
