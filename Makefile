# One install path for users, CI and the Docker image.
#   make demo   - install if needed, run the built-in default scene (Example 1)
#   make test   - install if needed: the layering check, the test suite (serial, then mpirun -n 2; the demos too), a wheel install
#   make test-portable - the numerics-sensitive tests again on netlib's reference BLAS and on another OpenBLAS kernel
#   make check-slurm - as root: a one-node Slurm runs docs/install/cluster.md's job script past its time limit
#   make docs   - install the docs extra if needed, build the site (docs/ -> docs/_build/html), warnings as errors
# Installing: Debian packages (dolfinx 0.5.2 stack) with apt-get, then a virtual
# environment made from Debian's interpreter with --system-site-packages, into
# which pip installs the project and its pip-only dependencies.

SHELL := /bin/bash
PY := .venv/bin/python
# PLOTS=0 leaves out the plotting stack (matplotlib, pyvista/VTK and the EGL it renders with off-screen):
# runs, studies and tests work without it; `solver plot` and the charts then say what is missing
PLOTS ?= 1
# libopenblas0-serial: an optimized BLAS/LAPACK for MUMPS, numpy and LAPACK (Debian's default libblas3 is netlib's
# reference BLAS, 8x slower on a 107k-dof MUMPS Cholesky, issue 30); the serial build, so that mpirun's ranks do not
# each start BLAS threads on the same cores. `python -m studies bench` names the BLAS it ran on.
APT_PACKAGES := python3-dolfinx-real python3-gmsh python3-h5py python3-tomlkit python3-scipy python3-venv python3-pip openmpi-bin \
	libopenblas0-serial
ifeq ($(PLOTS),1)
APT_PACKAGES += python3-matplotlib libegl1 libegl-mesa0
EXTRAS := dev,plots
else
EXTRAS := dev
endif
export OMPI_ALLOW_RUN_AS_ROOT := 1
export OMPI_ALLOW_RUN_AS_ROOT_CONFIRM := 1
export OMPI_MCA_rmaps_base_oversubscribe := 1
MPIRUN := mpirun -n 2
# the one-process leg of `make test` runs its test modules on this many pytest-xdist workers (each module on one worker)
TEST_WORKERS ?= 2
SUDO := $(shell [ "$$(id -u)" = 0 ] || echo sudo)

.PHONY: install system-packages demo test test-serial test-mpi test-portable check-slurm lint layers docs clean

install: .venv/.installed

