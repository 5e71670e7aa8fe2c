#!/usr/bin/python3
"""What colouring an isosurface by a second field costs, beside VTK, in one run, as ratios.

The Marschner–Lobb volume (256³ float32 points over [-1, 1]³, isovalue 0.5) is contoured with and
without a second point field to colour by, c(x) = sin(4x) + y·z (float32, the same layout):

- VTK: vtkFlyingEdges3D (its SMP backend on all cores, normals on) with InterpolateAttributes
  off and on (on: every point array of the input interpolated onto the surface's vertices, which
  is how a VTK pipeline carries a colour field to its isosurface);
- ldimesh: `ldimesh mesh --grid` (three axis views, coherent casters) without and with
  `--colour-by`, its step run --steps times per process (`--repeat`), the first (a cold process)
  left out; "ray cast" is binding plus casting the three views, "solver's share" adds
  quantizing the fragments and the reduction.

Also the GLB each writes (ldimesh's `--out .glb`: Draco, positions, normals, view colours and,
with the field, _SCALAR) in bytes per triangle. Runs alternate; every figure is the median of
--repeats runs. glibc keeps freed memory on both sides, as in bench/flying_edges.py.

    /usr/bin/python3 bench/colour_cost.py [--build build] [--repeats 5] [--threads 2] [--steps 4]

Prints a Markdown table (docs/performance.md, "Colouring by a second field").
"""
import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from flying_edges import image, np, sample, vtk  # noqa: E402  (the same volume and image)
from vtk.util import numpy_support  # noqa: E402


def colour_volume(info, path):
    """c = sin(4x) + y·z at the volume's points (x fastest), float32, into `path`."""
    n = info["dims"]
    axes = [info["origin"][a] + info["spacing"][a] * np.arange(n[a]) for a in range(3)]
    z, y, x = np.meshgrid(axes[2], axes[1], axes[0], indexing="ij")
    c = (np.sin(4.0 * x) + y * z).astype(np.float32)
    c.tofile(path)
    return c.ravel()


def flying_edges(img, interpolate):
    fe = vtk.vtkFlyingEdges3D()
    fe.SetInputData(img)
    fe.SetValue(0, 0.5)
    fe.SetInterpolateAttributes(interpolate)
    start = time.perf_counter()
    fe.Update()
    seconds = time.perf_counter() - start
    out = fe.GetOutput()
    if interpolate and out.GetPointData().GetArray("c") is None:
        sys.exit("colour_cost.py: Flying Edges did not carry the colour field")
    return seconds, out.GetNumberOfCells()


def ldimesh(build, info, path, colour, args, glb):
    dims = ",".join(str(d) for d in info["dims"])
    cmd = [os.path.join(build, "bin", "ldimesh"), "mesh", "--grid", path, "--dims", dims,
           "--origin", ",".join(repr(x) for x in info["origin"]),
           "--spacing", ",".join(repr(x) for x in info["spacing"]), "--iso", "0.5", "--res",
           "256", "--threads", str(args.threads), "--repeat", str(args.steps), "--json",
           "--out", glb]
    if colour:
        cmd += ["--colour-by", colour]
    j = json.loads(subprocess.run(cmd, check=True, capture_output=True, text=True).stdout)
    runs = j["repeats"][1:] or j["repeats"]
    return {"cast": statistics.median(r["scene"] + r["raycast"] for r in runs),
            "solver": statistics.median(r["scene"] + r["raycast"] + r["reduce"] for r in runs),
            "triangles": j["triangles"], "bytes": os.path.getsize(glb),
            "colour": j.get("colour")}


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--build", default="build")
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--steps", type=int, default=4)
    ap.add_argument("--threads", type=int, default=os.cpu_count())
    args = ap.parse_args()
    keep = {"MALLOC_MMAP_MAX_": "0", "MALLOC_TRIM_THRESHOLD_": str(1 << 40),
            "MALLOC_TOP_PAD_": str(1 << 30)}
    if any(os.environ.get(k) != v for k, v in keep.items()):
        os.execve(sys.executable, [sys.executable] + sys.argv, {**os.environ, **keep})
    vtk.vtkSMPTools.Initialize(args.threads)
    with tempfile.TemporaryDirectory() as tmp:
        path, cpath = os.path.join(tmp, "ml256.raw"), os.path.join(tmp, "c256.raw")
        info = sample(args.build, 256, path)
        img = image(info, path)
        c = numpy_support.numpy_to_vtk(colour_volume(info, cpath), deep=True)
        c.SetName("c")
        img.GetPointData().AddArray(c)
        fe = {False: [], True: []}
        ours = {False: [], True: []}
        flying_edges(img, False), flying_edges(img, True)  # warm-up, untimed
        for rep in range(args.repeats):
            print(f"colour_cost.py: run {rep + 1} of {args.repeats}", file=sys.stderr)
            for coloured in (False, True):
                fe[coloured].append(flying_edges(img, coloured))
                ours[coloured].append(ldimesh(args.build, info, path, cpath if coloured else None,
                                              args, os.path.join(tmp, "out.glb")))
    med = lambda xs: statistics.median(xs)  # noqa: E731
    fe_s = {k: med(t for t, _ in v) for k, v in fe.items()}
    cast = {k: med(r["cast"] for r in v) for k, v in ours.items()}
    solver = {k: med(r["solver"] for r in v) for k, v in ours.items()}
    tri = ours[True][0]["triangles"]
    bpt = {k: med(r["bytes"] for r in v) / v[0]["triangles"] for k, v in ours.items()}
    print(f"Marschner–Lobb 256³, isovalue 0.5, colour c = sin(4x) + yz; {args.threads} threads; "
          f"medians of {args.repeats} interleaved runs; ldimesh 3 × 256² ({tri} triangles), "
          f"Flying Edges {fe[True][0][1]} triangles. Colour range on the mesh: "
          f"{ours[True][0]['colour']}.\n")
    print("| | without colour s | with colour s | colour costs |")
    print("|---|---|---|---|")
    print(f"| vtkFlyingEdges3D (InterpolateAttributes) | {fe_s[False]:.4f} | {fe_s[True]:.4f} | "
          f"{fe_s[True] / fe_s[False]:.2f}× |")
    print(f"| ldimesh ray cast (bind + cast), later steps | {cast[False]:.4f} | {cast[True]:.4f} | "
          f"{cast[True] / cast[False]:.2f}× |")
    print(f"| ldimesh solver's share (+ encode + reduce) | {solver[False]:.4f} | "
          f"{solver[True]:.4f} | {solver[True] / solver[False]:.2f}× |")
    print(f"| ldimesh with colour / Flying Edges with colour | | "
          f"{cast[True] / fe_s[True]:.2f} (ray cast), {solver[True] / fe_s[True]:.2f} (share) | |")
    print(f"| ldimesh GLB, bytes per triangle | {bpt[False]:.2f} | {bpt[True]:.2f} | "
          f"+{bpt[True] - bpt[False]:.2f} |")


if __name__ == "__main__":
    main()
