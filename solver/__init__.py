"""Quasistatic frictionless normal-compliance contact of a damageable viscoelastic body
with long memory (Campo, Fernandez, Rodriguez-Aros 2008) on FEniCSx/dolfinx 0.5.2."""

__version__ = "0.1.0"


def _installed_version(name: str) -> str:
    """The version of installed distribution ``name``, read from the ``Version:`` line of its metadata file.

    The first ``NAME-*.dist-info`` (or ``.egg-info``) on sys.path, as importlib.metadata finds it, without importing
    importlib.metadata (with the email package it parses with: a tenth of a run's own imports, docs/benchmarks/
    performance.md); importlib.metadata answers where that file is not found."""
    import os
    import sys

    stem = name.replace("-", "_").lower() + "-"
    for entry in sys.path:
        try:
            found = [n for n in os.listdir(entry or ".") if n.lower().startswith(stem) and n.endswith((".dist-info", ".egg-info"))]
        except OSError:
            continue
        for folder in found:
            for meta in ("METADATA", "PKG-INFO"):
                try:
                    with open(os.path.join(entry or ".", folder, meta), encoding="utf-8") as f:
                        for line in f:
                            if line.startswith("Version:"):
                                return line.split(":", 1)[1].strip()
                            if not line.strip():
                                break  # the headers end at the first empty line
                except OSError:
                    continue
    from importlib import metadata

    return metadata.version(name)


def _versions_without_pkg_resources() -> None:
    """Import ufl and ffcx with their ``pkg_resources.get_distribution(NAME).version`` answered by
    :func:`_installed_version`.

    Both read their version so at import, and importing pkg_resources (it scans every installed distribution) was
    about half of a run's import time (docs/benchmarks/speed.md). The stand-in is in sys.modules only while
    they are imported; a later ``import pkg_resources`` (setuptools, when a form is compiled) gets the real one."""
    import sys
    import types

    if "pkg_resources" in sys.modules or "ufl" in sys.modules:
        return
    stand_in = types.ModuleType("pkg_resources")
    stand_in.get_distribution = lambda name: types.SimpleNamespace(version=_installed_version(name))
    sys.modules["pkg_resources"] = stand_in
    try:
        import ffcx  # noqa: F401
        import ufl  # noqa: F401
    finally:
        if sys.modules.get("pkg_resources") is stand_in:
            del sys.modules["pkg_resources"]

_versions_without_pkg_resources()
