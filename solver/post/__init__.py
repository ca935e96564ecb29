"""Reading results back and drawing them: the series and CSV readers, matplotlib/pyvista pictures, ParaView.

Layer 7: imports solver.io and below. The pictures run without dolfinx in the process (VTK and dolfinx's C++ do
not mix in one process).
"""
