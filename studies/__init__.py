"""The studies and benchmarks behind the project's published figures (not part of the installed package).

They import :mod:`solver` as any user would and read their data (``configs/``, ``benchmarks/``)
from the repository they live in: run them from a checkout, ``python -m studies --help``.
"""

from pathlib import Path

REPO = Path(__file__).resolve().parent.parent  # the checkout these studies belong to
CONFIGS = REPO / "configs"
RESULTS = REPO / "benchmarks" / "results"
