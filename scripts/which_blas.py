"""Print the BLAS and LAPACK libraries this process loads (numpy and PETSc), and OpenBLAS's kernel core type.

`make test-portable` runs it before each pass so that its log shows the pass ran on the library it meant to.
"""

import ctypes

import numpy  # noqa: F401  (loads numpy's BLAS)
import petsc4py

petsc4py.init([])
from petsc4py import PETSc  # noqa: E402,F401  (loads PETSc's BLAS/LAPACK, MUMPS)


def loaded_blas() -> list[str]:
    """The shared libraries named like a BLAS or LAPACK mapped into this process."""
    with open("/proc/self/maps") as maps:
        paths = {line.split()[-1] for line in maps if "/" in line}
    return sorted(p for p in paths if "blas" in p.rsplit("/", 1)[-1] or "lapack" in p.rsplit("/", 1)[-1])


def main() -> None:
    libraries = loaded_blas()
    for path in libraries:
        print("BLAS/LAPACK:", path)
    for path in libraries:
        if "libopenblas" in path:
            lib = ctypes.CDLL(path)
            lib.openblas_get_corename.restype = ctypes.c_char_p
            print("OpenBLAS core:", lib.openblas_get_corename().decode())
            break
    else:
        print("OpenBLAS core: none (OpenBLAS not loaded)")


if __name__ == "__main__":
    main()
