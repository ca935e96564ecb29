"""Writing a run to a directory: the XDMF series, the fields written, the CSV time series, checkpoints and
restart (results.run drives run.stepper.levels and writes what it yields).

Layer 6: imports solver.run and below.
"""
