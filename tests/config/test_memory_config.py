"""[memory]: the tabulated and power kernels' keys, their sum of exponentials chosen at load, and the refusals."""

import pytest

from solver.config import ConfigError, dumps, from_dict, load, to_dict

pytestmark = pytest.mark.serial  # no MPI in this layer: on 2 ranks each would run the same checks again

TIME = {"T": 1.0, "k": 0.001}


def test_power_kernel_keys_are_read_and_fitted():
    cfg = from_dict({"time": TIME, "memory": {"kernel": "power", "coefficient": 2.0, "exponent": 0.3,
                                              "kernel_tolerance": 1e-6}})
    m = cfg.memory
    assert (m.kernel, m.coefficient, m.exponent, m.kernel_tolerance, m.rule) == ("power", 2.0, 0.3, 1e-6, "left")
    fit = m.fit(cfg.time.k, cfg.time.steps)
    assert fit.error <= 1e-6 and 1 <= fit.terms <= 64
    assert (fit.lag_min, fit.lag_max) == pytest.approx((0.001, 1.0))


def test_tabulated_kernel_runs_with_order_two(tmp_path):
    """A tabulated kernel is a Prony series now: time.order = 2 takes it, with the extrapolated trapezoid (g(0))."""
    cfg = from_dict({"time": {**TIME, "order": 2}, "memory": {"kernel": "tabulated", "table": [[0, 2.0], [1, 1.0]]}})
    assert cfg.memory.rule == "trapezoid_extrapolated"
    fit = cfg.memory.fit(cfg.time.k, cfg.time.steps)
    assert fit.lag_min == 0.0 and fit.error <= 1e-8
    path = tmp_path / "c.toml"
    path.write_text(dumps(cfg))
    assert load(path).memory == cfg.memory


def test_keys_of_other_kernels_are_left_out_of_the_written_scene():
    out = to_dict(from_dict({}))["memory"]
    assert not {"coefficient", "exponent", "kernel_tolerance", "table"} & set(out)
    power = to_dict(from_dict({"memory": {"kernel": "power"}}))["memory"]
    assert {"coefficient", "exponent", "kernel_tolerance"} <= set(power) and "weights" not in power


@pytest.mark.parametrize("memory,key,says", [
    ({"kernel": "power", "exponent": 1.0}, "memory.exponent", "between 0 and 1"),
    ({"kernel": "power", "exponent": 0.0}, "memory.exponent", "between 0 and 1"),
    ({"kernel": "power", "coefficient": 0.0}, "memory.coefficient", "nonzero"),
    ({"kernel": "power", "rule": "trapezoid"}, "memory.rule", "g(0)"),
    ({"kernel": "power", "kernel_tolerance": 0.0}, "memory.kernel_tolerance", "[1e-14, 1)"),
    ({"kernel": "constant", "kernel_tolerance": 1e-6}, "memory.kernel_tolerance", "not used"),
    ({"kernel": "exponential", "weights": [1.0], "times": [1.0], "exponent": 0.5}, "memory.exponent", "not used"),
    ({"kernel": "tabulated", "table": [[0, 1.0], [0.5, -1.0], [1, 1.0]]}, "memory.kernel_tolerance", "one sign"),
    ({"kernel": "constant", "rule": "trapezoid_extrapolated"}, "memory.rule", "time.order = 2's rule"),
])
def test_refusals_name_the_key(memory, key, says):
    with pytest.raises(ConfigError) as err:
        from_dict({"time": TIME, "memory": memory})
    assert err.value.key == key and says in err.value.allowed


def test_a_kernel_no_sum_meets_is_refused_in_one_line_that_says_why():
    """A coarse table of a fast exponential, read at lags between its rows: its kinks keep any sum of exponentials
    ~1e-4 away, so 1e-8 is refused, naming what was reached; a looser tolerance takes it."""
    rows = [[0.01 * i, 2.0 * 2.718281828459045 ** (-0.01 * i / 0.2)] for i in range(101)]
    with pytest.raises(ConfigError) as err:
        from_dict({"time": TIME, "memory": {"kernel": "tabulated", "table": rows}})
    exc = err.value
    assert exc.key == "memory.kernel_tolerance" and exc.value == 1e-8
    assert "no sum of at most 64 exponentials" in exc.allowed and "reached" in exc.allowed
    assert "\n" not in str(exc)
    cfg = from_dict({"time": TIME, "memory": {"kernel": "tabulated", "table": rows, "kernel_tolerance": 1e-3}})
    assert cfg.memory.fit(cfg.time.k, cfg.time.steps).error <= 1e-3
