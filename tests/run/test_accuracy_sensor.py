"""solver/run/accuracy/sensor.py: the run's estimated error per level, and its largest values."""

import pytest
from conftest import ROOT
from mpi4py import MPI

from solver.config import load
from solver.physics.estimator import estimator_for
from solver.run.accuracy import plan
from solver.run.accuracy.sensor import ErrorSensor
from solver.run.model import build_model
from solver.run.stepper import levels


def test_the_sensor_adds_c_eta_and_the_plans_parts_and_keeps_their_largest(comm):
    scene = load(ROOT / "configs/example1.toml").replace({"time": {"T": 0.2}, "accuracy": {"tolerance": 1e-2}})
    p = plan(scene, comm, log=lambda *a: None)
    model = build_model(p.config, comm, p.geo)
    sensor = ErrorSensor(model, p)
    est = estimator_for(model)
    rows = list(levels(model, sensors=(sensor,)))
    assert set(ErrorSensor.columns) <= set(rows[-1])
    for row in rows[-1:]:
        assert row["est_space"] == pytest.approx(p.C * est.total() + p.estimate.space_zeta, rel=1e-12)
        assert row["est_time"] == p.time_error(row["t"])
    space = max(r["est_space"] for r in rows)
    tim = max(r["est_time"] for r in rows)
    total = max(r["est_space"] + r["est_time"] for r in rows)
    assert (sensor.largest.space, sensor.largest.time, sensor.largest.total) == (space, tim, total)
    assert MPI.COMM_WORLD.allreduce(sensor.largest.total, op=MPI.MAX) == sensor.largest.total  # the same on ranks


def test_eta_is_evaluated_on_about_samples_levels_and_the_last(comm):
    from solver.run.accuracy.sensor import SAMPLES

    scene = load(ROOT / "configs/example1.toml").replace({"time": {"T": 0.5}, "accuracy": {"tolerance": 1e-2}})
    p = plan(scene, comm, log=lambda *a: None)
    cfg = p.config.replace({"time": {"k": 0.5 / 40}})  # 40 steps
    model = build_model(cfg, comm, p.geo)
    sensor = ErrorSensor(model, p)
    seen = []
    total = sensor.est.total
    sensor.est.total = lambda *a: seen.append(1) or total(*a)
    rows = list(levels(model, sensors=(sensor,)))
    assert len(rows) == 41 and SAMPLES <= len(seen) <= SAMPLES + 2
    assert rows[-1]["est_space"] == pytest.approx(p.C * total() + p.estimate.space_zeta, rel=1e-12)  # the last: now
