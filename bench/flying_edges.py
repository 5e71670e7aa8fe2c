#!/usr/bin/python3
"""Ray casting beside VTK's Flying Edges, in one run, as ratios.

The same Marschner–Lobb volume (256³ float32 points over [-1, 1]³, isovalue 0.5) is contoured by
vtkFlyingEdges3D (Debian's python3-vtk9, its SMP backend on all cores) and ray cast by ldimesh
(`ldimesh mesh --grid`, three axis views) with the coherent axis casters and with Embree on every
ray; the 16³ elements of order 4 (GLL nodes) of ldimesh_bench_sources are set beside Flying Edges
on their field sampled at 65³ points (what a user would contour instead). Runs alternate, and
every figure is the median of --repeats runs, so that the ratios hold on a noisy machine.

Both sides are timed as a running simulation meets them, step after step in one process: Flying
Edges runs in this process (a first, untimed run warms it up), and each ldimesh process runs
its step --steps times (`ldimesh mesh --repeat`); its first step, a cold start of a fresh
process (page faults on every new buffer, cold caches), is reported on its own row.

Both sides run with glibc told to keep freed memory (MALLOC_MMAP_MAX_=0 and large trim and top-pad
thresholds; the script re-executes itself with them, and its children inherit them): Flying Edges
allocates its edge cases and its output anew on every Update, and on a virtual machine where a page
fault is expensive (this one: ≈ 3.5 µs, perf in the exception handler) those faults were most of
its time — 0.12 s against 0.024 s with the memory kept, on the same data and threads — and varied
from day to day. ldimesh's later steps reuse their buffers anyway. --default-allocator times both
sides without the setting (the peer then looks slower than it is).

    /usr/bin/python3 bench/flying_edges.py [--build build] [--repeats 5] [--threads 2] [--steps 4]
                                           [--baseline OTHER_BUILD]

--baseline OTHER_BUILD also runs that build's `ldimesh mesh` (e.g. of an earlier commit) on the
coherent grid cases, interleaved with this one's, and prints its rows beside them: a change's
cost measured in one run, against the same Flying Edges.

Prints a Markdown table (docs/performance.md, "Ray casting grids beside Flying Edges") and, with
--json FILE, writes the figures there.
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
    sys.exit(f"flying_edges.py: needs python3-vtk9 and python3-numpy ({error}); "
             "run it with /usr/bin/python3")


def sample(build, n, path):
    """ML on n³ points over [-1, 1]³ into `path` (float32); returns the sampler's JSON."""
    out = subprocess.run([os.path.join(build, "bin", "ldimesh_sample_field"), "--surface",
                          "marschner-lobb", "--n", str(n), "--out", path],
                         check=True, capture_output=True, text=True).stdout
    return json.loads(out)


def image(info, path):
    dims = info["dims"]
    values = np.fromfile(path, dtype=np.float32)
    img = vtk.vtkImageData()
    img.SetDimensions(*dims)
    img.SetOrigin(*info["origin"])
    img.SetSpacing(*info["spacing"])
    array = numpy_support.numpy_to_vtk(values, deep=True)
    array.SetName("f")
    img.GetPointData().SetScalars(array)
    return img


def flying_edges(img, iso):
    """Seconds and triangles of one vtkFlyingEdges3D run (normals on, as a viewer needs)."""
    fe = vtk.vtkFlyingEdges3D()
    fe.SetInputData(img)
    fe.SetValue(0, iso)
    start = time.perf_counter()
    fe.Update()
    return time.perf_counter() - start, fe.GetOutput().GetNumberOfCells()


def ldimesh_grid(build, info, path, res, caster, threads, steps):
    """One `ldimesh mesh` process that runs the step `steps` times (--repeat): the first run is
    a cold start (a fresh process: page faults, cold caches), the later ones what each time step of
    a running simulation pays."""
    dims = ",".join(str(d) for d in info["dims"])
    cmd = [os.path.join(build, "bin", "ldimesh"), "mesh", "--grid", path, "--dims", dims,
           "--origin", ",".join(repr(x) for x in info["origin"]),
           "--spacing", ",".join(repr(x) for x in info["spacing"]),
           "--iso", "0.5", "--res", str(res), "--caster", caster, "--threads", str(threads),
           "--repeat", str(steps), "--json"]
    j = json.loads(subprocess.run(cmd, check=True, capture_output=True, text=True).stdout)
    runs = j["repeats"]
    cast = [r["scene"] + r["raycast"] for r in runs]
    solver = [r["scene"] + r["raycast"] + r["reduce"] for r in runs]
    warm = slice(1, None) if len(runs) > 1 else slice(None)
    return {"cast_cold": cast[0], "cast": statistics.median(cast[warm]),
            "solver": statistics.median(solver[warm]), "samples": j["samples"],
            "triangles": j["triangles"]}


