#!/usr/bin/python3
"""P2/P3 tetrahedra and P2 wedges: our exact meshes beside VTK's contour of the same file and
tessellate-then-contour, at equal triangles and at equal accuracy (issue 58 (b)), as Markdown.

Each mesh is a cube [-1, 1]³ of n³ sub-cubes split into cells of one type — VTK_QUADRATIC_TETRA
(P2, 6 Kuhn tetrahedra per sub-cube), VTK_LAGRANGE_TETRAHEDRON of order 3 (P3), or
VTK_QUADRATIC_WEDGE (15 nodes, 2 wedges per sub-cube; VTK 9.1's vtkTessellatorFilter
tessellates no wedge, so that row is absent for them) — its nodes at VTK's own
parametric coordinates, written by VTK's writer, with f = |x|² at the nodes: the cells hold f
exactly, so the file's isosurface f = 0.49 is the sphere of radius 0.7 and every mesh can be
measured against it exactly. Errors are | |x| − 0.7 | at the vertices and at 10 points inside
each triangle (its faces' error: a flat triangle's chord), largest and mean.

Methods, each on one thread, each time the median of --repeats runs:
- ldimesh: `ldimesh mesh --vtu FILE --field f --iso 0.49 --res R [--merge] --threads 1
  --repeat 3` — a whole step (bind, cast, §3 meshing and trimming; with --merge §5's merging
  of the three views into one closed mesh), the last of 3 in one process;
- vtkContourFilter: VTK's contour of the quadratic/Lagrange cells (each cell split into linear
  ones at its nodes and contoured);
- vtkTessellatorFilter (level L, chord error 10⁻⁴ of the box) then vtkContourFilter: the cells
  tessellated into linear tetrahedra (the field interpolated at the new points) and contoured,
  both timed (a running simulation's field changes every step).

    /usr/bin/python3 bench/highorder_cells_contour.py [--build build] [--n 8] [--res 64 128 256]
                                                      [--levels 1 2 3] [--repeats 3]

Figures: docs/performance.md, "High-order cells beside VTK".
"""
import argparse
import json
import math
import os
import statistics
import struct
import subprocess
import sys
import tempfile
import time

try:
    import numpy as np
    import vtk
    from vtk.util import numpy_support
except ImportError as error:  # pragma: no cover
    sys.exit(f"highorder_cells_contour.py: needs python3-vtk9 and python3-numpy ({error}); "
             "run it with /usr/bin/python3")

RADIUS, ISO = 0.7, 0.49
CORNERS = [(0, 0, 0), (1, 0, 0), (1, 1, 0), (0, 1, 0), (0, 0, 1), (1, 0, 1), (1, 1, 1), (0, 1, 1)]
KUHN = [(0, 1, 2, 6), (0, 2, 3, 6), (0, 3, 7, 6), (0, 7, 4, 6), (0, 4, 5, 6), (0, 5, 1, 6)]
WEDGES = [(0, 1, 2, 4, 5, 6), (0, 2, 3, 4, 6, 7)]


def lagrange_tetra(n_points):
    cell = vtk.vtkLagrangeTetra()
    cell.GetPointIds().SetNumberOfIds(n_points)
    cell.GetPoints().SetNumberOfPoints(n_points)
    cell.Initialize()
    return cell


# name: (VTK type, cell whose parametric coordinates place the nodes, linear cell for the map,
#        split of a sub-cube)
KINDS = {
    "P2 tetrahedra": (vtk.VTK_QUADRATIC_TETRA, vtk.vtkQuadraticTetra(), vtk.vtkTetra(), KUHN),
    "P3 tetrahedra": (vtk.VTK_LAGRANGE_TETRAHEDRON, lagrange_tetra(20), vtk.vtkTetra(), KUHN),
    "P2 wedges": (vtk.VTK_QUADRATIC_WEDGE, vtk.vtkQuadraticWedge(), vtk.vtkWedge(), WEDGES),
}


