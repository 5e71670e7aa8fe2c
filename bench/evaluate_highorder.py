"""High-order data beside VTK: the section of bench/evaluate on VTU files of Lagrange hexahedra.

The same files contoured three ways:
- VTK's vtkContourFilter on the VTK_LAGRANGE_HEXAHEDRON cells, as ParaView does (each cell is
  contoured as the linear cells between its nodes);
- VTK's vtkTessellatorFilter (1–3 subdivisions of the cells' tetrahedra, every edge split: a
  field criterion at 10⁻¹² on the contoured array) then vtkContourFilter on the tetrahedra;
- ldimesh mesh --vtu (the cells' polynomials intersected exactly), at several LDI resolutions.
Forward distance: ldimesh distance --vtu, to the exact isosurface of the cells' polynomials (the
data's own surface: the point's element found, its map inverted, Newton steps on the
polynomial). Backward: from the vertices of a reference (VTK's finest tessellation contoured,
its vertices projected onto that isosurface with ldimesh_project_mesh --vtu) to each mesh.

Data: Marschner–Lobb sampled on 16³ order-4 cells (VTK Lagrange nodes, straight cells); a
curved shell (a cubed sphere of order-4 cells, geometry of order 4) carrying a smooth field; a
deal.II output (the mini-app's DataOut with write_higher_order_cells, FE_Q(4) on MappingQ(4)).
Used by bench/evaluate.py; not a program of its own.
"""
import json
import math
import os
import statistics
import subprocess
import sys
import time

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))

# Resolutions tried for ldimesh (pixels along the longer side of each view).
LADDER = [24, 32, 48, 64, 96, 128, 192, 256, 384, 512]
QUICK_LADDER = [32, 64, 128]
# The tessellation levels VTK runs, as long as their tetrahedra stay below this many (each
# level multiplies them by 8).
TESSELLATE_LEVELS = [1, 2, 3]
MAX_TETS = 2.0e7
QUICK_MAX_TETS = 2.0e6


def ml_field(x, y, z):
    import numpy as np
    r = np.sqrt(x * x + y * y)
    rho = np.cos(2.0 * np.pi * 6.0 * np.cos(0.5 * np.pi * r))
    return (1.0 - np.sin(0.5 * np.pi * z) + 0.25 * (1.0 + rho)) / (2.0 * 1.25)


def shell_field(p):
    import numpy as np
    return (np.linalg.norm(p, axis=1) + 0.1 * np.sin(4.0 * p[:, 0]) * np.sin(4.0 * p[:, 1] + 1.0)
            * np.sin(4.0 * p[:, 2] + 2.0))


def write_lagrange_vtu(path, points, cells, order, values, name):
    """A VTK XML unstructured grid of VTK_LAGRANGE_HEXAHEDRON cells (each row of `cells` the
    point ids in VTK's node order), written by VTK's own writer."""
    import numpy as np
    from vtkmodules.util.numpy_support import numpy_to_vtk, numpy_to_vtkIdTypeArray
    from vtkmodules.vtkCommonCore import vtkPoints
    from vtkmodules.vtkCommonDataModel import (VTK_LAGRANGE_HEXAHEDRON, vtkCellArray,
                                               vtkUnstructuredGrid)
    from vtkmodules.vtkIOXML import vtkXMLUnstructuredGridWriter
    grid = vtkUnstructuredGrid()
    vp = vtkPoints()
    vp.SetData(numpy_to_vtk(np.ascontiguousarray(points, dtype=float), deep=1))
    grid.SetPoints(vp)
    n = len(cells)
    conn = np.hstack([np.full((n, 1), (order + 1) ** 3), cells]).ravel().astype(np.int64)
    ca = vtkCellArray()
    ca.SetCells(n, numpy_to_vtkIdTypeArray(conn, deep=1))
    grid.SetCells(VTK_LAGRANGE_HEXAHEDRON, ca)
    a = numpy_to_vtk(np.ascontiguousarray(values, dtype=float), deep=1)
    a.SetName(name)
    grid.GetPointData().AddArray(a)
    w = vtkXMLUnstructuredGridWriter()
    w.SetFileName(path)
    w.SetInputData(grid)
    w.SetDataModeToAppended()
    if not w.Write():
        sys.exit(f"evaluate: writing {path} failed")


