"""``study tolerance``: does a run with a tolerance reach it, and at what cost against the best uniform choice?

For every scene (Examples 1-3, configs/hard.toml, Example 1 with a gap of 0.02 and with
mu = 1e-3) and every tolerance, the tolerance run (solver/run/accuracy/) is measured against a
fine reference in the paper's norm (max over levels of ||eps(u - u_ref)|| + ||zeta - zeta_ref||),
with :class:`reference.PointwiseError` (the adapted meshes do not nest in the reference's).
The reference is itself a P2, second-order tolerance run at ``ref_tol``, with a step a few
times smaller than any judged; its own error is estimated by a second reference at
3 ``ref_tol``. A scene whose reference at ``ref_tol`` is out of reach can be given its own
reference tolerance (``--scene-ref-tol NAME=TOL``), or a uniform P2, second-order reference on its
rectangle (``--scene-ref-uniform NAME=N:STEPS``, its own error from one at N/2 and 2k); the
output states it per scene, and beside
every run the reference's own error over the run's tolerance, so a row judged against a
coarser reference says so. The uniform runs ((P1, P2) x (order 1, 2) x meshes x steps T/10 ... T/80,
measured against the same reference) give the cheapest uniform choice that meets each
tolerance. Cost: seconds of computing after the scene is read -- the time loop, and for the
tolerance run also its planning (every solve, estimate and pilot run); the set-up of the
final model and form compilation are left out on both sides (forms are compiled before
anything is timed). Writes tolerance.csv, tolerance.json, tolerance.md and tolerance.png.
"""

from __future__ import annotations

import csv
import gc
import json
import time
from pathlib import Path

import numpy as np
from mpi4py import MPI

from studies import REPO as ROOT  # noqa: E402

CONFIGS = ROOT / "configs"
SCENES = {  # name -> (scene file, its changes)
    "example1": (CONFIGS / "example1.toml", {}),
    "example2": (CONFIGS / "example2.toml", {}),
    "example3": (CONFIGS / "example3.toml", {}),
    "hard": (CONFIGS / "hard.toml", {}),
    "example1-gap0.02": (CONFIGS / "example1.toml", {"boundary": {"bottom": {"gap": 0.02}}}),
    "example1-mu1e-3": (CONFIGS / "example1.toml", {"boundary": {"bottom": {"mu": 1e-3}}}),
}
TOLS = (1e-2, 3e-3, 1e-3)
QUIET = {"output": {"xdmf": False}}
MAX_DOFS = 300_000  # per run of the study (the tolerance runs' accuracy.max_dofs, and the uniform meshes)


def scene(name: str):
    """The study's scene ``name`` (a Config, without XDMF output)."""
    from solver.config import load, merge

    path, changes = SCENES[name]
    return load(path).replace(merge(changes, QUIET), label=f"study tolerance {name}")


def quiet(cfg):
    """``cfg`` without XDMF output."""
    return cfg.replace(QUIET, label="study tolerance")


