"""Quasistatic frictionless normal-compliance contact of a damageable viscoelastic body
with long memory (Campo, Fernandez, Rodriguez-Aros 2008) on FEniCSx/dolfinx 0.5.2."""

__version__ = "0.1.0"
