"""newton_condensed's active-set iteration on every level of a run, replayed offline with other iterations
(docs/model.md §4, "Moving contact: what the stiff P2 set does").

    python benchmarks/reduced_variants.py dump SCENE N DIR      # run SCENE at P2, order 2, n = N; save each level
    python benchmarks/reduced_variants.py replay DIR [--variants NAME ...] [--out PATH_WITHOUT_SUFFIX]

``dump`` runs ``python -m solver run`` in this process (P2, order 2, mesh n x n, no XDMF) with
:class:`solver.solvers.reduced.PointReduced`'s ``run`` wrapped to save each level's reduced problem (S, P u0, N_B,
c, W, 1/mu, the start v and the predictor's previous start, the points' x) to DIR/levelNNNN.npz (serial, linear law).
``replay`` solves each saved level by the shipped iteration (``shipped``: PointReduced._iterate, its compliance path
on a first contact and the predicted first set, re-implemented in numpy) and by the variants, and counts what the run
counts: the steps taken on v, plus one step through K where the iteration ends on a step that keeps its set. The
counts exclude what the run adds outside the reduced iteration (auto's Newton iterations before the take-over).
Variants: ``smooth:E1,E2,...`` (the law max(r, 0)/mu replaced by the Chen-Harker-Kanzow-Smale smoothing
(r + sqrt(r^2 + e^2)) / (2 mu), one Newton step per e, then the shipped iteration from there), ``merit:M`` (globalized
semismooth Newton: full step, halved until ||F|| falls below (1 - 1e-4 lam) times the largest of the last M
values; M = 1 monotone), ``hold:THETA`` (points whose state would change with |r| below THETA times the median r
of the set's points in contact keep their state, unless they are all the changes), ``path:R1,R2,...`` (a level whose
first predicted step does not keep its set restarts from its start on the compliance path with these stiffness
ratios, one step each, then the stiff law), ``tail:K`` (a point leaving contact takes the same point of up to K
next facets in full contact with it: the tail behind a lift-off edge; needs a straight contact side).
Writes OUT.csv: variant, total, largest, per-level counts.
"""

from __future__ import annotations

import argparse
import csv
import glob
import os
import runpy
import sys
from pathlib import Path

import numpy as np
import scipy.linalg as sla
import scipy.sparse as sp

ROOT = Path(__file__).resolve().parents[1]
FREE_STEPS, PREDICT, RATIOS, STIFF = 2, 0.5, (1.0, 10.0, 100.0), 1000.0  # the shipped constants (reduced.py)


def dump(scene: str, n: int, out: Path) -> None:
    """Run ``scene`` at P2, order 2, n x n with every reduced level saved to ``out``."""
    from solver.solvers import point_contact, reduced

    out.mkdir(parents=True, exist_ok=True)
    shipped_run = reduced.PointReduced.run
    count = [0]

    def run(self):
        cond, pc = self.cond, self.points
        cond.level()
        cond.u0.ghostUpdate()
        with cond.u0.localForm() as local:
            pc.level(local.array_r)
        count[0] += 1
        NB = pc.NB.tocsr()
        np.savez(out / f"level{count[0]:04d}.npz", S=cond.S, a=cond.u0_B, NBd=NB.data, NBi=NB.indices,
                 NBp=NB.indptr, NBshape=NB.shape, c=pc.c, W=pc.W, inv_mu=np.nan_to_num(pc.inv_mu.astype(float)),
                 v=self.dofs.gather(self.problem.u.vector.array_r[self.dofs.local]),
                 previous=self.previous if self.previous is not None else np.zeros(0), scale=self.scale,
                 rtol=self.settings.rtol, unorm=self.problem.u.vector.norm(), x=pc.x)
        return shipped_run(self)

    reduced.PointReduced.run = run
    shipped_init = point_contact.PointContact.__init__

    def init(self, points, dofs, u):
        shipped_init(self, points, dofs, u)
        self.x = points.x[:, 0]  # the points' x (serial: N_B's order), for the tail variant

    point_contact.PointContact.__init__ = init
    sets = ["discretization.u_degree=2", "discretization.zeta_degree=2", "time.order=2", "output.xdmf=false",
            f"mesh.nx={n}", f"mesh.ny={n}", f"output.directory='{out / 'run'}'"]
    sys.argv = ["solver", "run", scene, "--overwrite", *[a for s in sets for a in ("--set", s)]]
    try:
        runpy.run_module("solver", run_name="__main__")
    except SystemExit as exc:
        if exc.code:
            raise