class Reference:
    """A fine run kept at every level (u, zeta), on its own mesh: a tolerance run (:meth:`planned`) or a uniform
    P2, second-order run (:meth:`uniform`, for a scene whose planned reference is out of reach)."""

    def __init__(self, scene, chosen: dict, k: float, geo, what: str,
                 estimate: float | None = None, log=print) -> None:
        from solver.errors import SolveFailure
        from solver.io.results import run

        t0 = time.perf_counter()
        self.scene, self.geo, self.estimate = quiet(scene).replace(chosen, label="reference"), geo, estimate
        for halving in range(3):  # a step Newton cannot take on the fine mesh is halved
            self.k = k / 2**halving
            self.model = model = self.build()
            self.u, self.zeta = [], []
            self.loop_seconds = 0.0

            def keep(row, model=model):
                self.loop_seconds += row["wall_time"]
                self.u.append(model.u.x.array.copy())
                self.zeta.append(model.damage.zeta.x.array.copy() if model.damage is not None else None)

            try:
                run(model, None, on_step=keep)
                break
            except SolveFailure:
                if halving == 2:
                    raise
                log(f"  reference: Newton failed at k = {self.k:g}; halving the step")
        self.seconds = time.perf_counter() - t0
        self.cells = model.geo.num_cells()
        self.dofs = model.u.x.array.size
        log(f"  reference: {what}, {self.cells} cells ({self.dofs} dofs), k = {self.k:g}"
            + (f", estimate {estimate:.2e}" if estimate is not None else "") + f"; {self.seconds:.1f} s")

    def build(self):
        """A new model of the reference's discretization (not yet run)."""
        from solver.run.model import build_model

        cfg = self.scene.replace({"time": {"k": self.k}}, label="reference")
        return build_model(cfg, MPI.COMM_SELF, self.geo)

    @classmethod
    def planned(cls, scene, tol: float, refine_k: int, log=print) -> Reference:
        """A P2 tolerance run at ``tol`` with a ``refine_k`` times smaller step than the plan's."""
        from solver.run.accuracy import plan

        t0 = time.perf_counter()
        accuracy = {"accuracy": {"tolerance": tol, "degrees": [2], "max_dofs": MAX_DOFS}}
        p = plan(quiet(scene).replace(accuracy, label="reference"), MPI.COMM_SELF, log=lambda *a: None)
        ref = cls(scene, p.changes, p.k / refine_k, p.geo, f"TOL {tol:g}, P2 order {p.order}",
                  p.estimate.total, log=log)
        ref.seconds = time.perf_counter() - t0  # its planning too
        return ref

    @classmethod
    def uniform(cls, scene, n: int, steps: int, log=print) -> Reference:
        """P2, second order, on the scene's rectangle with n cells across its shorter side and k = T / steps."""
        chosen = {**_rectangle(scene, n), "discretization": {"u_degree": 2, "zeta_degree": 2}, "time": {"order": 2}}
        return cls(scene, chosen, scene.time.T / steps, None, f"uniform P2 order 2, n = {n}", log=log)

    def level(self, t: float) -> int | None:
        m = t / self.k
        return int(round(m)) if abs(m - round(m)) < 1e-9 and round(m) < len(self.u) else None

    def replay_against(self, other: Reference) -> float:
        """This run's error against ``other`` (max over the levels both have, in the paper's norm), from the levels
        this run kept: the values :meth:`measure` would give, without running it again."""
        from studies.reference import PointwiseError

        model = self.model
        judge = PointwiseError(other.model.u.function_space,
                               other.model.damage.V if other.model.damage is not None else None, model)
        largest = 0.0
        for j, (u, zeta) in enumerate(zip(self.u, self.zeta)):
            jr = other.level(j * self.k)
            if jr is None:
                continue
            model.u.x.array[:] = u
            if zeta is not None:
                model.damage.zeta.x.array[:] = zeta
            eu, ez = judge(other.u[jr], other.zeta[jr])
            largest = max(largest, eu + ez)
        return largest

    def measure(self, model, extra_seconds: float = 0.0) -> dict:
        """Run ``model`` (built, not yet run) and return its error against this reference and its cost."""
        from solver.errors import SolveFailure
        from solver.io.results import run
        from studies.reference import PointwiseError

        judge = PointwiseError(self.model.u.function_space,
                               self.model.damage.V if self.model.damage is not None else None, model)
        errs, loop = [], [0.0]

        def compare(row):
            loop[0] += row["wall_time"]
            j = self.level(row["t"])
            if j is not None:
                eu, ez = judge(self.u[j], self.zeta[j])
                errs.append((row["t"], eu, ez))

        failure = None
        try:
            run(model, None, on_step=compare)
        except SolveFailure as exc:
            failure = exc.kind
        e = np.array(errs) if errs else np.full((1, 3), np.nan)
        total = e[:, 1] + e[:, 2]
        m = int(np.nanargmax(total)) if np.isfinite(total).any() else 0
        return {"error": float(total[m]), "error_u": float(e[m, 1]), "error_zeta": float(e[m, 2]),
                "t_max": float(e[m, 0]), "loop_seconds": loop[0], "cost": loop[0] + extra_seconds,
                "levels": len(errs), "failure": failure, "dofs": int(model.u.x.array.size)}


def _rectangle(cfg, n: int) -> dict:
    """mesh.nx, mesh.ny of n cells across the rectangle's shorter side (cells about square)."""
    (x0, y0), (x1, y1) = cfg.mesh.corners
    short = min(x1 - x0, y1 - y0)
    return {"mesh": {"nx": round(n * (x1 - x0) / short), "ny": round(n * (y1 - y0) / short)}}


def _uniform_meshes(cfg, levels: int):
    """(label, mesh changes, geo or None) of uniform meshes: n = 4, 8, ... on a rectangle (cells about square),
    the scene's mesh refined uniformly 0, 1, ... times otherwise."""
    from solver.mesh.adapt import refine_uniformly
    from solver.mesh.geometry import build

    if cfg.mesh.kind == "rectangle":
        for i in range(levels):
            n = 4 * 2**i
            yield f"n={n}", _rectangle(cfg, n), None
        return
    geo = build(MPI.COMM_SELF, cfg.mesh, cfg.boundaries, cfg.dim)
    for r in range(min(levels, 3)):  # a gmsh mesh is already fine: 16x its cells at r = 2
        yield f"r={r}", {}, geo
        geo = refine_uniformly(geo)


