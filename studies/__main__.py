"""``python -m studies {bench,convergence,study,contact} ...`` from the repository's root."""

from __future__ import annotations

import sys

USAGE = """usage: python -m studies {bench,convergence,study,contact} ...

  bench        time the loop of Example 1 and its parts (bench --help; bench --scaling: the 3-D scaling benchmark)
  convergence  the paper's Table 1: errors against a fine reference (convergence --help)
  contact      a 10^5-row gap table against a constant gap (contact bench); the p(s) figure (contact figure)
  study        stability map, work-precision, orders, tolerance, estimator, Table 1 variants (study --help)
"""


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    if not argv or argv[0] in ("-h", "--help"):
        print(USAGE, end="")
        return 0 if argv else 2
    from solver.run import formcache

    formcache.install()  # studies build many models per process: keep compiled forms in memory
    command, rest = argv[0], argv[1:]
    if command == "bench":
        from studies.bench import main as run
    elif command == "convergence":
        from studies.convergence import main as run
    elif command == "contact":
        from studies.contact import main as run
    elif command == "study":
        from studies.study import main as run
    else:
        print(f"error: unknown study command {command!r}\n{USAGE}", file=sys.stderr, end="")
        return 2
    return run(rest)


if __name__ == "__main__":
    sys.exit(main())
