"""The model's constitutive laws as pure mathematics: each law one object with its parameters, their validation,
its UFL form and its fast (numpy) form side by side (docs/model.md §1).

This layer knows neither meshes nor dolfinx: :mod:`solver.config` asks a law to validate a scene's values, and
:mod:`solver.physics` asks it for the forms it assembles or evaluates at points. ``tests/laws`` checks that each
law's two forms agree at random points.
"""