def uniform_sweep(ref: Reference, scene, tols, levels: int, steps: tuple[int, ...],
                  log=print) -> list[dict]:
    """Every (degree, order, mesh, step) until the mesh no longer helps or the smallest tolerance is met."""
    from solver.run.model import build_model

    scene = quiet(scene)
    T = scene.time.T
    rows = []
    for degree in (1, 2):
        for order in (1, 2):
            for n_steps in steps:
                k = T / n_steps
                last = np.inf
                for label, mesh, geo in _uniform_meshes(scene, levels):
                    cfg = scene.replace({**mesh, "discretization": {"u_degree": degree},
                                         "time": {"order": order, "k": k}}, label="uniform sweep")
                    model = build_model(cfg, MPI.COMM_SELF, geo)
                    if model.u.x.array.size > MAX_DOFS:
                        break
                    rec = ref.measure(model)
                    del model
                    gc.collect()  # PETSc objects in reference cycles: free each run's factorization now
                    rec.update({"degree": degree, "order": order, "mesh": label, "k": k})
                    rows.append(rec)
                    log(f"  uniform P{degree} order {order} {label:6s} k={k:<7g} error {rec['error']:.3e} "
                        f"cost {rec['cost']:.3f} s")
                    if rec["failure"] or rec["error"] <= min(tols) or rec["error"] > 0.9 * last:
                        break  # finer meshes cost more and meet no more tolerances, or the step dominates
                    last = rec["error"]
    return rows


def verified_uniform(ref: Reference, scene, tol: float, max_halvings: int = 5, log=print,
                     cache: dict | None = None) -> dict:
    """The verified uniform alternative a user without a tolerance would run: uniform P2, second order, from the
    scene's own mesh and step, n and k halved together (a rectangle's n doubled, a gmsh mesh refined uniformly)
    until two successive runs differ by less than TOL / 4 (max over levels, in the paper's norm); the last run is
    the answer. Its cost: the loops of every run of the sequence (a user runs them all). Its error: the last run's
    against ``ref``. ``cache`` (one dict per scene): the sequence's runs measured for a larger tolerance, reused
    (the same runs; their loops are counted again for this tolerance, as a user would run them). The differences and
    the answer's error are measured on the levels each run kept (:meth:`Reference.replay_against`)."""
    from solver.mesh.adapt import refine_uniformly
    from solver.mesh.geometry import build

    scene = quiet(scene)
    cache = {} if cache is None else cache
    recs, answers = cache.setdefault("recs", []), cache.setdefault("answers", {})
    p2 = {"discretization": {"u_degree": 2, "zeta_degree": 2}, "time": {"order": 2}}
    steps = scene.time.steps
    runs, cost = [], 0.0
    for j in range(max_halvings + 1):
        if j >= len(recs):
            geo = None
            if scene.mesh.kind != "rectangle":
                geo = cache.get("geo") or build(MPI.COMM_SELF, scene.mesh, scene.boundaries, scene.dim)
                for _ in range(j - cache.get("geo_level", 0)):
                    geo = refine_uniformly(geo)
                cache["geo"], cache["geo_level"] = geo, j
            mesh = {"mesh": {"nx": scene.mesh.nx * 2**j, "ny": scene.mesh.ny * 2**j}} if geo is None else {}
            if (geo.num_cells() if geo is not None else 2 * mesh["mesh"]["nx"] * mesh["mesh"]["ny"]) * 4 * 2 > MAX_DOFS:
                break
            cur = Reference(scene, {**mesh, **p2}, scene.time.T / (steps * 2**j), geo,
                            f"verified uniform P2 order 2, run {j}", log=lambda *a: None)
            rec = {"mesh": mesh.get("mesh", {"r": j}), "k": cur.k, "dofs": cur.dofs, "loop_seconds": cur.loop_seconds}
            if j > 0:
                rec["difference_to_previous"] = cache["last"].replay_against(cur)
            recs.append(rec)
            cache["last"] = cur
            gc.collect()
        rec = recs[j]
        cost += rec["loop_seconds"]
        runs.append(rec)
        log(f"  verified uniform TOL {tol:g}: run {j} {rec['mesh']} k={rec['k']:g} loop {rec['loop_seconds']:.3f} s"
            + (f", differs from the previous by {rec['difference_to_previous']:.3e}" if j > 0 else ""))
        if j > 0 and rec["difference_to_previous"] < tol / 4:
            if j not in answers:  # the last run made is this one (the tolerances come largest first)
                answers[j] = cache["last"].replay_against(ref)
            return {"runs": runs, "cost": cost, "error": answers[j], "verified": True}
    return {"runs": runs, "cost": cost, "error": None, "verified": False}


