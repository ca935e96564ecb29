"""How each level's equations are solved: linear solvers and PETSc options, Newton and its parts, the damped
fallback, the fixed-point methods, the damage steps of each scheme, and Mechanics (a method wired to a problem).

Layer 4: imports solver.physics and below.
"""
