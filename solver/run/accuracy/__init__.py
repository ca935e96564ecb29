"""Accuracy on demand: the degree, the mesh and the step that bring the paper's error below a tolerance
(docs/guide/accuracy.md).

Where to read it:

- :mod:`.planner` -- the plan, stage by stage (:func:`plan`);
- :mod:`.time_error` -- the step, by step doubling or from the run's step controller (``accuracy.time``); :mod:`.zeta` --
  the damage's space part on nested meshes;
- :mod:`.solves` -- the solves the planner measures with, and the strategies that judge u's mesh;
- :mod:`.records` -- what a plan chose (:class:`Plan`, plan.json) and its estimates;
- :mod:`.sensor` -- the run's estimated error per level (:class:`ErrorSensor`);
- :mod:`.calibration` -- the estimator's constant on the scene; :mod:`.ingredients` -- how much each optional
  ingredient changes the answer, and what ``accuracy.simplify`` leaves out;
- :mod:`.constants` -- calibration constants; :mod:`.memory` -- the dof limit; :mod:`.check` -- the command
  line's check of ``--set`` against a tolerance; :mod:`.scene` -- the scene changes the planner tries.
"""

from .check import CHOSEN_KEYS, contradicting
from .constants import ADAPTED_RATE, C_TIMES_2MU, COST_PER_DOF
from .memory import BYTES_PER_DOF, MEMORY_SHARE, dof_limit, memory_dofs
from .planner import GROWTH_AT_0, ROOM_MARGIN, ROOM_ZETA_MAX, THETA_MAX, ZETA_SHARE, Planner, dorfler_fraction, plan
from .records import ErrorEstimate, MeshRecord, Plan
from .scene import degrees
from .sensor import ErrorSensor, Largest
from .time_error import N0, SAFETY
from .zeta import ZETA_EXPONENT_MAX, ZETA_EXPONENT_MIN, observed_exponent

_theta = dorfler_fraction  # the name tests/run/test_accuracy.py imported

__all__ = ["ADAPTED_RATE", "BYTES_PER_DOF", "CHOSEN_KEYS", "COST_PER_DOF", "C_TIMES_2MU", "GROWTH_AT_0", "MEMORY_SHARE",
           "N0", "ROOM_MARGIN", "ROOM_ZETA_MAX", "SAFETY", "THETA_MAX", "ZETA_EXPONENT_MAX", "ZETA_EXPONENT_MIN",
           "ZETA_SHARE", "ErrorEstimate", "ErrorSensor", "Largest", "MeshRecord", "Plan", "Planner", "contradicting",
           "degrees", "dof_limit", "dorfler_fraction", "memory_dofs", "observed_exponent", "plan"]