def vtk_order(order):
    """perm[k] = lexicographic index i + (p+1)(j + (p+1)k) of VTK's k-th Lagrange node."""
    from vtkmodules.vtkCommonDataModel import vtkLagrangeHexahedron
    m = order + 1
    perm = [0] * m ** 3
    for k in range(m):
        for j in range(m):
            for i in range(m):
                perm[vtkLagrangeHexahedron.PointIndexFromIJK(i, j, k, [order] * 3)] = \
                    i + m * (j + m * k)
    return perm


def write_ml(path, n, p):
    """Marschner–Lobb on n³ straight order-p cells over [-1, 1]³, one lattice of points."""
    import numpy as np
    m = n * p + 1
    g = np.linspace(-1.0, 1.0, m)
    Z, Y, X = np.meshgrid(g, g, g, indexing="ij")
    points = np.stack([X.ravel(), Y.ravel(), Z.ravel()], 1)
    values = ml_field(X, Y, Z).ravel()
    q = p + 1
    lex = np.array([i + m * (j + m * k) for k in range(q) for j in range(q) for i in range(q)])
    local = lex[vtk_order(p)]
    cells = [local + (ci * p + m * (cj * p + m * ck * p))
             for ck in range(n) for cj in range(n) for ci in range(n)]
    write_lagrange_vtu(path, points, np.array(cells), p, values, "f")
    return n ** 3


def write_shell(path, n, layers, p, r0=0.5, r1=1.0):
    """A spherical shell r0 ≤ |x| ≤ r1 as a cubed sphere (equiangular) of 6 n² `layers`
    order-p cells, every node on the sphere of its radius, each cell its own points (as
    DataOut writes them), carrying shell_field."""
    import numpy as np
    t = np.linspace(0.0, 1.0, p + 1)
    lex = [(i, j, k) for k in range(p + 1) for j in range(p + 1) for i in range(p + 1)]
    perm = vtk_order(p)
    points, cells = [], []
    for axis in range(3):
        for sign in (1.0, -1.0):
            for layer in range(layers):
                for pj in range(n):
                    for pi in range(n):
                        cell = np.empty(((p + 1) ** 3, 3))
                        for idx, (i, j, k) in enumerate(lex):
                            u = math.tan(0.25 * math.pi * (-1.0 + 2.0 * (pi + t[i]) / n))
                            v = math.tan(0.25 * math.pi * (-1.0 + 2.0 * (pj + t[j]) / n))
                            c = [0.0, 0.0, 0.0]
                            c[axis] = sign
                            c[(axis + 1) % 3] = u
                            c[(axis + 2) % 3] = v
                            r = r0 + (r1 - r0) * (layer + t[k]) / layers
                            cell[idx] = r * np.array(c) / math.sqrt(1.0 + u * u + v * v)
                        base = len(points) * (p + 1) ** 3
                        points.append(cell)
                        cells.append([base + perm[q] for q in range((p + 1) ** 3)])
    points = np.concatenate(points)
    write_lagrange_vtu(path, points, np.array(cells), p, shell_field(points), "f")
    return len(cells)