def make_grid(kind, n):
    cell_type, cell, shape, splits = KINDS[kind]
    pc = cell.GetParametricCoords()
    count = len(pc) // 3
    weights = [0.0] * shape.GetNumberOfPoints()
    ref = []
    for m in range(count):
        shape.InterpolateFunctions(pc[3 * m:3 * m + 3], weights)
        ref.append(list(weights))
    ref = np.array(ref)  # nodes × corners
    h = 2.0 / n
    coords, index, cells = [], {}, []
    for k in range(n):
        for j in range(n):
            for i in range(n):
                c = np.array([[-1.0 + h * (i + a), -1.0 + h * (j + b), -1.0 + h * (k + d)]
                              for a, b, d in CORNERS])
                for split in splits:
                    ids = []
                    for x in ref @ c[list(split)]:
                        key = tuple(np.round(x, 12))
                        if key not in index:  # shared nodes once: a conforming mesh
                            index[key] = len(coords)
                            coords.append(x)
                        ids.append(index[key])
                    cells.append(ids)
    points = np.array(coords)
    grid = vtk.vtkUnstructuredGrid()
    vtk_points = vtk.vtkPoints()
    vtk_points.SetData(numpy_support.numpy_to_vtk(points, deep=True))
    grid.SetPoints(vtk_points)
    cell_array = vtk.vtkCellArray()
    offsets = numpy_support.numpy_to_vtkIdTypeArray(
        np.arange(0, count * len(cells) + 1, count, dtype=np.int64), deep=True)
    ids = numpy_support.numpy_to_vtkIdTypeArray(np.array(cells, dtype=np.int64).ravel(), deep=True)
    cell_array.SetData(offsets, ids)
    grid.SetCells(cell_type, cell_array)
    values = numpy_support.numpy_to_vtk((points ** 2).sum(axis=1), deep=True)
    values.SetName("f")
    grid.GetPointData().SetScalars(values)
    return grid, len(cells)


def errors(points, triangles):
    """Largest and mean | |x| − R | at the vertices and at 10 points inside each triangle."""
    vertex = np.abs(np.linalg.norm(points, axis=1) - RADIUS)
    a, b, c = (points[triangles[:, m]] for m in range(3))
    inside = []
    for u, v in [(1 / 3, 1 / 3), (0.5, 0.25), (0.25, 0.5), (0.25, 0.25), (0.6, 0.2), (0.2, 0.6),
                 (0.2, 0.2), (0.1, 0.45), (0.45, 0.1), (0.45, 0.45)]:
        inside.append(np.abs(np.linalg.norm(a + u * (b - a) + v * (c - a), axis=1) - RADIUS))
    faces = np.concatenate(inside)
    return vertex.max(), vertex.mean(), faces.max(), faces.mean()


def polydata_triangles(poly):
    tri = vtk.vtkTriangleFilter()
    tri.SetInputData(poly)
    tri.Update()
    out = tri.GetOutput()
    points = numpy_support.vtk_to_numpy(out.GetPoints().GetData()).astype(np.float64)
    conn = numpy_support.vtk_to_numpy(out.GetPolys().GetConnectivityArray()).reshape(-1, 3)
    return points, conn


def vtk_contour(grid, level):
    """Seconds and output of VTK's contour, after tessellation at `level` (0: none)."""
    start = time.perf_counter()
    source = grid
    if level > 0:
        tess = vtk.vtkTessellatorFilter()
        tess.SetInputData(grid)
        tess.SetOutputDimension(3)
        tess.SetMaximumNumberOfSubdivisions(level)
        tess.SetChordError(1e-4 * 2.0)
        tess.SetFieldCriterion(0, 1e-4)
        tess.MergePointsOn()
        tess.Update()
        source = tess.GetOutput()
    contour = vtk.vtkContourFilter()
    contour.SetInputData(source)
    contour.SetInputArrayToProcess(0, 0, 0, vtk.vtkDataObject.FIELD_ASSOCIATION_POINTS, "f")
    contour.SetValue(0, ISO)
    contour.ComputeNormalsOn()
    contour.Update()
    return time.perf_counter() - start, contour.GetOutput()


