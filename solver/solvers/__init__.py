"""How each level's equations are solved: linear solvers and PETSc options (linear.py), the settings each part
uses (settings.py), the displacement methods as a registry (methods.py: newton, newton_energy, newton_condensed,
auto, fixed_point, penalty_duality, each behind the interface of method.py), the damage steps of each scheme
(damage.py), and Mechanics (mechanics.py: the scene's displacement physics with its method).

Layer 4: imports solver.physics and below.
"""