system-packages:
	@missing=""; for p in $(APT_PACKAGES); do dpkg -s $$p >/dev/null 2>&1 || missing="$$missing $$p"; done; \
	if [ -n "$$missing" ]; then \
	  echo "installing Debian packages:$$missing"; \
	  $(SUDO) apt-get update -qq && DEBIAN_FRONTEND=noninteractive $(SUDO) apt-get install -y -qq --no-install-recommends $$missing; \
	fi
	@# OpenBLAS registers itself above netlib's BLAS; an alternative left pinned (manual) to netlib is set back to
	@# automatic (the highest priority), any other manual choice (MKL, BLIS) is kept
	@for alt in $$(ls /etc/alternatives | grep -E '^lib(blas|lapack)\.so\.3-'); do \
	  case "$$(readlink -f /etc/alternatives/$$alt)" in */blas/*|*/lapack/*) \
	    echo "BLAS: $$alt was netlib's reference library, now automatic (OpenBLAS)"; $(SUDO) update-alternatives --quiet --auto $$alt;; \
	  esac; \
	done

# pip is held to Debian's numpy (petsc4py is built against it) by a constraints file
.venv/.installed: pyproject.toml | system-packages
	@[ -x $(PY) ] || /usr/bin/python3 -m venv --system-site-packages .venv
	@/usr/bin/python3 -c 'import numpy; print("numpy==" + numpy.__version__)' > .venv/constraints.txt
	$(PY) -m pip install -q --upgrade pip
	@# the distribution is campo-solver; one installed under the name solver would also claim `import solver`
	@if $(PY) -m pip show -q solver >/dev/null 2>&1; then $(PY) -m pip uninstall -q -y solver; fi
	$(PY) -m pip install -q -c .venv/constraints.txt -e ".[$(EXTRAS)]"
	@touch $@

demo: install
	$(PY) -m solver run configs/example1.toml --output results/example1 --overwrite

test: install layers
	$(PY) -m pytest -q -n $(TEST_WORKERS) --dist loadscope
	$(MPIRUN) $(PY) -m pytest -q -m "not serial" -p no:cacheprovider
	bash scripts/check-install.sh

# The tests that compare round-off-level quantities (tight rel/abs bounds, eps, 1e-12), run serially twice more: once with
# netlib's reference BLAS/LAPACK (Debian's libblas3/liblapack3, always installed) first on the library path, once with
# OpenBLAS forced to another processor's kernels. A bound that holds only for one BLAS's summation order fails here.
# The OPENBLAS_* variables the machine sets are left as they are for the netlib pass (they do not touch netlib).
MULTIARCH := $(shell /usr/bin/python3 -c 'import sysconfig; print(sysconfig.get_config_var("MULTIARCH"))')
NETLIB_PATH := /usr/lib/$(MULTIARCH)/blas:/usr/lib/$(MULTIARCH)/lapack
# Sandybridge (AVX) differs from the generic kernels a virtual processor gets and reproduced an AMD-only failure;
# where the machine already forces Sandybridge, the generic SSE3 kernels (Prescott) are the other one
OTHER_CORETYPE ?= $(if $(filter Sandybridge SANDYBRIDGE,$(OPENBLAS_CORETYPE)),Prescott,Sandybridge)
PORTABLE_TESTS := tests/physics tests/laws tests/solvers/test_damage_step.py tests/solvers/test_mechanics.py tests/solvers/test_condensed.py \
	tests/solvers/test_near_nullspace.py tests/solvers/test_auto.py tests/solvers/test_linear.py tests/solvers/test_energy_newton.py \
	tests/solvers/test_damped_newton.py tests/run/test_stepper.py tests/run/test_adaptive.py tests/run/test_accuracy.py tests/io/test_checkpoint.py \
	tests/io/test_fields.py tests/mesh/test_geometry.py tests/mesh/test_adapt.py tests/test_api.py tests/test_examples.py \
	tests/test_paper_claims.py
PYTEST_PORTABLE := $(PY) -m pytest -q -p no:cacheprovider $(PORTABLE_TESTS)

test-portable: install
	@echo "== netlib reference BLAS/LAPACK first on the library path"
	LD_LIBRARY_PATH=$(NETLIB_PATH)$${LD_LIBRARY_PATH:+:$$LD_LIBRARY_PATH} $(PY) scripts/which_blas.py
	LD_LIBRARY_PATH=$(NETLIB_PATH)$${LD_LIBRARY_PATH:+:$$LD_LIBRARY_PATH} $(PYTEST_PORTABLE)
	@echo "== OpenBLAS with the $(OTHER_CORETYPE) kernels"
	OPENBLAS_CORETYPE=$(OTHER_CORETYPE) $(PY) scripts/which_blas.py
	OPENBLAS_CORETYPE=$(OTHER_CORETYPE) $(PYTEST_PORTABLE)

# the cluster route (docs/install/cluster.md) under a real one-node Slurm, stopped by its time limit, requeued,
# continued with --restart to the uninterrupted result; installs slurm-wlm and munge (apt-get), needs root
check-slurm: install
	$(SUDO) bash scripts/check-slurm.sh

# the layers of solver/ point one way (contracts in pyproject.toml's [tool.importlinter])
layers: install
	.venv/bin/lint-imports

lint: install
	$(PY) -m ruff check solver studies tests scripts

# the site: Sphinx + MyST + furo (the docs extra); the scene-key reference and the demos' pages are generated by docs/conf.py
.venv/.installed-docs: pyproject.toml | .venv/.installed
	$(PY) -m pip install -q -c .venv/constraints.txt -e ".[$(EXTRAS),docs]"
	@touch $@

docs: .venv/.installed-docs
	$(PY) -m sphinx -W --keep-going -E -q -b html docs docs/_build/html
	@echo "the site: docs/_build/html/index.html"

clean:
	rm -rf .venv results .pytest_cache docs/_build docs/demos
