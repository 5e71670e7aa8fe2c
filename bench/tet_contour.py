#!/usr/bin/python3
"""Linear tetrahedra ray cast beside VTK's contour of them, in one run, as ratios (issue 58 (a)).

A cube [-1, 1]³ of n³ cubes, each split into 6 Kuhn tetrahedra around its diagonal (n = 55:
998 250 VTK_TETRA cells), carries the Marschner–Lobb field at its (n + 1)³ points (sampled by
ldimesh_sample_field). VTK's fast path for linear cells, vtkContour3DLinearGrid (its SMP
backend on all cores, point merging and normals on, as a viewer needs), contours it at 0.5 in
this process; `ldimesh mesh --vtu` (the file written by VTK's own writer, read once) ray casts
its three axis views at --res, --steps times in one process (`--repeat`): the first a cold
start, reported apart, the others what each step of a running simulation pays — the bind
(selecting the active tetrahedra, their planes) plus the cast. Runs alternate, and each figure
is the median of --repeats runs. Both sides with glibc told to keep freed memory, as
bench/flying_edges.py explains.

    /usr/bin/python3 bench/tet_contour.py [--build build] [--n 55] [--res 256 512]
                                          [--repeats 5] [--threads 2] [--steps 4]

Prints a Markdown table (docs/performance.md, "Linear tetrahedra beside vtkContour3DLinearGrid").
"""
import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time

try:
    import numpy as np
    import vtk
    from vtk.util import numpy_support
except ImportError as error:  # pragma: no cover
    sys.exit(f"tet_contour.py: needs python3-vtk9 and python3-numpy ({error}); "
             "run it with /usr/bin/python3")

# Kuhn's 6 tetrahedra of a cube, as corner offsets (i, j, k), around the diagonal 0–7.
KUHN = [[(0, 0, 0), (1, 0, 0), (1, 1, 0), (1, 1, 1)], [(0, 0, 0), (1, 1, 0), (0, 1, 0), (1, 1, 1)],
        [(0, 0, 0), (0, 1, 0), (0, 1, 1), (1, 1, 1)], [(0, 0, 0), (0, 1, 1), (0, 0, 1), (1, 1, 1)],
        [(0, 0, 0), (0, 0, 1), (1, 0, 1), (1, 1, 1)], [(0, 0, 0), (1, 0, 1), (1, 0, 0), (1, 1, 1)]]


def tetrahedra(build, n, directory):
    """The grid of Kuhn tetrahedra with ML at its points, written to a .vtu; returns the grid and
    the file."""
    raw = os.path.join(directory, "ml.raw")
    subprocess.run([os.path.join(build, "bin", "ldimesh_sample_field"), "--surface",
                    "marschner-lobb", "--n", str(n + 1), "--out", raw], check=True,
                   capture_output=True)
    values = np.fromfile(raw, dtype=np.float32)
    m = n + 1
    axis = np.linspace(-1.0, 1.0, m)
    z, y, x = np.meshgrid(axis, axis, axis, indexing="ij")
    points = np.stack([x.ravel(), y.ravel(), z.ravel()], axis=1)
    i, j, k = np.meshgrid(np.arange(n), np.arange(n), np.arange(n), indexing="ij")
    i, j, k = i.ravel(), j.ravel(), k.ravel()
    cells = []
    for tet in KUHN:
        ids = [(k + c[2]) * m * m + (j + c[1]) * m + (i + c[0]) for c in tet]
        cells.append(np.stack(ids, axis=1))
    connectivity = np.concatenate(cells).astype(np.int64)
    count = connectivity.shape[0]
    grid = vtk.vtkUnstructuredGrid()
    vtk_points = vtk.vtkPoints()
    vtk_points.SetData(numpy_support.numpy_to_vtk(points, deep=True))
    grid.SetPoints(vtk_points)
    cell_array = vtk.vtkCellArray()
    offsets = numpy_support.numpy_to_vtkIdTypeArray(np.arange(0, 4 * count + 1, 4), deep=True)
    ids = numpy_support.numpy_to_vtkIdTypeArray(connectivity.ravel(), deep=True)
    cell_array.SetData(offsets, ids)
    grid.SetCells(vtk.VTK_TETRA, cell_array)
    array = numpy_support.numpy_to_vtk(values.astype(np.float64), deep=True)
    array.SetName("f")
    grid.GetPointData().SetScalars(array)
    path = os.path.join(directory, "tets.vtu")
    writer = vtk.vtkXMLUnstructuredGridWriter()
    writer.SetFileName(path)
    writer.SetInputData(grid)
    writer.SetDataModeToAppended()
    writer.EncodeAppendedDataOff()
    writer.Write()
    return grid, path, count


