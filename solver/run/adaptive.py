"""Adaptive steps (``time.adaptive``; docs/model.md §3.9): a step controller around the time loop.

Each trial step is the scheme's own level (:meth:`solver.run.stepper.Stepper.step` with its k). Its local error is
estimated from the difference between the level and the polynomial extrapolation of the past levels (Milne's
device: for a scheme of order p, the degree-p extrapolation through the last p + 1 levels misses by a known
multiple of the same (p+1)-th derivative the scheme's local error is made of), in the paper's norm
||eps(u)|| + ||zeta||; it costs two norms a level and no solve. A step is accepted when its error per unit step is
within its share of the tolerance, est <= SMOOTH_SHARE tolerance k / T (so that these local errors add up to at
most that share of ``time.tolerance``), else the state is put back and the step retried smaller. Across a kink of
the solution (a point of the contact zone that opens or closes, damage reaching zeta*) the estimate falls only
like k, so no step would pass the per-unit-step test: such a step is accepted when its error fits in what remains
of the events' budget, EVENT_SHARE of the tolerance (at most a tenth of it per event). The next step follows
Söderlind's PI controller (PI.4.2, PETSc's TSAdapt DSP default). Steps land on every kink of a load table (the
extrapolation restarts there, since the load's slope changes), on ``output.times`` and on T; a step over which
the contact zone changes by more than ACTIVE_FRACTION of Γ_C does not let the next one grow. The controller's
state (the step history, the PI memory, the budget and the past levels of the extrapolation) goes into
checkpoints, so that a restart takes the same steps.
"""

from __future__ import annotations

import math
from collections.abc import Iterator

import numpy as np
import ufl
from dolfinx import fem
from mpi4py import MPI

from solver.config import Config
from solver.errors import SolveFailure