def cheapest(rows: list[dict], tol: float) -> dict | None:
    ok = [r for r in rows if not r["failure"] and r["error"] <= tol]
    return min(ok, key=lambda r: r["cost"]) if ok else None


def tolerance_run(ref: Reference, scene, tol: float, log=print) -> dict:
    """Plan and run at ``tol``; the error against the reference, the cost (planning + loop) and the estimate."""
    from solver.errors import SolveFailure, ToleranceError
    from solver.run.accuracy import ErrorSensor, plan
    from solver.run.model import build_model

    t0 = time.perf_counter()
    try:
        at_tol = scene.replace({"accuracy": {"tolerance": tol, "max_dofs": MAX_DOFS}}, label=f"TOL {tol:g}")
        p = plan(at_tol, MPI.COMM_SELF, log=lambda *a: None)
    except (ToleranceError, SolveFailure) as exc:
        log(f"  TOL {tol:g}: out of reach ({exc})")
        return {"tolerance": tol, "out_of_reach": str(exc), "planning_seconds": time.perf_counter() - t0}
    planning = time.perf_counter() - t0
    cfg = quiet(p.config)  # the scene planned for (without what accuracy.simplify left out) with the plan's choices
    model = build_model(cfg, MPI.COMM_SELF, p.geo)
    p.warm_start(model)  # as the command line does: level 0's Newton starts at the planner's last t = 0 solution
    sensor = ErrorSensor(model, p)
    sensor_rows = []
    # the sensor (the run's own estimate) is evaluated after the measurement, outside the timed loop
    rec = ref.measure(model, extra_seconds=planning)
    sensor_rows.append(sensor({"t": cfg.time.T}))
    rec.update({"tolerance": tol, "degree": p.degree, "order": p.order, "k": p.k, "cells": p.geo.num_cells(),
                "planning_seconds": planning, "estimate": p.estimate.total, "estimate_parts": p.estimate.as_dict(),
                "left_out": [i.name for i in p.ingredients if i.dropped],
                "estimate_final_level": sensor_rows[-1]["est_space"] + sensor_rows[-1]["est_time"]})
    del model, sensor, p  # the plan holds its mesh: free it before the next run
    gc.collect()
    log(f"  TOL {tol:g}: P{rec['degree']} order {rec['order']} k={rec['k']:g} {rec['cells']} cells: error "
        f"{rec['error']:.3e} (estimate {rec['estimate']:.3e}) cost {rec['cost']:.3f} s (planning {planning:.3f} s)")
    return rec


def _scene_item(item: str, form: str) -> tuple[str, str]:
    """(scene, value) of a ``NAME=...`` item; ValueError naming ``form`` for a missing '=' or an unknown scene."""
    name, sep, value = item.partition("=")
    if not sep or name not in SCENES:
        raise ValueError(f"{item}: expected {form} with NAME one of {', '.join(SCENES)}")
    return name, value


def scene_ref_tol(item: str) -> tuple[str, float]:
    """One ``--scene-ref-tol NAME=TOL`` item as (scene, reference tolerance); ValueError for an unknown scene or a
    tolerance not strictly between 0 and 1."""
    name, value = _scene_item(item, "NAME=TOL")
    try:
        tol = float(value)
    except ValueError:
        tol = float("nan")
    if not 0.0 < tol < 1.0:
        raise ValueError(f"{item}: TOL must be a number strictly between 0 and 1")
    return name, tol


def scene_ref_uniform(item: str) -> tuple[str, tuple[int, int]]:
    """One ``--scene-ref-uniform NAME=N:STEPS`` item as (scene, (n, steps)); ValueError for an unknown scene, a scene
    not on a rectangle, or n, steps that are not even integers >= 2 (the second reference is at n / 2, steps / 2)."""

    name, value = _scene_item(item, "NAME=N:STEPS")
    n_text, colon, steps_text = value.partition(":")
    try:
        n, steps = int(n_text), int(steps_text)
    except ValueError:
        n = steps = 0
    if not colon or n < 2 or steps < 2 or n % 2 or steps % 2:
        raise ValueError(f"{item}: N and STEPS must be even integers >= 2 (the second reference takes half of each)")
    if scene(name).mesh.kind != "rectangle":
        raise ValueError(f"{item}: a uniform reference needs a scene on a built-in rectangle, not a gmsh mesh")
    return name, (n, steps)


def _spec(name: str, ref_tol: float, per_scene: dict[str, float], uniform: dict[str, tuple[int, int]]) -> dict:
    """What the study asks of a scene's reference: {"uniform": [n, steps]} or {"ref_tol": TOL}."""
    if name in uniform:
        return {"uniform": list(uniform[name])}
    return {"ref_tol": per_scene.get(name, ref_tol)}