class Level:
    """One saved level's reduced problem (linear law p = r_+ / mu at each point)."""

    def __init__(self, path: str) -> None:
        z = np.load(path)
        self.S, self.a, self.c, self.W, self.imu = z["S"], z["a"], z["c"], z["W"], z["inv_mu"]
        self.NB = sp.csr_matrix((z["NBd"], z["NBi"], z["NBp"]), shape=tuple(z["NBshape"]))
        self.NBT = self.NB.T.tocsr()
        self.v0 = z["v"]
        self.prev = z["previous"] if z["previous"].size else None
        self.scale, self.rtol, self.unorm = float(z["scale"]), float(z["rtol"]), float(z["unorm"])
        self.order = np.argsort(z["x"], kind="stable") if "x" in z else None  # the points along a straight side
        self.chol = sla.cho_factor(self.S)
        self.eye = np.eye(len(self.v0))

    @staticmethod
    def state(r):
        return (r > 0).astype(np.int8)

    def force(self, r, W):
        return self.NBT @ (W * np.maximum(r, 0.0) * self.imu)

    def piece_force(self, r, st, W):
        return self.NBT @ (W * np.where(st > 0, r * self.imu, 0.0))

    def jac(self, st, W):
        return (self.NBT @ sp.diags(W * np.where(st > 0, self.imu, 0.0)) @ self.NB).toarray()

    def fnorm(self, v, r, W):
        return float(np.linalg.norm(sla.cho_solve(self.chol, v - self.a + self.S @ self.force(r, W))))

    def line_minimum(self, alpha, beta, r, s, W):
        """point_contact.PointContact.line_minimum."""
        def dphi(lam):
            return alpha + lam * beta + float(s @ (W * np.maximum(r + lam * s, 0.0) * self.imu))

        with np.errstate(divide="ignore", invalid="ignore"):
            lam_ = -r / s
        knots = np.concatenate([[0.0], np.unique(lam_[np.isfinite(lam_) & (lam_ > 0) & (lam_ < 1)]), [1.0]])
        values = {0: dphi(0.0)}
        lo, hi = 0, len(knots) - 1
        values[hi] = dphi(1.0)
        if values[hi] <= 0 or values[0] >= 0:
            lam, after = 1.0, 1.0
        else:
            while hi - lo > 1:
                mid = (lo + hi) // 2
                values[mid] = dphi(knots[mid])
                lo, hi = (mid, hi) if values[mid] < 0 else (lo, mid)
            a, b = values[lo], values[hi]
            lam = knots[lo] + (knots[hi] - knots[lo]) * (-a / (b - a))
            if b == 0 or lam >= knots[hi] * (1 - 1e-12):
                lam = knots[hi]
                after = 0.5 * (knots[hi] + knots[hi + 1]) if hi + 1 < len(knots) else 1.0
            else:
                after = 0.5 * (lam + knots[hi])
        return float(lam), self.state(r + after * s)

    def ratio(self) -> float:
        compliance = np.einsum("ij,ij->i", self.NB @ self.S, self.NB.toarray())
        return float(np.max(self.W * self.imu * compliance, initial=0.0))


def tail(L: Level, state, sy, reach: int):
    """The tail variant: a point leaving contact takes with it the same point of the next ``reach`` facets on
    either side that are in contact on all three points (three points a facet, in x order on a straight side)."""
    o = L.order
    so, st = sy[o].copy(), state[o]
    q = len(so)
    for j in np.where((st > 0) & (so == 0))[0]:
        for sign in (-1, 1):
            for k in range(1, reach + 1):
                jj = j + sign * 3 * k
                if not (0 < jj < q - 1 and so[jj] > 0 and st[jj] > 0 and so[jj - 1] > 0 and so[jj + 1] > 0):
                    break
                so[jj] = 0
    out = np.empty_like(sy)
    out[o] = so
    return sy if np.array_equal(out, state) else out


def iterate(L: Level, v, steps: list, limit: int, predict: bool, W=None, hold: float = 0.0, reach: int = 0):
    """PointReduced._iterate (``hold`` > 0, ``reach`` > 0: those variants); returns v and how it ended."""
    W = L.W if W is None else W
    r = L.NB @ v + L.c
    state = L.state(r)
    fn = L.fnorm(v, r, W)
    if predict and L.prev is not None:
        state = L.state(L.NB @ (v + PREDICT * (v - L.prev)) + L.c)
    seen = [state.tobytes()]
    for _ in range(limit):
        if fn <= L.rtol * L.scale:
            return v, "tol"
        d = -np.linalg.solve(L.eye + L.S @ L.jac(state, W), v - L.a + L.S @ L.piece_force(r, state, W))
        s = L.NB @ d
        ry = r + s
        sy = L.state(ry)
        if np.array_equal(sy, state):
            return v, "kept"
        if hold > 0.0:
            on = (state > 0) & (ry > 0)
            typical = float(np.median(ry[on])) if on.any() else 0.0
            change = np.where(sy != state, np.abs(ry), 0.0)
            sy = np.where((change < hold * typical) & (change < change.max()), state, sy).astype(np.int8)
        if reach > 0:
            sy = tail(L, state, sy, reach)
        steps.append(fn)
        fy = L.fnorm(v + d, ry, W)
        if sy.tobytes() not in seen and (len(seen) <= FREE_STEPS or fy < fn):
            v, r, state, fn = v + d, ry, sy, fy
        else:
            w = sla.cho_solve(L.chol, d)
            lam, state = L.line_minimum(float((v - L.a) @ w), float(d @ w), r, s, W)
            v, r = v + lam * d, r + lam * s
            fn = L.fnorm(v, r, W)
        seen.append(state.tobytes())
        if float(np.linalg.norm(d)) <= L.rtol * L.unorm:
            return v, "step"
    return v, "limit"


