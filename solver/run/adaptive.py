"""Adaptive steps (``time.adaptive``; docs/model.md §3.9): a step controller around the time loop.

Each trial step is the scheme's own level (:meth:`solver.run.stepper.Stepper.step` with its k). The scheme is
quasistatic: u_n is an algebraic function of the state at t_n (the memory sum M_n, the damage zeta_n) and the
load, and the implicit solve makes no time error in it. The time error enters through the state only, so the
local error is estimated on the state and carried to u by a bound, at the cost of a few vector operations and no
solve:
- memory: the left rule's error over the step, (k/2)(g(0) H_n - g(k) H_{n-1}) at the memory points (order 2: the
  extrapolated trapezoid's, from the miss of H_n by the extrapolation of H_{n-1}, H_{n-2});
- damage: the explicit source's error over the step, (k/2)(phi_n - phi_{n-1}) at the nodes (order 2: AB2's), zero
  at nodes clipped to zeta*;
- accumulated as fields, the damage error moving M over each step by k g(0) E_zeta Phi_L(A eps(u_n)), and carried
  to u by ||eps(du)|| <= ||dM|| / (2 mu_L) (A's smallest eigenvalue; the contact term only stiffens).
A kink of u (a contact point that opens or closes) is no error of the state, and costs no step. The local errors
are accumulated as fields and a step's error is the growth of the accumulated error's norm; a step is accepted
when it is within an equal quantum per step (:meth:`StepController._ratio`), else the state is put back and the
step retried smaller. The next step follows Söderlind's PI controller (PI.4.2, PETSc's TSAdapt
DSP default). Steps land on every kink of a load table, on ``output.times`` and on T; a step over which the
contact zone changes by more than ACTIVE_FRACTION of Γ_C does not let the next one grow. The controller's state
(the step history, the PI memory and the state's past values the estimate differences) goes into checkpoints,
so that a restart takes the same steps.
"""

from __future__ import annotations

import math
from collections.abc import Iterator

import dolfinx.fem.petsc  # noqa: F401  (fem.petsc)
import numpy as np
import ufl
from dolfinx import fem
from mpi4py import MPI
from petsc4py import PETSc

from solver.config import Config
from solver.errors import SolveFailure
from solver.physics.material import lame, strain
from solver.physics.memory_source import point_weights

SAFETY = 0.9  # the next step aims at SAFETY times the tolerance
GROW, SHRINK = 2.0, 0.2  # the most a step grows or shrinks to the next one
RETRY = (0.1, 0.9)  # a rejected step is retried at this fraction of it (the controller's choice clipped)
BETA = (0.6, -0.2)  # PI.4.2: k_{n+1} = k_n (1/r_n)^{BETA[0]/p} (1/r_{n-1})^{BETA[1]/p}
ACTIVE_FRACTION = 0.05  # a change of the contact zone beyond this fraction of Γ_C's measure stops the step's growth
STRETCH = 0.25  # a mark this fraction of a step ahead or less is reached by stretching the step
FREEZE = True  # the quantum never grows back: one quantum for the run, the best use of its steps
HOLD = 2  # grid points a step must grow by at least (else it is kept)
GRID = 8  # steps are T 2^(j/GRID): a round-off in an estimate (another partition, a restart) moves no step
SHARE = 0.7  # of the tolerance, for the sum of the steps' errors (each at most (SHARE tol / S)^2, see _ratio)


def lumped_mass(V: fem.FunctionSpace) -> np.ndarray:
    """The owned nodes' lumped masses: P1, the row sums (1, xi_i); higher degrees, the consistent mass matrix's
    diagonal scaled to the domain's measure (Hinton-Rock-Zienkiewicz), positive where P2's row sums vanish (triangles'
    vertices) or are negative (tetrahedra's)."""
    xi = ufl.TestFunction(V)
    n = V.dofmap.index_map.size_local
    if V.ufl_element().degree() == 1:
        mass = fem.petsc.assemble_vector(fem.form(xi * ufl.dx))
        mass.ghostUpdate(addv=PETSc.InsertMode.ADD, mode=PETSc.ScatterMode.REVERSE)
        return mass.array_r[:n].copy()
    M = fem.petsc.assemble_matrix(fem.form(ufl.TrialFunction(V) * xi * ufl.dx))
    M.assemble()
    diag = M.getDiagonal().array_r[:n].copy()
    M.destroy()
    comm = V.mesh.comm
    measure = comm.allreduce(fem.assemble_scalar(fem.form(fem.Constant(V.mesh, 1.0) * ufl.dx)), op=MPI.SUM)
    return diag * (measure / comm.allreduce(float(diag.sum()), op=MPI.SUM))