SAFETY = 0.9  # the next step aims at SAFETY times the tolerance
GROW, SHRINK = 2.0, 0.2  # the most a step grows or shrinks to the next one
RETRY = (0.1, 0.9)  # a rejected step is retried at this fraction of it (the controller's choice clipped)
BETA = (0.6, -0.2)  # PI.4.2: k_{n+1} = k_n (1/r_n)^{BETA[0]/p} (1/r_{n-1})^{BETA[1]/p}
ACTIVE_FRACTION = 0.05  # a change of the contact zone beyond this fraction of Γ_C's measure stops the step's growth
STRETCH = 0.25  # a mark this fraction of a step ahead or less is reached by stretching the step
GRID = 8  # steps are T 2^(j/GRID): a round-off in an estimate (another partition, a restart) moves no step
SMOOTH_SHARE = 0.75  # of the tolerance, for the steps' errors per unit step (est <= SMOOTH_SHARE tol k / T)
EVENT_SHARE = 0.25  # of the tolerance, the budget of the steps across events (kinks of the solution)


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
    """A copy of the model's whole state at an accepted level, put back when a trial step is rejected."""

    def __init__(self, model) -> None:
        self.model = model
        self.fields = [(f.x.array, f.x.array.copy()) for f in self._functions(model)]
        self.damage = ({k: v.copy() for k, v in model.damage.state().items()}, model.damage.scalars()) \
            if model.damage is not None else None
        self.history = {k: v.copy() for k, v in model.history.state().items()} if model.history is not None else {}
        self.mech = ({k: v.copy() for k, v in model.mech.state().items()}, model.mech.scalars())

    @staticmethod
    def _functions(model) -> list[fem.Function]:
        out = [model.u]
        if model.u_prev is not None:
            out.append(model.u_prev)
        if model.damage is not None:
            out.append(model.damage.zeta)
        return out

    def restore(self) -> None:
        model = self.model
        for target, values in self.fields:
            target[:] = values
        if self.damage is not None:
            arrays, scalars = self.damage
            for k, v in arrays.items():
                model.damage.restore(k, v)
            model.damage.restore_scalars(scalars)
        if model.history is not None:
            live = model.history.state()
            for k, v in self.history.items():
                live[k][...] = v
        arrays, scalars = self.mech
        for k, v in arrays.items():
            model.mech.restore_vector(k, v)
        model.mech.restore_scalars(scalars)


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
        self.budget = EVENT_SHARE * tc.tolerance  # what the steps across events may still spend
        self.have = 0  # past levels held for the extrapolation (since the start or the last kink)
        slots = self.p + 1
        self.past_t = np.zeros(slots)
        self.past_u = [np.zeros_like(model.u.x.array) for _ in range(slots)]
        self.past_z = [np.zeros_like(model.damage.zeta.x.array) for _ in range(slots)] if model.damage else []
        self._norm_forms(model)
        self.gamma_c = self._contact_measure(model)

    # ------------------------------------------------------------------ state
    def scalars(self) -> dict[str, float]:
        return {"n": float(self.n), "t": self.t, "k_prev": self.k_prev, "k_next": self.k_next, "r_prev": self.r_prev,
                "length_prev": self.length_prev, "have": float(self.have), "budget": self.budget,
                **{f"past_t{i}": float(v) for i, v in enumerate(self.past_t)}}

    def restore_scalars(self, s: dict[str, float]) -> None:
        self.n, self.t, self.k_prev, self.k_next = int(s["n"]), s["t"], s["k_prev"], s["k_next"]
        self.r_prev, self.length_prev, self.have = s["r_prev"], s["length_prev"], int(s["have"])
        self.budget = s["budget"]
        self.past_t[:] = [s[f"past_t{i}"] for i in range(len(self.past_t))]

    def arrays(self) -> dict[str, tuple[str, np.ndarray]]:
        """The past levels of the extrapolation: name -> (space "u" | "zeta", the array, written back in place)."""
        out = {f"past_u{i}": ("u", a) for i, a in enumerate(self.past_u)}
        out.update({f"past_z{i}": ("zeta", a) for i, a in enumerate(self.past_z)})
        return out

    # ------------------------------------------------------------------ the paper's norm
    def _norm_forms(self, model) -> None:
        self._du = fem.Function(model.u.function_space)
        e = ufl.sym(ufl.grad(self._du))
        self._fu = fem.form(ufl.inner(e, e) * ufl.dx)
        self._dz = fem.Function(model.damage.V) if model.damage is not None else None
        self._fz = fem.form(self._dz * self._dz * ufl.dx) if model.damage is not None else None

    def _norm(self, form) -> float:
        return math.sqrt(max(self.comm.allreduce(fem.assemble_scalar(form), op=MPI.SUM), 0.0))

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

    # ------------------------------------------------------------------ the estimate
    def estimate(self, t: float) -> float:
        """The local error of the level just solved at t (NaN while fewer than p + 1 past levels are held)."""
        p = self.p
        if self.have < p + 1:
            return math.nan
        ts = self.past_t[: p + 1]  # newest first
        w = np.array([np.prod([(t - ts[j]) / (ts[i] - ts[j]) for j in range(p + 1) if j != i]) for i in range(p + 1)])
        k = [t - ts[0]] + [ts[i] - ts[i + 1] for i in range(p)]
        if p == 1:
            c = k[0] / (k[0] + k[1])
        else:
            c = k[0] ** 2 / (2 * (k[0] + k[1]) * (k[0] + k[1] + k[2]))
        du = self._du.x.array
        du[:] = self.model.u.x.array
        for wi, a in zip(w, self.past_u):
            du -= wi * a
        err = self._norm(self._fu)
        if self._dz is not None:
            dz = self._dz.x.array
            dz[:] = self.model.damage.zeta.x.array
            for wi, a in zip(w, self.past_z):
                dz -= wi * a
            err += self._norm(self._fz)
        return c * err

    def _push(self, t: float, restart: bool) -> None:
        """Level n (the model's) becomes the newest past level; ``restart``: the only one (at a kink)."""
        self.past_t[1:] = self.past_t[:-1].copy()
        self.past_u.insert(0, self.past_u.pop())
        if self.past_z:
            self.past_z.insert(0, self.past_z.pop())
        self.past_t[0] = t
        self.past_u[0][:] = self.model.u.x.array
        if self.past_z:
            self.past_z[0][:] = self.model.damage.zeta.x.array
        self.have = 1 if restart else min(self.have + 1, len(self.past_t))

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

    def _snap(self, k: float) -> float:
        """k rounded down to the grid T 2^(j/GRID), within the bounds: the chosen steps are exact powers, and two
        runs whose estimates differ by round-off choose the same steps (unless one sits on a grid point)."""
        j = math.floor(GRID * math.log2(k / self.T))
        return min(max(self.T * 2.0 ** (j / GRID), self.k_min), self.k_max)

    def _ratio(self, est: float, k: float) -> float:
        """The error per unit step over the tolerance (NaN without an estimate)."""
        return est / (SMOOTH_SHARE * self.tol * k / self.T) if math.isfinite(est) else math.nan

    def levels(self, stepper, start: int) -> Iterator[dict]:
        """Level 0 (when ``start`` is 0), then accepted levels until T, each row with its k, estimate and the
        number of rejected trials before it."""
        model = self.model
        if start == 0:
            row = stepper.step(0, 0.0, 0.0, None)
            self.length_prev = row["contact_length"]
            self._push(0.0, restart=True)
            row.update({"k": 0.0, "error_estimate": 0.0, "rejected": 0})
            yield row
        while self.t < self.T:
            k, t_new = self._propose()
            wanted = max(self.k_next, k)
            snap, rejected = Snapshot(model), 0
            while True:
                try:
                    row = stepper.step(self.n + 1, t_new, k, None if self.n == 0 else self.k_prev)
                except SolveFailure:
                    if k <= self.k_min * (1 + 1e-12):
                        raise
                    snap.restore()
                    rejected += 1
                    k, t_new = self._land(self._snap(max(0.25 * k, self.k_min)))
                    wanted = k
                    continue
                est = self.estimate(t_new)
                r = self._ratio(est, k)
                event = r > 1.0 and est <= min(self.budget, 0.1 * self.tol)
                if k > self.k_min * (1 + 1e-12) and r > 1.0 and not event:
                    snap.restore()
                    rejected += 1
                    shrink = min(max(SAFETY * r ** (-1.0 / self.p), RETRY[0]), RETRY[1])
                    k, t_new = self._land(self._snap(max(k * shrink, self.k_min)))
                    wanted = k
                    continue
                break
            kink = any(abs(t_new - m) <= 1e-12 * self.T for m in self.kinks)
            # the contact zone moved: the step is not let grow (the next one checks the new zone at this size)
            moved = abs(row["contact_length"] - self.length_prev) > ACTIVE_FRACTION * self.gamma_c
            self.n, self.t, self.k_prev = self.n + 1, t_new, k
            self.length_prev = row["contact_length"]
            self._push(t_new, restart=kink)
            if event:  # an event's step: spent from the budget; the next step keeps its size
                self.budget -= est
                self.k_next = k
            elif math.isfinite(r):
                factor = SAFETY * max(r, 1e-10) ** (-BETA[0] / self.p) * max(self.r_prev, 1e-10) ** (-BETA[1] / self.p)
                factor = min(max(factor, SHRINK), 1.0 if rejected or moved else GROW)
                self.r_prev = r
                self.k_next = self._snap(min(max(wanted * factor, self.k_min), self.k_max))
            else:
                self.k_next = wanted
            row.update({"k": k, "error_estimate": est if math.isfinite(est) else 0.0, "rejected": rejected})
            yield row
