"""The largest mesh the planner may grow: ``accuracy.max_dofs`` or what fits in the machines' memory."""

from __future__ import annotations

import os
import socket

from mpi4py import MPI

from solver.config import AccuracyConfig

# memory a run needs per displacement dof, all ranks together (measured: docs/guide/accuracy.md)
BYTES_PER_DOF = 8.4e3
# the share of the machines' memory a planned mesh may take
MEMORY_SHARE = 0.8


def memory_dofs(comm: MPI.Comm) -> int:
    """The displacement dofs that fit in MEMORY_SHARE of the memory of the machines the ranks run on (each node
    counted once), at BYTES_PER_DOF. Collective."""
    try:
        mine = os.sysconf("SC_PHYS_PAGES") * os.sysconf("SC_PAGE_SIZE")
    except (ValueError, OSError):
        return 2**62
    nodes = dict(comm.allgather((socket.gethostname(), mine)))
    return int(MEMORY_SHARE * sum(nodes.values()) / BYTES_PER_DOF)


def dof_limit(acc: AccuracyConfig, comm: MPI.Comm) -> tuple[int, str]:
    """The planner's limit on the dofs of a mesh and the setting it comes from (for the refusal's message):
    accuracy.max_dofs, or the memory. Collective."""
    mem = memory_dofs(comm)
    if mem < acc.max_dofs:
        return mem, f"the memory ({mem} dofs fit in {MEMORY_SHARE:.0%} of it; accuracy.max_dofs = {acc.max_dofs})"
    return acc.max_dofs, "accuracy.max_dofs"
