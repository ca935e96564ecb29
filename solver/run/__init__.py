"""Running a scene in memory: the model a scene builds, the time scheme, the stepper and its loop of levels
(writes nothing), and the accuracy planner (--tolerance).

Layer 5: imports solver.solvers and below.
"""
