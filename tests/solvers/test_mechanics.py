"""The displacement problem against closed forms: a patch test (with memory) and a block
pressed by a deformable foundation (normal compliance)."""

import math

import numpy as np
import pytest
from conftest import ROOT, solve
from mpi4py import MPI

from solver.config import from_dict
from solver.run.model import build_model


def _x_stretch_scene(memory: dict, T=0.5, k=0.1, t=10.0, L=1000.0):
    # nu = 0: uniaxial stress, clamping the left side does not constrain lateral contraction
    return from_dict({
        "mesh": {"nx": 4, "ny": 3, "corners": [[0, 0], [2, 1]]},
        "boundary": {"left": {"role": "clamped"}, "right": {"role": "traction", "traction": [t, 0.0]}},
        "material": {"E": 100.0, "nu": 0.0},
        "memory": {**memory, "L": L},
        "damage": {"enabled": False, "zeta0": 0.8},
        "time": {"T": T, "k": k},
    })


def _tip_strain(model) -> float:
    """u_x / x at the right side: the uniform strain eps_xx."""
    x = model.u.function_space.tabulate_dof_coordinates()
    u = model.u.x.array.reshape(-1, 2)
    sel = np.isclose(x[:, 0], 2.0)
    vals = u[sel, 0] / 2.0
    vmax = model.comm.allreduce(vals.max() if vals.size else -np.inf, op=MPI.MAX)
    vmin = model.comm.allreduce(vals.min() if vals.size else np.inf, op=MPI.MIN)
    assert vmax - vmin < 1e-12
    uy = model.comm.allreduce(np.abs(u[:, 1]).max(), op=MPI.MAX)
    assert uy < 1e-12
    return vmax


@pytest.mark.parametrize("memory,g", [
    ({"kernel": "none"}, None),
    ({"kernel": "constant", "weights": [1.0]}, lambda s: 1.0),
    ({"kernel": "exponential", "weights": [-1.0], "times": [1.0]}, lambda s: -math.exp(-s)),
])
@pytest.mark.parametrize("L", [1000.0, 6.0])
def test_patch_with_memory(comm, memory, g, L):
    """Uniform stress t: E eps_n + k sum_m g((n-m)k) zeta0 min(L, E eps_m) = t, solved exactly by P1."""
    E, t, k, zeta0 = 100.0, 10.0, 0.1, 0.8
    cfg = _x_stretch_scene(memory, k=k, t=t, L=L)
    model = build_model(cfg, comm)
    eps = []
    for n in range(cfg.time.steps + 1):
        model.mech.solve(n * k)
        if model.history is not None:
            model.history.commit(n)
        mem = 0.0 if g is None else k * sum(g((n - m) * k) * zeta0 * min(L, E * eps[m]) for m in range(n))
        want = (t - mem) / E
        eps.append(want)
        assert _tip_strain(model) == pytest.approx(want, rel=1e-10)


@pytest.mark.parametrize("mu", [1e-2, 1e-4, 1e-10])
def test_block_pressed_by_foundation(comm, mu):
    """Clamped top, foundation overlapping the bottom by delta (gap g = -delta), nu = 0:
    u_y = a (1 - y), a = delta / (1 + E mu); the contact force is E a."""
    E, delta = 100.0, 1e-3
    cfg = from_dict({
        "mesh": {"nx": 3, "ny": 5},
        "boundary": {"top": {"role": "clamped"}, "bottom": {"role": "contact", "gap": -delta, "mu": mu}},
        "material": {"E": E, "nu": 0.0},
        "memory": {"kernel": "none"},
        "damage": {"enabled": False},
        "time": {"T": 1.0, "k": 1.0},
    })
    model, rows = solve(cfg, comm)
    a = delta / (1 + E * mu)
    x = model.u.function_space.tabulate_dof_coordinates()
    u = model.u.x.array.reshape(-1, 2)
    err = comm.allreduce(np.abs(u[:, 1] - a * (1 - x[:, 1])).max(), op=MPI.MAX)
    assert err < 1e-9 * a
    assert rows[-1]["contact_force"] == pytest.approx(E * a, rel=1e-6)
    assert rows[-1]["contact_length"] == pytest.approx(1.0)
    assert rows[0]["newton_iterations"] <= 3


def _box_msh(path, n=3):
    """A unit cube meshed by gmsh with named faces: top (z = 1), bottom (z = 0), and the volume."""
    import gmsh

    gmsh.initialize(readConfigFiles=False)
    try:
        gmsh.option.setNumber("General.Terminal", 0)
        gmsh.model.add("box")
        vol = gmsh.model.occ.addBox(0, 0, 0, 1, 1, 1)
        gmsh.model.occ.synchronize()
        for tag, (name, z) in enumerate((("top", 1.0), ("bottom", 0.0)), start=1):
            faces = [s for _, s in gmsh.model.getEntities(2)
                     if abs(gmsh.model.occ.getCenterOfMass(2, s)[2] - z) < 1e-9]
            gmsh.model.addPhysicalGroup(2, faces, tag)
            gmsh.model.setPhysicalName(2, tag, name)
        gmsh.model.addPhysicalGroup(3, [vol], 10)
        gmsh.option.setNumber("Mesh.MeshSizeMax", 1.0 / n)
        gmsh.model.mesh.generate(3)
        gmsh.write(str(path))
    finally:
        gmsh.finalize()