def load_kinks(cfg: Config) -> list[float]:
    """The times in (0, T) of the rows of every load table (tractions, displacements, body force)."""
    tables = [b.traction for b in cfg.boundaries if b.role == "traction"]
    tables += [c for b in cfg.boundaries if b.role == "displacement" for c in b.displacement if c is not None]
    tables.append(cfg.body_force.f)
    T = cfg.time.T
    return sorted({float(r[0]) for table in tables for r in table if 0.0 < r[0] < T})


def output_times(cfg: Config) -> list[float]:
    """The times in (0, T] an adaptive run lands on to write them: ``output.times`` and T."""
    T = cfg.time.T
    return sorted({*(t for t in cfg.output.times if 0.0 < t < T), T})


class Snapshot:
    """A copy of the model's whole state at an accepted level, put back when a trial step is rejected. One object
    serves the whole run: :meth:`take` copies into the buffers of the last take (no allocation per step)."""

    def __init__(self, model) -> None:
        self.model = model
        self.fields: list[tuple[np.ndarray, np.ndarray]] = []
        self.arrays: dict[str, dict[str, np.ndarray]] = {}
        self.scalars: dict[str, dict[str, float]] = {}
        self.take()

    @staticmethod
    def _functions(model) -> list[fem.Function]:
        out = [model.u]
        if model.u_prev is not None:
            out.append(model.u_prev)
        if model.damage is not None:
            out.append(model.damage.zeta)
        return out

    def _parts(self) -> dict:
        model = self.model
        out = {"mech": model.mech}
        if model.damage is not None:
            out["damage"] = model.damage
        if model.history is not None:
            out["history"] = model.history
        return out

    @staticmethod
    def _copy(into: dict[str, np.ndarray], arrays: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
        out = {}
        for k, v in arrays.items():
            old = into.get(k)
            if old is not None and old.shape == v.shape and old.dtype == v.dtype:
                np.copyto(old, v)
                out[k] = old
            else:
                out[k] = v.copy()
        return out

    def take(self) -> None:
        """Copy the current state (the accepted level's)."""
        live = [f.x.array for f in self._functions(self.model)]
        if len(live) == len(self.fields) and all(a is t for a, (t, _) in zip(live, self.fields)):
            for target, values in self.fields:
                np.copyto(values, target)
        else:
            self.fields = [(a, a.copy()) for a in live]
        for name, part in self._parts().items():
            self.arrays[name] = self._copy(self.arrays.get(name, {}), part.state())
            if name != "history":
                self.scalars[name] = part.scalars()

    def restore(self) -> None:
        model = self.model
        for target, values in self.fields:
            target[:] = values
        if model.damage is not None:
            for k, v in self.arrays["damage"].items():
                model.damage.restore(k, v)
            model.damage.restore_scalars(self.scalars["damage"])
        if model.history is not None:
            live = model.history.state()
            for k, v in self.arrays["history"].items():
                live[k][...] = v
        for k, v in self.arrays["mech"].items():
            model.mech.restore_vector(k, v)
        model.mech.restore_scalars(self.scalars["mech"])


class StepController:
    """Chooses the steps of an adaptive run and steps the levels (:meth:`levels`); its state is checkpointed."""

    columns = ("k", "error_estimate", "rejected")

    def __init__(self, model) -> None:
        cfg = model.cfg
        self.model = model
        tc = cfg.time
        self.T, self.tol, self.p = tc.T, tc.tolerance, tc.order
        self.k_min, self.k_max = tc.smallest, tc.largest
        self.kinks = load_kinks(cfg)
        self.marks = sorted(set(self.kinks) | set(output_times(cfg)))
        self.comm = model.comm
        # the state a checkpoint keeps
        self.n, self.t, self.k_prev, self.k_next, self.r_prev = 0, 0.0, math.nan, tc.k, 1.0
        self.length_prev = 0.0
        self.S = 0.0  # sum over the accepted steps of sqrt(their error)
        self.mu = math.inf  # the smallest quantum taken so far
        self.have = 0  # past values of the state held for the estimate (since the start, or a kink at order 2)
        self.past_t = np.zeros(self.p)
        self._sums = np.zeros(4)
        self._memory_parts(model)
        self._damage_parts(model)
        self.gamma_c = self._contact_measure(model)
        self._snapshot: Snapshot | None = None

    # ------------------------------------------------------------------ state
    def scalars(self) -> dict[str, float]:
        return {"n": float(self.n), "t": self.t, "k_prev": self.k_prev, "k_next": self.k_next, "r_prev": self.r_prev,
                "length_prev": self.length_prev, "have": float(self.have), "S": self.S, "mu": self.mu,
                **{f"past_t{i}": float(v) for i, v in enumerate(self.past_t)}}

    def restore_scalars(self, s: dict[str, float]) -> None:
        self.n, self.t, self.k_prev, self.k_next = int(s["n"]), s["t"], s["k_prev"], s["k_next"]
        self.r_prev, self.length_prev, self.have = s["r_prev"], s["length_prev"], int(s["have"])
        self.S, self.mu = s["S"], s["mu"]
        self.past_t[:] = [s[f"past_t{i}"] for i in range(len(self.past_t))]

    def arrays(self) -> dict[str, tuple[str, np.ndarray]]:
        """The state's past values the estimate differences: name -> (space "memory" | "zeta", the array, written
        back in place)."""
        out = {f"past_H{i}": ("memory", a) for i, a in enumerate(self.past_H)}
        out.update({f"past_phi{i}": ("zeta", a) for i, a in enumerate(self.past_phi)})
        if self.past_H:
            out["E_M"] = ("memory", self.E_M)
        if self.past_phi:
            out["E_z"] = ("zeta", self.E_z)
        return out

    # ------------------------------------------------------------------ the parts of the estimate
    def _memory_parts(self, model) -> None:
        """H at the memory points, its norm, Phi_L(A eps(u)) for the damage's weight, the kernel's sums."""
        history, cfg = model.history, model.cfg
        mat = cfg.material
        lam, mu = lame(mat.E, mat.nu, mat.model)
        self.alpha = 2.0 * mu  # A's smallest eigenvalue: ||eps(du)|| <= ||dM|| / alpha
        self.past_H: list[np.ndarray] = []
        if history is None:
            return
        main = getattr(history, "main", history)
        self.c, self.tau = np.asarray(main.weights, dtype=float), np.asarray(main.taus, dtype=float)
        self.g0 = float(np.sum(self.c))
        self._gk = (math.nan, math.nan)  # (k, g(k)) of the last estimate
        self.source = history.H
        self.source.remember()  # H_n formed here is the one the next step's commit reads
        self.past_H = [np.zeros_like(history.M.x.array) for _ in range(self.p)]
        self._H = np.zeros_like(history.M.x.array)
        self._dm = np.zeros_like(history.M.x.array)  # the step's error of M (scratch)
        self._lm = np.zeros_like(history.M.x.array)  # the last trial's, added to E_M when it is accepted
        # ||dM||^2 = sum over the points of w_q |J_K| dM : dM (the memory rule's own integral; ghosts weigh 0)
        self._w = point_weights(history.rule, history.H)
        self._dd = history.M.x.array.size // max(self._w.size, 1)
        self.E_M = np.zeros_like(history.M.x.array)  # the accumulated error of M
        if model.damage is not None:  # E_zeta Phi_L(A eps(u)): the accumulated damage error's rate into M
            self._Ez = fem.Function(model.damage.V)

    def _damage_parts(self, model) -> None:
        """phi at the nodes (lumped: (phi, xi) / m_i), the nodes' masses m_i (:func:`lumped_mass`)."""
        self.past_phi: list[np.ndarray] = []
        damage = model.damage
        if damage is None:
            return
        V = damage.V
        xi = ufl.TestFunction(V)
        dx = ufl.dx(metadata={"quadrature_degree": model.cfg.solver.damage_quadrature_degree})
        self._fphi = fem.form(damage.law.ufl(strain(model.u), damage.zeta) * xi * dx)
        self.nz = V.dofmap.index_map.size_local
        self.mass = lumped_mass(V)
        self._bphi = fem.petsc.create_vector(self._fphi)
        self._phi = fem.Function(V)
        self.past_phi = [np.zeros_like(damage.zeta.x.array) for _ in range(self.p)]
        self.E_z = np.zeros_like(damage.zeta.x.array)  # the accumulated error of zeta
        self.zeta_star = model.cfg.damage.zeta_star if model.cfg.damage.clip else -math.inf

    def _square_m(self, dm: np.ndarray) -> float:
        """This rank's part of ||dM||^2 in L2 over the memory rule's points (dM a memory-space array)."""
        sq = dm.reshape(-1, self._dd)
        return float(np.dot(self._w, np.einsum("ij,ij->i", sq, sq)))

    @staticmethod
    def _contact_measure(model) -> float:
        """|Γ_C| (0 without contact)."""
        parts = model.cfg.contact
        if not parts:
            return 0.0
        geo = model.geo
        one = fem.Constant(geo.mesh, 1.0)
        form = fem.form(sum(one * geo.ds(geo.tags[p.name]) for p in parts))
        return model.comm.allreduce(fem.assemble_scalar(form), op=MPI.SUM)

    def _level_state(self) -> None:
        """H_n (memory points) and phi_n (nodes) of the level just solved, into the work arrays."""
        if self.past_H:
            self.source(self._H)
        if self.past_phi:
            b = self._bphi
            with b.localForm() as bl:
                bl.set(0.0)
            fem.petsc.assemble_vector(b, self._fphi)
            b.ghostUpdate(addv=PETSc.InsertMode.ADD, mode=PETSc.ScatterMode.REVERSE)
            self._phi.x.array[: self.nz] = b.array_r[: self.nz] / self.mass
            self._phi.x.scatter_forward()

    # ------------------------------------------------------------------ the estimate
    def estimate(self, t: float) -> float:
        """The local time error of the level just solved at t, carried to the paper's norm (NaN at order 2 while
        fewer than 2 past levels are held)."""
        self._level_state()
        if self.have < self.p:
            return math.nan
        k = t - self.past_t[0]
        if self.p == 1:
            now, old, extra = 0.5 * k, 0.5 * k, 1.0
        else:  # the miss of the linear extrapolation through the two past levels
            r = k / (self.past_t[0] - self.past_t[1])
            now, old, extra = 1.0, 1.0 + r, -r
        sums = self._sums  # ||E_M||^2, ||E_M + dM||^2, ||E_z||^2, ||E_z + dz||^2 on this rank: one allreduce
        sums[:] = 0.0
        if self.past_H:
            g0 = self.g0
            if self.p == 1 and self._gk[0] != k:  # g(k), for the step's k (most steps repeat the last k)
                self._gk = (k, float(np.sum(self.c * np.exp(-k / self.tau))))
            gk = self._gk[1] if self.p == 1 else g0
            dm = self._dm
            np.multiply(self._H, now * g0, out=dm)
            dm -= (old * gk) * self.past_H[0]
            if self.p == 2:
                kp = self.past_t[0] - self.past_t[1]
                dm -= (extra * g0) * self.past_H[1]
                dm *= 0.5 * k * (1.0 + k / (3.0 * (k + kp)))  # the extrapolated term's miss and the trapezoid's
            np.copyto(self._lm, dm)
            sums[0] = self._square_m(self.E_M)
            dm += self.E_M
            sums[1] = self._square_m(dm)
        if self.past_phi:
            zeta = self.model.damage.zeta.x.array[: self.nz]
            phi = self._phi.x.array[: self.nz]
            dz = now * phi - old * self.past_phi[0][: self.nz]
            if self.p == 2:
                kp = self.past_t[0] - self.past_t[1]
                dz -= extra * self.past_phi[1][: self.nz]
                dz *= 5.0 * k * k / (6.0 * (k + kp))  # AB2's error (5/12) k^3 phi''
            held = zeta <= self.zeta_star * (1 + 1e-12)  # held at zeta*: the clip makes no error, and ends one
            dz[held] = 0.0
            self._lz, self._held = dz, held
            Ez = np.where(held, 0.0, self.E_z[: self.nz])
            sums[2] = float(np.dot(self.mass, Ez * Ez))
            Ez += dz
            sums[3] = float(np.dot(self.mass, Ez * Ez))
        total = np.sqrt(np.maximum(self.comm.allreduce(sums, op=MPI.SUM), 0.0))
        err_u0, err_u, err_z0, err_z = total[0] / self.alpha, total[1] / self.alpha, total[2], total[3]
        # the growth of the accumulated error's norm that this step's local error makes
        return float((err_u + err_z) - (err_u0 + err_z0))

    def _accumulate(self, k: float) -> None:
        """The accepted level's local errors join the accumulated ones (fields: errors of one sign add up, of
        opposite signs or at disjoint points do not); the damage error accumulated so far moves M over the step."""
        if self.past_phi:
            e = self.E_z
            e[: self.nz] += self._lz
            e[: self.nz][self._held] = 0.0
            self._Ez.x.array[: self.nz] = e[: self.nz]
            self._Ez.x.scatter_forward()
            e[:] = self._Ez.x.array
        if self.past_H:
            self.E_M += self._lm
            if self.past_phi:  # E_M += k g0 E_z Phi_L(A eps(u_n)), Phi kept by the source since the estimate
                d2 = self._dd
                ez = self.source.zeta_at_points(self._Ez.x.array)
                phi = self.source.unit().reshape(-1, d2)
                em = self.E_M.reshape(-1, d2)
                em += (k * self.g0) * (phi * ez[:, None])

    def _push(self, t: float, restart: bool) -> None:
        """Level n's state (the work arrays) becomes the newest past one; ``restart``: the only one."""
        self.past_t[1:] = self.past_t[:-1].copy()
        self.past_t[0] = t
        if self.past_H:  # the work array becomes the newest past one, the oldest the next work array (no copy)
            self.past_H.insert(0, self._H)
            self._H = self.past_H.pop()
        if self.past_phi:
            self.past_phi.insert(0, self.past_phi.pop())
            self.past_phi[0][:] = self._phi.x.array
        self.have = 1 if restart else min(self.have + 1, self.p)

    # ------------------------------------------------------------------ the steps
    def _propose(self) -> tuple[float, float]:
        """The next trial step and the level's time: k_next within the bounds, landing on the next mark."""
        k = min(max(self.k_next, self.k_min), self.k_max)
        return self._land(k)

    def _land(self, k: float) -> tuple[float, float]:
        mark = next((m for m in self.marks if m > self.t * (1 + 1e-14) + 1e-300), self.T)
        if self.t + k * (1 + STRETCH) >= mark:
            left = mark - self.t
            if left <= k * (1 + STRETCH) and left <= self.k_max * (1 + 1e-12):
                if self.t + k >= mark or left - k < STRETCH * k:
                    return left, mark
            return 0.5 * left, self.t + 0.5 * left
        return k, self.t + k

    def _retry(self, rejected: float, k: float) -> tuple[float, float]:
        """A rejected trial's retry at k, landed on the next mark like any step, but never stretched back to the
        rejected size (a trial that lands on a mark would be retried unchanged for ever): then half the way."""
        k_new, t_new = self._land(k)
        if k_new < rejected * (1 - 1e-12):
            return k_new, t_new
        half = 0.5 * (t_new - self.t)
        return half, self.t + half

    def _snap(self, k: float) -> float:
        """k rounded down to the grid T 2^(j/GRID), within the bounds: the chosen steps are exact powers, and two
        runs whose estimates differ by round-off choose the same steps (unless one sits on a grid point)."""
        j = math.floor(GRID * math.log2(k / self.T))
        return min(max(self.T * 2.0 ** (j / GRID), self.k_min), self.k_max)

    def _ratio(self, est: float, k: float) -> float:
        """The step's error over its quantum (NaN without an estimate). Error per step, equal for every step, is
        the best use of N steps (for p = 1: k ~ c^(-1/2) where the local error is c k^2; error per unit step gives
        k ~ 1/c, no better than uniform steps over the times where error is made). The quantum mu is
        (SHARE tol / S)^2, S = sum of sqrt(local error) over the run: the past steps' and, for the rest, this
        step's repeated to T (a high rate now, which later steps do not keep, makes mu smaller: safe; the mean rate
        so far instead: hard.toml 928 levels, not 840, at tolerance 1e-2)."""
        if not math.isfinite(est):
            return math.nan
        root = math.sqrt(max(est, 0.0))
        total = self.S + root * (1.0 + (self.T - self.t - k) / k)
        mu = (SHARE * self.tol / total) ** 2 if total > 0 else math.inf
        if FREEZE:
            mu = min(mu, self.mu)
        self._mu = mu
        return est / mu if est > 0 else 0.0

    def levels(self, stepper, start: int) -> Iterator[dict]:
        """Level 0 (when ``start`` is 0), then accepted levels until T, each row with its k, estimate and the
        number of rejected trials before it."""
        model = self.model
        if start == 0:
            row = stepper.step(0, 0.0, 0.0, None)
            self.length_prev = row["contact_length"]
            self._level_state()
            self._push(0.0, restart=True)
            row.update({"k": 0.0, "error_estimate": 0.0, "rejected": 0})
            yield row
        while self.t < self.T:
            k, t_new = self._propose()
            wanted = max(self.k_next, k)
            if self._snapshot is None:
                self._snapshot = Snapshot(model)
            else:
                self._snapshot.take()
            snap, rejected = self._snapshot, 0
            while True:
                try:
                    row = stepper.step(self.n + 1, t_new, k, None if self.n == 0 else self.k_prev)
                except SolveFailure:
                    if k <= self.k_min * (1 + 1e-12):
                        raise
                    snap.restore()
                    rejected += 1
                    k, t_new = self._retry(k, self._snap(max(0.25 * k, self.k_min)))
                    wanted = k
                    continue
                est = self.estimate(t_new)
                r = self._ratio(est, k)
                if k > self.k_min * (1 + 1e-12) and r > 1.0:
                    snap.restore()
                    rejected += 1
                    shrink = min(max(SAFETY * r ** (-1.0 / (self.p + 1)), RETRY[0]), RETRY[1])
                    k, t_new = self._retry(k, self._snap(max(k * shrink, self.k_min)))
                    wanted = k
                    continue
                break
            # order 2 differences two past levels: not across a kink of the load (order 1 uses the step alone)
            kink = self.p == 2 and any(abs(t_new - m) <= 1e-12 * self.T for m in self.kinks)
            # the contact zone moved: the step is not let grow (the next one checks the new zone at this size)
            moved = abs(row["contact_length"] - self.length_prev) > ACTIVE_FRACTION * self.gamma_c
            self.n, self.t, self.k_prev = self.n + 1, t_new, k
            self.length_prev = row["contact_length"]
            if math.isfinite(est):
                self._accumulate(k)
                self.S += math.sqrt(max(est, 0.0))
                self.mu = min(self.mu, self._mu)
            self._push(t_new, restart=kink)
            if math.isfinite(r):
                q = self.p + 1  # the step's error is O(k^(p+1))
                factor = SAFETY * max(r, 1e-10) ** (-BETA[0] / q) * max(self.r_prev, 1e-10) ** (-BETA[1] / q)
                factor = min(max(factor, SHRINK), 1.0 if rejected or moved else GROW)
                self.r_prev = r
                k_next = self._snap(min(max(wanted * factor, self.k_min), self.k_max))
                # a growth by less than HOLD grid points keeps the step: a new k assembles and factors the damage
                # matrix again, which costs more than the step it saves
                self.k_next = wanted if wanted < k_next <= wanted * 2.0 ** (HOLD / GRID) * (1 + 1e-12) else k_next
            else:
                self.k_next = wanted
            row.update({"k": k, "error_estimate": est if math.isfinite(est) else 0.0, "rejected": rejected})
            yield row
