"""Hertz contact against the reported contact pressure (contact_traces.py): a cylinder on a block (2-D line contact,
plane strain) and a sphere on a quarter block (3-D), each pressed into the body by a rigid obstacle with the normal
compliance law.

    python scripts/hertz_contact.py [--line 50 100 200] [--line-p2 50 100] [--out benchmarks/results/hertz_contact.md]
        [--sphere P1:0 P1:1 P1:2 P2:0 P2:1] [--sphere-h 0.06] [--sphere-mu 1e-6]
        [--sphere-out benchmarks/results/hertz_sphere.md] [--points gauss nodes]

Line contact (μ = 1e-8): the block (0, 1)², symmetric about x = 0 (u_x = 0 there), clamped at y = 1, pressed at y = 0
by the circle of radius R = 1 whose centre is at (0, −(R − δ)); with the measured force per unit length P of the half
model (2P for the whole cylinder), Hertz's half-width a = (8 R P / (π E*))^{1/2} and peak p₀ = 4P / (π a),
E* = E / (1 − ν²). Written per mesh: the peak against p₀, Hertz's profile against the reported pressure at the
vertices with x < a/2, the contact force, and the reported pressure's integral against the force.

Sphere: the quarter block (0, L)³ (meshes/hertz3d.py, graded to ``--sphere-h`` at the contact, then split uniformly
``n`` times for the case ``P<degree>:<n>``: nested meshes, every size halved), symmetric about x = 0 and y = 0,
clamped at z = L, pressed at z = 0 by the sphere R = 1 at depth δ = 0.01; with the measured force F of the quarter
(4F on the whole sphere), a = (3 (4F) R / (4 E*))^{1/3} and p₀ = 3 (4F) / (2 π a²). Each case runs in a process of
its own (``--sphere-case``) and measures the reported pressure (the lumped-mass recovery at the vertices) and the
law's pressure at the contact term's quadrature points, each as a weighted mean near the axis (weight
(1 − r²/ρ²)₊, ρ = a/4) against Hertz's mean, and as an L² error over r < a/2; and the reported pressure at the
vertices: the centre one, the largest and rms difference from Hertz over r < a/2.

``--points A B``: every line case is run with ``solver.contact_points`` = A and = B (the law at the Gauss points or at
the nodes); a sphere case takes the tag ``:nodes`` (``P1:0:nodes``), and the reference of the reference table is
always a Gauss case.
"""

from __future__ import annotations

import argparse
import json
import math
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from solver.io.xdmf import read_series  # noqa: E402
from solver.post.results import read_csv  # noqa: E402

E, NU, R, MU = 100.0, 0.3, 1.0, 1e-8
E_STAR = E / (1 - NU**2)
BASE = """
[memory]
kernel = "none"
[damage]
enabled = false
[time]
T = 1.0
k = 1.0
[output]
every = 1
fields = ["displacement"]
[material]
E = {E}
nu = {NU}
model = "{model}"
"""


def run(toml: str, directory: Path, sets: list[str]) -> tuple[dict, dict]:
    """Run a scene (written as a file in ``directory``); the contact dataset and the time series' level 0."""
    scene = directory / "scene.toml"
    scene.write_text(toml)
    cmd = [sys.executable, "-m", "solver", "run", str(scene), "--output", str(directory / "r"), "--no-progress"]
    for s in sets:
        cmd += ["--set", s]
    res = subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True)
    if res.returncode != 0:
        raise RuntimeError(res.stderr[-3000:])
    return read_series(directory / "r" / "contact.xdmf"), read_csv(directory / "r" / "timeseries.csv")[0]


def line(n: int, degree: int, delta: float, points: str = "gauss") -> dict:
    toml = BASE.format(E=E, NU=NU, model="plane_strain") + f"""
[mesh]
nx = {n}
ny = {n}
[discretization]
u_degree = {degree}
[boundary.left]
role = "displacement"
displacement = [0.0, "free"]
[boundary.top]
role = "clamped"
[boundary.bottom]
role = "contact"
mu = {MU}
obstacle = {{shape = "circle", centre = [0.0, {-(R - delta)}], radius = {R}}}
"""
    with tempfile.TemporaryDirectory() as tmp:
        start = time.perf_counter()
        contact, row = run(toml, Path(tmp), [f"solver.contact_points='{points}'"] if points != "gauss" else [])
        seconds = time.perf_counter() - start
    x, p = contact["points"][:, 0], contact["fields"]["contact_pressure"][0]
    order = np.argsort(x)
    x, p = x[order], p[order]
    force = row["contact_force"]
    a = math.sqrt(8 * R * force / (math.pi * E_STAR))
    p0 = 4 * force / (math.pi * a)
    inner = x < a / 2
    diff = (p[inner] - p0 * np.sqrt(1 - (x[inner] / a) ** 2)) / p0
    profile, rms = float(np.max(np.abs(diff))), float(np.sqrt(np.mean(diff**2)))
    return {"mesh": f"P{degree}, n = {n}" + (f", {points}" if points != "gauss" else ""), "h": 1.0 / n,
            "newton": row["newton_iterations"], "a/h": a * n, "force": force, "peak": float(p.max()),
            "p0": p0, "profile": profile, "rms": rms, "integral": float(np.trapz(p, x)), "seconds": seconds}


