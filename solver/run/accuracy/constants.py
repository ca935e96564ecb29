"""Calibration constants of accuracy on demand: measured, not derived (figures and provenance in
docs/guide/accuracy.md, "Calibration constants")."""

from __future__ import annotations

# C = error / indicator of the residual estimator times 2 mu (the indicator is a stress, the error a strain), per
# displacement degree: the largest values measured on Example 1, rounded up
C_TIMES_2MU = {1: 4.0e-3 * 100.0 / 1.3, 2: 1.8e-3 * 100.0 / 1.3}
# error ~ dofs^-rate on meshes adapted by Dörfler marking, per displacement degree
ADAPTED_RATE = {1: 0.49, 2: 1.02}
# a time step's cost per displacement dof, per degree, relative to P1
COST_PER_DOF = {1: 1.0, 2: 1.13}
