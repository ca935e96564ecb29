"""solver/__init__.py: ufl and ffcx imported with their versions read from the installed metadata files."""

import subprocess
import sys
from importlib import metadata

import pytest

import solver

pytestmark = pytest.mark.serial  # no MPI here: on 2 ranks each would run the same checks again


@pytest.mark.parametrize("name", ["fenics-ufl", "fenics-ffcx", "numpy", "mpi4py"])
def test_installed_version_is_importlib_metadata_s(name):
    assert solver._installed_version(name) == metadata.version(name)


def test_an_unknown_distribution_is_refused_as_importlib_metadata_refuses_it():
    with pytest.raises(metadata.PackageNotFoundError):
        solver._installed_version("no-such-distribution-campo")


def test_import_leaves_out_pkg_resources_and_importlib_metadata_with_the_versions_right():
    code = ("import sys, solver, ufl, ffcx; print('pkg_resources' in sys.modules, 'importlib.metadata' in sys.modules, "
            "ufl.__version__, ffcx.__version__)")
    out = subprocess.run([sys.executable, "-c", code], check=True, capture_output=True, text=True).stdout.split()
    assert out == ["False", "False", metadata.version("fenics-ufl"), metadata.version("fenics-ffcx")]
