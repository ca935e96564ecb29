"""solver/run/accuracy/memory.py: the planner's dof limit, accuracy.max_dofs or what fits in the memory."""

import os

from solver.config import AccuracyConfig
from solver.run.accuracy import memory
from solver.run.accuracy.memory import BYTES_PER_DOF, MEMORY_SHARE, dof_limit, memory_dofs


def test_the_memory_gives_the_dofs_of_its_share(comm):
    machine = os.sysconf("SC_PHYS_PAGES") * os.sysconf("SC_PAGE_SIZE")  # the ranks of a test share one machine
    assert memory_dofs(comm) == int(MEMORY_SHARE * machine / BYTES_PER_DOF)


def test_the_limit_is_the_smaller_and_names_its_setting(comm, monkeypatch):
    assert dof_limit(AccuracyConfig(max_dofs=10), comm) == (10, "accuracy.max_dofs")
    monkeypatch.setattr(memory, "BYTES_PER_DOF", BYTES_PER_DOF * 1e9)
    fit = memory_dofs(comm)
    limit, setting = dof_limit(AccuracyConfig(max_dofs=fit + 1), comm)
    assert limit == fit and setting.startswith("the memory (") and f"accuracy.max_dofs = {fit + 1}" in setting
