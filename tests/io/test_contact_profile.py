"""The contact results: the pressure, the gap and the penetration as fields in solution.xdmf and
along Γ_C in contact.csv, and the peak pressure in timeseries.csv. They are the lumped-mass means of the law's values
at the contact term's quadrature points (contact_traces.py): the pressure is >= 0 and carries exactly the contact
force of the discrete equations (its integral over Γ_C with the lumped mass, the trapezoidal rule on a uniform
straight part, equals the ``contact_force`` column at every level, 1 and 2 ranks), the gap and u_ν integrate to
their integrals with the contact rule, and the penetration is positive exactly where the pressure is."""

import numpy as np
import pytest
from conftest import solve

from solver.config import from_dict
from solver.post.results import read_csv, read_profile, read_results

FIELDS = ["displacement", "contact_pressure", "gap", "penetration"]
SCENES = {
    # Example 1 (linear law, constant gap), every level written
    "example1": {"mesh": {"nx": 16, "ny": 4}, "time": {"T": 0.3, "k": 0.1}},
    # a body on a curved foundation given as a table, the power law, pulled down: the zone grows
    "table": {"mesh": {"nx": 16, "ny": 4}, "time": {"T": 0.2, "k": 0.1}, "memory": {"kernel": "none"},
              "boundary": {"left": {"role": "clamped"}, "right": {"role": "traction", "traction": [0.0, -20.0]},
                           "bottom": {"role": "contact", "law": "power", "coefficient": 1e6, "exponent": 1.5,
                                      "gap": [[0.0, 0.0], [0.33, 2e-4], [0.71, -1e-4], [1.0, 3e-4]]}}},
}


@pytest.mark.parametrize("scene", sorted(SCENES))
def test_pressure_integrates_to_the_contact_force(comm, shared_tmp, scene):
    cfg = from_dict({**SCENES[scene], "output": {"every": 1, "fields": FIELDS}})
    model, _ = solve(cfg, comm, shared_tmp)
    if comm.rank != 0:
        return
    rows = read_csv(shared_tmp / "timeseries.csv")
    profile = read_profile(shared_tmp / "contact.csv")
    res = read_results(shared_tmp)
    x = res["geometry"]
    bottom = np.flatnonzero(np.abs(x[:, 1]) < 1e-12)
    bottom = bottom[np.argsort(x[bottom, 0])]
    part = model.cfg.boundaries[-1]
    assert len(rows) == len(res["times"]) == 1 + model.cfg.time.steps
    for row, t in zip(rows, res["times"]):
        force = row["contact_force"]
        assert force > 0
        p = profile[(int(row["step"]), "bottom")]
        # every node of the part, in order; the profile's coordinates are dolfinx's dof coordinates, computed with a
        # dense product whose last bit depends on the BLAS (OpenBLAS gives 1.3e-18 for a node at x = 0)
        assert np.allclose(p["x"], x[bottom, 0], rtol=0.0, atol=1e-14)
        # lambda_h is P1 along the straight part: the trapezoidal rule integrates it exactly
        assert np.trapz(p["pressure"], p["s"]) == pytest.approx(force, rel=1e-8)
        field = res["fields"]["contact_pressure"][t]
        assert np.trapz(field[bottom], x[bottom, 0]) == pytest.approx(force, rel=1e-8)
        assert np.all(np.delete(field, bottom) == 0.0)  # zero off the contact part
        assert row["peak_pressure"] == p["pressure"].max()
        assert row["peak_pressure_x"] == p["x"][np.argmax(p["pressure"])]
        assert field.min() >= 0.0
        # g and u_ν: their lumped integrals are ∫ g ds and ∫ u_ν ds with the contact rule (2-point Gauss per facet)
        u = res["fields"]["displacement"][t]
        xb = x[bottom, 0]
        gauss = np.concatenate([a + (b - a) * np.array([0.5 - 0.5 / np.sqrt(3), 0.5 + 0.5 / np.sqrt(3)])
                                for a, b in zip(xb[:-1], xb[1:])])
        weights = np.repeat(np.diff(xb) / 2, 2)
        g_points = np.interp(gauss, *np.array(part.gap_table).T) if part.gap_table else np.full(len(gauss), part.gap)
        assert np.trapz(res["fields"]["gap"][t][bottom], xb) == pytest.approx(weights @ g_points, rel=1e-12)
        assert np.trapz(p["gap"], p["s"]) == pytest.approx(weights @ g_points, rel=1e-12)
        assert np.trapz(p["u_normal"], p["s"]) == pytest.approx(np.trapz(-u[bottom, 1], xb), rel=1e-9)
        # a positive pressure beside a positive penetration; elsewhere the mean separation u_ν − g <= 0
        pressed = p["pressure"] > 0
        assert np.all(p["penetration"][pressed] > 0)
        assert np.all(p["penetration"][~pressed] <= 0)
        assert np.allclose(p["penetration"][~pressed], (p["u_normal"] - p["gap"])[~pressed], rtol=0,
                           atol=1e-12 * np.abs(p["gap"]).max(initial=1e-300) + 1e-20)
        if part.law == "linear":  # the mean of r₊ = μ p
            assert np.allclose(p["penetration"][pressed], part.mu * p["pressure"][pressed], rtol=1e-12)
        assert np.allclose(p["penetration"], res["fields"]["penetration"][t][bottom], rtol=0, atol=0)