@pytest.mark.serial  # the mesh file is written by this process
def test_block_pressed_by_foundation_3d(tmp_path):
    """The 1-D closed form of the pressed block in 3-D (nu = 0): u_z = a (1 - z), a = delta / (1 + E mu)."""
    E, delta, mu = 100.0, 1e-3, 1e-2
    msh = tmp_path / "box.msh"
    _box_msh(msh)
    cfg = from_dict({
        "mesh": {"kind": "gmsh", "file": str(msh)},
        "boundary": {"top": {"role": "clamped"}, "bottom": {"role": "contact", "gap": -delta, "mu": mu}},
        "material": {"E": E, "nu": 0.0, "model": "3d"},
        "memory": {"kernel": "none"},
        "damage": {"enabled": False},
        "time": {"T": 1.0, "k": 1.0},
    })
    comm = MPI.COMM_WORLD
    model, rows = solve(cfg, comm)
    a = delta / (1 + E * mu)
    x = model.u.function_space.tabulate_dof_coordinates()
    u = model.u.x.array.reshape(-1, 3)
    assert np.abs(u[:, 2] - a * (1 - x[:, 2])).max() < 1e-9 * a
    assert np.abs(u[:, :2]).max() < 1e-12
    assert rows[-1]["contact_force"] == pytest.approx(E * a, rel=1e-6)


def test_p2_elastic_contact_matches_an_independent_p2_solve(comm):
    """Example 1 at t = 0 with u_degree = 2, n = 16, against the same static problem written here in plain dolfinx
    (P2, plane stress, clamped left, load (-10, -10) on the right, p(r) = r+/1e-10 on the bottom with a degree-4
    facet rule) and solved by dolfinx's own Newton solver: u(1, 1) to 1e-8."""
    import ufl
    from conftest import point_value
    from dolfinx import fem, mesh, nls
    from dolfinx.fem import petsc as fpetsc

    from solver.config import load
    from solver.run.stepper import Stepper

    msh = mesh.create_unit_square(comm, 16, 16)
    V = fem.VectorFunctionSpace(msh, ("CG", 2))
    E, nu = 100.0, 0.3
    lam, mu_l = E * nu / (1 - nu**2), E / (2 * (1 + nu))
    fdim = msh.topology.dim - 1
    sides = {1: lambda x: np.isclose(x[0], 0.0), 2: lambda x: np.isclose(x[0], 1.0), 3: lambda x: np.isclose(x[1], 0.0)}
    found = [(mesh.locate_entities_boundary(msh, fdim, f), tag) for tag, f in sides.items()]
    idx = np.concatenate([f for f, _ in found])
    val = np.concatenate([np.full(len(f), tag, dtype=np.int32) for f, tag in found])
    order = np.argsort(idx)
    tags = mesh.meshtags(msh, fdim, idx[order], val[order])
    ds = ufl.Measure("ds", domain=msh, subdomain_data=tags)
    u, w = fem.Function(V), ufl.TestFunction(V)
    n = ufl.FacetNormal(msh)

    def eps(v):
        return ufl.sym(ufl.grad(v))

    sigma = lam * ufl.tr(eps(u)) * ufl.Identity(2) + 2 * mu_l * eps(u)
    f = fem.Constant(msh, np.array([-10.0, -10.0]))
    F = (ufl.inner(sigma, eps(w)) * ufl.dx - ufl.dot(f, w) * ds(2)
         + ufl.max_value(ufl.dot(u, n), 0.0) / 1e-10 * ufl.dot(w, n) * ds(3, metadata={"quadrature_degree": 4}))
    clamped = fem.locate_dofs_topological(V, fdim, tags.find(1))
    bc = fem.dirichletbc(np.zeros(2), clamped, V)
    problem = fpetsc.NonlinearProblem(F, u, bcs=[bc])
    newton = nls.petsc.NewtonSolver(comm, problem)
    newton.convergence_criterion, newton.rtol, newton.atol, newton.max_it = "incremental", 1e-13, 0.0, 50
    ksp = newton.krylov_solver
    ksp.setType("preonly")
    ksp.getPC().setType("lu")
    its, converged = newton.solve(u)
    assert converged

    cfg = load(ROOT / "configs/example1.toml",
               ["mesh.nx=16", "mesh.ny=16", "discretization.u_degree=2"])
    model = build_model(cfg, comm)
    assert cfg.solver.contact_quadrature_degree == 4
    Stepper(model).step(0)
    ours, theirs = point_value(model.u, [1.0, 1.0]), point_value(u, [1.0, 1.0])
    print(f"u(1, 1): ours {ours}, independent {theirs}, difference {np.abs(ours - theirs).max():.2e}")
    assert np.abs(ours - theirs).max() <= 1e-8, (ours, theirs)