def read_ply(path):
    """The vertices and triangles (faces fanned) of a binary PLY as ldimesh writes it: float
    vertex properties, x, y, z first; a face's index list, then uchar properties."""
    data = open(path, "rb").read()
    header, body = data.split(b"end_header\n", 1)
    counts, props, element = {}, {"vertex": [], "face": []}, None
    for line in header.decode().splitlines():
        words = line.split()
        if words[0] == "element":
            element = words[1]
            counts[element] = int(words[2])
        elif words[0] == "property":
            props[element].append(words)
    if any(p[1] != "float" for p in props["vertex"]) or props["face"][0][1] != "list" or \
            any(p[1] != "uchar" for p in props["face"][1:]):
        sys.exit(f"highorder_cells_contour.py: unexpected PLY layout in {path}")
    n, stride = counts["vertex"], 4 * len(props["vertex"])
    points = np.array([struct.unpack_from("<3f", body, stride * v) for v in range(n)],
                      dtype=np.float64)
    extra = len(props["face"]) - 1
    offset, faces = stride * n, []
    for _ in range(counts["face"]):
        k = body[offset]
        ids = struct.unpack_from(f"<{k}I", body, offset + 1)
        offset += 1 + 4 * k + extra
        faces.extend([(ids[0], ids[m], ids[m + 1]) for m in range(1, k - 1)])
    return points, np.array(faces, dtype=np.int64)


def ldimesh(build, path, res, merge, directory):
    out = os.path.join(directory, f"ours-{res}.ply")
    cmd = [os.path.join(build, "bin", "ldimesh"), "mesh", "--vtu", path, "--field", "f", "--iso",
           str(ISO), "--res", str(res), "--threads", "1", "--repeat", "3", "--json",
           "--out", out] + (["--merge"] if merge else [])
    j = json.loads(subprocess.run(cmd, check=True, capture_output=True, text=True).stdout)
    seconds = sum(v for k, v in j["seconds"].items() if k not in ("load", "write", "encode"))
    return seconds, out


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--build", default="build")
    parser.add_argument("--n", type=int, default=8)
    parser.add_argument("--res", type=int, nargs="+", default=[64, 128, 256])
    parser.add_argument("--levels", type=int, nargs="+", default=[1, 2, 3])
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--kinds", default=",".join(KINDS))
    args = parser.parse_args()
    vtk.vtkLogger.SetStderrVerbosity(vtk.vtkLogger.VERBOSITY_WARNING)
    with tempfile.TemporaryDirectory() as directory:
        for kind in args.kinds.split(","):
            grid, count = make_grid(kind, args.n)
            path = os.path.join(directory, "cells.vtu")
            writer = vtk.vtkXMLUnstructuredGridWriter()
            writer.SetFileName(path)
            writer.SetInputData(grid)
            writer.SetDataModeToAppended()
            writer.EncodeAppendedDataOff()
            writer.Write()
            rows = []
            for res in args.res:
                for merge in (False, True):
                    times = []
                    for _ in range(args.repeats):
                        seconds, out = ldimesh(args.build, path, res, merge, directory)
                        times.append(seconds)
                    points, faces = read_ply(out)
                    name = f"ldimesh 3 × {res}², " + ("merged" if merge else "three views")
                    rows.append((name, len(faces), statistics.median(times),
                                 errors(points, faces)))
            for level in [0] + args.levels:
                times, output = [], None
                for _ in range(args.repeats):
                    seconds, output = vtk_contour(grid, level)
                    times.append(seconds)
                if output.GetNumberOfPoints() == 0:  # VTK 9.1's tessellator skips wedges
                    rows.append((f"vtkTessellatorFilter (level {level}): {kind} not supported",
                                 0, float("nan"), (float("nan"),) * 4))
                    continue
                points, faces = polydata_triangles(output)
                name = ("vtkContourFilter" if level == 0 else
                        f"vtkTessellatorFilter (level {level}) + vtkContourFilter")
                rows.append((name, len(faces), statistics.median(times), errors(points, faces)))
            print(f"\n{kind}: {count} cells ({args.n}³ sub-cubes over [-1, 1]³), f = |x|² at the "
                  f"nodes, isovalue 0.49 (the sphere of radius 0.7), one thread, medians of "
                  f"{args.repeats} runs\n")
            print("| method | triangles | seconds | vertex error max / mean | face error max / "
                  "mean |")
            print("|---|---|---|---|---|")
            for name, triangles, seconds, (vmax, vmean, fmax, fmean) in rows:
                if math.isnan(seconds):  # a method VTK does not have for this cell type
                    print(f"| {name} | – | – | – | – |")
                    continue
                print(f"| {name} | {triangles} | {seconds:.3f} | {vmax:.1e} / {vmean:.1e} | "
                      f"{fmax:.1e} / {fmean:.1e} |")
            sys.stdout.flush()


if __name__ == "__main__":
    main()
