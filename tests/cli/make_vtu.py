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
  make_vtu.py cells OUT.vtu    a cube of side 2.5 as 5³ sub-cubes, each quadratic cells of one
                               kind in turn: a VTK_TRIQUADRATIC_HEXAHEDRON, a
                               VTK_QUADRATIC_HEXAHEDRON, 6 VTK_QUADRATIC_TETRA, 2 VTK_QUADRATIC_WEDGE,
                               6 VTK_QUADRATIC_PYRAMID (only where the sub-cube misses the sphere
                               r = 0.7: the 13-node space does not hold |x|²), nodes at VTK's own
                               parametric coordinates, r = |x|²
  make_vtu.py triangle OUT.vtu one VTK_TRIANGLE (not a volume cell) beside one Lagrange hexahedron
  make_vtu.py tet15 OUT.vtu    one 15-node VTK_LAGRANGE_TETRAHEDRON (VTK's bubble-enriched P2)
  make_vtu.py degrees OUT.vtu  one order-2 Lagrange hexahedron whose HigherOrderDegrees say 2, 2, 3
  make_vtu.py badpoint OUT.vtu two order-2 Lagrange hexahedra, the second naming point 1000 of 54
                               (VTK writes and reads such a file without a word)
  make_vtu.py pieces OUT.pvtu  the sphere's cells as a .pvtu record over two .vtu pieces
  make_vtu.py ghosts OUT.pvtu  the sphere's cells over two pieces as a parallel writer with a
                               ghost layer leaves them (dolfinx): the cells of z < 0 and of z >= 0,
                               each piece also holding the other's layer next to z = 0, flagged
                               DUPLICATECELL in vtkGhostType; the cells kept are the sphere's, in
                               its order
  make_vtu.py zeroblock OUT.vtu the sphere, zlib-compressed (base64 appended data, 32-bit
                               headers), with the block size in the compression header of its
                               array "r" set to 0: VTK 9.1's reader divides by it (SIGFPE on
                               x86-64)
