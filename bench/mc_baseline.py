#!/usr/bin/python3
"""Marching Cubes baseline for bench/evaluate: VTK's vtkFlyingEdges3D on a sampled field.

    /usr/bin/python3 bench/mc_baseline.py --raw ml.raw --meta ml.json --out ml_mc.ply
        [--iso V] [--threads N] [--no-clip] [--repeat K]

--raw is a float32 file, x fastest (what build/bin/ldimesh_sample_field writes) and --meta the
JSON line that ldimesh_sample_field printed (dims, origin, spacing, isovalue, clip). The
isosurface is extracted with vtkFlyingEdges3D (Flying Edges, Schroeder et al. 2015: the same
triangles as Marching Cubes' case table up to the triangulation of ambiguous cases, in
four passes over the x edges; VTK runs it with vtkSMPTools, here TBB, on --threads threads,
default all cores). When the surface is clipped (the Barth sextic to the ball of radius 2, as the
ray caster only reports roots inside that ball), the triangles are clipped alike with
vtkClipPolyData and a vtkSphere of that radius (triangles crossing the sphere are cut at its
intersection with their edges, linearly interpolated). The result is written as a binary PLY
(vtkPLYWriter: float x, y, z; uchar/int vertex_indices) and one JSON line goes to stdout:
triangles, vertices, seconds (median of --repeat runs of the extraction alone; the clip and the
PLY write separately), VTK's version and SMP backend.

Needs Debian's python3-vtk9 (run with /usr/bin/python3); and python3-numpy (python3-vtk9 only recommends it).
"""
import argparse
import json
import os
import statistics
import sys
import time

import numpy as np
import vtk
from vtk.util import numpy_support


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--raw", required=True, help="float32 values, x fastest")
    ap.add_argument("--meta", required=True, help="JSON from ldimesh_sample_field (file)")
    ap.add_argument("--out", help="output PLY (binary); none: no file")
    ap.add_argument("--iso", type=float, help="isovalue (default: the meta's)")
    ap.add_argument("--threads", type=int, default=0, help="VTK SMP threads (0: all cores)")
    ap.add_argument("--repeat", type=int, default=1, help="extraction runs; the median is kept")
    ap.add_argument("--no-clip", action="store_true", help="do not apply the meta's clip")
    args = ap.parse_args()

    with open(args.meta) as f:
        meta = json.loads(f.readline())
    dims = [int(d) for d in meta["dims"]]
    iso = args.iso if args.iso is not None else float(meta["isovalue"])

    threads = args.threads if args.threads > 0 else (os.cpu_count() or 1)
    smp = vtk.vtkSMPTools()
    smp.Initialize(threads)

    start = time.perf_counter()
    values = np.fromfile(args.raw, dtype="<f4")
    if values.size != dims[0] * dims[1] * dims[2]:
        sys.exit(f"mc_baseline: {args.raw} holds {values.size} values, dims {dims} need "
                 f"{dims[0] * dims[1] * dims[2]}")
    image = vtk.vtkImageData()
    image.SetDimensions(*dims)
    image.SetOrigin(*meta["origin"])
    image.SetSpacing(*meta["spacing"])
    array = numpy_support.numpy_to_vtk(values, deep=0, array_type=vtk.VTK_FLOAT)
    array.SetName("f")
    image.GetPointData().SetScalars(array)
    load_seconds = time.perf_counter() - start

    times = []
    surface = None
    for _ in range(max(1, args.repeat)):
        fe = vtk.vtkFlyingEdges3D()
        fe.SetInputData(image)
        fe.SetValue(0, iso)
        fe.ComputeNormalsOff()
        fe.ComputeGradientsOff()
        fe.ComputeScalarsOff()
        fe.InterpolateAttributesOff()
        start = time.perf_counter()
        fe.Update()
        times.append(time.perf_counter() - start)
        surface = fe.GetOutput()
    mc_seconds = statistics.median(times)
    triangles_unclipped = surface.GetNumberOfPolys()

    clip = meta.get("clip")
    clip_seconds = 0.0
    if clip and not args.no_clip:
        if clip.get("type") != "ball":
            sys.exit(f"mc_baseline: unknown clip {clip}")
        start = time.perf_counter()
        sphere = vtk.vtkSphere()
        sphere.SetCenter(*clip["center"])
        sphere.SetRadius(float(clip["radius"]))
        clipper = vtk.vtkClipPolyData()
        clipper.SetInputData(surface)
        clipper.SetClipFunction(sphere)
        clipper.InsideOutOn()  # keep where (x - c)² − R² < 0, inside the ball
        clipper.SetValue(0.0)
        triangulate = vtk.vtkTriangleFilter()
        triangulate.SetInputConnection(clipper.GetOutputPort())
        clean = vtk.vtkCleanPolyData()  # drop the points the clip left unused
        clean.SetInputConnection(triangulate.GetOutputPort())
        clean.PointMergingOff()
        clean.Update()
        surface = clean.GetOutput()
        clip_seconds = time.perf_counter() - start

    write_seconds = 0.0
    if args.out:
        start = time.perf_counter()
        writer = vtk.vtkPLYWriter()
        writer.SetFileName(args.out)
        writer.SetInputData(surface)
        writer.SetFileTypeToBinary()
        if not writer.Write():
            sys.exit(f"mc_baseline: cannot write {args.out}")
        write_seconds = time.perf_counter() - start

    print(json.dumps({
        "raw": args.raw,
        "output": args.out,
        "dims": dims,
        "isovalue": iso,
        "triangles": surface.GetNumberOfPolys(),
        "triangles_unclipped": triangles_unclipped,
        "vertices": surface.GetNumberOfPoints(),
        "clipped": bool(clip) and not args.no_clip,
        "threads": threads,
        "smp_backend": smp.GetBackend(),
        "vtk": vtk.vtkVersion.GetVTKVersion(),
        "seconds": mc_seconds,
        "seconds_all": times,
        "load_seconds": load_seconds,
        "clip_seconds": clip_seconds,
        "write_seconds": write_seconds,
    }), flush=True)


if __name__ == "__main__":
    main()
