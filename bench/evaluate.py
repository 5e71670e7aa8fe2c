#!/usr/bin/python3
"""Evaluation driver behind bench/evaluate (run that: it installs VTK/matplotlib and builds).

For each data set and LDI resolution: our mesh (three axis views, r = 0.5) against Marching
Cubes (VTK's vtkFlyingEdges3D on the field sampled on a grid, bench/mc_baseline.py) at about the
same triangle count; forward and backward distances with `ldimesh distance`; the paper's Table 1
rows on one core; high-order VTU files beside VTK's contour and tessellation
(bench/evaluate_highorder.py). Writes docs/evaluation.md, docs/evaluation/*.png and
docs/evaluation/results.json (with --quick: out/evaluate-quick/ instead of docs/).
"""
import argparse
import datetime
import json
import math
import os
import platform
import shutil
import statistics
import subprocess
import sys
import time

from evaluate_highorder import HighOrder
from mesh_figures import draw_shaded, load_triangles

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
PY = "/usr/bin/python3"

# Data sets and LDI resolutions (pixels along the longer side of each view).
FULL_PLAN = [
    ("marschner-lobb", [16, 32, 64, 128, 256, 512]),
    ("slices", [16, 24, 32, 64, 128, 256, 512]),
    ("sphere", [64, 256]),
    ("torus", [64, 256]),
    ("barth", [64, 128, 256, 512]),
    ("klein", [128, 256]),
]
QUICK_PLAN = [
    ("marschner-lobb", [16, 32, 64]),
    ("slices", [16, 24, 32]),
    ("sphere", [64]),
]

# The paper's Table 1 (seconds, one core of a Core i7 at 3.4 GHz; "-": step not executed).
# (data set, LDI resolution, figure, Mesh., Ref., Bridge, Sew, Qual., Tot.)
PAPER_TABLE1 = [
    ("klein", 128, "2", "0.04", "-", "-", "-", "-", "0.04"),
    ("barth", 64, "2(g)", "0.02", "-", "-", "-", "-", "0.02"),
    ("barth", 128, "2(h)", "0.11", "-", "-", "-", "-", "0.11"),
    ("barth", 256, "2(o)", "0.43", "-", "-", "-", "-", "0.43"),
    ("barth", 512, "2(p)", "1.84", "-", "-", "-", "-", "1.84"),
    ("marschner-lobb", 64, "6(g)", "0.08", "-", "0.11", "0.04", "0.23", "0.46"),
    ("marschner-lobb", 64, "6(h) (ref.)", "0.08", "0.73", "0.62", "0.1", "0.79", "2.32"),
    ("marschner-lobb", 512, "6(i)", "7.19", "-", "0.82", "3.38", "22.07", "33.46"),
    ("sphere", 64, "5(b)", "< 0.01", "-", "< 0.01", "0.01", "0.40", "0.40"),
    ("slices", 16, "6(j)", "< 0.01", "-", "< 0.01", "< 0.01", "< 0.01", "< 0.01"),
    ("slices", 24, "6(k)", "< 0.01", "-", "0.01", "0.01", "< 0.01", "0.02"),
    ("slices", 32, "6(l)", "0.02", "-", "0.02", "0.01", "0.04", "0.09"),
]
# Rows the paper refined (§4), with the refinement levels we run them at (`--refine N`): the paper
# does not give its levels for Fig. 6(h).
REFINED_ROWS = {"6(h) (ref.)": 2}
# The accuracy of refined meshes against MC at equal triangle count: (data set, LDI, levels).
REFINED_ACCURACY = [("marschner-lobb", 64, 2)]
PAPER_TRIANGLES = {("barth", 64): "24k", ("barth", 128): "136k", ("barth", 256): "625k",
                   ("barth", 512): "2 646k"}

# Side-by-side images (ours | MC at about the same triangle count), as Fig. 6.
FULL_IMAGES = [("marschner-lobb", 32), ("marschner-lobb", 64), ("slices", 16), ("slices", 24),
               ("slices", 32), ("barth", 64), ("klein", 128)]
QUICK_IMAGES = [("slices", 16)]

# Cross-sections: (data set, LDI, plane axis, offset, ((u0, u1), (v0, v1)) window).
SECTIONS = [("marschner-lobb", 64, "y", 0.55, ((0.3, 0.8), (-0.2, 0.2))),
            ("marschner-lobb", 256, "y", 0.55, ((0.55, 0.8), (-0.18, 0.18))),
            ("slices", 32, "z", 0.0, ((-1.45, 1.45), (-1.45, 1.45))),
            ("barth", 128, "z", 0.0, ((-0.8, 0.8), (0.7, 1.65)))]
SECTIONS_QUICK = [("marschner-lobb", 64, "y", 0.55, ((0.3, 0.8), (-0.2, 0.2)))]

NICE = {"marschner-lobb": "Marschner–Lobb", "slices": "Slices", "sphere": "Sphere",
        "torus": "Torus", "barth": "Barth sextic", "klein": "Klein bottle"}

T0 = time.monotonic()


def log(msg):
    print(f"[{time.monotonic() - T0:7.1f} s] {msg}", file=sys.stderr, flush=True)


