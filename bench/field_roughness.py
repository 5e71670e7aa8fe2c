#!/usr/bin/python3
"""How far a colour field on a mesh can be predicted: what Draco's parallelogram prediction of a
_SCALAR attribute has to work with.

For each binary little-endian PLY with a per-vertex property `value` (ldimesh mesh --colour-by
--out X.ply, ldimesh-fetch --ply of a coloured step), the field is quantized as the GLB does it
(over its range, --bits bits) and, over every pair of triangles that share an edge (a, b) with
opposite vertices c and d:

- the step along the edge, |q(a) − q(b)|, in quantization levels;
- the parallelogram residual q(d) − (q(a) + q(b) − q(c)) (Draco's prediction for a vertex of a
  triangle across an edge), its mean size and the entropy of its values in bits: about the bits
  per vertex an entropy coder needs for the field after that prediction;
- the same for the positions, the residual's length against the median edge length.

A smooth field has residuals far smaller than its steps (a linear one: 0); a field that changes
at the scale of the mesh's edges has residuals as large as its steps, and costs about as many
bits a vertex as it was quantized to.

    /usr/bin/python3 bench/field_roughness.py [--bits 8] MESH.ply...
"""
import argparse
import sys

import numpy as np

PLY_TYPES = {"char": "i1", "uchar": "u1", "int8": "i1", "uint8": "u1", "short": "<i2",
             "ushort": "<u2", "int16": "<i2", "uint16": "<u2", "int": "<i4", "uint": "<u4",
             "int32": "<i4", "uint32": "<u4", "float": "<f4", "float32": "<f4",
             "double": "<f8", "float64": "<f8"}


def read_ply(path):
    """Vertex properties (name → array) and triangles of a binary little-endian PLY."""
    data = open(path, "rb").read()
    end = data.find(b"end_header\n")
    if not data.startswith(b"ply\n") or end < 0:
        sys.exit(f"{path}: not a PLY file")
    header = data[:end].decode("ascii", "replace").splitlines()
    if "format binary_little_endian 1.0" not in header:
        sys.exit(f"{path}: only binary little-endian PLY files are read")
    elements = []  # [name, count, [(property, dtype) | (property, count dtype, item dtype)]]
    for line in header:
        w = line.split()
        if w[:1] == ["element"]:
            elements.append([w[1], int(w[2]), []])
        elif w[:1] == ["property"]:
            if w[1] == "list":
                elements[-1][2].append((w[4], PLY_TYPES[w[2]], PLY_TYPES[w[3]]))
            else:
                elements[-1][2].append((w[2], PLY_TYPES[w[1]]))
    offset = end + len(b"end_header\n")
    vertices, triangles = {}, None
    for name, count, props in elements:
        if all(len(p) == 2 for p in props):
            dtype = np.dtype([(p[0], p[1]) for p in props])
            table = np.frombuffer(data, dtype, count, offset)
            offset += dtype.itemsize * count
            if name == "vertex":
                vertices = {p[0]: table[p[0]].astype(np.float64) for p in props}
            continue
        if name != "face":
            sys.exit(f"{path}: a list property outside the face element")
        # Faces of triangles only, as ldimesh writes them: a fixed record per face.
        fields = []
        for p in props:
            if len(p) == 3:
                fields += [(p[0] + "_n", p[1]), (p[0], p[2], 3)]
            else:
                fields.append(p)
        dtype = np.dtype(fields)
        table = np.frombuffer(data, dtype, count, offset)
        list_name = next(p[0] for p in props if len(p) == 3)
        if count and not np.all(table[list_name + "_n"] == 3):
            sys.exit(f"{path}: faces other than triangles")
        triangles = table[list_name].astype(np.int64)
        offset += dtype.itemsize * count
    if triangles is None or "value" not in vertices:
        sys.exit(f"{path}: needs vertices with a 'value' property and triangles")
    return vertices, triangles


def entropy(values):
    _, counts = np.unique(values, return_counts=True)
    p = counts / counts.sum()
    return float(-(p * np.log2(p)).sum())


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--bits", type=int, default=8, help="quantization bits of the field")
    parser.add_argument("meshes", nargs="+")
    args = parser.parse_args()
    print("| mesh | vertices | triangles | step along an edge (levels, median / mean) | "
          "parallelogram residual (levels, mean) | residual entropy (bits / vertex) | "
          "position residual / edge |")
    print("|---|---|---|---|---|---|---|")
    for path in args.meshes:
        v, t = read_ply(path)
        value = v["value"]
        lo, hi = value.min(), value.max()
        levels = (1 << args.bits) - 1
        q = np.round((value - lo) / (hi - lo if hi > lo else 1.0) * levels).astype(np.int64)
        p = np.stack([v["x"], v["y"], v["z"]], axis=1)
        edges = np.concatenate([t[:, [0, 1]], t[:, [1, 2]], t[:, [2, 0]]])
        opposite = np.concatenate([t[:, 2], t[:, 0], t[:, 1]])
        key = np.sort(edges, axis=1)
        order = np.lexsort((key[:, 1], key[:, 0]))
        key, opposite = key[order], opposite[order]
        shared = np.nonzero(np.all(key[1:] == key[:-1], axis=1))[0]
        a, b = key[shared, 0], key[shared, 1]
        c, d = opposite[shared], opposite[shared + 1]
        step = np.abs(q[a] - q[b])
        residual = q[d] - (q[a] + q[b] - q[c])
        edge = np.median(np.linalg.norm(p[a] - p[b], axis=1))
        moved = np.median(np.linalg.norm(p[d] - (p[a] + p[b] - p[c]), axis=1))
        print(f"| {path} | {len(value)} | {len(t)} | {int(np.median(step))} / {step.mean():.1f} | "
              f"{np.abs(residual).mean():.1f} | {entropy(residual):.2f} | "
              f"{moved / edge if edge > 0 else 0.0:.2f} |")


if __name__ == "__main__":
    main()