def sphere_case(h: float, refine: int, size: float, degree: int, mu: float, quad: int, max_it: int,
                delta: float = 0.01, points: str = "gauss") -> dict:
    """One sphere run in this process (scripts call it through ``--sphere-case``): the block (0, L)³ meshed by
    meshes/hertz3d.py, clamped at z = L, pressed at z = 0 by the sphere R at depth δ; level 0 solved, then the
    pressure measured at the vertices (the reported, recovered one) and at the contact term's quadrature points
    (the law's, integrated)."""
    import ufl
    from dolfinx import fem
    from mpi4py import MPI

    from solver.config import from_dict
    from solver.physics.contact import compliance, gap_function, penetration
    from solver.physics.quadrature import ContactRule, facet_type
    from solver.run.model import build_model
    from solver.run.stepper import Stepper

    sys.path.insert(0, str(ROOT / "meshes"))
    import hertz3d as mesher

    with tempfile.TemporaryDirectory() as tmp:
        msh = Path(tmp) / "hertz3d.msh"
        summary = mesher.write(msh, h, size=size, near=0.15, far=0.2 * size, grade=0.6 * size, refine=refine)
        scene = {
            "mesh": {"kind": "gmsh", "file": str(msh)},
            "material": {"E": E, "nu": NU, "model": "3d"}, "discretization": {"u_degree": degree},
            "memory": {"kernel": "none"}, "damage": {"enabled": False}, "time": {"T": 1.0, "k": 1.0},
            "solver": {"max_it": max_it, "contact_points": points,
                       **({"contact_quadrature_degree": quad} if quad else {})},
            "boundary": {
                "sym_x": {"role": "displacement", "displacement": [0.0, "free", "free"]},
                "sym_y": {"role": "displacement", "displacement": ["free", 0.0, "free"]},
                "top": {"role": "clamped"},
                "bottom": {"role": "contact", "mu": mu,
                           "obstacle": {"shape": "sphere", "centre": [0.0, 0.0, -(R - delta)], "radius": R}},
            },
        }
        start = time.perf_counter()
        model = build_model(from_dict(scene), MPI.COMM_WORLD)
        row = Stepper(model).step(0)
        seconds = time.perf_counter() - start
    geo, u = model.geo, model.u
    part = next(b for b in model.cfg.boundaries if b.role == "contact")
    rule = ContactRule.of(model.cfg)
    qdeg = rule.degree if points == "gauss" else "nodes"
    x = ufl.SpatialCoordinate(geo.mesh)
    r2 = x[0] ** 2 + x[1] ** 2
    law = compliance(penetration(u, ufl.FacetNormal(geo.mesh), gap_function(part, geo, rule)), part)
    ds = geo.ds(geo.tags[part.name], metadata=rule.metadata(facet_type(geo.mesh)))
    traces = model.mech.diagnostics.traces
    recovered = traces.pressure

    def integral(f):
        return geo.comm.allreduce(fem.assemble_scalar(fem.form(f * ds)), op=MPI.SUM)

    force = row["contact_force"]
    a = (3 * 4 * force * R / (4 * E_STAR)) ** (1 / 3)  # Hertz for the measured force (4 x the quarter's)
    p0 = 3 * 4 * force / (2 * math.pi * a**2)
    hertz = p0 * ufl.sqrt(ufl.max_value(1.0 - r2 / a**2, 0.0))
    inner = ufl.conditional(ufl.lt(r2, (a / 2) ** 2), 1.0, 0.0)
    area = integral(inner)
    # the weighted mean near the axis, w = (1 - r²/ρ²)₊ with ρ = a/4, and Hertz's for the same w (trapezoid rule)
    rho = a / 4
    w = ufl.max_value(1.0 - r2 / rho**2, 0.0)
    t = np.linspace(0.0, 1.0, 20001)
    weight = (1.0 - t**2) * t
    central_hertz = p0 * np.trapz(np.sqrt(1.0 - (rho * t / a) ** 2) * weight, t) / np.trapz(weight, t)
    out = {"h": h / 2**refine, "refine": refine, "size": size, "degree": degree, "mu": mu, "quad": qdeg, "points": points,
           "force": force, "a": a, "p0": p0, "mesh": summary, "seconds": seconds,
           "newton": row["newton_iterations"], "dofs": model.u.function_space.dofmap.index_map.size_global * 3,
           "moment_a": math.sqrt(2.5 * integral(law * r2) / force),
           # the law's pressure at the quadrature points (no recovery)
           "law_l2": math.sqrt(integral(inner * (law - hertz) ** 2) / area) / p0,
           "law_central": integral(law * w) / integral(w) / central_hertz,
           # the reported pressure (the lumped-mass recovery at the vertices, P1 between them)
           "rec_l2": math.sqrt(integral(inner * (recovered - hertz) ** 2) / area) / p0,
           "rec_central": integral(recovered * w) / integral(w) / central_hertz}
    on = traces.on[traces.on < traces.n_local]
    pts, p = traces.x[on], recovered.x.array[on]
    rr = np.hypot(pts[:, 0], pts[:, 1])
    near = rr < a / 2
    diff = (p[near] - p0 * np.sqrt(1 - (rr[near] / a) ** 2)) / p0
    out.update({"centre": float(p[np.argmin(rr)]) / p0, "vertex_rms": float(np.sqrt(np.mean(diff**2))),
                "vertex_max": float(np.max(np.abs(diff))), "vertices": int(near.sum())})
    return out


