"""solver/config/accuracy.py: the [accuracy] table's checks."""

import pytest
from conftest import ROOT

from solver.config import load
from solver.errors import ConfigError

pytestmark = pytest.mark.serial  # no MPI in this layer: on 2 ranks each would run the same checks again

SCENE = ROOT / "configs/example1.toml"


@pytest.mark.parametrize("bad", ["nan", "0", "1", "1.5", "-1e-3", "inf", '"small"'])
def test_bad_tolerances_are_refused(bad):
    with pytest.raises(ConfigError) as err:
        load(SCENE, [f"accuracy.tolerance={bad}"])
    assert err.value.key == "accuracy.tolerance"


@pytest.mark.parametrize("key,bad", [("space_share", "0"), ("space_share", "1"), ("theta", "1.5"), ("max_dofs", "0"),
                                     ("degrees", "[]"), ("degrees", "[3]"), ("simplify", "1"), ("simplify", "\"yes\""),
                                     ("time", "\"variable\""), ("time", "true")])
def test_bad_settings_are_refused(key, bad):
    with pytest.raises(ConfigError) as err:
        load(SCENE, [f"accuracy.{key}={bad}"])
    assert err.value.key == f"accuracy.{key}"


def test_a_tolerance_on_a_3d_scene_is_accepted():
    assert load(ROOT / "configs/example1_3d.toml", ["accuracy.tolerance=1e-2"]).accuracy.tolerance == 1e-2


def test_simplify_is_off_unless_asked():
    assert load(SCENE).accuracy.simplify is False
    assert load(SCENE, ["accuracy.simplify=true"]).accuracy.simplify is True


def test_the_step_is_uniform_unless_the_controller_is_asked_for():
    assert load(SCENE).accuracy.time == "uniform"
    assert load(SCENE, ['accuracy.time="adaptive"']).accuracy.time == "adaptive"
