"""matplotlib for the studies' charts, or None where the plotting extra is not installed (a slim image)."""

from __future__ import annotations

import importlib.util


def pyplot(what: str):
    """``matplotlib.pyplot`` on the off-screen backend; None (and a note) if matplotlib is missing, in which
    case the study writes its tables and skips ``what``."""
    try:
        found = importlib.util.find_spec("matplotlib") is not None
    except ValueError:  # already imported as None (how a test hides a module)
        found = False
    if not found:
        print(f"{what} skipped: matplotlib is not installed (make install PLOTS=1)", flush=True)
        return None
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt
