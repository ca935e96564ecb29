"""Meshes and their named boundary parts: building (geometry), refining (adapt), carrying fields between meshes (transfer).

Layer 2 of the house: imports solver.config and solver.errors only.
"""