class HighOrder:
    def __init__(self, ev, log, run, run_json, fmt_int):
        self.ev, self.log, self.run, self.run_json, self.fmt_int = ev, log, run, run_json, fmt_int
        self.args = ev.args
        self.quick = ev.args.quick
        self.work = os.path.join(ev.work, "highorder")
        os.makedirs(self.work, exist_ok=True)
        self.max_tets = QUICK_MAX_TETS if self.quick else MAX_TETS
        self.ladder = QUICK_LADDER if self.quick else LADDER

    def tool(self, name):
        return os.path.join(self.ev.bin, name)

    # ---- the data ----

    def datasets(self):
        sets = []
        n = 8 if self.quick else 16
        path = os.path.join(self.work, f"ml_{n}_p4.vtu")
        cells = write_ml(path, n, 4)
        sets.append({"key": "ml", "name": f"Marschner–Lobb, {n}³ cells of order 4",
                     "path": path, "field": "f", "iso": 0.5, "cells": cells, "order": 4,
                     "crop": [[0.0, 0.0, -1.0], [1.0, 1.0, 1.0]],
                     "origin": "written by VTK (vtkXMLUnstructuredGridWriter) from the field "
                               "sampled at the cells' equispaced nodes; straight cells"})
        if not self.quick:
            path = os.path.join(self.work, "shell_p4.vtu")
            cells = write_shell(path, 4, 2, 4)
            sets.append({"key": "shell", "name": "curved shell, cells of order 4",
                         "path": path, "field": "f", "iso": 0.75, "cells": cells, "order": 4,
                         "origin": "written by VTK: a cubed sphere 0.5 ≤ |x| ≤ 1 (4 × 4 patches "
                                   "per face, 2 layers), geometry of order 4 on the spheres, "
                                   "f = |x| + 0.1 sin 4x sin(4y + 1) sin(4z + 2)"})
            d = self.dealii()
            if d:
                sets.append(d)
        return sets

    def dealii(self):
        app = self.tool("ldimesh-dealii")
        if not os.path.exists(app):
            self.log("  high-order: build/bin/ldimesh-dealii missing (deal.II not installed): "
                     "the deal.II data set is left out")
            self.skipped_dealii = True
            return None
        out = os.path.join(self.work, "dealii")
        os.makedirs(out, exist_ok=True)
        options = os.path.join(self.work, "dealii_options.json")
        with open(options, "w") as f:
            json.dump({"server": {"enabled": False}, "output_dir": os.path.join(out, "steps"),
                       "resolution": 64}, f)
        cmd = ["mpiexec", "-n", "2", "--oversubscribe"]
        if os.geteuid() == 0:
            cmd.append("--allow-run-as-root")
        cmd += [app, "--order", "4", "--refinements", "2", "--steps", "100", "--output-every",
                "100", "--options", options, "--vtu", os.path.join(out, "vtu")]
        self.run(cmd, "the deal.II mini-app")
        return {"key": "dealii", "name": "deal.II heat equation, cells of order 4",
                "path": os.path.join(out, "vtu", "solution_0001.pvtu"), "field": "u",
                "iso": 0.5, "cells": 384, "order": 4,
                "origin": "miniapps/dealii on 2 ranks (FE_Q(4), MappingQ(4) on a refined "
                          "hyper_shell, two heat blobs after 100 explicit Euler steps), written "
                          "by DataOut with write_higher_order_cells (.pvtu over two pieces)"}

    # ---- VTK ----

    def vtk_meshes(self, ds):
        """VTK's contour on the Lagrange cells and after each tessellation level: PLY files,
        triangles, seconds (median of the repeats; the file's reading not counted)."""
        from vtkmodules.vtkFiltersCore import vtkContourFilter
        from vtkmodules.vtkFiltersGeneral import vtkTessellatorFilter
        from vtkmodules.vtkIOPLY import vtkPLYWriter
        from vtkmodules.vtkIOXML import (vtkXMLPUnstructuredGridReader,
                                         vtkXMLUnstructuredGridReader)
        reader = (vtkXMLPUnstructuredGridReader() if ds["path"].endswith(".pvtu")
                  else vtkXMLUnstructuredGridReader())
        reader.SetFileName(ds["path"])
        reader.Update()
        grid = reader.GetOutput()
        grid.GetPointData().SetActiveScalars(ds["field"])
        ds["cells"] = grid.GetNumberOfCells()
        rows = []

        def contour(data):
            c = vtkContourFilter()
            c.SetInputData(data)
            c.SetValue(0, ds["iso"])
            c.ComputeScalarsOff()
            c.Update()
            return c.GetOutput()

        def save(poly, name):
            path = os.path.join(self.work, f"{ds['key']}_{name}.ply")
            w = vtkPLYWriter()
            w.SetFileName(path)
            w.SetInputData(poly)
            w.SetFileTypeToBinary()
            w.Write()
            return path

        times = []
        for _ in range(self.args.repeat):
            t = time.perf_counter()
            poly = contour(grid)
            times.append(time.perf_counter() - t)
        rows.append({"method": "contour", "level": 0, "triangles": poly.GetNumberOfCells(),
                     "vertices": poly.GetNumberOfPoints(), "seconds": statistics.median(times),
                     "ply": save(poly, "vtk_contour")})
        self.log(f"  {ds['key']}: VTK contour of the Lagrange cells: "
                 f"{self.fmt_int(rows[-1]['triangles'])} triangles, {rows[-1]['seconds']:.3f} s")
        for level in TESSELLATE_LEVELS:
            tets = ds["cells"] * 48 * 8 ** level
            if tets > self.max_tets:
                rows.append({"method": "tessellate", "level": level, "skipped": True,
                             "tets_estimate": tets})
                self.log(f"  {ds['key']}: tessellation level {level} left out "
                         f"(~{tets / 1e6:.0f} M tetrahedra)")
                continue
            times, tess_times = [], []
            # One run where it takes long; the median of the repeats otherwise.
            for k in range(self.args.repeat):
                t = time.perf_counter()
                tf = vtkTessellatorFilter()
                tf.SetInputData(grid)
                tf.SetMaximumNumberOfSubdivisions(level)
                tf.SetChordError(1e-12)
                tf.SetFieldCriterion(0, 1e-12)
                tf.MergePointsOn()
                tf.Update()
                t_tess = time.perf_counter() - t
                tess = tf.GetOutput()
                tess.GetPointData().SetActiveScalars(ds["field"])
                poly = contour(tess)
                times.append(time.perf_counter() - t)
                tess_times.append(t_tess)
                cells = tess.GetNumberOfCells()
                del tf, tess
                if times[-1] > 5.0:
                    break
            rows.append({"method": "tessellate", "level": level, "tets": cells,
                         "triangles": poly.GetNumberOfCells(),
                         "vertices": poly.GetNumberOfPoints(),
                         "seconds": statistics.median(times),
                         "tessellate_seconds": statistics.median(tess_times),
                         "ply": save(poly, f"vtk_tess{level}")})
            self.log(f"  {ds['key']}: VTK tessellation level {level} ({self.fmt_int(cells)} "
                     f"tetrahedra) + contour: {self.fmt_int(rows[-1]['triangles'])} triangles, "
                     f"{rows[-1]['seconds']:.2f} s")
        return rows

    # ---- ldimesh ----

    def ours(self, ds, res, r=0.5):
        path = os.path.join(self.work, f"{ds['key']}_ours_{res}" +
                            ("" if r == 0.5 else f"_r{r:g}") + ".ply")
        runs = []
        for k in range(self.args.repeat):
            cmd = [self.tool("ldimesh"), "mesh", "--vtu", ds["path"], "--field", ds["field"],
                   "--iso", str(ds["iso"]), "--res", str(res), "--views", "xyz", "--r", str(r),
                   "--lossless", "--json"]
            if k == 0:
                cmd += ["--out", path]
            runs.append(self.run_json(cmd, f"ldimesh mesh --vtu {ds['key']} {res}"))
        j = runs[0]
        # Building the element sources from the cells read counts (VTK's contour gets the
        # cells as read too); reading the file does not.
        total = statistics.median(sum(r["seconds"].get(k, 0.0) for k in
                                      ("prepare", "scene", "raycast", "match", "trim", "assemble"))
                                  for r in runs)
        return {"method": "ldimesh", "res": res, "r": r, "triangles": j["triangles"],
                "vertices": j["vertices"], "threads": j["threads"], "seconds": total,
                "load_seconds": statistics.median(r["seconds"]["load"] for r in runs),
                "ply": path}

    # ---- distances ----

    def forward(self, ds, m):
        s = self.ev.metro_samples(m["triangles"], m["vertices"])
        a = self.run_json([self.tool("ldimesh"), "distance", m["ply"], "--vtu", ds["path"],
                           "--field", ds["field"], "--iso", str(ds["iso"]), "--samples", str(s),
                           "--json"], f"distance {m['ply']} → the cells' isosurface")
        m.update({"fwd_mean": a["forward"]["mean"], "fwd_rms": a["forward"]["rms"],
                  "fwd_max": a["forward"]["max"], "fwd_samples": a["forward"]["samples"],
                  "fwd_left_out": a["not_converged"] + a["outside_clip"],
                  "diagonal": a["diagonal"]})
        if ds.get("reference"):
            b = self.run_json([self.tool("ldimesh"), "distance", ds["reference"]["ply"],
                               m["ply"], "--samples", "1", "--json"],
                              f"distance reference → {m['ply']}")
            m.update({"bwd_mean": b["forward"]["mean"], "bwd_max": b["forward"]["max"]})
            # A cross-check of the projection (which may end on a farther sheet where the
            # field is flat): the same samples' distance to the reference mesh.
            c = self.run_json([self.tool("ldimesh"), "distance", m["ply"],
                               ds["reference"]["ply"], "--samples", str(s), "--json"],
                              f"distance {m['ply']} → reference")
            m.update({"fwd_ref_mean": c["forward"]["mean"], "fwd_ref_max": c["forward"]["max"]})
        return m

    def reference(self, ds, vtk_rows):
        """VTK's finest tessellation's contour, its vertices projected onto the cells'
        isosurface."""
        finest = [r for r in vtk_rows if not r.get("skipped")][-1]
        path = os.path.join(self.work, f"{ds['key']}_reference.ply")
        proj = self.run_json([self.tool("ldimesh_project_mesh"), "--vtu", ds["path"], "--field",
                              ds["field"], "--iso", str(ds["iso"]), "--in", finest["ply"],
                              "--out", path, "--drop-failed"],
                             f"projecting the {ds['key']} reference")
        ds["reference"] = {"from": f"{finest['method']} {finest['level']}", "ply": path,
                           "vertices": proj["vertices"], "triangles": proj["faces"],
                           "failed": proj["failed"] + proj["too_far"],
                           "dropped_faces": proj["dropped_faces"],
                           "max_move": proj["max_move"]}
        self.log(f"  {ds['key']}: reference: VTK {finest['method']} level {finest['level']}, "
                 f"{self.fmt_int(proj['vertices'])} vertices projected (largest move "
                 f"{proj['max_move']:.1e}; {ds['reference']['failed']} not, their "
                 f"{proj['dropped_faces']} faces dropped)")

    def equal_triangles(self, ds, target, tried, r=0.5):
        """ldimesh (trimming parameter r) at the resolution whose triangle count is closest to
        `target` (a search on triangles ∝ res²; `tried` maps res → result, for this r)."""
        def get(res):
            if res not in tried:
                tried[res] = self.ours(ds, res, r)
            return tried[res]
        probe = get(64)
        if not probe["triangles"]:
            return probe
        res = max(8, int(round(64 * math.sqrt(target / probe["triangles"]))))
        for _ in range(3):
            m = get(res)
            nxt = max(8, int(round(res * math.sqrt(target / max(m["triangles"], 1)))))
            if nxt == res or abs(m["triangles"] - target) <= 0.02 * target:
                break
            res = nxt
        return min((m for m in tried.values()), key=lambda m: abs(m["triangles"] - target))

    # ---- the section ----

    def evaluate(self):
        t0 = time.monotonic()
        self.skipped_dealii = False
        results = {"datasets": [], "ladder": self.ladder, "max_tets": self.max_tets,
                   "vtk_version": self.ev.results.get("machine", {}).get("vtk", "9")}
        for ds in self.datasets():
            self.log(f"high-order: {ds['name']}")
            vtk_rows = self.vtk_meshes(ds)
            self.reference(ds, vtk_rows)
            for r in vtk_rows:
                if not r.get("skipped"):
                    self.forward(ds, r)
            tried = {}
            for res in self.ladder:
                tried[res] = self.ours(ds, res)
            ladder = [self.forward(ds, tried[res]) for res in self.ladder]
            equal = []
            tried_r1 = {}  # r = 1: each vertex kept by its best view only (fewer triangles)
            for r in vtk_rows:
                if r.get("skipped"):
                    continue
                m = self.equal_triangles(ds, r["triangles"], tried)
                m1 = self.equal_triangles(ds, r["triangles"], tried_r1, r=1.0)
                for x in (m, m1):
                    if "fwd_mean" not in x:
                        self.forward(ds, x)
                equal.append({"vtk": f"{r['method']} {r['level']}", "ours": m, "ours_r1": m1})
                self.log(f"  {ds['key']}: at {self.fmt_int(r['triangles'])} triangles "
                         f"(VTK {r['method']} {r['level']}): forward mean VTK "
                         f"{r['fwd_mean']:.2e}, ours {m['fwd_mean']:.2e} (LDI {m['res']}², "
                         f"{self.fmt_int(m['triangles'])} triangles; r = 1: {m1['fwd_mean']:.2e})")
            for m in ladder:
                self.log(f"  {ds['key']}: ours LDI {m['res']}²: {self.fmt_int(m['triangles'])} "
                         f"triangles, {m['seconds']:.3f} s, forward mean {m['fwd_mean']:.2e}")
            results["datasets"].append({k: v for k, v in ds.items()} |
                                       {"vtk": vtk_rows, "ladder": ladder, "equal": equal})
        results["dealii_skipped"] = self.skipped_dealii
        results["seconds"] = time.monotonic() - t0
        return results

    # ---- figures ----

    def figures(self, results, fig_dir):
        """Per data set: distance against triangles and seconds against distance (VTK's rows,
        our ladder), and the meshes side by side. Returns {key: (plot, image)} file names."""
        import matplotlib
        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
        import numpy as np
        from mesh_figures import draw_shaded, load_triangles
        files = {}
        colours = {"contour": "tab:red", "tessellate": "tab:orange"}
        for ds in results["datasets"]:
            diag = ds["ladder"][0]["diagonal"]
            fig, axes = plt.subplots(1, 3, figsize=(14, 4.2), dpi=110)
            ours = sorted(ds["ladder"], key=lambda m: m["triangles"])
            vtk_rows = [r for r in ds["vtk"] if not r.get("skipped")]
            panels = [("triangles", "fwd_mean", "forward mean (mesh → exact isosurface)"),
                      ("triangles", "bwd_mean", "backward mean (reference → mesh)"),
                      ("fwd_mean", "seconds", "seconds (reading not counted) vs forward mean")]
            for ax, (xk, yk, title) in zip(axes, panels):
                def xy(rows):
                    xs = [r[xk] if xk == "triangles" else 100 * r[xk] / diag for r in rows]
                    ys = [r[yk] if yk == "seconds" else 100 * max(r[yk], 1e-12) / diag
                          for r in rows]
                    return xs, ys
                ax.loglog(*xy(ours), "o-", color="tab:blue", ms=4,
                          label=f"ldimesh (LDI, 3 views, {ours[0]['threads']} threads)")
                for m, (x, y) in zip(ours, zip(*xy(ours))):
                    ax.annotate(f"{m['res']}²", (x, y), textcoords="offset points",
                                xytext=(4, 4), fontsize=7, color="tab:blue")
                for r in vtk_rows:
                    (x,), (y,) = xy([r])
                    label = ("VTK contour (Lagrange cells)" if r["method"] == "contour" else
                             f"VTK tessellate {r['level']} + contour")
                    ax.loglog([x], [y], "s" if r["method"] == "contour" else "D",
                              color=colours[r["method"]], ms=6, label=label)
                ax.set_xlabel("triangles" if xk == "triangles" else "forward mean, % of diagonal")
                ax.set_ylabel("seconds" if yk == "seconds" else "% of the diagonal")
                ax.set_title(title, fontsize=9)
                ax.grid(True, which="both", alpha=0.3)
                ax.legend(fontsize=7)
            fig.suptitle(f"{ds['name']}: ldimesh beside VTK", fontsize=11)
            fig.tight_layout()
            plot = f"highorder_{ds['key']}.png"
            fig.savefig(os.path.join(fig_dir, plot))
            plt.close(fig)

            # The meshes: VTK's contour of the Lagrange cells, ours at its triangle count, and
            # VTK's first tessellation (when small enough to draw).
            contour = next(r for r in vtk_rows if r["method"] == "contour")
            same = next(e["ours"] for e in ds["equal"] if e["vtk"] == "contour 0")
            items = [(contour, f"VTK contour of the Lagrange cells\n"
                               f"{self.fmt_int(contour['triangles'])} triangles", (1.0, 0.72, 0.55)),
                     (same, f"ldimesh, LDI {same['res']}²\n"
                            f"{self.fmt_int(same['triangles'])} triangles", (0.55, 0.7, 1.0))]
            tess = [r for r in vtk_rows if r["method"] == "tessellate"
                    and r["triangles"] <= 400000]
            if tess:
                items.append((tess[0], f"VTK tessellate {tess[0]['level']} + contour\n"
                                       f"{self.fmt_int(tess[0]['triangles'])} triangles",
                              (1.0, 0.85, 0.5)))
            crop = ds.get("crop")
            fig = plt.figure(figsize=(5 * len(items), 5.4), dpi=100)
            for k, (m, title, rgb) in enumerate(items):
                # results.json holds relative paths
                tri = load_triangles(os.path.join(ROOT, m["ply"]))
                if crop:
                    c = tri.mean(axis=1)
                    tri = tri[np.all((c >= crop[0]) & (c <= crop[1]), axis=1)]
                lo, hi = (np.array(crop[0]), np.array(crop[1])) if crop else \
                    (tri.reshape(-1, 3).min(axis=0), tri.reshape(-1, 3).max(axis=0))
                draw_shaded(fig, (1, len(items), k + 1), tri, rgb, lo, hi, title, 1.2)
            fig.subplots_adjust(left=0.0, right=1.0, bottom=0.0, top=0.9, wspace=0.0)
            image = f"highorder_mesh_{ds['key']}.png"
            fig.savefig(os.path.join(fig_dir, image))
            plt.close(fig)
            files[ds["key"]] = (plot, image)
            self.log(f"  high-order figures {plot}, {image}")
        return files

    # ---- the report ----

    @staticmethod
    def goals(ds):
        """Per VTK row: ours at its triangle count (the forward means' ratio) and the cheapest
        of our ladder at least as accurate (the seconds' ratio)."""
        rows = []
        for e in ds["equal"]:
            v = next(r for r in ds["vtk"] if f"{r['method']} {r['level']}" == e["vtk"])
            o = e["ours"]
            accurate = [m for m in ds["ladder"] if m["fwd_mean"] <= v["fwd_mean"]]
            cheapest = min(accurate, key=lambda m: m["seconds"]) if accurate else None
            o1 = e.get("ours_r1")
            rows.append({"vtk": v, "ours": o, "ratio": o["fwd_mean"] / v["fwd_mean"],
                         "ours_r1": o1,
                         "ratio_r1": o1["fwd_mean"] / v["fwd_mean"] if o1 else None,
                         "accurate": cheapest,
                         "speedup": v["seconds"] / cheapest["seconds"] if cheapest else None})
        return rows

    def report(self, R, w, fmt_e, fmt_pct, fmt_s):
        fmt_int = self.fmt_int
        w("## High-order data: beside VTK on Lagrange cells")
        w("")
        w("Files of `VTK_LAGRANGE_HEXAHEDRON` cells (issue 24), contoured three ways "
          "(bench/evaluate_highorder.py):")
        w("")
        w("- **VTK contour**: `vtkContourFilter` on the Lagrange cells, what ParaView does: VTK "
          "contours each cell as the p³ linear cells between its nodes.")
        w("- **VTK tessellate L + contour**: `vtkTessellatorFilter` with L subdivisions (the "
          "cells' tetrahedra split L times, every edge: the field criterion at 10⁻¹² on the "
          "contoured array), then `vtkContourFilter` on the tetrahedra. Each level multiplies the "
          f"tetrahedra by 8; levels beyond {R['max_tets'] / 1e6:.0f} M tetrahedra are left out "
          "(Marschner–Lobb at level 3: 100 M tetrahedra; measured once while writing this "
          "section, 5 min).")
        w("- **ldimesh**: `ldimesh mesh --vtu FILE --field NAME --iso V --res R --views xyz "
          "--r 0.5 --lossless` (the cells' polynomials intersected exactly; §3 meshing and "
          "trimming, no §4/§5), at the resolutions "
          f"{', '.join(f'{r}²' for r in R['ladder'])}, and at the resolution whose triangle "
          "count is closest to each VTK mesh's — also with `--r 1` there (each vertex kept by "
          "its best view only: the views' patches overlap less, fewer triangles for the same "
          "accuracy).")
        w("- **Forward distance** (mesh → exact isosurface): `ldimesh distance M.ply --vtu FILE "
          "--field NAME --iso V`, Metro samples as above, each projected onto the isosurface of "
          "the cells' own polynomials — the data's exact surface, not an approximation of it "
          "(`HexFieldLookup`: the element holding a point, its map inverted by Newton's method, "
          "the polynomial and its gradient J⁻ᵀ∇ξf there). Samples whose projection leaves the "
          "cells are left out (counted in results.json). \"fwd vs ref\": the same samples' "
          "distance to the reference mesh, a cross-check of the projection (which can end on a "
          "farther sheet where the field is nearly flat; the reference's chords add to it).")
        w("- **Backward distance** (reference → mesh): the vertices of a reference to the "
          "closest point of each mesh. The reference is VTK's finest tessellation's contour with "
          "every vertex projected onto the exact isosurface (`ldimesh_project_mesh --vtu "
          "--drop-failed`: faces of vertices that do not converge within 1 % of the diagonal "
          "are dropped), so its vertices are exact points of the surface. That VTK row's own "
          "backward figure is its vertices' projection distance, not an independent measure.")
        w("- **Seconds**: without reading the file (VTK's reader is ours too). VTK "
          f"{R.get('vtk_version', '9')}: tessellation + contour in-process, the median of the "
          "repeats (one run where it takes over 5 s); `vtkTessellatorFilter` and the contour of "
          "the Lagrange cells run on one thread, the contour of the tetrahedra is handed to "
          "`vtkContour3DLinearGrid` (VTK's SMP backend, all cores). ldimesh: building the "
          "element sources from the cells read (their geometry's Bernstein form, the Jacobian "
          "checks) + scene + ray cast + mesh, all cores, median of the repeats.")
        if R.get("machine"):
            m = R["machine"]
            w(f"- This section: {m['date']}, {m['commit']}, {m['cpu']}, {m['cores']} cores.")
        if R.get("error"):
            w(f"- **Not run to the end**: {R['error']}")
        w("")
        for ds in R["datasets"]:
            diag = ds["ladder"][0]["diagonal"]
            w(f"### {ds['name']}")
            w("")
            w(f"{ds['origin'][0].upper()}{ds['origin'][1:]}; isovalue {ds['iso']}, "
              f"{fmt_int(ds['cells'])} cells. Reference: VTK {ds['reference']['from']}, "
              f"{fmt_int(ds['reference']['vertices'])} vertices projected (largest move "
              f"{fmt_e(ds['reference']['max_move'])}; {ds['reference']['failed']} did not "
              f"converge, {fmt_int(ds['reference']['dropped_faces'])} faces dropped).")
            w("")
            plot, image = R.get("figures", {}).get(ds["key"], (None, None))
            if plot:
                w(f"![{ds['name']}: distances and seconds](evaluation/{plot})")
                w("")
            w("| mesh | triangles | seconds | fwd mean | fwd mean % | fwd max | fwd max % | "
              "fwd vs ref mean / max | bwd mean | bwd max |")
            w("|---|---|---|---|---|---|---|---|---|---|")
            rows = [(("VTK contour" if r["method"] == "contour" else
                      f"VTK tessellate {r['level']} + contour") +
                     (" (the reference's source)" if f"{r['method']} {r['level']}" ==
                      ds["reference"]["from"] else ""), r)
                    for r in ds["vtk"] if not r.get("skipped")]
            rows += [(f"ldimesh {m['res']}²", m) for m in ds["ladder"]]
            for label, m in rows:
                w(f"| {label} | {fmt_int(m['triangles'])} | {fmt_s(m['seconds'])} | "
                  f"{fmt_e(m['fwd_mean'])} | {fmt_pct(m['fwd_mean'], diag)} | "
                  f"{fmt_e(m['fwd_max'])} | {fmt_pct(m['fwd_max'], diag)} | "
                  f"{fmt_e(m.get('fwd_ref_mean'))} / {fmt_e(m.get('fwd_ref_max'))} | "
                  f"{fmt_e(m.get('bwd_mean'))} | {fmt_e(m.get('bwd_max'))} |")
            w("")
            w("The goals: at equal triangle count a forward mean at most ⅓ of VTK's; at equal "
              "accuracy faster than VTK's tessellate-then-contour.")
            w("")
            w("| VTK | triangles | VTK fwd mean | ldimesh at equal triangles | ldimesh fwd mean | "
              "ratio (goal ≤ 0.33) | same with r = 1 | ratio r = 1 | "
              "ldimesh at least as accurate | seconds VTK / ldimesh |")
            w("|---|---|---|---|---|---|---|---|---|---|")
            for g in self.goals(ds):
                v, o, a = g["vtk"], g["ours"], g["accurate"]
                name = ("contour" if v["method"] == "contour" else
                        f"tessellate {v['level']} + contour")
                acc = (f"{a['res']}² ({fmt_int(a['triangles'])} triangles, "
                       f"{fmt_e(a['fwd_mean'])})" if a else "none of the ladder")
                speed = (f"{fmt_s(v['seconds'])} / {fmt_s(a['seconds'])} = "
                         f"{g['speedup']:.{0 if g['speedup'] >= 10 else 1}f}×" if a else "–")
                w(f"| {name} | {fmt_int(v['triangles'])} | {fmt_e(v['fwd_mean'])} | "
                  f"{o['res']}², {fmt_int(o['triangles'])} | {fmt_e(o['fwd_mean'])} | "
                  f"{g['ratio']:.3f} | " +
                  (f"{g['ours_r1']['res']}², {fmt_int(g['ours_r1']['triangles'])}: "
                   f"{fmt_e(g['ours_r1']['fwd_mean'])} | {g['ratio_r1']:.3f}"
                   if g["ours_r1"] else "– | –") + f" | {acc} | {speed} |")
            w("")
            if image:
                w(f"![{ds['name']}: the meshes side by side](evaluation/{image})")
                w("")
        if R.get("dealii_skipped"):
            w("The deal.II data set was left out: `build/bin/ldimesh-dealii` was not built "
              "(libdeal.ii-dev not installed; scripts/setup.sh installs it).")
            w("")
