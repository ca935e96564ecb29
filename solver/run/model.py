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
from solver.config.time import TimeScheme
from solver.laws.memory import MemoryIntegrand
from solver.mesh.geometry import Geometry, build
from solver.physics.material import lame
from solver.physics.memory import SUM_RULES, History, PlaneStrainHistory, make_history, trapezoid_term
from solver.physics.memory_source import MemorySource, OutOfPlaneSource
from solver.physics.quadrature import QuadratureRule
from solver.solvers.damage_step import Damage, DamageLinearSolve, make_damage
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
    scheme: TimeScheme
    u_prev: fem.Function | None = None  # u_{n-1} while level n is solved (time.order = 2: the extrapolation)

    @property
    def comm(self) -> MPI.Comm:
        return self.geo.comm

    @property
    def linear(self) -> str:
        """The linear solver solver.linear resolved to on this mesh (linear.choose_linear); cfg keeps the scene's."""
        return self.mech.settings.linear.kind

def time_scheme(cfg: Config) -> TimeScheme:
    """The scene's time scheme (memory rule, damage step, start-up), decided here once for the model."""
    return TimeScheme.decide(cfg.time.order, cfg.memory.kernel, cfg.memory.rule, cfg.damage.enabled,
                             cfg.solver.damage_scheme)


def build_model(cfg: Config, comm: MPI.Comm, geo: Geometry | None = None, contact_near_nullspace: bool = True) -> Model:
    """Mesh, spaces and the physics terms the scene switches on (``geo``: a mesh already made, e.g. refined,
    instead of the scene's; ``contact_near_nullspace``: see settings.NewtonSettings)."""
    scheme = time_scheme(cfg)
    sum_rule = SUM_RULES[scheme.memory_rule]
    geo = build(comm, cfg.mesh, cfg.boundaries, cfg.dim) if geo is None else geo
    mesh = geo.mesh
    disc = cfg.discretization
    V = fem.VectorFunctionSpace(mesh, ("CG", disc.u_degree))
    u = fem.Function(V, name="displacement")
    k, steps = cfg.time.k, cfg.time.steps
    dofs = V.dofmap.index_map.size_global * V.dofmap.index_map_bs
    linear = choose_linear(cfg.solver.linear, comm, geo.dim, dofs, cfg.solver.method, steps)
    # the resolved linear solver's one truth; cfg itself keeps the scene's value (restart's hash)
    settings = MethodSettings.from_config(cfg.solver, linear, contact_near_nullspace, cfg.discretization.u_degree)
    damage = None
    if cfg.damage.enabled:
        Z = fem.FunctionSpace(mesh, ("CG", disc.zeta_degree))
        solve = DamageLinearSolve(cfg.solver.petsc_options, linear, cfg.solver.rtol)
        damage = make_damage(scheme.damage_scheme, Z, u, cfg.damage, k,
                             cfg.solver.damage_quadrature_degree, solve)
        zeta = damage.zeta
    else:
        zeta = fem.Constant(mesh, PETSc.ScalarType(cfg.damage.zeta0))
    rule = QuadratureRule(mesh, cfg.solver.quadrature_degree)
    mat = cfg.material
    history = None
    implicit = None
    if cfg.memory.kernel != "none":
        integrand = MemoryIntegrand(cfg.memory.L, *lame(mat.E, mat.nu, mat.model))
        # the strains read again: u_n's (strain norm, H_33, the next commit); u_{n-1}'s too for the extrapolation
        source = MemorySource(rule, u, zeta, integrand, keep=2 if sum_rule.extrapolated else 1)
        history = make_history(cfg.memory, scheme.memory_rule, rule, source, k, steps)
        if sum_rule.implicit:
            implicit = trapezoid_term(history, integrand, zeta)
        if mat.model == "plane_strain":  # sigma_33 has a memory part too
            out_of_plane = make_history(cfg.memory, scheme.memory_rule, rule, OutOfPlaneSource(rule, source), k, steps)
            history = PlaneStrainHistory(history, out_of_plane)
    mech = build_mechanics(geo, u, mat, cfg.boundaries, settings, history, implicit_term=implicit,
                           body_force=cfg.body_force)
    u_prev = fem.Function(V, name="displacement_previous") if history is not None and history.extrapolated else None
    return Model(cfg, geo, u, zeta, damage, history, rule, mech, scheme, u_prev)
