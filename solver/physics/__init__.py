"""The model in UFL and at quadrature points (docs/model.md §1-§3): material, memory, damage law, contact,
the displacement problem and its operators, diagnostics and the error estimator.

Layer 3: imports solver.mesh, solver.config, solver.errors.
"""
