"""Hertz contact against the reported contact pressure (contact_traces.py): a cylinder on a block (2-D line contact,
plane strain) and a sphere on a quarter block (3-D), each pressed into the body by a rigid obstacle with the normal
compliance law and a tiny μ.

    python scripts/hertz_contact.py [--line 50 100 200] [--line-p2 50 100] [--sphere 0.06 0.03 0.015]
        [--out benchmarks/results/hertz_contact.md]

Line contact: the block (0, 1)², symmetric about x = 0 (u_x = 0 there), clamped at y = 1, pressed at y = 0 by the
circle of radius R = 1 whose centre is at (0, −(R − δ)); with the measured force per unit length P of the half
model (2P for the whole cylinder), Hertz's half-width a = (8 R P / (π E*))^{1/2} and peak p₀ = 4P / (π a),
E* = E / (1 − ν²). Sphere: the quarter block (0, 1)³ (meshes/hertz_sphere.py, graded to ``h`` at the contact),
symmetric about x = 0 and y = 0, clamped at z = 1, pressed at z = 0 by the sphere R = 1 at depth δ = 0.01; with
the measured force F of the quarter (4F on the whole sphere), a = (3 (4F) R / (4 E*))^{1/3} and p₀ = 3 (4F) / (2 π a²)
(the half-space's a = (R δ)^{1/2} = 0.1 and p₀ = 7.00 for that depth would ignore the block's finite size, which
makes it about 13% stiffer). Written per mesh: the peak (2-D) or the pressure at
the vertex at the centre (3-D) against p₀, Hertz's profile p₀ (1 − r²/a²)^{1/2} against the reported pressure at the
vertices with r < a/2 (the largest relative difference), the contact force, and the reported pressure's integral
(the P1 interpolant of its vertex values) against the force.
"""

from __future__ import annotations

import argparse
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


def line(n: int, degree: int, delta: float) -> dict:
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
        contact, row = run(toml, Path(tmp), [])
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
    return {"mesh": f"P{degree}, n = {n}", "h": 1.0 / n, "a/h": a * n, "force": force, "peak": float(p.max()),
            "p0": p0, "profile": profile, "rms": rms, "integral": float(np.trapz(p, x)), "seconds": seconds}


def sphere(h: float, delta: float, max_it: int) -> dict:
    with tempfile.TemporaryDirectory() as tmp:
        mesh = Path(tmp) / "hertz.msh"
        subprocess.run([sys.executable, str(ROOT / "meshes" / "hertz_sphere.py"), "--h", str(h), "--output", str(mesh)],
                       check=True, capture_output=True)
        toml = BASE.format(E=E, NU=NU, model="3d") + f"""
[mesh]
kind = "gmsh"
file = "{mesh}"
[boundary.xsym]
role = "displacement"
displacement = [0.0, "free", "free"]
[boundary.ysym]
role = "displacement"
displacement = ["free", 0.0, "free"]
[boundary.top]
role = "clamped"
[solver]
max_it = {max_it}
[boundary.contact]
role = "contact"
mu = {MU}
obstacle = {{shape = "sphere", centre = [0.0, 0.0, {-(R - delta)}], radius = {R}}}
"""
        start = time.perf_counter()
        contact, row = run(toml, Path(tmp), [])
        seconds = time.perf_counter() - start
    pts, cells, p = contact["points"], contact["cells"], contact["fields"]["contact_pressure"][0]
    r = np.hypot(pts[:, 0], pts[:, 1])
    force = row["contact_force"]
    a = (3 * 4 * force * R / (4 * E_STAR)) ** (1 / 3)  # the whole sphere's load is 4 x the quarter's
    p0 = 3 * 4 * force / (2 * math.pi * a**2)
    centre = int(np.argmin(r))
    inner = r < a / 2
    diff = (p[inner] - p0 * np.sqrt(1 - (r[inner] / a) ** 2)) / p0
    profile, rms = float(np.max(np.abs(diff))), float(np.sqrt(np.mean(diff**2)))
    tri = pts[cells]
    areas = 0.5 * np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1)
    integral = float(areas @ p[cells].mean(axis=1))
    return {"mesh": f"P1, h = {h}", "h": h, "a/h": a / h, "a": a, "force": force, "peak": float(p[centre]), "p0": p0,
            "profile": profile, "rms": rms, "vertices": int(inner.sum()), "integral": integral, "seconds": seconds,
            "cells": len(cells)}


def table(rows: list[dict], what: str) -> list[str]:
    out = [f"| mesh | a / h | contact force F | {what} | p₀ | {what} / p₀ − 1 | abs(p − Hertz) / p₀ at the vertices "
           "r < a/2: max, rms | ∫ p_h ds / F − 1 | run (s) |", "|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        out.append(f"| {r['mesh']} | {r['a/h']:.1f} | {r['force']:.5g} | {r['peak']:.5g} | {r['p0']:.5g} | "
                   f"{r['peak'] / r['p0'] - 1:+.2%} | {r['profile']:.2%}, {r['rms']:.2%} | "
                   f"{r['integral'] / r['force'] - 1:+.1e} | {r['seconds']:.0f} |")
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--line", type=int, nargs="*", default=[50, 100, 200], help="P1 meshes n x n of the line contact")
    ap.add_argument("--line-p2", type=int, nargs="*", default=[50, 100], help="P2 meshes of the line contact")
    ap.add_argument("--line-delta", type=float, default=0.01, help="the cylinder's depth")
    ap.add_argument("--sphere", type=float, nargs="*", default=[0.06, 0.03, 0.015], help="mesh sizes at the contact")
    ap.add_argument("--max-it", type=int, default=200, help="Newton iterations allowed for the sphere (solver.max_it)")
    ap.add_argument("--out", type=Path, default=ROOT / "benchmarks" / "results" / "hertz_contact.md")
    args = ap.parse_args(argv)
    cmd = "python scripts/hertz_contact.py " + " ".join(a for a in (argv if argv is not None else sys.argv[1:]))
    text = [f"# Hertz contact: the reported contact pressure\n\n`{cmd.strip()}`\n",
            f"E = {E}, ν = {NU}, R = {R}, μ = {MU}.\n"]
    lines = []
    for n in args.line:
        lines.append(line(n, 1, args.line_delta))
        print(table(lines, "peak")[-1], flush=True)
    for n in args.line_p2:
        lines.append(line(n, 2, args.line_delta))
        print(table(lines, "peak")[-1], flush=True)
    if lines:
        text += [f"## Line contact (plane strain, cylinder at depth δ = {args.line_delta})\n", *table(lines, "peak"), ""]
    spheres = []
    for h in args.sphere:
        spheres.append(sphere(h, 0.01, args.max_it))
        print(table(spheres, "p at the centre")[-1], f"({spheres[-1]['cells']} contact triangles)", flush=True)
    if spheres:
        text += ["## Sphere (3-D, quarter block, δ = 0.01)\n", *table(spheres, "p at the centre"), ""]
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text("\n".join(text) + "\n")
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