def merit_iterate(L: Level, v, steps: list, limit: int, M: int):
    """Globalized semismooth Newton: backtracking on ||F|| against the largest of the last M values."""
    W = L.W
    r = L.NB @ v + L.c
    fn = L.fnorm(v, r, W)
    state = L.state(L.NB @ (v + PREDICT * (v - L.prev)) + L.c) if L.prev is not None else L.state(r)
    past = [fn]
    for _ in range(limit):
        if fn <= L.rtol * L.scale:
            return v, "tol"
        d = -np.linalg.solve(L.eye + L.S @ L.jac(state, W), v - L.a + L.S @ L.piece_force(r, state, W))
        s = L.NB @ d
        if np.array_equal(L.state(r + s), state):
            return v, "kept"
        steps.append(fn)
        ref, lam = max(past[-M:]), 1.0
        while True:
            fl = L.fnorm(v + lam * d, r + lam * s, W)
            if fl <= (1 - 1e-4 * lam) * ref or lam < 1e-4:
                break
            lam *= 0.5
        v, r, fn = v + lam * d, r + lam * s, fl
        state = L.state(r)
        past.append(fn)
        if lam * float(np.linalg.norm(d)) <= L.rtol * L.unorm:
            return v, "step"
    return v, "limit"


def solve(L: Level, variant: str) -> int:
    """The level's count under ``variant`` (module docstring)."""
    name, _, arg = variant.partition(":")
    steps: list = []
    v = L.v0
    R = L.ratio()
    first = not L.state(L.NB @ v + L.c).any()
    path = first and R > STIFF
    if path:  # the shipped compliance path of a first contact, in every variant
        for ratio in RATIOS:
            v, _ = iterate(L, v, steps, 2, False, L.W * ratio / R)
    limit = 200
    if path or name == "shipped":
        v, how = iterate(L, v, steps, limit, not path)
    elif name == "hold":
        v, how = iterate(L, v, steps, limit, True, hold=float(arg))
    elif name == "tail":
        v, how = iterate(L, v, steps, limit, True, reach=int(arg))
    elif name == "merit":
        v, how = merit_iterate(L, v, steps, 60, int(arg))
    elif name == "smooth":
        for e in map(float, arg.split(",")):
            r = L.NB @ v + L.c
            q = np.sqrt(r * r + e * e)
            H = v - L.a + L.S @ (L.NBT @ (L.W * L.imu * (r + q) / 2))
            J = L.eye + L.S @ (L.NBT @ sp.diags(L.W * L.imu * (1 + r / q) / 2) @ L.NB).toarray()
            v = v - np.linalg.solve(J, H)
            steps.append(0.0)
        v, how = iterate(L, v, steps, limit, False)
    elif name == "path":
        probe: list = []
        _, how = iterate(L, v, probe, 1, True)
        if how in ("kept", "tol", "step"):
            return len(probe) + (how == "kept")
        steps += probe
        for ratio in map(float, arg.split(",")):
            v, _ = iterate(L, v, steps, 1, False, L.W * ratio / R)
        v, how = iterate(L, v, steps, limit, False)
    else:
        raise SystemExit(f"unknown variant {variant!r}")
    return len(steps) + (how == "kept")


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    sub = parser.add_subparsers(dest="cmd", required=True)
    d = sub.add_parser("dump")
    d.add_argument("scene")
    d.add_argument("n", type=int)
    d.add_argument("dir")
    p = sub.add_parser("replay")
    p.add_argument("dir")
    p.add_argument("--variants", nargs="*", default=["shipped"])
    p.add_argument("--out", help="OUT.csv (default: DIR/variants)")
    args = parser.parse_args()
    if args.cmd == "dump":
        dump(args.scene, args.n, Path(args.dir).resolve())
        return 0
    levels = [Level(f) for f in sorted(glob.glob(os.path.join(args.dir, "level*.npz")))]
    rows = []
    for variant in args.variants:
        counts = [solve(L, variant) for L in levels]
        rows.append({"variant": variant, "total": sum(counts), "largest": max(counts),
                     "levels": " ".join(map(str, counts))})
        print(variant, sum(counts), max(counts), flush=True)
    with open(f"{args.out or os.path.join(args.dir, 'variants')}.csv", "w", newline="") as f:
        w = csv.DictWriter(f, list(rows[0]))
        w.writeheader()
        w.writerows(rows)
    return 0


if __name__ == "__main__":
    sys.exit(main())
