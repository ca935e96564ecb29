"""What one scene builds (docs/model.md §3): mesh, spaces and the physics terms it switches on.

No damage solve without damage, no history without memory, no contact term without a
contact part. :class:`Model` holds the parts; :class:`solver.run.stepper.Stepper` advances it.
"""

from __future__ import annotations

from dataclasses import dataclass

from dolfinx import fem
from mpi4py import MPI
from petsc4py import PETSc

from solver.config import Config
from solver.mesh.geometry import Geometry, build
from solver.physics.material import elasticity, lame
from solver.physics.memory import History, PlaneStrainHistory, make_history, trapezoid_term
from solver.physics.memory_source import MemorySource, OutOfPlaneSource
from solver.physics.quadrature import QuadratureRule
from solver.run.scheme import time_scheme
from solver.solvers.damage import Damage, DamageLinearSolve, make_damage
from solver.solvers.linear import choose_linear
from solver.solvers.mechanics import Mechanics, build_mechanics
from solver.solvers.settings import MethodSettings


@dataclass
class Model:
    """Everything one scene builds: geometry, fields and the physics it switches on."""

    cfg: Config
    geo: Geometry
    u: fem.Function
    zeta: fem.Function | fem.Constant
    damage: Damage | None
    history: History | None
    rule: QuadratureRule
    mech: Mechanics
    u_prev: fem.Function | None = None  # u_{n-1} while level n is solved (time.order = 2: the extrapolation)

    @property
    def comm(self) -> MPI.Comm:
        return self.geo.comm

    @property
    def linear(self) -> str:
        """The linear solver solver.linear resolved to on this mesh (linear.choose_linear); cfg keeps the scene's."""
        return self.mech.settings.linear.kind


def build_model(cfg: Config, comm: MPI.Comm, geo: Geometry | None = None, contact_near_nullspace: bool = True) -> Model:
    """Mesh, spaces and the physics terms the scene switches on (``geo``: a mesh already made, e.g. refined,
    instead of the scene's; ``contact_near_nullspace``: see settings.NewtonSettings)."""
    geo = build(comm, cfg.mesh, cfg.boundaries, cfg.dim) if geo is None else geo
    mesh = geo.mesh
    disc = cfg.discretization
    V = fem.VectorFunctionSpace(mesh, ("CG", disc.u_degree))
    u = fem.Function(V, name="displacement")
    k, steps = cfg.time.k, cfg.time.steps
    dofs = V.dofmap.index_map.size_global * V.dofmap.index_map_bs
    linear = choose_linear(cfg.solver.linear, comm, geo.dim, dofs, cfg.solver.method, steps)
    # the resolved linear solver's one truth; cfg itself keeps the scene's value (restart's hash)
    settings = MethodSettings.from_config(cfg.solver, linear, contact_near_nullspace)
    damage = None
    if cfg.damage.enabled:
        Z = fem.FunctionSpace(mesh, ("CG", disc.zeta_degree))
        solve = DamageLinearSolve(cfg.solver.petsc_options, linear, cfg.solver.rtol)
        damage = make_damage(time_scheme(cfg).damage_scheme(cfg), Z, u, cfg.damage, k,
                             cfg.solver.damage_quadrature_degree, solve)
        zeta = damage.zeta
    else:
        zeta = fem.Constant(mesh, PETSc.ScalarType(cfg.damage.zeta0))
    rule = QuadratureRule(mesh, cfg.solver.quadrature_degree)
    mat = cfg.material
    history = None
    if cfg.memory.kernel != "none":
        lame_lambda, lame_mu = lame(mat.E, mat.nu, mat.model)
        source = MemorySource(rule, u, zeta, lame_lambda, lame_mu, cfg.memory.L)
        history = make_history(cfg.memory, rule, source, k, steps)
    implicit = None
    if history is not None and cfg.memory.rule == "trapezoid":
        implicit = trapezoid_term(history, zeta, lambda e: elasticity(e, mat.E, mat.nu, mat.model), cfg.memory.L)
    if history is not None and mat.model == "plane_strain":  # sigma_33 has a memory part too
        history = PlaneStrainHistory(history, make_history(cfg.memory, rule, OutOfPlaneSource(rule, source), k, steps))
    mech = build_mechanics(geo, u, mat, cfg.boundaries, settings, history, implicit_term=implicit,
                           body_force=cfg.body_force)
    u_prev = fem.Function(V, name="displacement_previous") if history is not None and history.extrapolated else None
    return Model(cfg, geo, u, zeta, damage, history, rule, mech, u_prev)
