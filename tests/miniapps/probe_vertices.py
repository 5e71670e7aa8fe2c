#!/usr/bin/python3
"""probe_vertices.py FILE.(p)vtu FIELD ISOVALUE MESH.ply: every vertex of the binary PLY (x, y, z
floats first, as ldimesh writes it) lies in a cell of the VTU file, and VTK's own interpolation
of FIELD there (vtkProbeFilter, each cell's shape functions) is ISOVALUE within 1e-6. The cells
are found by a cell locator: deal.II's files give every cell its own copies of its points, and
the probe's default search, from the nearest point, misses the cells of the other copies. Exit
status 0 when so; prints the figures."""
import struct
import sys

import numpy as np
from vtkmodules.util.numpy_support import numpy_to_vtk, vtk_to_numpy
from vtkmodules.vtkCommonCore import vtkPoints
from vtkmodules.vtkCommonDataModel import vtkCellLocatorStrategy, vtkPolyData, vtkStaticCellLocator
from vtkmodules.vtkFiltersCore import vtkProbeFilter
from vtkmodules.vtkIOXML import vtkXMLPUnstructuredGridReader, vtkXMLUnstructuredGridReader

path, field, iso, ply = sys.argv[1], sys.argv[2], float(sys.argv[3]), sys.argv[4]
reader = vtkXMLPUnstructuredGridReader() if path.endswith(".pvtu") else vtkXMLUnstructuredGridReader()
reader.SetFileName(path)
reader.Update()
data = open(ply, "rb").read()
header, body = data.split(b"end_header\n", 1)
n = int(next(l for l in header.decode().splitlines() if l.startswith("element vertex")).split()[2])
x = np.array([struct.unpack_from("<3f", body, 24 * v) for v in range(n)], dtype=float)
points = vtkPoints()
points.SetData(numpy_to_vtk(x, deep=True))
cloud = vtkPolyData()
cloud.SetPoints(points)
strategy = vtkCellLocatorStrategy()
strategy.SetCellLocator(vtkStaticCellLocator())
probe = vtkProbeFilter()
probe.SetInputData(cloud)
probe.SetSourceData(reader.GetOutput())
probe.SetFindCellStrategy(strategy)
probe.Update()
out = probe.GetOutput()
found = vtk_to_numpy(out.GetPointData().GetArray(probe.GetValidPointMaskArrayName())).astype(bool)
u = vtk_to_numpy(out.GetPointData().GetArray(field)).astype(float)
worst = np.abs(u[found] - iso).max() if found.any() else float("inf")
print(f"{ply}: {n} vertices, {n - found.sum()} outside every cell of {path}; largest "
      f"|{field} - {iso}| by VTK's interpolation {worst:.1e}")
sys.exit(0 if n > 1000 and found.all() and worst < 1e-6 else 1)