def _kept(earlier: dict, tols, ref_tol: float, per_scene: dict[str, float], scenes: list[str],
          uniform: dict[str, tuple[int, int]] | None = None) -> dict:
    """The scenes of an earlier tolerance.json that can be kept: same tolerances, a reference that did not fail,
    of the kind and at the tolerance (or uniform mesh and steps) this study asks of the scene."""
    if earlier.get("tolerances") != list(tols):
        return {}
    kept = {}
    for name, sc in earlier.get("scenes", {}).items():
        if name not in scenes or "failure" in sc["reference"]:
            continue
        if _spec_of(sc["reference"], earlier) == _spec(name, ref_tol, per_scene, uniform or {}):
            kept[name] = sc
    return kept


def run_study(scenes: list[str], tols, out: Path, ref_tol: float, levels: int, steps, log=print,
              per_scene: dict[str, float] | None = None, uniform: dict[str, tuple[int, int]] | None = None,
              sweep: bool = True) -> dict:
    """Every scene in turn (``sweep``: with the uniform sweep; every tolerance run has its verified uniform
    alternative, :func:`verified_uniform`); scenes already in ``out``/tolerance.json (same tolerances and reference) are kept, not
    redone. ``per_scene``: reference tolerances that replace ``ref_tol`` for the scenes named; ``uniform``: scenes
    whose reference is a uniform run, (n, steps)."""
    per_scene, uniform = per_scene or {}, uniform or {}
    out.mkdir(parents=True, exist_ok=True)
    result = {"tolerances": list(tols), "ref_tol": ref_tol, "scenes": {}}
    old = out / "tolerance.json"
    if old.exists():
        result["scenes"] = _kept(json.loads(old.read_text()), tols, ref_tol, per_scene, scenes, uniform)
    for name in scenes:
        if name in result["scenes"]:
            log(f"{name}: kept from {old}")
            continue
        cfg = scene(name)
        spec = _spec(name, ref_tol, per_scene, uniform)
        own = name in per_scene or name in uniform
        log(f"{name}:" + (f" its own reference, {_label(spec)}" if own else ""))
        from solver.errors import SolveFailure, ToleranceError

        try:
            if "uniform" in spec:
                n, n_steps = spec["uniform"]
                ref = Reference.uniform(cfg, n, n_steps, log=log)
                second = Reference.uniform(cfg, n // 2, n_steps // 2, log=log)
            else:
                ref = Reference.planned(cfg, spec["ref_tol"], 4, log=log)
                second = Reference.planned(cfg, 3 * spec["ref_tol"], 2, log=log)
        except (ToleranceError, SolveFailure) as exc:
            log(f"  no reference: {exc}")
            result["scenes"][name] = {"reference": {"failure": str(exc), **spec}, "runs": [], "uniform": []}
            _write(result, out)
            continue

        ref_check = ref.measure(second.build())
        log(f"  second reference against it: {ref_check['error']:.2e}")
        uniform_rows = uniform_sweep(ref, cfg, tols, levels, steps, log=log) if sweep else []
        runs, sequence = [], {}  # the verified uniform sequence's runs, shared by the tolerances
        for tol in sorted(tols, reverse=True):
            rec = tolerance_run(ref, cfg, tol, log=log)
            if "out_of_reach" in rec:
                runs.append(rec)
                continue
            rec["verified_uniform"] = verified_uniform(ref, cfg, tol, log=log, cache=sequence)
            best = cheapest(uniform_rows, tol)
            rec["uniform_best"] = None if best is None else {key: best[key] for key in
                                                            ("degree", "order", "mesh", "k", "error", "cost", "dofs")}
            runs.append(rec)
            result["scenes"][name] = {  # written after every tolerance: a long study keeps what it measured
                "reference": {**spec, "cells": ref.cells, "dofs": ref.dofs, "k": ref.k, "estimate": ref.estimate,
                              "seconds": ref.seconds, "second_vs_first": ref_check["error"]},
                "runs": runs, "uniform": uniform_rows}
            _write(result, out)
        result["scenes"][name] = {
            "reference": {**spec, "cells": ref.cells, "dofs": ref.dofs, "k": ref.k, "estimate": ref.estimate,
                          "seconds": ref.seconds, "second_vs_first": ref_check["error"]},
            "runs": runs, "uniform": uniform_rows}
        _write(result, out)
        del ref, second, uniform_rows
        gc.collect()
    return result


def _ref_tol(reference: dict, result: dict) -> float | None:
    """The reference tolerance a scene was measured against: its own, or the study's (older files have none);
    None for a uniform reference."""
    if "uniform" in reference:
        return None
    return reference.get("ref_tol", result.get("ref_tol"))


def _spec_of(reference: dict, result: dict) -> dict:
    """The spec (:func:`_spec`) a scene's reference was made to."""
    if "uniform" in reference:
        return {"uniform": reference["uniform"]}
    return {"ref_tol": _ref_tol(reference, result)}


def _label(spec: dict) -> str:
    """A reference as the output names it: its tolerance, or its uniform mesh and steps."""
    if "uniform" in spec:
        n, n_steps = spec["uniform"]
        return f"uniform P2 order 2, n = {n}, k = T/{n_steps}"
    return f"{spec['ref_tol']:g}"


def _write(result: dict, out: Path) -> None:
    rows, unreached = [], []
    for name, sc in result["scenes"].items():
        label, ref_tol = _label(_spec_of(sc["reference"], result)), _ref_tol(sc["reference"], result)
        if "failure" in sc["reference"]:
            unreached.append((name, None, f"no reference at {label}: " + sc["reference"]["failure"]))
        for r in sc["runs"]:
            if "out_of_reach" in r:
                unreached.append((name, r["tolerance"], r["out_of_reach"]))
                continue
            b = r["uniform_best"] or {}
            own = sc["reference"].get("second_vs_first")
            rows.append({"scene": name, "tolerance": r["tolerance"], "error": r["error"],
                         "ref_tol": ref_tol, "reference": label,
                         "ref_error_over_tol": own / r["tolerance"] if own is not None else None,
                         "error_over_tol": r["error"] / r["tolerance"], "levels_judged": r.get("levels"),
                         "estimate": r["estimate"],
                         "degree": r["degree"], "order": r["order"], "k": r["k"], "cells": r["cells"],
                         "dofs": r["dofs"], "planning_seconds": r["planning_seconds"], "loop_seconds": r["loop_seconds"],
                         "cost": r["cost"], "uniform_degree": b.get("degree"), "uniform_order": b.get("order"),
                         "uniform_mesh": b.get("mesh"), "uniform_k": b.get("k"), "uniform_error": b.get("error"),
                         "uniform_cost": b.get("cost"),
                         "cost_ratio": r["cost"] / b["cost"] if b else None,
                         "loop_ratio": r["loop_seconds"] / b["cost"] if b else None, "failure": r["failure"]})
    if rows:
        with open(out / "tolerance.csv", "w", newline="") as f:
            w = csv.DictWriter(f, fieldnames=list(rows[0]))
            w.writeheader()
            w.writerows(rows)
    (out / "tolerance.json").write_text(json.dumps(result, indent=1, default=str))
    (out / "tolerance.md").write_text(markdown(result, rows, unreached))


def _swept(result: dict) -> bool:
    """Whether the study ran the uniform sweep (False: --no-sweep): some scene has its rows or a run its best."""
    return any(sc.get("uniform") or any(r.get("uniform_best") for r in sc["runs"]) for sc in result["scenes"].values())


def _mesh_label(mesh: dict) -> str:
    """A verified uniform run's mesh as the table names it: n = cells across a rectangle's sides, or r = uniform
    refinements of a gmsh mesh."""
    if "r" in mesh:
        return f"r={mesh['r']}"
    return f"n={mesh['nx']}" if mesh.get("nx") == mesh.get("ny") else f"{mesh.get('nx')}x{mesh.get('ny')}"


def _ratio(x: float) -> str:
    """A cost ratio with two significant digits (0.0040, not 0.00: a ratio far below 1/2 still shows its size)."""
    return f"{x:.2f}" if x >= 0.1 or not np.isfinite(x) else f"{x:.2g}"


def verified_table(result: dict) -> list[str]:
    """The tolerance runs against the verified uniform alternative (:func:`verified_uniform`), as markdown lines."""
    lines = ["", "Against the verified uniform alternative (uniform P2, order 2, n and k halved together from the "
             "scene's mesh and step until two successive runs differ by < TOL/4; its cost: all its runs' loops):", "",
             "| scene | TOL | tolerance run: error / TOL | its cost (s) | verified uniform: runs | last run | its error "
             "/ TOL | its cost (s) | cost / verified |", "|---|---|---|---|---|---|---|---|---|"]
    count = ok = unverified = below = 0
    for name, sc in result["scenes"].items():
        for r in sc["runs"]:
            v = r.get("verified_uniform")
            if v is None or "error" not in r:
                continue
            last = v["runs"][-1] if v["runs"] else {}
            if not v["verified"]:
                # the runs made are part of the sequence: its cost is at least theirs, the ratio at most this
                bound = f"≤ {_ratio(r['cost'] / v['cost'])}" if v["cost"] > 0 else "—"
                unverified += 1
                below += r["cost"] <= 0.5 * v["cost"] and r["error"] <= r["tolerance"]
                lines.append(f"| {name} | {r['tolerance']:g} | {r['error'] / r['tolerance']:.2f} | {r['cost']:.3f} "
                             f"| {len(v['runs'])} | not verified within {MAX_DOFS} dofs | — | ≥ {v['cost']:.3f} "
                             f"| {bound} |")
                continue
            ratio = r["cost"] / v["cost"] if v["cost"] > 0 else float("inf")
            count += 1
            ok += ratio <= 0.5 and r["error"] <= r["tolerance"]
            lines.append(f"| {name} | {r['tolerance']:g} | {r['error'] / r['tolerance']:.2f} | {r['cost']:.3f} "
                         f"| {len(v['runs'])} | {_mesh_label(last['mesh'])} k={last['k']:g} "
                         f"| {v['error'] / r['tolerance']:.2f} "
                         f"| {v['cost']:.3f} | {_ratio(ratio)} |")
    lines += ["", f"Within 1/2 of the verified uniform alternative's cost and reliable: {ok} of {count} verified."]
    if unverified:
        lines.append(f"Not verified within {MAX_DOFS} dofs (the sequence needs finer runs; the cost of the runs made "
                     f"is a lower bound of its cost, so the ratio is an upper bound): {unverified}, of which {below} "
                     "reliable and within 1/2 of that lower bound already.")
    return lines


def _or_dash(value: float | None, spec: str) -> str:
    return "—" if value is None else format(value, spec)


def markdown(result: dict, rows: list[dict], unreached: list = ()) -> str:
    lines = ["# Tolerance runs against a fine reference (`python -m studies study tolerance`)", "",
             "| scene | TOL | achieved error | error / TOL | levels judged | reference's own error / TOL | estimate | chosen "
             "| cost (s) | cheapest uniform meeting TOL | its cost (s) | cost / uniform | loop / uniform |",
             "|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    swept = _swept(result)
    for r in rows:
        own = r.get("ref_error_over_tol")
        uni = (f"P{r['uniform_degree']} o{r['uniform_order']} {r['uniform_mesh']} k={r['uniform_k']:g} "
               f"({r['uniform_error']:.2e})" if r["uniform_cost"] is not None else
               "none in the sweep" if swept else "not swept (--no-sweep)")
        ratio, loop, ucost = (_or_dash(r[key], spec) for key, spec in
                              (("cost_ratio", ".2f"), ("loop_ratio", ".2f"), ("uniform_cost", ".3f")))
        lines.append(f"| {r['scene']} | {r['tolerance']:g} | {r['error']:.2e} | {r['error_over_tol']:.2f} "
                     f"| {_or_dash(r.get('levels_judged'), 'd')} | {_or_dash(own, '.2f')} | {r['estimate']:.2e} "
                     f"| P{r['degree']} o{r['order']} k={r['k']:g}, {r['cells']} cells "
                     f"| {r['cost']:.3f} | {uni} | {ucost} | {ratio} | {loop} |")
    lines += ["", "References (P2, second order, a tolerance run at the reference TOL "
              f"({result['ref_tol']:g} unless a scene has its own) with a 4x smaller step; its own error: a second one "
              "at 3x the tolerance, measured against it. A uniform reference, for a scene whose tolerance reference "
              "is out of reach: P2, second order, n cells across, k = T/steps; its own error: a second one at n/2 "
              "and 2k, measured against it):", "",
              "| scene | reference | cells | dofs | k | its estimate | second reference against it | seconds |",
              "|---|---|---|---|---|---|---|---|"]
    for name, sc in result["scenes"].items():
        r = sc["reference"]
        if "failure" in r:
            continue
        own = "" if _ref_tol(r, result) == result["ref_tol"] else " (this scene's own)"
        estimate = _or_dash(r.get("estimate"), ".2e")
        lines.append(f"| {name} | {_label(_spec_of(r, result))}{own} | {r['cells']} | {r['dofs']} | {r['k']:g} "
                     f"| {estimate} "
                     f"| {r['second_vs_first']:.2e} | {r['seconds']:.1f} |")
    lines += verified_table(result)
    n = len(rows)
    ok = sum(r["error"] <= r["tolerance"] for r in rows)
    tight = sum(r["error"] >= 0.2 * r["tolerance"] for r in rows)
    within = sum(r["cost_ratio"] is not None and r["cost_ratio"] <= 2 for r in rows)
    loops = sum(r["loop_ratio"] is not None and r["loop_ratio"] <= 2 for r in rows)
    none = sum(r["cost_ratio"] is None for r in rows)
    if unreached:
        lines += ["", f"Not measured: a reference or a plan that failed (a Newton failure is a failed solve, exit 1, "
                  f"for a user), or a tolerance out of reach within {MAX_DOFS} displacement dofs (exit 2):", ""]
        lines += [f"- {name}" + (f", TOL {tol:g}" if tol is not None else "") + f": {why}" for name, tol, why in unreached]
    lines += ["", "Levels judged: the levels a run shares with its reference (at the same time; where the reference's "
              "step does not divide the run's, as few as t = 0 and T). "
              "`scripts/tolerance_all_levels.py` judges every level.",
              "", f"Reliable (error <= TOL): {ok} of {n}. Error >= 0.2 TOL: {tight} of {n}. " + (
              f"Cost within 2x of the cheapest uniform choice: {within} of {n} (planning + loop); the loop alone: "
              f"{loops} of {n} ({none} with no uniform choice in the sweep). " if swept else "") +
              "The cost counts everything after the scene is read; the uniform choice's is its loop.",
              ""]
    return "\n".join(lines)


def chart(result: dict, out: Path) -> None:
    from solver.post.charts import pyplot

    plt = pyplot("tolerance.png")
    if plt is None:
        return
    fig, (a, b) = plt.subplots(1, 2, figsize=(11, 4.5))
    swept = _swept(result)
    for name, sc in result["scenes"].items():
        done = [r for r in sc["runs"] if "error" in r]
        if not done:
            continue
        a.loglog([r["tolerance"] for r in done], [r["error"] for r in done], "o-", label=name)
        if not swept:  # against the verified uniform alternative: filled verified, hollow its lower bound
            v = [(r["verified_uniform"], r["cost"]) for r in done if r.get("verified_uniform", {}).get("cost")]
            line, = b.loglog([x["cost"] for x, _ in v if x["verified"]], [c for x, c in v if x["verified"]], "o",
                             label=name)
            b.loglog([x["cost"] for x, _ in v if not x["verified"]], [c for x, c in v if not x["verified"]], "o",
                     mfc="none", color=line.get_color())
            continue
        pairs = [(r["uniform_best"]["cost"], r["cost"], r["loop_seconds"]) for r in done if r["uniform_best"]]
        if pairs:
            x, cost, loop = zip(*pairs)
            line, = b.loglog(x, cost, "o", label=name)
            b.loglog(x, loop, "o", mfc="none", color=line.get_color())
    t = np.array([min(result["tolerances"]) / 2, max(result["tolerances"]) * 2])
    a.loglog(t, t, "k-", lw=0.8, label="error = TOL")
    a.loglog(t, 0.2 * t, "k:", lw=0.8, label="error = 0.2 TOL")
    a.set_xlabel("asked: TOL")
    a.set_ylabel("achieved: error against the reference")
    a.legend(fontsize=7)
    # the reference lines span the points plotted (a factor 2 beyond them)
    drawn = [v for line in b.get_lines() for xy in (line.get_xdata(), line.get_ydata()) for v in xy if v > 0]
    lim = (np.array([min(drawn) / 2, max(drawn) * 2]) if drawn else
           np.array([1e-3, 1e2]) if swept else np.array([10.0, 1e3]))
    b.loglog(lim, lim, "k-", lw=0.8, label="equal cost")
    if swept:
        b.loglog(lim, 2 * lim, "k:", lw=0.8, label="2x")
        b.set_xlabel("cheapest uniform (n, k, degree) meeting TOL: seconds")
        b.set_ylabel("tolerance run (s): filled planning + loop, hollow loop", fontsize=9)
    else:
        b.loglog(lim, 0.5 * lim, "k:", lw=0.8, label="1/2 (the issue's bound)")
        b.plot([], [], "o", color="0.4", label="filled: verified")
        b.plot([], [], "o", mfc="none", color="0.4", label="hollow: not verified (x: its runs made)")
        b.set_xlabel("verified uniform alternative: seconds (hollow: not verified, its runs made)", fontsize=9)
        b.set_ylabel("tolerance run (s): planning + loop", fontsize=9)
    b.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(out / "tolerance.png", dpi=120)


def main(args) -> int:
    out = Path(args.output)
    result = run_study(args.scenes, args.tols, out, args.ref_tol, args.levels, tuple(args.steps),
                       per_scene=dict(args.scene_ref_tol), uniform=dict(args.scene_ref_uniform),
                       sweep=not getattr(args, "no_sweep", False))
    chart(result, out)
    print((out / "tolerance.md").read_text())
    return 0