def element_casts(build, res, threads):
    cmd = [os.path.join(build, "bin", "ldimesh_bench_sources"), "--res", str(res), "--embree",
           "--json"]
    lines = subprocess.run(cmd, check=True, capture_output=True, text=True).stdout
    rows = json.loads(lines.strip().splitlines()[-1])["casts"]
    return {("elements" if "elements" in r["source"] else "grid", r["caster"], r["threads"]): r
            for r in rows if r["threads"] == threads}


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--build", default="build")
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--steps", type=int, default=4,
                    help="steps per ldimesh process (the first is the cold start)")
    ap.add_argument("--threads", type=int, default=os.cpu_count())
    ap.add_argument("--json", help="write the figures to this file")
    ap.add_argument("--baseline", help="another build folder to time beside --build (coherent "
                    "grid cases)")
    ap.add_argument("--default-allocator", action="store_true",
                    help="leave glibc's allocator as it is (see the module's comment)")
    args = ap.parse_args()
    keep = {"MALLOC_MMAP_MAX_": "0", "MALLOC_TRIM_THRESHOLD_": str(1 << 40),
            "MALLOC_TOP_PAD_": str(1 << 30)}
    if not args.default_allocator and any(os.environ.get(k) != v for k, v in keep.items()):
        os.execve(sys.executable, [sys.executable] + sys.argv, {**os.environ, **keep})
    vtk.vtkSMPTools.Initialize(args.threads)

    with tempfile.TemporaryDirectory() as tmp:
        grid_path, fine_path = os.path.join(tmp, "ml256.raw"), os.path.join(tmp, "ml65.raw")
        grid_info, fine_info = sample(args.build, 256, grid_path), sample(args.build, 65, fine_path)
        grid_img, fine_img = image(grid_info, grid_path), image(fine_info, fine_path)
        fe, fe65, runs, elements, baseline = [], [], {}, [], {}
        triangles = {}
        flying_edges(grid_img, 0.5), flying_edges(fine_img, 0.5)  # warm-up, untimed
        for rep in range(args.repeats):
            print(f"flying_edges.py: run {rep + 1} of {args.repeats}", file=sys.stderr)
            for res in (256, 512):
                for caster in ("auto", "embree"):
                    t, tri = flying_edges(grid_img, 0.5)
                    fe.append(t)
                    triangles["fe"] = tri
                    # With a baseline, the two builds take turns going first (the machine's
                    # state drifts; neither always runs warm after the other).
                    order = [args.build]
                    if args.baseline and caster == "auto":
                        order = [args.build, args.baseline] if rep % 2 == 0 else [args.baseline,
                                                                                 args.build]
                    for build in order:
                        r = ldimesh_grid(build, grid_info, grid_path, res, caster, args.threads,
                                         args.steps)
                        if build == args.build:
                            runs.setdefault((res, caster), []).append(r)
                        else:
                            baseline.setdefault(res, []).append(r)
            t, _ = flying_edges(fine_img, 0.5)
            fe65.append(t)
            elements.append(element_casts(args.build, 512, args.threads))

    med = statistics.median
    fe_s, fe65_s = med(fe), med(fe65)
    rows = []
    allocator = ("glibc's default allocator" if args.default_allocator else
                 "freed memory kept (MALLOC_MMAP_MAX_=0)")
    print(f"Marschner–Lobb, isovalue 0.5; {args.threads} threads; {allocator}; medians of "
          f"{args.repeats} interleaved runs. vtkFlyingEdges3D on 256³: {fe_s:.4f} s "
          f"({triangles['fe']} triangles); on the 65³ samples of the elements: {fe65_s:.4f} s.\n")
    print("| case | ldimesh s | Flying Edges s | ratio |")
    print("|---|---|---|---|")
    for res in (256, 512):
        for caster in ("auto", "embree"):
            rs = runs[(res, caster)]
            cast, solver = med(r["cast"] for r in rs), med(r["solver"] for r in rs)
            cold = med(r["cast_cold"] for r in rs)
            name = "coherent" if caster == "auto" else "Embree"
            print(f"| 256³ grid, 3 × {res}², {name}: ray cast (bind + cast), first step of a "
                  f"process | {cold:.4f} | {fe_s:.4f} | {cold / fe_s:.2f} |")
            print(f"| 256³ grid, 3 × {res}², {name}: ray cast (bind + cast), later steps | "
                  f"{cast:.4f} | {fe_s:.4f} | {cast / fe_s:.2f} |")
            print(f"| 256³ grid, 3 × {res}², {name}: solver's share (cast + encode + reduce, one "
                  f"rank), later steps | {solver:.4f} | {fe_s:.4f} | {solver / fe_s:.2f} |")
            rows.append({"source": "grid", "resolution": res, "caster": name, "cast": cast,
                         "cast_first_step": cold,
                         "solver": solver, "flying_edges": fe_s, "samples": rs[0]["samples"]})
    for res, bs in baseline.items():
        cast, solver = med(r["cast"] for r in bs), med(r["solver"] for r in bs)
        ours = med(r["cast"] for r in runs[(res, "auto")])
        print(f"| 256³ grid, 3 × {res}², coherent, baseline {args.baseline}: ray cast (bind + "
              f"cast), later steps (this build: {ours / cast:.2f}× it) | {cast:.4f} | {fe_s:.4f} "
              f"| {cast / fe_s:.2f} |")
        print(f"| 256³ grid, 3 × {res}², coherent, baseline {args.baseline}: solver's share, "
              f"later steps | {solver:.4f} | {fe_s:.4f} | {solver / fe_s:.2f} |")
        rows.append({"source": "grid", "resolution": res, "caster": "coherent",
                     "build": args.baseline, "cast": cast, "solver": solver,
                     "flying_edges": fe_s})
    for caster in ("coherent", "Embree"):
        s = med(e[("elements", caster, args.threads)]["seconds"] for e in elements)
        hits = elements[0][("elements", caster, args.threads)]["hits"]
        print(f"| 16³ elements p = 4 GLL, 3 × 512², {caster}: bind + cast ({hits} hits) | {s:.4f} "
              f"| {fe65_s:.4f} (65³) | {s / fe65_s:.1f} |")
        rows.append({"source": "elements", "resolution": 512, "caster": caster, "cast": s,
                     "flying_edges_65": fe65_s, "hits": hits})
    if args.json:
        with open(args.json, "w") as f:
            json.dump({"threads": args.threads, "repeats": args.repeats,
                       "default_allocator": args.default_allocator, "rows": rows}, f,
                      indent=1)


if __name__ == "__main__":
    main()