"""
import base64
import re
import struct
import sys

from vtkmodules.vtkCommonCore import vtkDoubleArray, vtkIdList, vtkPoints, vtkUnsignedCharArray
from vtkmodules.vtkCommonDataModel import (VTK_HEXAHEDRON, VTK_LAGRANGE_HEXAHEDRON,
                                           VTK_LAGRANGE_TETRAHEDRON, VTK_QUADRATIC_HEXAHEDRON,
                                           VTK_QUADRATIC_PYRAMID, VTK_QUADRATIC_TETRA,
                                           VTK_QUADRATIC_WEDGE, VTK_TRIANGLE,
                                           VTK_TRIQUADRATIC_HEXAHEDRON, vtkHexahedron,
                                           vtkLagrangeHexahedron, vtkPyramid,
                                           vtkQuadraticHexahedron, vtkQuadraticPyramid,
                                           vtkQuadraticTetra, vtkQuadraticWedge, vtkTetra,
                                           vtkTriQuadraticHexahedron, vtkUnstructuredGrid,
                                           vtkWedge)
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


def mixed_cells(grid, points, values, field):
    """The sub-cubes of the 'cells' kind, each split into quadratic cells of one type."""
    n, lo = 5, -1.25
    h = 2.5 / n
    linear = {VTK_TRIQUADRATIC_HEXAHEDRON: vtkHexahedron, VTK_QUADRATIC_HEXAHEDRON: vtkHexahedron,
              VTK_QUADRATIC_TETRA: vtkTetra, VTK_QUADRATIC_WEDGE: vtkWedge,
              VTK_QUADRATIC_PYRAMID: vtkPyramid}
    quadratic = {VTK_TRIQUADRATIC_HEXAHEDRON: vtkTriQuadraticHexahedron,
                 VTK_QUADRATIC_HEXAHEDRON: vtkQuadraticHexahedron,
                 VTK_QUADRATIC_TETRA: vtkQuadraticTetra, VTK_QUADRATIC_WEDGE: vtkQuadraticWedge,
                 VTK_QUADRATIC_PYRAMID: vtkQuadraticPyramid}
    for k in range(n):
        for j in range(n):
            for i in range(n):
                o = [lo + h * i, lo + h * j, lo + h * k]
                c = [[o[0] + h * a, o[1] + h * b, o[2] + h * d] for a, b, d in
                     [(0, 0, 0), (1, 0, 0), (1, 1, 0), (0, 1, 0), (0, 0, 1), (1, 0, 1), (1, 1, 1),
                      (0, 1, 1)]]
                centre = [x + 0.5 * h for x in o]
                near = max(abs(x) for x in centre) - 0.5 * h  # the sub-cube's nearest |x_i|
                misses = sum(max(0.0, abs(x) - 0.5 * h) ** 2 for x in centre) > 0.5
                kind = (i + 2 * j + 3 * k) % 4
                if misses and (i + j + k) % 2 == 0:
                    kind = 4
                if kind == 0:
                    parts = [(VTK_TRIQUADRATIC_HEXAHEDRON, c)]
                elif kind == 1:
                    parts = [(VTK_QUADRATIC_HEXAHEDRON, c)]
                elif kind == 2:
                    parts = [(VTK_QUADRATIC_TETRA, [c[a] for a in t]) for t in
                             [(0, 1, 2, 6), (0, 2, 3, 6), (0, 3, 7, 6), (0, 7, 4, 6), (0, 4, 5, 6),
                              (0, 5, 1, 6)]]
                elif kind == 3:
                    parts = [(VTK_QUADRATIC_WEDGE, [c[a] for a in w]) for w in
                             [(0, 1, 2, 4, 5, 6), (0, 2, 3, 4, 6, 7)]]
                else:
                    parts = [(VTK_QUADRATIC_PYRAMID, [c[a] for a in f] + [centre]) for f in
                             [(0, 3, 2, 1), (4, 5, 6, 7), (0, 1, 5, 4), (1, 2, 6, 5), (2, 3, 7, 6),
                              (3, 0, 4, 7)]]
                for cell_type, corners in parts:
                    cell = quadratic[cell_type]()
                    pc = cell.GetParametricCoords()
                    count = cell.GetNumberOfPoints() or len(pc) // 3
                    shape = linear[cell_type]()
                    weights = [0.0] * shape.GetNumberOfPoints()
                    ids = []
                    for m in range(len(pc) // 3):
                        shape.InterpolateFunctions(pc[3 * m:3 * m + 3], weights)
                        x = [sum(w * v[a] for w, v in zip(weights, corners)) for a in range(3)]
                        ids.append(points.InsertNextPoint(x))
                        values.InsertNextValue(field(x))
                    grid.InsertNextCell(cell_type, len(ids), ids)


def main():
    kind, out = sys.argv[1], sys.argv[2]
    grid, points = vtkUnstructuredGrid(), vtkPoints()
    values = vtkDoubleArray()
    values.SetName("r")
    r2 = lambda x: x[0] ** 2 + x[1] ** 2 + x[2] ** 2
    if kind in ("sphere", "ascii", "raw", "timesteps", "pieces", "zeroblock", "ghosts"):
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
    elif kind == "cells":
        mixed_cells(grid, points, values, r2)
    elif kind == "triangle":
        lagrange_cell(grid, points, values, [0, 0, 0], 1, 2, r2)
        ids = [points.InsertNextPoint(x) for x in [(2, 0, 0), (3, 0, 0), (2, 1, 0)]]
        for _ in ids:
            values.InsertNextValue(1.0)
        grid.InsertNextCell(VTK_TRIANGLE, 3, ids)
    elif kind == "tet15":
        ids = [points.InsertNextPoint((0.1 * k, 0.01 * k * k, 0.001 * k ** 3)) for k in range(15)]
        for _ in ids:
            values.InsertNextValue(1.0)
        grid.InsertNextCell(VTK_LAGRANGE_TETRAHEDRON, 15, ids)
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
    if kind == "ghosts":
        write_ghost_pieces(grid, out)
        return
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


def write_ghost_pieces(grid, out):
    """The cells of `grid` (the sphere's: 4³ Lagrange hexahedra in rows of z, then 2 linear ones)
    as two pieces split at z = 0, each with the other's layer of cells beside z = 0 as ghosts,
    and the .pvtu record naming them."""
    lo = [grid.GetCell(c).GetBounds()[4] for c in range(grid.GetNumberOfCells())]
    own = [[c for c in range(len(lo)) if lo[c] < -1e-9], [c for c in range(len(lo)) if lo[c] >= -1e-9]]
    layer = [[c for c in own[1] if abs(lo[c]) < 1e-9], [c for c in own[0] if abs(lo[c] + 0.5) < 1e-9]]
    base = out[:-len(".pvtu")]
    names = []
    for piece in range(2):
        part = vtkUnstructuredGrid()
        part.SetPoints(grid.GetPoints())
        part.GetPointData().ShallowCopy(grid.GetPointData())
        ghosts = vtkUnsignedCharArray()
        ghosts.SetName("vtkGhostType")
        # Piece 1 lists its ghosts first, piece 0 last: either way they are skipped.
        cells = layer[1] + own[1] if piece == 1 else own[0] + layer[0]
        for c in cells:
            ids = vtkIdList()
            grid.GetCellPoints(c, ids)
            part.InsertNextCell(grid.GetCellType(c), ids)
            ghosts.InsertNextValue(0 if c in own[piece] else 1)  # 1: DUPLICATECELL
        part.GetCellData().AddArray(ghosts)
        name = f"{base}_{piece}.vtu"
        writer = vtkXMLUnstructuredGridWriter()
        writer.SetFileName(name)
        writer.SetInputData(part)
        if not writer.Write():
            sys.exit("make_vtu.py: VTK could not write " + name)
        names.append(name.rsplit("/", 1)[-1])
    vtk_type = {"float": "Float32", "double": "Float64"}
    data = grid.GetPointData()
    arrays = "".join(f'<PDataArray type="{vtk_type[data.GetArray(a).GetDataTypeAsString()]}" '
                     f'Name="{data.GetArrayName(a)}" '
                     f'NumberOfComponents="{data.GetArray(a).GetNumberOfComponents()}"/>'
                     for a in range(data.GetNumberOfArrays()))
    point_type = vtk_type[grid.GetPoints().GetData().GetDataTypeAsString()]
    with open(out, "w") as f:
        f.write('<?xml version="1.0"?>\n'
                '<VTKFile type="PUnstructuredGrid" version="0.1" byte_order="LittleEndian">\n'
                '<PUnstructuredGrid GhostLevel="1">\n'
                f'<PPointData>{arrays}</PPointData>\n'
                '<PCellData><PDataArray type="UInt8" Name="vtkGhostType"/></PCellData>\n'
                f'<PPoints><PDataArray type="{point_type}" Name="Points" '
                'NumberOfComponents="3"/></PPoints>\n'
                + "".join(f'<Piece Source="{n}"/>\n' for n in names) +
                '</PUnstructuredGrid>\n</VTKFile>\n')


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
