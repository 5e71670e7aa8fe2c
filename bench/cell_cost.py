#!/usr/bin/python3
"""Curved tetrahedra, wedges and pyramids beside an affine hexahedron: the cost of a ray–element
pair (issue 58 (c)), as a Markdown table.

One cube [-1, 1]³ of n³ sub-cubes, each split into quadratic cells of one type (VTK_QUADRATIC_TETRA:
6 Kuhn tetrahedra, VTK_QUADRATIC_WEDGE: 2 wedges, VTK_QUADRATIC_PYRAMID: 6 pyramids, apex at the
centre; VTK_TRIQUADRATIC_HEXAHEDRON: the sub-cube itself), the nodes placed from VTK's own
parametric coordinates and written by VTK's writer. "curved": every node moved by a smooth
displacement that vanishes on the cube's faces (the cells' edges and faces bend, the mesh stays
conforming); "affine": the nodes where the straight cell has them. The field at the nodes is
f = |x|² + 0.1 sin 5x sin 5y sin 5z (quadratic in each cell: the surface is the field's own
interpolant), isovalue 0.6. `ldimesh mesh --vtu` casts the three axis views at --res on one
thread, --steps times in one process; the later steps' bind + cast over the pairs gives the
cost of one pair, a pair being a pixel ray and a cell whose box (of its nodes) holds the ray
(counted here, per view). Medians of --repeats runs.

    /usr/bin/python3 bench/cell_cost.py [--build build] [--n 12] [--res 128] [--repeats 3]
                                        [--steps 3]

Figures: docs/performance.md, "Cell shapes: the cost of a ray–cell pair".
"""
import argparse
import json
import math
import os
import statistics
import subprocess
import sys
import tempfile

try:
    import numpy as np
    import vtk
except ImportError as error:  # pragma: no cover
    sys.exit(f"cell_cost.py: needs python3-vtk9 and python3-numpy ({error}); "
             "run it with /usr/bin/python3")

CORNERS = [(0, 0, 0), (1, 0, 0), (1, 1, 0), (0, 1, 0), (0, 0, 1), (1, 0, 1), (1, 1, 1), (0, 1, 1)]
SPLITS = {
    "tetrahedra": (vtk.VTK_QUADRATIC_TETRA, vtk.vtkQuadraticTetra, vtk.vtkTetra,
                   [(0, 1, 2, 6), (0, 2, 3, 6), (0, 3, 7, 6), (0, 7, 4, 6), (0, 4, 5, 6),
                    (0, 5, 1, 6)]),
    "wedges": (vtk.VTK_QUADRATIC_WEDGE, vtk.vtkQuadraticWedge, vtk.vtkWedge,
               [(0, 1, 2, 4, 5, 6), (0, 2, 3, 4, 6, 7)]),
    "pyramids": (vtk.VTK_QUADRATIC_PYRAMID, vtk.vtkQuadraticPyramid, vtk.vtkPyramid,
                 [(0, 3, 2, 1, 8), (4, 5, 6, 7, 8), (0, 1, 5, 4, 8), (1, 2, 6, 5, 8),
                  (2, 3, 7, 6, 8), (3, 0, 4, 7, 8)]),
    "hexahedra": (vtk.VTK_TRIQUADRATIC_HEXAHEDRON, vtk.vtkTriQuadraticHexahedron,
                  vtk.vtkHexahedron, [(0, 1, 2, 3, 4, 5, 6, 7)]),
}


def field(x):
    return (x[0] ** 2 + x[1] ** 2 + x[2] ** 2 +
            0.1 * math.sin(5 * x[0]) * math.sin(5 * x[1]) * math.sin(5 * x[2]))


def bend(x):
    """A displacement that vanishes on the faces of [-1, 1]³."""
    s = math.cos(0.5 * math.pi * x[0]) * math.cos(0.5 * math.pi * x[1]) * \
        math.cos(0.5 * math.pi * x[2])
    return [x[0] + 0.08 * s * math.sin(2.0 * x[1]), x[1] + 0.08 * s * math.sin(2.0 * x[2]),
            x[2] + 0.08 * s * math.sin(2.0 * x[0])]


