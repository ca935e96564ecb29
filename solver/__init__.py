"""Quasistatic frictionless normal-compliance contact of a damageable viscoelastic body
with long memory (Campo, Fernandez, Rodriguez-Aros 2008) on FEniCSx/dolfinx 0.5.2."""

__version__ = "0.1.0"


def _versions_without_pkg_resources() -> None:
    """Import ufl and ffcx with their ``pkg_resources.get_distribution(NAME).version`` answered by importlib.metadata.

    Both read their version so at import, and importing pkg_resources (it scans every installed distribution) was
    about half of a run's import time (docs/benchmarks/speed.md). The stand-in is in sys.modules only while
    they are imported; a later ``import pkg_resources`` (setuptools, when a form is compiled) gets the real one."""
    import sys
    import types
    from importlib import metadata

    if "pkg_resources" in sys.modules or "ufl" in sys.modules:
        return
    stand_in = types.ModuleType("pkg_resources")
    stand_in.get_distribution = lambda name: types.SimpleNamespace(version=metadata.version(name))
    sys.modules["pkg_resources"] = stand_in
    try:
        import ffcx  # noqa: F401
        import ufl  # noqa: F401
    finally:
        if sys.modules.get("pkg_resources") is stand_in:
            del sys.modules["pkg_resources"]


_versions_without_pkg_resources()