def test_no_contact_fields_without_contact(comm, shared_tmp):
    """A scene without a contact part writes neither contact.csv nor the contact fields (asked for or not)."""
    cfg = from_dict({"mesh": {"nx": 4, "ny": 2}, "time": {"T": 0.1, "k": 0.1}, "output": {"fields": FIELDS},
                     "boundary": {"left": {"role": "clamped"}, "right": {"role": "traction", "traction": [0.0, -1.0]}}})
    solve(cfg, comm, shared_tmp)
    if comm.rank == 0:
        assert not (shared_tmp / "contact.csv").exists()
        assert set(read_results(shared_tmp)["fields"]) == {"displacement"}
        assert "peak_pressure" not in read_csv(shared_tmp / "timeseries.csv")[0]


def test_profile_lines_are_each_values_repr_whether_the_gap_stays_or_moves(tmp_path):
    """contact.csv's lines are the reprs of the values, whatever the writer keeps formatted (s and the point, and the
    gap once it repeats): a gap that stays, one that moves every level, one that moves and stops, a part whose name
    holds a %, a point that moves, and a penetration equal to u_ν on all rows, some or none."""
    from mpi4py import MPI

    from solver.io.contact_profile import ProfileWriter
    from solver.io.layout import PROFILE_COLUMNS

    rng = np.random.default_rng(3)
    head = np.column_stack([np.linspace(0.0, 1.0, 5), rng.random((5, 3))])
    gaps = [rng.random(5)] * 3 + [rng.random(5) for _ in range(3)] + [np.full(5, 0.1)] * 3

    class Traces:
        level = 0

        def profile(self):
            g = gaps[self.level]
            other = np.column_stack([head[:, :1], head[:, 1:] + (self.level == 8)])  # the point moves at level 8
            return [(name, np.column_stack([other if name == "top" else head, g, self.values()]))
                    for name in ("bottom", "100%", "top")]

        def values(self):
            """u_ν, penetration, pressure: the penetration u_ν's own value on every row, on some, or on none (the
            writer formats such a value once), and once -0.0 beside 0.0 (equal numbers, not the same text)."""
            v = rng.standard_normal((5, 3))
            if self.level % 3 == 0:
                v[:, 1] = v[:, 0]
            elif self.level % 3 == 1:
                v[::2, 1] = v[::2, 0]
                v[1, :2] = -0.0, 0.0
            return v

    traces = Traces()
    writer = ProfileWriter(tmp_path / "contact.csv", MPI.COMM_SELF, traces)
    want = [",".join(PROFILE_COLUMNS) + "\n"]
    for level in range(len(gaps)):
        traces.level = level
        state = rng.bit_generator.state
        expected = traces.profile()
        rng.bit_generator.state = state  # the writer's call draws the same values
        writer.write(level, 0.1 * level)
        want += [f"{level},{0.1 * level!r},{name}," + ",".join(map(repr, row)) + "\n"
                 for name, rows in expected for row in rows.tolist()]
    writer.close()
    assert (tmp_path / "contact.csv").read_text() == "".join(want)
