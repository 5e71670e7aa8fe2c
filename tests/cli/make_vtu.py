#!/usr/bin/python3
"""Writes test VTU files with VTK itself (tests/cli/vtu_test.sh):

  make_vtu.py sphere OUT.vtu   n³ order-2 Lagrange hexahedra over [-1, 1]³ carrying r = |x|²
                               (exact: degree 2 per axis on straight cells), plus linear
                               VTK_HEXAHEDRON cells beyond x = 1 (r > 1 there: no surface), as
                               mixed-order files have them; a second point array "vec" with 3
                               components, and "h" = x + 2y (exact on every cell: to colour by).
  make_vtu.py ascii OUT.vtu    the sphere, uncompressed ASCII
  make_vtu.py raw OUT.vtu      the sphere, uncompressed raw appended data, in two pieces (a
                               .vtu's pieces: VTK allocates the first's arrays for all)
  make_vtu.py timesteps OUT.vtu the sphere at two time steps (raw appended, uncompressed): r at
                               step 0, 1.5 r at step 1, and a cell array "q" at both, each array
                               written once per step under its name (VTK reads step 0)
  make_vtu.py tetra OUT.vtu    one VTK_TETRA beside one Lagrange hexahedron
  make_vtu.py degrees OUT.vtu  one order-2 Lagrange hexahedron whose HigherOrderDegrees say 2, 2, 3
  make_vtu.py badpoint OUT.vtu two order-2 Lagrange hexahedra, the second naming point 1000 of 54
                               (VTK writes and reads such a file without a word)
  make_vtu.py pieces OUT.pvtu  the sphere's cells as a .pvtu record over two .vtu pieces
  make_vtu.py zeroblock OUT.vtu the sphere, zlib-compressed (base64 appended data, 32-bit
                               headers), with the block size in the compression header of its
                               array "r" set to 0: VTK 9.1's reader divides by it (SIGFPE on
                               x86-64)
"""
import base64
import re
import struct
import sys

from vtkmodules.vtkCommonCore import vtkDoubleArray, vtkIdList, vtkPoints
from vtkmodules.vtkCommonDataModel import (VTK_HEXAHEDRON, VTK_LAGRANGE_HEXAHEDRON, VTK_TETRA,
                                           vtkLagrangeHexahedron, vtkUnstructuredGrid)
from vtkmodules.vtkIOParallelXML import vtkXMLPUnstructuredGridWriter
from vtkmodules.vtkIOXML import vtkXMLUnstructuredGridWriter


def lagrange_cell(grid, points, values, lo, size, order, field):
    """Adds one Lagrange hexahedron of `order` over the box lo + [0, size]³."""
    m = order + 1
    ids = [0] * m ** 3
    for k in range(m):
        for j in range(m):
            for i in range(m):
                x = [lo[0] + size * i / order, lo[1] + size * j / order, lo[2] + size * k / order]
                ids[vtkLagrangeHexahedron.PointIndexFromIJK(i, j, k, [order] * 3)] = \
                    points.InsertNextPoint(x)
                values.InsertNextValue(field(x))
    return grid.InsertNextCell(VTK_LAGRANGE_HEXAHEDRON, len(ids), ids)