def vtk_contour(grid):
    """Seconds and triangles of one vtkContour3DLinearGrid run."""
    contour = vtk.vtkContour3DLinearGrid()
    contour.SetInputData(grid)
    contour.SetValue(0, 0.5)
    contour.MergePointsOn()
    contour.ComputeNormalsOn()
    contour.SequentialProcessingOff()
    start = time.perf_counter()
    contour.Update()
    return time.perf_counter() - start, contour.GetOutput().GetNumberOfCells()


def ldimesh_cast(build, path, res, threads, steps):
    cmd = [os.path.join(build, "bin", "ldimesh"), "mesh", "--vtu", path, "--field", "f", "--iso",
           "0.5", "--res", str(res), "--threads", str(threads), "--repeat", str(steps), "--json"]
    j = json.loads(subprocess.run(cmd, check=True, capture_output=True, text=True).stdout)
    runs = j["repeats"]
    cast = [r["scene"] + r["raycast"] for r in runs]
    warm = slice(1, None) if len(runs) > 1 else slice(None)
    return {"cast_cold": cast[0], "cast": statistics.median(cast[warm]), "samples": j["samples"],
            "triangles": j["triangles"]}


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--build", default="build")
    parser.add_argument("--n", type=int, default=55)
    parser.add_argument("--res", type=int, nargs="+", default=[256, 512])
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--threads", type=int, default=2)
    parser.add_argument("--steps", type=int, default=4)
    args = parser.parse_args()
    keep = {"MALLOC_MMAP_MAX_": "0", "MALLOC_TRIM_THRESHOLD_": str(1 << 40),
            "MALLOC_TOP_PAD_": str(1 << 30)}
    if any(os.environ.get(k) != v for k, v in keep.items()):
        os.execve(sys.executable, [sys.executable] + sys.argv, {**os.environ, **keep})
    vtk.vtkSMPTools.SetBackend("TBB") if hasattr(vtk.vtkSMPTools, "SetBackend") else None
    vtk.vtkSMPTools.Initialize(args.threads)
    with tempfile.TemporaryDirectory() as directory:
        grid, path, count = tetrahedra(args.build, args.n, directory)
        vtk_contour(grid)  # warm-up, untimed
        peer, ours = [], {res: [] for res in args.res}
        triangles = 0
        for _ in range(args.repeats):
            seconds, triangles = vtk_contour(grid)
            peer.append(seconds)
            for res in args.res:
                ours[res].append(ldimesh_cast(args.build, path, res, args.threads, args.steps))
        vtk_s = statistics.median(peer)
        print(f"{count} linear tetrahedra (Kuhn, {args.n}³ cubes), Marschner–Lobb at 0.5, "
              f"{args.threads} threads, medians of {args.repeats} runs\n")
        print("| method | seconds | ratio to vtkContour3DLinearGrid | samples / triangles |")
        print("|---|---|---|---|")
        print(f"| vtkContour3DLinearGrid | {vtk_s:.4f} | 1 | {triangles} triangles |")
        for res in args.res:
            cast = statistics.median(r["cast"] for r in ours[res])
            cold = statistics.median(r["cast_cold"] for r in ours[res])
            samples = ours[res][0]["samples"]
            print(f"| ldimesh 3 × {res}², bind + cast, later steps | {cast:.4f} | "
                  f"{cast / vtk_s:.2f} | {samples} samples |")
            print(f"| ldimesh 3 × {res}², first step (cold) | {cold:.4f} | {cold / vtk_s:.2f} | |")


if __name__ == "__main__":
    main()
