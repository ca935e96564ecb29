#!/usr/bin/env bash
# The package as a user gets it: build the wheel, install it (not editable) into a fresh venv that sees
# Debian's dolfinx stack, and run a scene from a directory outside the checkout. Run by `make test`.
# The distribution is campo-solver (wheel campo_solver-*.whl), the import name solver. The wheel is built in an
# isolated environment with the setuptools pyproject.toml asks for, as `make install` builds the editable one.
set -euo pipefail
repo="$(cd "$(dirname "$0")/.." && pwd)"
work="$(mktemp -d)"
trap 'rm -rf "$work"' EXIT
cd "$repo"
.venv/bin/python -m pip wheel -q --no-deps -w "$work/dist" . 2>&1 | grep -v "^WARNING: Location" || true
/usr/bin/python3 -m venv --system-site-packages "$work/venv"
"$work/venv/bin/python" -m pip install -q -c .venv/constraints.txt "$work"/dist/campo_solver-*.whl 2>&1 | grep -v "^WARNING: Location" || true
cd "$work"  # not the checkout: `import solver` must find the installed copy
name="$("$work/venv/bin/python" -c 'from importlib.metadata import distribution as d; print(d("campo-solver").metadata["Name"])')"
[ "$name" = campo-solver ] || { echo "check-install: the installed distribution is '$name', not campo-solver" >&2; exit 1; }
where="$("$work/venv/bin/python" -c 'import solver, solver.config, solver.io.xdmf; print(solver.__file__)')"
case "$where" in "$work"/venv/*) ;; *) echo "check-install: solver imported from $where, not the fresh venv" >&2; exit 1 ;; esac
"$work/venv/bin/campo-solver" check "$repo/configs/example1.toml" >/dev/null  # the console script
"$work/venv/bin/python" -m solver run "$repo/configs/example1.toml" --set mesh.nx=4 --set mesh.ny=4 --set time.k=0.25 \
    --output "$work/out" --no-progress
test -s "$work/out/timeseries.csv" && test -s "$work/out/solution.xdmf"
echo "check-install: wheel installed in a fresh venv and ran example1 from $work: ok"