def sphere(case: dict) -> dict:
    """A sphere case in a process of its own (memory, and the forms compiled afresh)."""
    res = subprocess.run([sys.executable, __file__, "--sphere-case", json.dumps(case)], cwd=ROOT, capture_output=True,
                         text=True)
    if res.returncode != 0:
        raise RuntimeError(res.stderr[-3000:])
    return json.loads(res.stdout.strip().splitlines()[-1])


def table(rows: list[dict], what: str) -> list[str]:
    out = [f"| mesh | a / h | contact force F | {what} | p₀ | {what} / p₀ − 1 | abs(p − Hertz) / p₀ at the vertices "
           "r < a/2: max, rms | ∫ p_h ds / F − 1 | Newton | run (s) |", "|---|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        out.append(f"| {r['mesh']} | {r['a/h']:.1f} | {r['force']:.5g} | {r['peak']:.5g} | {r['p0']:.5g} | "
                   f"{r['peak'] / r['p0'] - 1:+.2%} | {r['profile']:.2%}, {r['rms']:.2%} | "
                   f"{r['integral'] / r['force'] - 1:+.1e} | {int(r['newton'])} | {r['seconds']:.0f} |")
    return out


def sphere_table(rows: list[dict]) -> list[str]:
    out = ["| mesh | tetrahedra | dofs | Newton | F (quarter) | a | a / h | p at the centre vertex / p₀ − 1 | reported, "
           "mean near the axis / Hertz's − 1 | the law's at the points, same | L² error / p₀ over r < a/2: reported, "
           "the law's | vertices r < a/2: max, rms of (p − Hertz)/p₀ | run (s) |",
           "|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        tets = int(r["mesh"].split(": ")[1].split()[0])
        out.append(f"| P{r['degree']}, h = {r['h']:g} (L = {r['size']:g}, μ = {r['mu']:g}, {_rule(r)}) | "
                   f"{tets} | {r['dofs']} | "
                   f"{r['newton']} | {r['force']:.5g} | {r['a']:.4g} | {r['a'] / r['h']:.1f} | {r['centre'] - 1:+.2%} | "
                   f"{r['rec_central'] - 1:+.2%} | {r['law_central'] - 1:+.2%} | {r['rec_l2']:.2%}, {r['law_l2']:.1%} | "
                   f"{r['vertex_max']:.2%}, {r['vertex_rms']:.2%} | {r['seconds']:.0f} |")
    return out


def reference_table(rows: list[dict]) -> list[str]:
    """Each case against the finest mesh of the highest degree with the same L and μ (the same continuous problem)."""
    out = ["Against the finest mesh of the highest degree for the same L and μ (the same continuous problem):\n",
           "| mesh | reference | F / F_ref − 1 | the law's mean near the axis / ref − 1 | reported mean / the law's ref − 1 |",
           "|---|---|---|---|---|"]
    for r in rows:
        same = [q for q in rows if q["size"] == r["size"] and q["mu"] == r["mu"] and q["quad"] == 2 * q["degree"]
                and q.get("points", "gauss") == "gauss"]
        ref = max(same, key=lambda q: (q["degree"], -q["h"])) if same else r
        if ref is r:
            continue
        law = r["law_central"] * r["p0"] / (ref["law_central"] * ref["p0"]) - 1  # the means themselves, not / p0
        rec = r["rec_central"] * r["p0"] / (ref["law_central"] * ref["p0"]) - 1
        out.append(f"| P{r['degree']}, h = {r['h']:g} (L = {r['size']:g}, μ = {r['mu']:g}, {_rule(r)}) | "
                   f"P{ref['degree']}, h = {ref['h']:g} | "
                   f"{r['force'] / ref['force'] - 1:+.2%} | {law:+.2%} | {rec:+.2%} |")
    return out


def _rule(r: dict) -> str:
    """The contact rule of a sphere row."""
    return "the nodes" if r.get("points", "gauss") == "nodes" else f"quadrature degree {r['quad']}"


def parse_case(spec: str, h: float, size: float, mu: float, max_it: int) -> dict:
    """``P<degree>:<refinements>[:L<size>][:mu<mu>]`` as sphere_case's arguments."""
    fields = spec.split(":")
    case = {"h": h, "refine": int(fields[1]), "size": size, "degree": int(fields[0].lstrip("P")), "mu": mu, "quad": 0,
            "max_it": max_it}
    for f in fields[2:]:
        if f.startswith("L"):
            case["size"] = float(f[1:])
        elif f.startswith("mu"):
            case["mu"] = float(f[2:])
        elif f in ("gauss", "nodes"):
            case["points"] = f
        elif f.startswith("q"):
            case["quad"] = int(f[1:])
        else:
            raise SystemExit(f"--sphere {spec}: {f!r} is not L<size>, mu<mu>, q<degree>, gauss or nodes")
    return case


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--line", type=int, nargs="*", default=[50, 100, 200], help="P1 meshes n x n of the line contact")
    ap.add_argument("--line-p2", type=int, nargs="*", default=[50, 100], help="P2 meshes of the line contact")
    ap.add_argument("--line-delta", type=float, default=0.01, help="the cylinder's depth")
    ap.add_argument("--sphere", nargs="*", default=["P1:0", "P1:1", "P1:2", "P2:0", "P2:1"],
                    help="sphere cases P<degree>:<refinements of the --sphere-h mesh>[:L<size>][:mu<mu>][:q<degree>]")
    ap.add_argument("--sphere-h", type=float, default=0.06, help="the sphere's coarsest mesh size at the contact")
    ap.add_argument("--sphere-mu", type=float, default=1e-6, help="the sphere's compliance")
    ap.add_argument("--max-it", type=int, default=200, help="Newton iterations allowed for the sphere (solver.max_it)")
    ap.add_argument("--points", nargs="*", default=["gauss"], help="solver.contact_points of the line cases")
    ap.add_argument("--out", type=Path, default=ROOT / "benchmarks" / "results" / "hertz_contact.md")
    ap.add_argument("--sphere-out", type=Path, default=ROOT / "benchmarks" / "results" / "hertz_sphere.md")
    ap.add_argument("--sphere-case", help=argparse.SUPPRESS)  # one sphere case (JSON), run by sphere()
    args = ap.parse_args(argv)
    if args.sphere_case:
        print(json.dumps(sphere_case(**json.loads(args.sphere_case))))
        return 0
    cmd = "python scripts/hertz_contact.py " + " ".join(a for a in (argv if argv is not None else sys.argv[1:]))
    text = [f"# Hertz contact: the reported contact pressure\n\n`{cmd.strip()}`\n",
            f"E = {E}, ν = {NU}, R = {R}, μ = {MU}.\n"]
    lines = []
    for degree, ns in ((1, args.line), (2, args.line_p2)):
        for n in ns:
            for points in args.points:
                lines.append(line(n, degree, args.line_delta, points))
                print(table(lines, "peak")[-1], flush=True)
    if lines:
        text += [f"## Line contact (plane strain, cylinder at depth δ = {args.line_delta})\n", *table(lines, "peak"), ""]
    if lines:
        args.out.parent.mkdir(parents=True, exist_ok=True)
        args.out.write_text("\n".join(text) + "\n")
        print(f"wrote {args.out}")
    spheres = []
    for spec in args.sphere:
        spheres.append(sphere(parse_case(spec, args.sphere_h, 1.0, args.sphere_mu, args.max_it)))
        print(sphere_table(spheres)[-1], flush=True)
    if spheres:
        args.sphere_out.parent.mkdir(parents=True, exist_ok=True)
        args.sphere_out.write_text("\n".join([
            f"# Hertz contact in 3-D: the sphere\n\n`{cmd.strip()}`\n",
            f"E = {E}, ν = {NU}, R = {R}, δ = 0.01; the quarter block (0, L)³ clamped at z = L (meshes/hertz3d.py "
            f"--size L --h {args.sphere_h} --near 0.15 --far 0.2L --grade 0.6L --refine n); p₀, a: Hertz's for the "
            "measured force.\n", *sphere_table(spheres), "", *reference_table(spheres), ""]) + "\n")
        print(f"wrote {args.sphere_out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
