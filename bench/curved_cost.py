#!/usr/bin/python3
"""Curved against affine hexahedra: the cost of a ray–element pair, as a Markdown table.

For each field order p and geometry order q (0: affine cubes given by their corners; 1: the
general trilinear hexahedron; 2, 4: curved) it runs

    ldimesh_bench_sources --only elements --grid-points 8 --elements E --order p --curved q --res R

(E³ elements tiling [−1, 1]³, Marschner–Lobb at 0.5, GLL nodes; for q ≥ 1 the mesh is bent by a
smooth displacement that vanishes on the cube's faces, so that the elements' corners move and
their faces curve) and prints, per (p, q), the elements left after culling, the hits, the three
axis views' bind + cast on one thread and on all, rays/s, and the cost of one pixel–element pair
on one thread: the one-thread time over the pairs, which are counted as the culled elements times
3 × (R / E)² pixels (each element's box covers about (R / E)² pixels of each view; a bent
element's box is a little larger, so the curved rows' figures are slight overestimates).

    /usr/bin/python3 bench/curved_cost.py [--build build] [--elements 8] [--res 128]
        [--orders 2,4,8] [--geometry 0,1,2,4]

Figures: docs/performance.md, "High-order elements: affine and curved hexahedra"; tables by
p and q: docs/history/benchmarks-log.md, "Curved elements".
"""
import argparse
import json
import os
import subprocess
import sys


def run(binary, elements, order, curved, res):
    out = subprocess.run(
        [binary, "--only", "elements", "--grid-points", "8", "--elements", str(elements),
         "--order", str(order), "--curved", str(curved), "--res", str(res), "--json"],
        check=True, capture_output=True, text=True).stdout
    lines = [line for line in out.splitlines() if line.startswith("{")]
    if not lines:
        sys.exit(f"curved_cost.py: no JSON line from {binary}")
    casts = json.loads(lines[-1])["casts"]
    by_threads = {row["threads"]: row for row in casts if row["caster"] == "coherent"}
    if 1 not in by_threads:
        sys.exit("curved_cost.py: no one-thread cast row")
    return by_threads


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--build", default="build")
    parser.add_argument("--elements", type=int, default=8)
    parser.add_argument("--res", type=int, default=128)
    parser.add_argument("--orders", default="2,4,8")
    parser.add_argument("--geometry", default="0,1,2,4")
    args = parser.parse_args()
    binary = os.path.join(args.build, "bin", "ldimesh_bench_sources")
    if not os.access(binary, os.X_OK):
        sys.exit(f"curved_cost.py: {binary} not found (build with scripts/build.sh)")
    pixels = 3 * (args.res / args.elements) ** 2
    print(f"{args.elements}³ elements over [−1, 1]³, Marschner–Lobb at 0.5, GLL, "
          f"3 × {args.res}²; pairs = culled elements × 3 × ({args.res}/{args.elements})²\n")
    print("| p | geometry | elements after culling | hits | 1 thread s | all threads s "
          "| Mrays/s (all) | ns per pair (1 thread) | × affine |")
    print("|---|---|---|---|---|---|---|---|---|")
    for order in [int(p) for p in args.orders.split(",")]:
        affine = None
        for curved in [int(q) for q in args.geometry.split(",")]:
            rows = run(binary, args.elements, order, curved, args.res)
            one = rows[1]
            most = rows[max(rows)]
            pairs = one["primitives"] * pixels
            ns = one["seconds"] / pairs * 1e9 if pairs else float("nan")
            if curved == 0:
                affine = ns
            ratio = f"{ns / affine:.0f}" if affine else "—"
            label = "affine (corners)" if curved == 0 else f"q = {curved}"
            print(f"| {order} | {label} | {one['primitives']} | {one['hits']} | "
                  f"{one['seconds']:.3f} | {most['seconds']:.3f} | "
                  f"{most['rays'] / most['seconds'] * 1e-6:.3f} | {ns:.0f} | {ratio} |",
                  flush=True)


if __name__ == "__main__":
    main()