def run(cmd, what):
    """Runs cmd, returns its stdout; exits with the command's stderr on failure."""
    p = subprocess.run(cmd, cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    if p.returncode != 0:
        sys.stderr.write(p.stderr)
        sys.exit(f"evaluate: {what} failed: {' '.join(cmd)}")
    return p.stdout


def run_json(cmd, what):
    out = run(cmd, what).strip()
    try:
        return json.loads(out)
    except json.JSONDecodeError:
        # One JSON object per line: take the last line.
        return json.loads(out.splitlines()[-1])


def fmt_e(v):
    if v is None:
        return "–"
    if v == 0:
        return "0"
    return f"{v:.2e}"


def fmt_pct(v, diag):
    if v is None:
        return "–"
    return f"{100.0 * v / diag:.4f}"


def fmt_share(v):
    return "–" if v is None else f"{100.0 * v:.2f} %"


def fmt_int(v):
    return f"{int(v):,}".replace(",", " ")


def fmt_s(v):
    if v is None:
        return "–"
    if v < 0.01:
        return f"{v:.4f}"
    if v < 1:
        return f"{v:.3f}"
    return f"{v:.2f}"


class Evaluation:
    def __init__(self, args):
        self.args = args
        self.bin = os.path.join(ROOT, args.build_dir, "bin")
        self.work = os.path.join(ROOT, args.work)
        os.makedirs(self.work, exist_ok=True)
        self.docs = os.path.join(ROOT, args.docs)
        self.fig_dir = os.path.join(self.docs, "evaluation")
        os.makedirs(self.fig_dir, exist_ok=True)
        self.probes = {}     # (surface, n) -> MC result
        self.meta = {}       # surface -> sampler meta (domain, diagonal, clip)
        self.distances = {}  # ply path -> distances
        self.refs = {}       # surface -> reference info
        self.results = {"datasets": {}, "table1": []}

    # ---- tools ----

    def ldimesh(self, *a):
        return [os.path.join(self.bin, "ldimesh"), *map(str, a)]

    def sample_and_mc(self, surface, n, ply, repeat=1):
        raw = os.path.join(self.work, f"{surface}_field.raw")
        meta_path = os.path.join(self.work, f"{surface}_field.json")
        meta = run_json([os.path.join(self.bin, "ldimesh_sample_field"), "--surface", surface,
                         "--n", str(n), "--out", raw], f"sampling {surface} at n={n}")
        with open(meta_path, "w") as f:
            f.write(json.dumps(meta) + "\n")
        self.meta.setdefault(surface, meta)
        mc = run_json([PY, os.path.join(ROOT, "bench", "mc_baseline.py"), "--raw", raw,
                       "--meta", meta_path, "--out", ply, "--repeat", str(repeat)],
                      f"Marching Cubes on {surface} at n={n}")
        os.remove(raw)
        return meta, mc

    def probe(self, surface, n):
        key = (surface, n)
        if key not in self.probes:
            ply = os.path.join(self.work, f"{surface}_mc{n}.ply")
            meta, mc = self.sample_and_mc(surface, n, ply, repeat=self.args.repeat)
            self.probes[key] = {
                "n": n, "dims": meta["dims"], "ply": ply, "triangles": mc["triangles"],
                "vertices": mc["vertices"], "sample_seconds": meta["seconds"],
                "mc_seconds": mc["seconds"], "clip_seconds": mc["clip_seconds"],
                "total_seconds": meta["seconds"] + mc["seconds"] + mc["clip_seconds"],
                "mc_threads": mc["threads"], "sample_threads": meta["threads"],
            }
            log(f"  MC {surface} n={n} ({'×'.join(map(str, meta['dims']))}): "
                f"{fmt_int(mc['triangles'])} triangles, sampling {meta['seconds']:.3f} s, "
                f"flying edges {mc['seconds']:.3f} s")
        return self.probes[key]

    def bracket(self, surface, target):
        """MC grid sizes n, n+1 whose triangle counts bracket `target`: (lower, upper, closest)."""
        def found():
            ns = sorted(n for (s, n) in self.probes if s == surface)
            for n in ns:
                t = self.probes[(surface, n)]["triangles"]
                if t == target:
                    return n, n
                if (surface, n + 1) in self.probes and \
                        t <= target <= self.probes[(surface, n + 1)]["triangles"]:
                    return n, n + 1
            return None

        def estimate():
            # From the probe nearest in triangle count: triangles ∝ (n − 1)².
            best = min((p for (s, _), p in self.probes.items() if s == surface),
                       key=lambda p: abs(math.log(max(p["triangles"], 1) / target)))
            return 1 + (best["n"] - 1) * math.sqrt(target / max(best["triangles"], 1))

        if not any(s == surface for (s, _) in self.probes):
            self.probe(surface, 24)
        for round_ in range(10):
            hit = found()
            if hit:
                break
            est = max(4.0, estimate())
            lo = int(math.floor(est))
            todo = [lo, lo + 1] if round_ > 0 else [int(round(est))]
            new = [n for n in todo if (surface, n) not in self.probes]
            if not new:  # counts not monotone here: widen
                new = [n for n in (lo - 1, lo + 2) if n >= 4 and (surface, n) not in self.probes]
            if not new:
                break
            for n in new:
                self.probe(surface, n)
        hit = found()
        if not hit:  # fall back to the nearest probes below and above
            ps = [p for (s, _), p in self.probes.items() if s == surface]
            below = [p for p in ps if p["triangles"] <= target]
            above = [p for p in ps if p["triangles"] >= target]
            lo = max(below, key=lambda p: p["triangles"]) if below else None
            hi = min(above, key=lambda p: p["triangles"]) if above else None
            lo = lo or hi
            hi = hi or lo
            hit = (lo["n"], hi["n"])
        lo, hi = (self.probes[(surface, n)] for n in hit)
        # Triangle counts are not monotone in n (by a few %): the closest of every grid size
        # probed for this surface, usually one of the bracketing pair.
        closest = min((p for (s, _), p in self.probes.items() if s == surface),
                      key=lambda p: (abs(p["triangles"] - target), p["n"]))
        return lo, hi, closest

    def reference(self, surface):
        """A fine MC mesh of ~ref_triangles triangles with its vertices projected onto the exact
        surface (bench/project_mesh.cpp)."""
        if surface in self.refs:
            return self.refs[surface]
        target = self.args.ref_triangles
        p = self.probe(surface, 64)
        n = int(round(1 + 63 * math.sqrt(target / p["triangles"])))
        mc_ply = os.path.join(self.work, f"{surface}_ref_mc{n}.ply")
        ref_ply = os.path.join(self.work, f"{surface}_ref.ply")
        meta, mc = self.sample_and_mc(surface, n, mc_ply)
        proj = run_json([os.path.join(self.bin, "ldimesh_project_mesh"), "--surface", surface,
                         "--in", mc_ply, "--out", ref_ply], f"projecting the {surface} reference")
        os.remove(mc_ply)
        floor = run_json(self.ldimesh("distance", ref_ply, "--surface", surface, "--samples",
                                      self.metro_samples(mc["triangles"], mc["vertices"]),
                                      "--json"), f"{surface} reference vs surface")
        ref = {"n": n, "dims": meta["dims"], "ply": ref_ply, "triangles": mc["triangles"],
               "vertices": mc["vertices"], "projection": proj,
               "floor_mean": floor["forward"]["mean"], "floor_max": floor["forward"]["max"],
               "floor_samples": floor["forward"]["samples"]}
        log(f"  reference {surface}: MC n={n}, {fmt_int(mc['triangles'])} triangles, "
            f"{fmt_int(mc['vertices'])} vertices projected (largest move "
            f"{proj['max_move']:.2e}, {proj['failed'] + proj['too_far']} left), faces within "
            f"{ref['floor_mean']:.2e} (mean) of the surface")
        self.refs[surface] = ref
        return ref

    def metro_samples(self, triangles, vertices):
        # Ten per triangle (the tool's default) up to a cap; at least 3 per vertex so that large
        # meshes still get points on edges and faces.
        return int(min(10 * triangles, max(self.args.samples_cap, 3 * vertices)))

    def distances_of(self, surface, ply, triangles, vertices, cross_check=False):
        key = ply
        d = self.distances.get(key)
        if d and (not cross_check or "fwd_ref_mean" in d):
            return d
        ref = self.reference(surface)
        d = d or {}
        if "fwd_mean" not in d:
            s = self.metro_samples(triangles, vertices)
            a = run_json(self.ldimesh("distance", ply, "--surface", surface, "--samples", s,
                                      "--json"), f"distance {ply} → {surface}")
            v = run_json(self.ldimesh("distance", ply, "--surface", surface, "--samples", 1,
                                      "--json"), f"vertex distance {ply} → {surface}")
            b = run_json(self.ldimesh("distance", ref["ply"], ply, "--samples", 1, "--json"),
                         f"distance reference → {ply}")
            d.update({
                "fwd_mean": a["forward"]["mean"], "fwd_max": a["forward"]["max"],
                "fwd_rms": a["forward"]["rms"], "fwd_samples": a["forward"]["samples"],
                "fwd_left_out": a.get("not_converged", 0) + a.get("outside_clip", 0),
                "fwdv_mean": v["forward"]["mean"], "fwdv_max": v["forward"]["max"],
                # `distance REF CAND`: its forward is the reference's vertices → candidate.
                "bwd_mean": b["forward"]["mean"], "bwd_max": b["forward"]["max"],
                "bwd_samples": b["forward"]["samples"],
                "fwdv_ref_mean": b["backward"]["mean"], "fwdv_ref_max": b["backward"]["max"],
                "seconds": a["seconds"] + v["seconds"] + b["seconds"],
            })
        if cross_check and "fwd_ref_mean" not in d:
            s = self.metro_samples(triangles, vertices)
            c = run_json(self.ldimesh("distance", ply, ref["ply"], "--samples", s, "--json"),
                         f"distance {ply} → reference")
            d.update({"fwd_ref_mean": c["forward"]["mean"], "fwd_ref_max": c["forward"]["max"]})
        self.distances[key] = d
        return d

    def ours(self, surface, res, threads=None, lossless=True, repeat=None, out=None, refine=0,
             merge=False):
        repeat = repeat or self.args.repeat
        runs = []
        for k in range(repeat):
            cmd = self.ldimesh("mesh", "--surface", surface, "--res", res, "--views", "xyz",
                               "--r", 0.5, "--json")
            if refine:
                cmd += ["--refine", str(refine)]
            if merge:
                cmd.append("--merge")
            if lossless:
                cmd.append("--lossless")
            if threads:
                cmd += ["--threads", str(threads)]
            if out and k == 0:
                cmd += ["--out", out]
            runs.append(run_json(cmd, f"ldimesh mesh {surface} {res}"))
        med = {k: statistics.median(r["seconds"][k] for r in runs) for k in runs[0]["seconds"]}
        j = runs[0]
        mesh_s = statistics.median(r["seconds"]["match"] + r["seconds"]["trim"] for r in runs)
        total = statistics.median(
            sum(r["seconds"].get(k, 0.0)
                for k in ("scene", "raycast", "match", "trim", "refine", "assemble"))
            for r in runs)
        o = {"triangles": j["triangles"], "vertices": j["vertices"], "samples": j["samples"],
             "quads_untrimmed": j["quads_untrimmed"], "quads": j["quads"], "rays": j["rays"],
             "threads": j["threads"], "scene": med["scene"], "raycast": med["raycast"],
             "match": med["match"], "trim": med["trim"], "assemble": med["assemble"],
             "mesh": mesh_s, "total": total, "ply": out}
        if refine:
            # §4: seconds.refine includes the ray casting of the extension samples
            # (refinement.sample_seconds); the paper's timings exclude ray casting.
            ref = j["refinement"]
            o.update({
                "refine_levels": refine, "refine": med["refine"],
                "refine_sample": statistics.median(r["refinement"]["sample_seconds"]
                                                   for r in runs),
                "refine_nosample": statistics.median(
                    r["seconds"]["refine"] - r["refinement"]["sample_seconds"] for r in runs),
                "refine_passes": ref["passes"], "refine_rays_per_pass": ref["rays_per_pass"],
                "refine_grown_cells": ref["grown_cells"],
                "refine_removed_faces": ref["removed_faces"],
            })
        if merge:
            # §5: Table 1's Bridge, Sew and Qual. columns; the projection of the sewing
            # region's new vertices (ray casting) is inside Qual.
            m = j["merging"]
            o.update({"bridge": med["bridge"], "sew": med["sew"], "quality": med["quality"],
                      "merge_total": statistics.median(
                          r["seconds"]["bridge"] + r["seconds"]["sew"] + r["seconds"]["quality"]
                          for r in runs),
                      "merge_patches": m["patches"], "merge_bridges": m["bridges"],
                      "merge_holes": m["holes"], "merge_unfilled": m["unfilled_holes"],
                      "merge_pieces": m["components"]})
        return o

    def against_mc(self, surface, o, ply):
        """Distances of our mesh `ply` (result `o`, which gains "dist") and of the MC meshes
        whose triangle counts bracket it: (the closest MC, all of them)."""
        lo, hi, closest = self.bracket(surface, o["triangles"])
        o["dist"] = self.distances_of(surface, ply, o["triangles"], o["vertices"])
        mcs = []
        for p in {lo["n"]: lo, hi["n"]: hi, closest["n"]: closest}.values():
            d = self.distances_of(surface, p["ply"], p["triangles"], p["vertices"],
                                  cross_check=p is closest)
            mcs.append(dict(p, dist=d))
        return next(m for m in mcs if m["n"] == closest["n"]), mcs

    # ---- the runs ----

    def run_dataset(self, surface, resolutions):
        log(f"{NICE[surface]}: LDI {', '.join(f'{r}²' for r in resolutions)}")
        self.reference(surface)
        rows = []
        for res in resolutions:
            ply = os.path.join(self.work, f"{surface}_ours{res}.ply")
            o = self.ours(surface, res, out=ply)
            log(f"  ours {surface} {res}²: {fmt_int(o['triangles'])} triangles, ray cast "
                f"{o['raycast']:.3f} s, mesh+trim {o['mesh']:.4f} s (median of "
                f"{self.args.repeat})")
            c, mcs = self.against_mc(surface, o, ply)
            rows.append({"res": res, "ours": o, "mc": c, "mc_bracket": mcs})
            od, cd = o["dist"], c["dist"]
            log(f"  {surface} {res}²: ours {fmt_int(o['triangles'])} vs MC n={c['n']} "
                f"{fmt_int(c['triangles'])}: forward mean {od['fwd_mean']:.2e} vs "
                f"{cd['fwd_mean']:.2e}, backward mean {od['bwd_mean']:.2e} vs "
                f"{cd['bwd_mean']:.2e}")
        meta = self.meta[surface]
        probes = sorted((p for (s, _), p in self.probes.items() if s == surface),
                        key=lambda p: p["n"])
        self.results["datasets"][surface] = {
            "domain": meta["domain"], "diagonal": meta["diagonal"], "clip": meta["clip"],
            "isovalue": meta["isovalue"], "reference": self.refs[surface], "rows": rows,
            "probes": [{k: p[k] for k in ("n", "triangles", "sample_seconds", "mc_seconds")}
                       for p in probes],
        }

    def run_highorder(self):
        """The high-order section (bench/evaluate_highorder.py). It needs an ldimesh built with
        VTK and, for its deal.II data set, the mini-app and OpenMPI's mpiexec; a failure there
        is reported in the section and does not lose the rest of the evaluation."""
        ho = HighOrder(self, log, run, run_json, fmt_int)
        try:
            R = ho.evaluate()
            if not self.args.no_images:
                R["figures"] = ho.figures(R, self.fig_dir)
        except (SystemExit, Exception) as e:  # run() exits on a failed command
            log(f"high-order section failed: {e}")
            R = {"datasets": [], "ladder": ho.ladder, "max_tets": ho.max_tets,
                 "error": str(e) or type(e).__name__}
        R["machine"] = machine_info(self.args)
        self.results["highorder"] = R

    def run_table1(self):
        log("Table 1 rows (one thread)")
        done = {}
        for row in PAPER_TABLE1:
            surface, res = row[0], row[1]
            if self.args.quick and (surface, res) not in {(s, r) for s, rs in QUICK_PLAN
                                                          for r in rs}:
                continue
            levels = REFINED_ROWS.get(row[2], 0)
            key = (surface, res, levels)
            if key not in done:
                done[key] = self.ours(surface, res, threads=1, repeat=max(3, self.args.repeat),
                                      refine=levels)
                o = done[key]
                log(f"  {surface} {res}² one thread: ray cast {o['raycast']:.3f} s, "
                    f"mesh+trim {o['mesh']:.4f} s, " +
                    (f"refine {levels} {o['refine']:.3f} s ({o['refine_nosample']:.3f} s "
                     "without its ray casting), " if levels else "") +
                    f"{fmt_int(o['triangles'])} triangles")
            entry = {"paper": list(row), "ours": done[key]}
            if row[5] != "-":
                # The paper merged this row (§5): the same run with --merge (r = 1).
                mkey = key + ("merge",)
                if mkey not in done:
                    done[mkey] = self.ours(surface, res, threads=1,
                                           repeat=max(3, self.args.repeat), refine=levels,
                                           merge=True)
                    o = done[mkey]
                    log(f"  {surface} {res}² merged: bridge {o['bridge']:.3f} s, sew "
                        f"{o['sew']:.3f} s, quality {o['quality']:.3f} s, "
                        f"{o['merge_pieces']} piece(s), {o['merge_unfilled']} hole(s) open")
                entry["merged"] = done[mkey]
            self.results["table1"].append(entry)

    def run_refined(self):
        """Refined meshes (§4) against MC at their own triangle count, beside the unrefined row
        of the same LDI resolution (run_dataset must have run for that data set)."""
        for surface, res, levels in REFINED_ACCURACY:
            ds = self.results["datasets"].get(surface)
            base = next((r for r in ds["rows"] if r["res"] == res), None) if ds else None
            if not base:
                continue
            log(f"{NICE[surface]} {res}², refined ({levels} levels)")
            ply = os.path.join(self.work, f"{surface}_ours{res}_ref{levels}.ply")
            o = self.ours(surface, res, out=ply, refine=levels)
            c, mcs = self.against_mc(surface, o, ply)
            self.results.setdefault("refined", []).append(
                {"surface": surface, "res": res, "levels": levels, "ours": o, "mc": c,
                 "mc_bracket": mcs})
            od, cd = o["dist"], c["dist"]
            log(f"  {surface} {res}² refined: ours {fmt_int(o['triangles'])} vs MC n={c['n']} "
                f"{fmt_int(c['triangles'])}: forward mean {od['fwd_mean']:.2e} vs "
                f"{cd['fwd_mean']:.2e}, backward mean {od['bwd_mean']:.2e} vs "
                f"{cd['bwd_mean']:.2e}")

    # ---- figures ----

    def plots(self):
        import matplotlib
        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
        files = {}
        for surface, ds in self.results["datasets"].items():
            diag = ds["diagonal"]
            fig, axes = plt.subplots(1, 2, figsize=(11, 4.2), dpi=110)
            ours = sorted((r["ours"] for r in ds["rows"]), key=lambda o: o["triangles"])
            mc = {}
            for r in ds["rows"]:
                for m in r["mc_bracket"]:
                    mc[m["n"]] = m
            mc = sorted(mc.values(), key=lambda m: m["triangles"])
            panels = [("fwd_mean", "forward mean (mesh → exact surface)", axes[0]),
                      ("bwd_mean", "backward mean (reference → mesh)", axes[1])]
            for key, title, ax in panels:
                ax.loglog([o["triangles"] for o in ours],
                          [100 * max(o["dist"][key], 1e-12) / diag for o in ours],
                          "o-", color="tab:blue", label="ours (LDI, 3 views, r = 0.5)")
                for o, r in zip(ours, sorted(ds["rows"], key=lambda r: r["ours"]["triangles"])):
                    ax.annotate(f"{r['res']}²", (o["triangles"], 100 * o["dist"][key] / diag),
                                textcoords="offset points", xytext=(4, 4), fontsize=7,
                                color="tab:blue")
                ax.loglog([m["triangles"] for m in mc],
                          [100 * max(m["dist"][key], 1e-12) / diag for m in mc],
                          "s--", color="tab:red", ms=4, label="Marching Cubes (flying edges)")
                if key == "fwd_mean":
                    ax.loglog([m["triangles"] for m in mc],
                              [100 * max(m["dist"]["fwdv_mean"], 1e-12) / diag for m in mc],
                              "s:", color="salmon", ms=3, label="MC, vertices only (ours: ~1e-6 %)")
                ax.set_xlabel("triangles")
                ax.set_ylabel("% of the domain diagonal")
                ax.set_title(title, fontsize=10)
                ax.grid(True, which="both", alpha=0.3)
                ax.legend(fontsize=7)
            fig.suptitle(f"{NICE[surface]}: distance vs triangle count", fontsize=11)
            fig.tight_layout()
            name = f"distance_{surface}.png"
            fig.savefig(os.path.join(self.fig_dir, name))
            plt.close(fig)
            files[surface] = name
        return files

    def images(self):
        import matplotlib
        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
        import numpy as np

        files = []
        wanted = QUICK_IMAGES if self.args.quick else FULL_IMAGES
        for surface, res in wanted:
            ds = self.results["datasets"].get(surface)
            row = next((r for r in ds["rows"] if r["res"] == res), None) if ds else None
            if not row:
                continue
            lo = np.array(ds["domain"]["lo"])
            hi = np.array(ds["domain"]["hi"])
            fig = plt.figure(figsize=(12, 6), dpi=100)
            items = [(row["ours"]["ply"], f"ours, LDI {res}², {fmt_int(row['ours']['triangles'])}"
                      " triangles", (0.55, 0.7, 1.0)),
                     (row["mc"]["ply"], f"Marching Cubes, n = {row['mc']['n']}, "
                      f"{fmt_int(row['mc']['triangles'])} triangles", (1.0, 0.72, 0.55))]
            for k, (ply, title, rgb) in enumerate(items):
                draw_shaded(fig, (1, 2, k + 1), load_triangles(ply), rgb, lo, hi, title, 1.3)
            fig.subplots_adjust(left=0.0, right=1.0, bottom=0.0, top=0.92, wspace=0.0)
            name = f"mesh_{surface}_{res}.png"
            fig.savefig(os.path.join(self.fig_dir, name))
            plt.close(fig)
            files.append((surface, res, name))
            log(f"  image {name}")
        return files

    def kept_pictures(self):
        """The mesh images and cross-sections a previous run left in the figure folder, as
        images() and sections() list them."""
        images = [(s_, r, f"mesh_{s_}_{r}.png") for s_, r in
                  (QUICK_IMAGES if self.args.quick else FULL_IMAGES)
                  if os.path.exists(os.path.join(self.fig_dir, f"mesh_{s_}_{r}.png"))]
        sections = [(s_, r, a, o, f"section_{s_}_{r}.png") for s_, r, a, o, _ in
                    (SECTIONS_QUICK if self.args.quick else SECTIONS)
                    if os.path.exists(os.path.join(self.fig_dir, f"section_{s_}_{r}.png"))]
        return images, sections

    # ---- where the backward distances come from ----

    def _vtk(self):
        import numpy as np
        import vtk
        from vtk.util import numpy_support as ns
        return np, vtk, ns

    def _read(self, ply):
        np, vtk, ns = self._vtk()
        r = vtk.vtkPLYReader()
        r.SetFileName(ply)
        r.Update()
        return r.GetOutput()

    def _ref_points(self, surface):
        np, vtk, ns = self._vtk()
        key = ("ref_points", surface)
        if key not in self.__dict__.setdefault("_cache", {}):
            pts = ns.vtk_to_numpy(self._read(self.refs[surface]["ply"]).GetPoints().GetData())
            self._cache[key] = np.ascontiguousarray(pts.astype(float))
        return self._cache[key]

    def _point_distances(self, ply, points):
        """Unsigned distances of points to the closest point of the mesh (VTK, one thread)."""
        np, vtk, ns = self._vtk()
        imp = vtk.vtkImplicitPolyDataDistance()
        imp.SetInput(self._read(ply))
        out = vtk.vtkDoubleArray()
        imp.FunctionValue(ns.numpy_to_vtk(np.ascontiguousarray(points), deep=1), out)
        return np.abs(ns.vtk_to_numpy(out))

    def _area(self, ply):
        np, vtk, ns = self._vtk()
        t = vtk.vtkTriangleFilter()
        t.SetInputData(self._read(ply))
        m = vtk.vtkMassProperties()
        m.SetInputConnection(t.GetOutputPort())
        m.Update()
        return m.GetSurfaceArea()

    def coverage(self):
        """Per row: the share of (a deterministic subsample of) the reference's vertices farther
        than one LDI pixel from the mesh, and their 99th percentile distance: holes and missing
        features, which the mean dilutes."""
        np, vtk, ns = self._vtk()
        log("coverage (reference vertices farther than one pixel)")
        for surface, ds in self.results["datasets"].items():
            pts = self._ref_points(surface)
            sub = pts[:: max(1, len(pts) // self.args.coverage_points)]
            extent = max(b - a for a, b in zip(ds["domain"]["lo"], ds["domain"]["hi"]))
            ref_area = self._area(self.refs[surface]["ply"])
            ds["reference"]["area"] = ref_area
            refined = [r for r in self.results.get("refined", []) if r["surface"] == surface]
            for r in ds["rows"] + refined:
                pixel = extent / r["res"]
                for m in (r["ours"], r["mc"]):
                    m["area_ratio"] = self._area(m["ply"]) / ref_area
                    d = self._point_distances(m["ply"], sub)
                    m["dist"]["bwd_over_pixel"] = float((d > pixel).mean())
                    m["dist"]["bwd_p99"] = float(np.percentile(d, 99))
                    m["dist"]["coverage_points"] = int(len(sub))
                log(f"  {surface} {r['res']}²{' refined' if 'levels' in r else ''}: reference "
                    f"vertices farther than a pixel "
                    f"({pixel:.3g}): ours {100 * r['ours']['dist']['bwd_over_pixel']:.2f} %, "
                    f"MC {100 * r['mc']['dist']['bwd_over_pixel']:.2f} %; area / reference "
                    f"area: ours {r['ours']['area_ratio']:.3f}, MC {r['mc']['area_ratio']:.3f}")

    def sections(self):
        """Cross-sections (as Fig. 6's backward maps): reference vertices near a plane coloured
        by their distance to the mesh, with the mesh's own cut by that plane."""
        import matplotlib
        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
        np, vtk, ns = self._vtk()
        files = []
        for surface, res, axis, offset, window in (SECTIONS_QUICK if self.args.quick
                                                   else SECTIONS):
            ds = self.results["datasets"].get(surface)
            row = next((r for r in ds["rows"] if r["res"] == res), None) if ds else None
            if not row:
                continue
            a = "xyz".index(axis)
            u, v = [k for k in range(3) if k != a]
            extent = max(b - a_ for a_, b in zip(ds["domain"]["lo"], ds["domain"]["hi"]))
            pixel = extent / res
            pts = self._ref_points(surface)
            half = 0.75 * (extent / (self.refs[surface]["dims"][a] - 1))
            sel = pts[np.abs(pts[:, a] - offset) < half]
            (u0, u1), (v0, v1) = window
            sel = sel[(sel[:, u] >= u0) & (sel[:, u] <= u1) & (sel[:, v] >= v0) &
                      (sel[:, v] <= v1)]
            aspect = (u1 - u0) / (v1 - v0)
            fig, axes = plt.subplots(1, 2, figsize=(2 * 5.0 * aspect + 2.0, 5.8), dpi=100,
                                     sharey=True)
            for ax, (label, m) in zip(axes, (("ours, LDI %d²" % res, row["ours"]),
                                             ("Marching Cubes, n = %d" % row["mc"]["n"],
                                              row["mc"]))):
                d = self._point_distances(m["ply"], sel)
                order = np.argsort(d)
                sc = ax.scatter(sel[order, u], sel[order, v], c=d[order], s=3, cmap="turbo",
                                vmin=0, vmax=0.5 * pixel, linewidths=0)
                cut = vtk.vtkCutter()
                plane = vtk.vtkPlane()
                origin = [0.0, 0.0, 0.0]
                origin[a] = offset
                normal = [0.0, 0.0, 0.0]
                normal[a] = 1.0
                plane.SetOrigin(*origin)
                plane.SetNormal(*normal)
                cut.SetCutFunction(plane)
                cut.SetInputData(self._read(m["ply"]))
                cut.Update()
                out = cut.GetOutput()
                if out.GetNumberOfLines():
                    cp = ns.vtk_to_numpy(out.GetPoints().GetData())
                    lines = ns.vtk_to_numpy(out.GetLines().GetData()).reshape(-1, 3)[:, 1:]
                    segs = cp[lines][:, :, [u, v]]
                    from matplotlib.collections import LineCollection
                    ax.add_collection(LineCollection(segs, colors="k", linewidths=0.6,
                                                     zorder=3))
                ax.set_xlim(u0, u1)
                ax.set_ylim(v0, v1)
                ax.set_aspect("equal")
                ax.set_xlabel("xyz"[u])
                ax.set_title(f"{label}, {fmt_int(m['triangles'])} triangles", fontsize=10)
            axes[0].set_ylabel("xyz"[v])
            fig.suptitle(f"{NICE[surface]}: reference vertices within {half:.1e} of the plane "
                         f"{axis} = {offset:g}, coloured by their distance to the mesh; black: "
                         "the mesh's cut", fontsize=9)
            fig.colorbar(sc, ax=axes,
                         label=f"distance (0 … half an LDI pixel, {0.5 * pixel:.3g})")
            name = f"section_{surface}_{res}.png"
            fig.savefig(os.path.join(self.fig_dir, name), bbox_inches="tight")
            plt.close(fig)
            files.append((surface, res, axis, offset, name))
            log(f"  section {name}")
        return files

    # ---- report ----

    def write_report(self, plot_files, image_files, section_files, seconds):
        R = self.results
        L = []
        w = L.append
        quick = self.args.quick
        w("# Evaluation: LDI meshes against Marching Cubes, high-order data beside VTK, and "
          "the paper's Table 1")
        w("")
        w("Generated by `bench/evaluate`" + (" --quick (a smoke run)" if quick else "") +
          f" in {seconds / 60:.1f} min on {R['machine']['cpu']}, {R['machine']['cores']} cores "
          f"({R['machine']['date']}, {R['machine']['commit']}). Do not edit by hand: rerun "
          "`bench/evaluate` (bench/README.md); the discussion at the end is "
          "`bench/evaluation_discussion.md`, included as it is. The figures are in "
          "`docs/evaluation/results.json`.")
        w("")
        w("## What is measured")
        w("")
        w("- **Ours**: `ldimesh mesh --surface S --res R --views xyz --r 0.5 --lossless` "
          "(§3: matching and trimming; refinement (§4) only where a section says so, with "
          "`--refine N`; §5 merging — bridging, hole filling, enhancement — is implemented "
          "(`--merge`, docs/method.md) but not used in these comparisons unless a section "
          "says so). `--lossless` so "
          "that the mesh is the method's, without the "
          "transport's 20-bit depth quantization (which moves vertices by at most "
          "2.4·10⁻⁴ pixel). Times are the median of "
          f"{self.args.repeat} runs on all cores: ray cast (incl. the scene build: interval "
          "culling and the Embree BVH) and mesh (§3 matching + trimming + the output arrays).")
        w(f"- **Marching Cubes**: VTK {R['machine']['vtk']}'s `vtkFlyingEdges3D` "
          "(bench/mc_baseline.py) on the field sampled at the points of an n-point grid along "
          "the domain box's longest side (same spacing on the other sides; the grid covers the "
          "box exactly, as the views do; `ldimesh_sample_field`). The Barth sextic is clipped to "
          "the ball of radius 2 by the ray caster, so its MC mesh is clipped alike "
          "(`vtkClipPolyData` with a `vtkSphere` of radius 2: triangles crossing the sphere are "
          "cut where their edges cross it). n is searched so that two consecutive grid sizes "
          "bracket our triangle count (triangles ∝ (n − 1)², then probing); the tables show the "
          "closer one, the plots both. Times: sampling the analytic field (all cores) + flying "
          "edges (VTK SMP with the TBB backend on all cores, median of "
          f"{self.args.repeat}) (+ the clip).")
        w("- **Forward distance** (mesh → exact surface): `ldimesh distance M.ply --surface S`, "
          "Metro-style: samples on the vertices, edges and faces of the mesh (ten per triangle, "
          f"at most max({fmt_int(self.args.samples_cap)}, 3 per vertex)), each projected onto "
          "the implicit surface by Newton steps (exact up to the projection finding the nearest "
          "sheet). *Vertices only* (`--samples 1`) is the paper's definition (\"all vertices of "
          "the candidate mesh\"); our vertices are ray hits, on the surface up to float "
          "rounding, so the paper's forward figure is ~0 for us by construction and the "
          "Metro figure (chords between the vertices) is the meaningful one.")
        w("- **Backward distance** (reference → mesh): all vertices of a reference mesh to the "
          "closest point of the candidate (`ldimesh distance REF.ply M.ply --samples 1`). The "
          "reference is Marching Cubes on a fine grid (about "
          f"{fmt_int(self.args.ref_triangles)} triangles; the paper used 5 M) with every vertex "
          "moved onto the exact surface by Newton steps (`ldimesh_project_mesh`), so the "
          "reference's vertices are exact samples of the surface: a hole, a missing thin "
          "feature or a bridge across a gap in the candidate shows here.")
        w("- Relative figures are % of the domain box's diagonal. \"Equal triangle count\" is "
          "the closest MC grid size, within a fraction of a percent except at the smallest "
          "sizes.")
        w("")

        # Reference table
        w("### References")
        w("")
        w("| data set | domain | diagonal | reference MC grid | triangles | vertices projected "
          "(largest move) | reference faces → surface, mean / max |")
        w("|---|---|---|---|---|---|---|")
        for surface, ds in R["datasets"].items():
            ref = ds["reference"]
            dom = ds["domain"]
            dom_s = " × ".join(f"[{a:g}, {b:g}]" for a, b in zip(dom["lo"], dom["hi"]))
            clip = f", clipped to the ball of radius {ds['clip']['radius']:g}" if ds["clip"] else ""
            w(f"| {NICE[surface]} | {dom_s}{clip} | {ds['diagonal']:.3f} | "
              f"{'×'.join(map(str, ref['dims']))} | {fmt_int(ref['triangles'])} | "
              f"{fmt_int(ref['vertices'])} ({ref['projection']['max_move']:.1e}; "
              f"{ref['projection']['failed'] + ref['projection']['too_far']} not moved) | "
              f"{fmt_e(ref['floor_mean'])} / {fmt_e(ref['floor_max'])} |")
        w("")

        # Headline
        w("## Headline: the target on Marschner–Lobb and Slices")
        w("")
        w("Target: at equal triangle count, forward mean ≤ ⅓ of MC's and backward mean ≤ MC's. "
          "Forward here is the Metro figure (faces sampled); \"MC fwd (ref)\" is MC's forward "
          "distance measured against the reference mesh instead of by Newton projection (a "
          "cross-check: the projection can land on a farther sheet from coarse MC faces, which "
          "inflates MC's figure); the verdict uses the smaller of MC's two figures.")
        w("")
        w("| data set | LDI | ours tri | MC n | MC tri | fwd mean ours | fwd mean MC | MC fwd "
          "(ref) | ours/MC fwd | bwd mean ours | bwd mean MC | ours/MC bwd | target | "
          "bwd > 1 px, ours / MC |")
        w("|---|---|---|---|---|---|---|---|---|---|---|---|---|---|")
        verdicts = []
        for surface in ("marschner-lobb", "slices"):
            ds = R["datasets"].get(surface)
            if not ds:
                continue
            for r in ds["rows"]:
                o, c = r["ours"], r["mc"]
                od, cd = o["dist"], c["dist"]
                mc_fwd = min(cd["fwd_mean"], cd.get("fwd_ref_mean", cd["fwd_mean"]))
                rf = od["fwd_mean"] / mc_fwd
                rb = od["bwd_mean"] / cd["bwd_mean"]
                ok_f, ok_b = rf <= 1 / 3, rb <= 1.0
                verdicts.append((surface, r["res"], ok_f, ok_b, rf, rb))
                mark = "met" if ok_f and ok_b else (
                    "forward only" if ok_f else ("backward only" if ok_b else "not met"))
                w(f"| {NICE[surface]} | {r['res']}² | {fmt_int(o['triangles'])} | {c['n']} | "
                  f"{fmt_int(c['triangles'])} | {fmt_e(od['fwd_mean'])} | {fmt_e(cd['fwd_mean'])}"
                  f" | {fmt_e(cd.get('fwd_ref_mean'))} | {rf:.2f} | {fmt_e(od['bwd_mean'])} | "
                  f"{fmt_e(cd['bwd_mean'])} | {rb:.2f} | {mark} | "
                  f"{fmt_share(od.get('bwd_over_pixel'))} / "
                  f"{fmt_share(cd.get('bwd_over_pixel'))} |")
        w("")
        w("\"bwd > 1 px\": the share of the reference's vertices (a subsample of "
          f"{fmt_int(self.args.coverage_points)}) farther than one LDI pixel (the domain's longest "
          "side / resolution) from the mesh — holes and missing features, which the mean "
          "dilutes.")
        w("")
        if verdicts:
            nf = sum(v[2] for v in verdicts)
            nb = sum(v[3] for v in verdicts)
            nboth = sum(v[2] and v[3] for v in verdicts)
            w(f"Forward target met in {nf} of {len(verdicts)} cases, backward in {nb} of "
              f"{len(verdicts)}, both in {nboth}. Failing cases: " +
              (", ".join(f"{NICE[s]} {res}² ({'fwd ' + format(rf, '.2f') if not f else ''}"
                         f"{' ' if not f and not b else ''}"
                         f"{'bwd ' + format(rb, '.2f') if not b else ''})"
                         for s, res, f, b, rf, rb in verdicts if not (f and b)) or "none") + ".")
            w("")

        # Per data set
        w("## Per data set")
        w("")
        w("Distances absolute (in the surface's units) and in % of the domain diagonal; "
          "\"fwd\" = mesh → exact surface (Metro samples), \"fwd v\" = vertices only (the "
          "paper's), \"fwd vs ref\" = the same Metro samples of the MC mesh against the reference "
          "mesh (exact closest points on a mesh within the reference's error of the surface; "
          "a cross-check of the Newton projection, which from coarse MC faces can land on a "
          "farther sheet: where the two maxima differ, trust this one), \"bwd\" = reference "
          "vertices → mesh. Times in seconds, all cores: ours = "
          "ray cast (with scene) + mesh; MC = sampling + flying edges (+ clip). \"bwd p99\": "
          "99th percentile of the backward distances, \"bwd > 1 px\": share of the reference's "
          "vertices farther than one LDI pixel from the mesh (both over a subsample of "
          f"{fmt_int(self.args.coverage_points)} reference vertices, VTK's "
          "vtkImplicitPolyDataDistance). \"area / ref. area\": the mesh's area over the "
          "reference's — above 1 for ours because the views' trimmed patches still overlap at "
          "r = 0.5 (§3: a vertex stays while its view sees it at least half as well as the best "
          "view), so that part of our triangles covers the surface twice or three times.")
        w("")
        for surface, ds in R["datasets"].items():
            diag = ds["diagonal"]
            w(f"### {NICE[surface]}")
            w("")
            if surface in plot_files:
                w(f"![{NICE[surface]}: distance vs triangles](evaluation/{plot_files[surface]})")
                w("")
            w("| LDI | mesh | n | triangles | fwd mean | fwd mean % | fwd max | fwd max % | "
              "fwd v mean | fwd vs ref mean / max | bwd mean | bwd mean % | bwd max | bwd max % "
              "| bwd p99 | bwd > 1 px | area / ref. area | time s | "
              "(ray cast + mesh / sampling + MC) |")
            w("|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|")
            for r in ds["rows"]:
                o, c = r["ours"], r["mc"]
                for label, m, n, t, detail in (
                        ("ours", o, "", o["scene"] + o["raycast"] + o["mesh"] + o["assemble"],
                         f"{fmt_s(o['scene'] + o['raycast'])} + "
                         f"{fmt_s(o['mesh'] + o['assemble'])}"),
                        ("MC", c, c["n"], c["total_seconds"],
                         f"{fmt_s(c['sample_seconds'])} + "
                         f"{fmt_s(c['mc_seconds'] + c['clip_seconds'])}")):
                    d = m["dist"]
                    w(f"| {r['res']}² | {label} | {n} | {fmt_int(m['triangles'])} | "
                      f"{fmt_e(d['fwd_mean'])} | {fmt_pct(d['fwd_mean'], diag)} | "
                      f"{fmt_e(d['fwd_max'])} | {fmt_pct(d['fwd_max'], diag)} | "
                      f"{fmt_e(d['fwdv_mean'])} | "
                      f"{fmt_e(d.get('fwd_ref_mean'))} / {fmt_e(d.get('fwd_ref_max'))} | "
                      f"{fmt_e(d['bwd_mean'])} | "
                      f"{fmt_pct(d['bwd_mean'], diag)} | {fmt_e(d['bwd_max'])} | "
                      f"{fmt_pct(d['bwd_max'], diag)} | {fmt_e(d.get('bwd_p99'))} | "
                      f"{fmt_share(d.get('bwd_over_pixel'))} | "
                      f"{'–' if 'area_ratio' not in m else format(m['area_ratio'], '.3f')} | "
                      f"{fmt_s(t)} | {detail} |")
            w("")
            lo_hi = [f"{r['res']}²: n = " + " / ".join(
                f"{m['n']} → {fmt_int(m['triangles'])}" for m in r["mc_bracket"])
                for r in ds["rows"]]
            w("MC grid sizes bracketing our triangle counts: " + "; ".join(lo_hi) + ".")
            w("")

        # Refined meshes against MC
        refined = R.get("refined", [])
        if refined:
            w("## Refinement (§4): accuracy at equal triangle count")
            w("")
            w("The same LDIs refined with `--refine N` (triangles, all cores), against MC at the "
              "refined mesh's triangle count, beside the unrefined row of the same resolution "
              "from the tables above. Columns as in the per-data-set tables; time = ray cast + "
              "mesh + refinement (its extension-sample ray casting included).")
            w("")
            w("| data set | LDI | mesh | n | triangles | fwd mean | fwd max | fwd vs ref mean / "
              "max | bwd mean | bwd max | bwd p99 | bwd > 1 px | area / ref. area | time s |")
            w("|---|---|---|---|---|---|---|---|---|---|---|---|---|---|")
            for rr in refined:
                ds = R["datasets"][rr["surface"]]
                base = next(r for r in ds["rows"] if r["res"] == rr["res"])
                o = rr["ours"]
                entries = [
                    ("ours, §3 only", "", base["ours"],
                     base["ours"]["scene"] + base["ours"]["raycast"] + base["ours"]["mesh"] +
                     base["ours"]["assemble"]),
                    (f"ours, --refine {rr['levels']}", "", o,
                     o["scene"] + o["raycast"] + o["mesh"] + o["refine"] + o["assemble"]),
                    ("MC at the refined count", rr["mc"]["n"], rr["mc"],
                     rr["mc"]["total_seconds"])]
                for label, n, m, t in entries:
                    d = m["dist"]
                    w(f"| {NICE[rr['surface']]} | {rr['res']}² | {label} | {n} | "
                      f"{fmt_int(m['triangles'])} | {fmt_e(d['fwd_mean'])} | "
                      f"{fmt_e(d['fwd_max'])} | {fmt_e(d.get('fwd_ref_mean'))} / "
                      f"{fmt_e(d.get('fwd_ref_max'))} | {fmt_e(d['bwd_mean'])} | "
                      f"{fmt_e(d['bwd_max'])} | {fmt_e(d.get('bwd_p99'))} | "
                      f"{fmt_share(d.get('bwd_over_pixel'))} | "
                      f"{'–' if 'area_ratio' not in m else format(m['area_ratio'], '.3f')} | "
                      f"{fmt_s(t)} |")
                mc_fwd = min(rr["mc"]["dist"]["fwd_mean"],
                             rr["mc"]["dist"].get("fwd_ref_mean", rr["mc"]["dist"]["fwd_mean"]))
                w("")
                w(f"{NICE[rr['surface']]} {rr['res']}², {rr['levels']} levels: "
                  f"{o['refine_passes']} passes, extension ray stretches per pass "
                  f"{' / '.join(map(str, o['refine_rays_per_pass']))}, "
                  f"{fmt_int(o['refine_grown_cells'])} cells grown; ours/MC forward mean "
                  f"{o['dist']['fwd_mean'] / mc_fwd:.2f}, backward mean "
                  f"{o['dist']['bwd_mean'] / rr['mc']['dist']['bwd_mean']:.2f} (unrefined "
                  f"at its own count: see the headline table).")
                w("")

        # Table 1
        if R.get("highorder"):
            HighOrder(self, log, run, run_json, fmt_int).report(R["highorder"], w, fmt_e,
                                                                fmt_pct, fmt_s)
        w("## Table 1 reproduction (one thread)")
        w("")
        refined_rows = ", ".join(f"{fig} with `--refine {lv}`" for fig, lv in
                                 REFINED_ROWS.items())
        w("`ldimesh mesh --surface S --res R --views xyz --r 0.5 --lossless --threads 1`, median "
          f"of {max(3, self.args.repeat)} runs. The paper's columns are seconds on one core of a "
          "Core i7 at 3.4 GHz, ray casting excluded (done on a GPU there). The \"Mesh.\" stage "
          "(§3 matching and trimming), refinement (§4) and merging (§5) exist here. Our total "
          "is mesh + trim (+ refinement where the paper refined) (+ the output arrays, shown "
          "apart). Where the paper merged, the same command with `--merge` (which trims with "
          "r = 1) gives \"ours Bridge/Sew/Qual.\": `seconds.bridge` (building the half-edge "
          "mesh, the boundary layer, patches and bridges), `seconds.sew` (ear cutting) and "
          "`seconds.quality` (enhancement, the sewing region's edge splits with the ray "
          "casting that projects their new vertices, and the output), with the merged mesh's "
          "pieces and open holes. "
          f"Refined rows: {refined_rows} (triangles; the paper does not give its "
          "levels); \"ours Ref.\" is the JSON's `seconds.refine`, which includes the ray "
          "casting of refinement's extension samples, and in parentheses the same without it "
          "(`refinement.sample_seconds` subtracted), the figure comparable to the paper's "
          "(whose timings exclude ray casting). Each run is a fresh process (cold caches and "
          "allocator); `ldimesh_bench_refine` (docs/performance.md) "
          "reports warm medians within one process, which are lower. "
          "Rows the paper shows that we cannot run: "
          "Coulomb and Shock Channel (not among our data sets; `ldimesh_bench_refine` times a "
          "stand-in for the Shock Channel, docs/performance.md).")
        w("")
        w("| data set | LDI | Fig. | paper Mesh. | Ref. | Bridge | Sew | Qual. | paper Tot. | "
          "ours scene + ray cast | ours Mesh. (match + trim) | ours arrays | "
          "ours Ref. (without its ray casting) | ours Bridge/Sew/Qual. "
          "| ours triangles | paper triangles |")
        w("|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|")
        for t in R["table1"]:
            p, o = t["paper"], t["ours"]
            ref = (f"{fmt_s(o['refine'])} ({fmt_s(o['refine_nosample'])}), "
                   f"{o['refine_levels']} levels" if "refine" in o else "–")
            mo = t.get("merged")
            merged = (f"{fmt_s(mo['bridge'])} / {fmt_s(mo['sew'])} / {fmt_s(mo['quality'])} "
                      f"(Σ {fmt_s(mo['merge_total'])}; {mo['merge_pieces']} piece"
                      f"{'' if mo['merge_pieces'] == 1 else 's'}, {mo['merge_unfilled']} "
                      f"open hole{'' if mo['merge_unfilled'] == 1 else 's'})" if mo else "–")
            w(f"| {NICE[p[0]]} | {p[1]}² | {p[2]} | {p[3]} | {p[4]} | {p[5]} | {p[6]} | {p[7]} "
              f"| {p[8]} | {fmt_s(o['scene'] + o['raycast'])} | {fmt_s(o['mesh'])} | "
              f"{fmt_s(o['assemble'])} | {ref} | {merged} | {fmt_int(o['triangles'])} | "
              f"{PAPER_TRIANGLES.get((p[0], p[1]), 'n/a')} |")
        w("")

        if image_files:
            w("## The meshes side by side")
            w("")
            w("Ours (left, blue) and Marching Cubes at about the same triangle count (right, "
              "orange), flat-shaded, rendered with matplotlib (VTK's offscreen rendering needs an "
              "X server here, Debian's VTK has no EGL/OSMesa build). As Fig. 6 of the paper.")
            w("")
            for surface, res, name in image_files:
                w(f"![{NICE[surface]} {res}²](evaluation/{name})")
                w("")

        if section_files:
            w("## Where the backward distance comes from: cross-sections")
            w("")
            w("Reference vertices (on the exact surface) near a plane, coloured by their "
              "distance to the mesh from 0 to half an LDI pixel (dark blue: covered; red: "
              "farther than half a pixel), with the mesh's own cut by the plane in black — as "
              "the backward maps of Fig. 6.")
            w("")
            for surface, res, axis, offset, name in section_files:
                w(f"![{NICE[surface]} {res}², section {axis} = {offset:g}](evaluation/{name})")
                w("")

        disc = os.path.join(ROOT, "bench", "evaluation_discussion.md")
        if os.path.exists(disc) and not quick:
            w("## Discussion")
            w("")
            with open(disc) as f:
                L.append(f.read().rstrip())
            w("")
        with open(os.path.join(self.docs, "evaluation.md"), "w") as f:
            f.write("\n".join(L) + "\n")


def machine_info(args):
    cpu = platform.processor() or "?"
    try:
        with open("/proc/cpuinfo") as f:
            for line in f:
                if line.startswith("model name"):
                    cpu = line.split(":", 1)[1].strip()
                    break
    except OSError:
        pass
    try:
        commit = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=ROOT,
                                capture_output=True, text=True).stdout.strip() or "?"
    except OSError:
        commit = "?"
    vtk_version = subprocess.run(
        [PY, "-c", "import vtk; print(vtk.vtkVersion.GetVTKVersion())"],
        capture_output=True, text=True).stdout.strip()
    return {"cpu": cpu, "cores": os.cpu_count(), "date": datetime.date.today().isoformat(),
            "commit": f"commit {commit} + working tree", "vtk": vtk_version,
            "platform": platform.platform()}


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true",
                    help="a smoke run (~1 min): few cases, small reference, out/evaluate-quick/")
    ap.add_argument("--build-dir", default="build", help="where bin/ldimesh is (default build)")
    ap.add_argument("--no-build", action="store_true", help="(bench/evaluate: skip the build)")
    ap.add_argument("--only", help="comma-separated data sets (default: all; 'highorder' for "
                                   "the high-order section)")
    ap.add_argument("--highorder-only", action="store_true",
                    help="rerun only the high-order section and rewrite the report with the "
                         "other sections from results.json")
    ap.add_argument("--repeat", type=int, help="timing runs per case (default 3; quick 1)")
    ap.add_argument("--ref-triangles", type=float,
                    help="reference MC size (default 2e6; quick 2e5)")
    ap.add_argument("--samples-cap", type=float, default=1e6,
                    help="Metro samples per mesh at most (but ≥ 3 per vertex); default 1e6")
    ap.add_argument("--work", help="scratch folder (default out/evaluate[-quick])")
    ap.add_argument("--docs", help="where evaluation.md and evaluation/ go "
                                   "(default docs; quick: out/evaluate-quick/docs)")
    ap.add_argument("--no-images", action="store_true", help="skip the mesh images")
    ap.add_argument("--post-only", action="store_true",
                    help="redo coverage, figures and report from results.json and the meshes "
                         "of the last run")
    ap.add_argument("--report-only", action="store_true",
                    help="only rewrite evaluation.md and the plots from results.json")
    ap.add_argument("--coverage-points", type=int, default=100000,
                    help="reference vertices used for the share beyond a pixel (default 1e5)")
    args = ap.parse_args()
    args.repeat = args.repeat or (1 if args.quick else 3)
    args.ref_triangles = int(args.ref_triangles or (2e5 if args.quick else 2e6))
    args.samples_cap = int(args.samples_cap)
    args.work = args.work or ("out/evaluate-quick" if args.quick else "out/evaluate")
    args.docs = args.docs or ("out/evaluate-quick/docs" if args.quick else "docs")

    plan = QUICK_PLAN if args.quick else FULL_PLAN
    highorder = True
    if args.only:
        wanted = args.only.split(",")
        plan = [(s, r) for s, r in plan if s in wanted]
        highorder = "highorder" in wanted
    if not os.path.exists(os.path.join(ROOT, args.build_dir, "bin", "ldimesh")):
        sys.exit(f"evaluate: {args.build_dir}/bin/ldimesh missing: run bench/evaluate (it builds)")

    ev = Evaluation(args)
    if args.post_only:
        # Coverage, plots, images, sections and the report again, from results.json and the
        # meshes left in the work folder by the last full run.
        with open(os.path.join(ev.fig_dir, "results.json")) as f:
            ev.results = json.load(f)
        for surface, ds in ev.results["datasets"].items():
            ds["reference"]["ply"] = os.path.join(ROOT, ds["reference"]["ply"])
            ev.refs[surface] = ds["reference"]
            for r in ds["rows"]:
                for m in [r["ours"], r["mc"], *r["mc_bracket"]]:
                    m["ply"] = os.path.join(ROOT, m["ply"])
        for r in ev.results.get("refined", []):
            for m in [r["ours"], r["mc"], *r["mc_bracket"]]:
                m["ply"] = os.path.join(ROOT, m["ply"])
        ev.coverage()
        plot_files = ev.plots()
        image_files = [] if args.no_images else ev.images()
        section_files = [] if args.no_images else ev.sections()
        if ev.results.get("highorder") and not args.no_images:
            ho = HighOrder(ev, log, run, run_json, fmt_int)
            ev.results["highorder"]["figures"] = ho.figures(ev.results["highorder"], ev.fig_dir)
        with open(os.path.join(ev.fig_dir, "results.json"), "w") as f:
            f.write(json.dumps(ev.results, indent=1).replace(ROOT + "/", ""))
        ev.write_report(plot_files, image_files, section_files, ev.results["seconds"])
        log(f"rewrote {os.path.join(args.docs, 'evaluation.md')} (post-processing only)")
        return
    if args.highorder_only:
        # The high-order section again; the other sections' figures and images as they are.
        with open(os.path.join(ev.fig_dir, "results.json")) as f:
            ev.results = json.load(f)
        ev.run_highorder()  # the section notes its own date and commit
        images, sections = ev.kept_pictures()
        with open(os.path.join(ev.fig_dir, "results.json"), "w") as f:
            f.write(json.dumps(ev.results, indent=1).replace(ROOT + "/", ""))
        ev.write_report(ev.plots(), images, sections, ev.results["seconds"])
        log(f"rewrote {os.path.join(args.docs, 'evaluation.md')} with a new high-order section")
        return
    if args.report_only:
        # Rewrites evaluation.md (and the plots) from results.json, e.g. after editing
        # bench/evaluation_discussion.md; the mesh images and sections are kept as they are.
        with open(os.path.join(ev.fig_dir, "results.json")) as f:
            ev.results = json.load(f)
        images, sections = ev.kept_pictures()
        ev.write_report(ev.plots(), images, sections, ev.results["seconds"])
        log(f"rewrote {os.path.join(args.docs, 'evaluation.md')} from results.json")
        return
    ev.results["machine"] = machine_info(args)
    ev.results["settings"] = {"repeat": args.repeat, "ref_triangles": args.ref_triangles,
                              "samples_cap": args.samples_cap, "quick": args.quick}
    log(f"evaluate: {len(plan)} data sets, work in {args.work}/, report in {args.docs}/")
    for surface, resolutions in plan:
        ev.run_dataset(surface, resolutions)
    if plan:
        ev.run_refined()
    if highorder:
        ev.run_highorder()
    if not args.only:
        ev.run_table1()
    ev.coverage()
    log("plots")
    plot_files = ev.plots()
    image_files = [] if args.no_images else ev.images()
    section_files = [] if args.no_images else ev.sections()
    seconds = time.monotonic() - T0
    ev.results["seconds"] = seconds
    with open(os.path.join(ev.fig_dir, "results.json"), "w") as f:
        f.write(json.dumps(ev.results, indent=1).replace(ROOT + "/", ""))
    ev.write_report(plot_files, image_files, section_files, seconds)
    log(f"wrote {os.path.join(args.docs, 'evaluation.md')} and {args.docs}/evaluation/ "
        f"in {seconds / 60:.1f} min")


if __name__ == "__main__":
    main()
