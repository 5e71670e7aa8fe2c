#!/usr/bin/python3
"""sphere_vertices.py MESH.ply TOLERANCE [closed]: every vertex of the binary PLY (x, y, z floats
first, as ldimesh writes it) within TOLERANCE of the sphere |x| = 0.7, and with `closed` every
edge shared by exactly two faces. Exit status 0 when so; prints the figures."""
import struct, sys, math
data = open(sys.argv[1], "rb").read()
header, body = data.split(b"end_header\n", 1)
lines = header.decode().splitlines()
n = int(next(l for l in lines if l.startswith("element vertex")).split()[2])
f = int(next(l for l in lines if l.startswith("element face")).split()[2])
worst = max(abs(math.sqrt(sum(c * c for c in struct.unpack_from("<3f", body, 24 * v))) - 0.7) for v in range(n))
off, edges = 24 * n, {}
for _ in range(f):
    k = body[off]; ids = struct.unpack_from("<%dI" % k, body, off + 1); off += 1 + 4 * k + 1
    for a, b in zip(ids, ids[1:] + ids[:1]):
        e = (min(a, b), max(a, b)); edges[e] = edges.get(e, 0) + 1
open_edges = sum(1 for c in edges.values() if c != 2)
print(f"{sys.argv[1]}: {n} vertices, {f} faces, largest | |x| - 0.7 | {worst:.1e}, {open_edges} edges not shared by two faces")
sys.exit(0 if worst < float(sys.argv[2]) and (len(sys.argv) < 4 or open_edges == 0) else 1)
