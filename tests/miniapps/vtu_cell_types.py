#!/usr/bin/python3
"""vtu_cell_types.py FILE.(p)vtu TYPES [FIELD]: VTK reads the file's cells as exactly TYPES (VTK
cell type: count, comma separated, e.g. "12:256,10:512"), and, where FIELD is given, that point
field is |x|² at the points within 1e-6. Exit status 0 when so; prints what it read."""
import collections
import sys

import numpy as np
from vtkmodules.util.numpy_support import vtk_to_numpy
from vtkmodules.vtkIOXML import vtkXMLPUnstructuredGridReader, vtkXMLUnstructuredGridReader

path, expected = sys.argv[1], sys.argv[2]
field = sys.argv[3] if len(sys.argv) > 3 else None
want = {int(t): int(n) for t, n in (item.split(":") for item in expected.split(","))}
reader = vtkXMLPUnstructuredGridReader() if path.endswith(".pvtu") else vtkXMLUnstructuredGridReader()
reader.SetFileName(path)
reader.Update()
grid = reader.GetOutput()
types = collections.Counter(grid.GetCellType(c) for c in range(grid.GetNumberOfCells()))
ok = dict(types) == want
text = f"{path}: cells by VTK type {dict(types)} (expected {want})"
if field is not None:
    array = grid.GetPointData().GetArray(field)
    if array is None:
        print(f"{text}; no point field '{field}'")
        sys.exit(1)
    x = vtk_to_numpy(grid.GetPoints().GetData()).astype(float)
    error = np.abs(vtk_to_numpy(array) - (x * x).sum(axis=1)).max()
    text += f", max |{field} - |x|²| {error:.1e}"
    ok = ok and error < 1e-6
print(text)
sys.exit(0 if ok else 1)