def main():
    kind, out = sys.argv[1], sys.argv[2]
    grid, points = vtkUnstructuredGrid(), vtkPoints()
    values = vtkDoubleArray()
    values.SetName("r")
    r2 = lambda x: x[0] ** 2 + x[1] ** 2 + x[2] ** 2
    if kind in ("sphere", "ascii", "raw", "timesteps", "pieces", "zeroblock"):
        n = 4
        for k in range(n):
            for j in range(n):
                for i in range(n):
                    lagrange_cell(grid, points, values, [-1 + 2 * i / n, -1 + 2 * j / n,
                                                         -1 + 2 * k / n], 2 / n, 2, r2)
        for k in range(2):  # linear hexahedra in VTK's corner order
            corners = [(1.0, -0.5, -0.5 + 0.5 * k), (1.5, -0.5, -0.5 + 0.5 * k),
                       (1.5, 0.0, -0.5 + 0.5 * k), (1.0, 0.0, -0.5 + 0.5 * k)]
            corners += [(x, y, z + 0.5) for (x, y, z) in corners]
            ids = []
            for c in corners:
                ids.append(points.InsertNextPoint(c))
                values.InsertNextValue(r2(c))
            grid.InsertNextCell(VTK_HEXAHEDRON, 8, ids)
        vec = vtkDoubleArray()
        vec.SetName("vec")
        vec.SetNumberOfComponents(3)
        for p in range(points.GetNumberOfPoints()):
            vec.InsertNextTuple(points.GetPoint(p))
        grid.GetPointData().AddArray(vec)
        h = vtkDoubleArray()
        h.SetName("h")
        for p in range(points.GetNumberOfPoints()):
            x = points.GetPoint(p)
            h.InsertNextValue(x[0] + 2 * x[1])
        grid.GetPointData().AddArray(h)
    elif kind == "tetra":
        lagrange_cell(grid, points, values, [0, 0, 0], 1, 2, r2)
        ids = [points.InsertNextPoint(x) for x in [(2, 0, 0), (3, 0, 0), (2, 1, 0), (2, 0, 1)]]
        for _ in ids:
            values.InsertNextValue(1.0)
        grid.InsertNextCell(VTK_TETRA, 4, ids)
    elif kind == "degrees":
        lagrange_cell(grid, points, values, [0, 0, 0], 1, 2, r2)
        degrees = vtkDoubleArray()
        degrees.SetName("HigherOrderDegrees")
        degrees.SetNumberOfComponents(3)
        degrees.InsertNextTuple((2, 2, 3))
        grid.GetCellData().AddArray(degrees)
    elif kind == "badpoint":
        lagrange_cell(grid, points, values, [0, 0, 0], 1, 2, r2)
        second = lagrange_cell(grid, points, values, [1, 0, 0], 1, 2, r2)
        ids = vtkIdList()
        grid.GetCellPoints(second, ids)
        ids.SetId(5, 1000)
        grid.ReplaceCell(second, ids.GetNumberOfIds(), [ids.GetId(k) for k in range(ids.GetNumberOfIds())])
    else:
        sys.exit(f"make_vtu.py: unknown kind {kind}")
    grid.SetPoints(points)
    grid.GetPointData().AddArray(values)
    if kind == "pieces":
        writer = vtkXMLPUnstructuredGridWriter()
        writer.SetNumberOfPieces(2)
        writer.SetStartPiece(0)
        writer.SetEndPiece(1)
    else:
        writer = vtkXMLUnstructuredGridWriter()
    if kind == "ascii":
        writer.SetCompressorTypeToNone()
        writer.SetDataModeToAscii()
    if kind in ("raw", "timesteps"):
        writer.SetCompressorTypeToNone()
        writer.SetDataModeToAppended()
        writer.EncodeAppendedDataOff()
    if kind == "raw":
        writer.SetNumberOfPieces(2)
    if kind == "timesteps":
        q = vtkDoubleArray()
        q.SetName("q")
        q.SetNumberOfTuples(grid.GetNumberOfCells())
        q.Fill(1.0)
        grid.GetCellData().AddArray(q)
        writer.SetFileName(out)
        writer.SetInputData(grid)
        writer.SetNumberOfTimeSteps(2)
        writer.Start()
        writer.WriteNextTime(0.0)
        for p in range(values.GetNumberOfTuples()):
            values.SetValue(p, 1.5 * values.GetValue(p))
        values.Modified()
        q.Fill(2.0)
        q.Modified()
        writer.WriteNextTime(1.0)
        writer.Stop()
        return
    if kind == "zeroblock":
        writer.SetCompressorTypeToZLib()
        writer.SetDataModeToAppended()
        writer.EncodeAppendedDataOn()
        writer.SetHeaderTypeToUInt32()
    writer.SetFileName(out)
    writer.SetInputData(grid)
    if not writer.Write():
        sys.exit("make_vtu.py: VTK could not write " + out)
    if kind == "zeroblock":
        zero_block_size(out, b"r")


def zero_block_size(path, name):
    """Sets the uncompressed block size in the compression header of array `name` to 0.

    Appended base64 data: after '_', each array at its offset, the header (UInt32: blocks, block
    size, last block's size, the blocks' compressed sizes) base64-encoded on its own."""
    data = open(path, "rb").read()
    start = data.index(b"_", data.index(b"<AppendedData")) + 1
    tag = re.search(rb'<DataArray[^>]*Name="' + name + rb'"[^>]*offset="(\d+)"', data)
    at = start + int(tag.group(1))
    blocks = struct.unpack("<I", base64.b64decode(data[at:at + 8])[:4])[0]
    size = (3 + blocks) * 4
    length = 4 * ((size + 2) // 3)
    header = list(struct.unpack(f"<{3 + blocks}I", base64.b64decode(data[at:at + length])[:size]))
    header[1] = 0
    encoded = base64.b64encode(struct.pack(f"<{3 + blocks}I", *header))
    assert len(encoded) == length
    open(path, "wb").write(data[:at] + encoded + data[at + length:])


main()