def write_cells(kind, curved, n, path):
    """Writes the mesh; returns the cell count and the cells' node boxes (lo, hi arrays)."""
    cell_type, quadratic, linear, splits = SPLITS[kind]
    grid = vtk.vtkUnstructuredGrid()
    points = vtk.vtkPoints()
    values = vtk.vtkDoubleArray()
    values.SetName("f")
    cell = quadratic()
    pc = cell.GetParametricCoords()
    shape = linear()
    weights = [0.0] * shape.GetNumberOfPoints()
    h = 2.0 / n
    cache = {}
    lo_boxes, hi_boxes = [], []
    for k in range(n):
        for j in range(n):
            for i in range(n):
                o = [-1.0 + h * i, -1.0 + h * j, -1.0 + h * k]
                c = [[o[0] + h * a, o[1] + h * b, o[2] + h * d] for a, b, d in CORNERS]
                c.append([x + 0.5 * h for x in o])
                for split in splits:
                    corners = [c[a] for a in split]
                    ids, xs = [], []
                    for m in range(len(pc) // 3):
                        shape.InterpolateFunctions(pc[3 * m:3 * m + 3], weights)
                        x = [sum(w * v[a] for w, v in zip(weights, corners)) for a in range(3)]
                        key = tuple(round(v, 12) for v in x)
                        if key not in cache:  # shared nodes once: the mesh is conforming
                            y = bend(x) if curved else x
                            cache[key] = (points.InsertNextPoint(y), y)
                            values.InsertNextValue(field(y))
                        ids.append(cache[key][0])
                        xs.append(cache[key][1])
                    grid.InsertNextCell(cell_type, len(ids), ids)
                    lo_boxes.append(np.min(xs, axis=0))
                    hi_boxes.append(np.max(xs, axis=0))
    grid.SetPoints(points)
    grid.GetPointData().SetScalars(values)
    writer = vtk.vtkXMLUnstructuredGridWriter()
    writer.SetFileName(path)
    writer.SetInputData(grid)
    writer.SetDataModeToAppended()
    writer.EncodeAppendedDataOff()
    writer.Write()
    return grid.GetNumberOfCells(), np.array(lo_boxes), np.array(hi_boxes)


def pairs(lo, hi, res):
    """Pixel rays × cells whose box holds them, over the three axis views of the cells' box (the
    pixel grid over the box's two other axes, res pixels along the longer)."""
    box_lo, box_hi = lo.min(axis=0), hi.max(axis=0)
    total = 0
    for axis in range(3):
        a, b = [d for d in range(3) if d != axis]
        spacing = max(box_hi[a] - box_lo[a], box_hi[b] - box_lo[b]) / res
        count = 1
        for d in (a, b):
            first = np.ceil((lo[:, d] - box_lo[d]) / spacing - 0.5)
            last = np.floor((hi[:, d] - box_lo[d]) / spacing - 0.5)
            count = count * np.maximum(last - first + 1, 0)
        total += int(count.sum())
    return total


def cast(build, path, res, steps):
    cmd = [os.path.join(build, "bin", "ldimesh"), "mesh", "--vtu", path, "--field", "f", "--iso",
           "0.6", "--res", str(res), "--threads", "1", "--repeat", str(steps), "--json"]
    j = json.loads(subprocess.run(cmd, check=True, capture_output=True, text=True).stdout)
    runs = j["repeats"][1:] or j["repeats"]
    return statistics.median(r["scene"] + r["raycast"] for r in runs), j["samples"]


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--build", default="build")
    parser.add_argument("--n", type=int, default=12)
    parser.add_argument("--res", type=int, default=128)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--steps", type=int, default=3)
    args = parser.parse_args()
    cases = [("hexahedra", False), ("hexahedra", True), ("tetrahedra", True), ("wedges", True),
             ("pyramids", True), ("tetrahedra", False)]
    rows = []
    with tempfile.TemporaryDirectory() as directory:
        meshes = []
        for kind, curved in cases:
            path = os.path.join(directory, f"{kind}-{int(curved)}.vtu")
            count, lo, hi = write_cells(kind, curved, args.n, path)
            meshes.append((kind, curved, path, count, pairs(lo, hi, args.res)))
        times = {m[2]: [] for m in meshes}
        samples = {}
        for _ in range(args.repeats):  # runs alternate between the cases
            for kind, curved, path, count, pair_count in meshes:
                seconds, samples[path] = cast(args.build, path, args.res, args.steps)
                times[path].append(seconds)
        base = None
        for kind, curved, path, count, pair_count in meshes:
            seconds = statistics.median(times[path])
            ns = 1e9 * seconds / pair_count
            base = base or ns
            rows.append((f"{'curved' if curved else 'affine'} quadratic {kind}", count,
                         pair_count, samples[path], seconds, ns, ns / base))
    print(f"{args.n}³ sub-cubes over [-1, 1]³, 3 × {args.res}², one thread, |x|² + 0.1 sin 5x "
          f"sin 5y sin 5z at 0.6, medians of {args.repeats} runs\n")
    print("| cells | count | ray–cell pairs | samples | bind + cast (s) | ns per pair | "
          "ratio to affine hexahedra |")
    print("|---|---|---|---|---|---|---|")
    for name, count, pair_count, sample_count, seconds, ns, ratio in rows:
        print(f"| {name} | {count} | {pair_count} | {sample_count} | {seconds:.3f} | {ns:.1f} | "
              f"{ratio:.2f} |")


if __name__ == "__main__":
    main()
