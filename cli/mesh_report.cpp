#include "mesh_report.hpp"

#include <algorithm>
#include <cstdio>
#include <iostream>

namespace ldimesh::cli {

namespace {

nlohmann::json refinement_json(const RefinementOptions& options, const RefinementStats& refined,
                               std::size_t refine_rays) {
  return {{"levels", options.levels},
          {"min_normal_dot", options.min_normal_dot},
          {"grow", options.grow},
          {"passes", refined.passes},
          {"round_trips", refined.round_trips},
          {"rays", refine_rays},
          {"rays_per_pass", refined.rays_per_pass},
          {"seconds_per_pass", refined.seconds_per_pass},
          {"grown_cells", refined.grown_cells},
          {"subdivided_cells", refined.subdivided_cells},
          {"invalid_vertices", refined.invalid_vertices},
          {"removed_faces", refined.removed_faces},
          {"trimmed_faces", refined.trimmed_faces},
          {"seconds", refined.seconds},
          {"sample_seconds", refined.sample_seconds}};
}

nlohmann::json merging_json(const MeshArgs& args, const MergeStats& merged) {
  nlohmann::json merging = {{"enabled", args.merge},
                            {"region_faces", merged.region_faces},
                            {"dropped_faces", merged.dropped_faces},
                            {"boundary_faces", merged.boundary_faces},
                            {"patches", merged.patches},
                            {"bridge_pairs", merged.bridge_pairs},
                            {"bridges", merged.bridges},
                            {"holes", merged.holes},
                            {"fill_triangles", merged.fill_triangles},
                            {"unfilled_holes", merged.unfilled_holes},
                            {"split_quads", merged.split_quads},
                            {"flips", merged.flips},
                            {"merges", merged.merges},
                            {"split_edges", merged.split_edges},
                            {"projected", merged.projected},
                            {"crossings_undone", merged.crossings_undone},
                            {"split_passes", merged.split_passes},
                            {"components", merged.components}};
  if (args.merge && args.quads) {
    const QuadStats& q = merged.quads;
    merging["quads"] = {{"input_triangles", q.input_triangles},
                        {"input_quads", q.input_quads},
                        {"paired", q.paired},
                        {"region_faces", q.region_faces},
                        {"paths", q.paths},
                        {"path_rounds", q.path_rounds},
                        {"path_splits", q.path_splits},
                        {"turns", q.turns},
                        {"quad_merges", q.quad_merges},
                        {"flips", q.flips},
                        {"boundary_splits", q.boundary_splits},
                        {"leftover_triangles", q.leftover_triangles},
                        {"projected", q.projected},
                        {"crossings_undone", q.crossings_undone},
                        {"output_quads", q.output_quads},
                        {"seconds", q.seconds},
                        {"stage_seconds",
                         {{"setup", q.setup_seconds},
                          {"pair", q.pair_seconds},
                          {"paths", q.path_seconds},
                          {"cleanup", q.cleanup_seconds},
                          {"smooth", q.smooth_seconds}}}};
  }
  return merging;
}

}  // namespace

std::size_t MeshRun::rays() const {
  std::size_t rays = 0;
  for (const View& view : views)
    rays += view.pixel_count();
  return rays;
}

std::size_t MeshRun::refine_rays() const {
  std::size_t rays = 0;
  for (std::size_t n : step.meshing.refinement.rays_per_pass)
    rays += n;
  return rays;
}

void print_mesh_json(const MeshArgs& args, const MeshRun& run) {
  const MeshingResult& result = run.step.meshing;
  nlohmann::json j;
  j[!args.vtu.empty() ? "vtu" : args.grid.empty() ? "surface" : "grid"] = run.input.name;
#ifdef LDIMESH_WITH_VTU
  if (!args.vtu.empty()) {
    j["cells"] = run.input.elements.cells;
    j["ghost_cells"] = run.input.elements.ghost_cells;
  }
#endif
  j["isovalue"] = run.iso;
  j["resolution"] = args.res;
  j["views"] = args.views;
  j["r"] = run.r_used;
  j["ranks"] = run.ranks;
  j["threads"] = run.threads;
  j["caster"] = args.caster;
  j["encoding"] = args.lossless ? "lossless" : "quantized";
  j["rays"] = run.rays();
  j["samples"] = result.samples;
  j["quads_untrimmed"] = result.quads_untrimmed;
  j["quads"] = result.quads;
  j["triangles"] = result.mesh.triangle_count();
  j["vertices"] = result.mesh.vertex_count();
  j["faces"] = result.mesh.face_count();
  j["face_type"] = args.quads ? "quads" : "triangles";
  if (!result.mesh.scalars.empty()) {
    const auto [lo, hi] =
        std::minmax_element(result.mesh.scalars.begin(), result.mesh.scalars.end());
    j["colour"] = {{"field", colour_name(args)},
                   {"min", *lo},
                   {"max", *hi},
                   {"uncoloured_vertices", run.uncoloured}};
  }
  j["bytes_to_root"] = run.step.bytes_to_root;
  j["bytes_moved"] = run.step.bytes_moved;
  j["refinement"] =
      refinement_json(run.options.meshing.refinement, result.refinement, run.refine_rays());
  j["merging"] = merging_json(args, result.merging);
  j["output"] = args.out.empty() ? nlohmann::json(nullptr) : nlohmann::json(args.out);
  j["repeats"] = run.repeats;
  j["seconds"] = {{"load", run.load_seconds},
                  {"prepare", run.input.prepare_seconds},
                  {"scene", run.max_scene},
                  {"raycast", run.step.seconds.cast},
                  {"encode", run.step.seconds.encode},
                  {"reduce", run.step.seconds.reduce},
                  {"decode", run.step.seconds.decode},
                  {"match", result.seconds.match},
                  {"trim", result.seconds.trim},
                  {"refine", result.seconds.refine},
                  {"assemble", result.seconds.assemble},
                  {"bridge", result.seconds.bridge},
                  {"sew", result.seconds.sew},
                  {"quality", result.seconds.quality},
                  {"write", run.write_seconds}};
  std::cout << j.dump(2) << "\n";
}

void print_mesh_text(const MeshArgs& args, const MeshRun& run) {
  const MeshingResult& result = run.step.meshing;
  std::printf("ldimesh: %s, isovalue %g, views %s at %d px, r = %g, %d rank%s x %d threads\n",
              run.input.name.c_str(), run.iso, args.views.c_str(), args.res, run.r_used, run.ranks,
              run.ranks == 1 ? "" : "s", run.threads);
  if (!args.grid.empty())
    std::printf("  load       %8.3f s  %lldx%lldx%lld %s, values in [%g, %g]\n", run.load_seconds,
                (long long)args.dims[0], (long long)args.dims[1], (long long)args.dims[2],
                args.type.c_str(), run.input.volume.min_value, run.input.volume.max_value);
#ifdef LDIMESH_WITH_VTU
  if (!args.vtu.empty())
    std::printf(
        "  load       %8.3f s  %zu cells in %zu block%s, %zu ghost cells skipped, values in "
        "[%g, %g]\n",
        run.load_seconds, run.input.elements.cells, run.input.elements.groups.size(),
        run.input.elements.groups.size() == 1 ? "" : "s", run.input.elements.ghost_cells,
        run.input.elements.min_value, run.input.elements.max_value);
#endif
  std::printf("  scene      %8.3f s  (slowest rank)\n", run.max_scene);
  std::printf("  ray cast   %8.3f s  %zu rays, %zu samples (%.2f M rays/s)\n",
              run.step.seconds.cast, run.rays(), result.samples,
              run.rays() / run.step.seconds.cast * 1e-6);
  std::printf("  encode     %8.3f s  %s\n", run.step.seconds.encode,
              args.lossless ? "lossless" : "quantized depths and normals, zstd");
  std::printf("  reduce     %8.3f s  %llu bytes moved, %llu to the root (%.2f bytes/sample)\n",
              run.step.seconds.reduce, (unsigned long long)run.step.bytes_moved,
              (unsigned long long)run.step.bytes_to_root,
              result.samples ? double(run.step.bytes_moved) / double(result.samples) : 0.0);
  std::printf("  decode     %8.3f s\n", run.step.seconds.decode);
  std::printf("  mesh       %8.3f s  %zu quads\n", result.seconds.match, result.quads_untrimmed);
  std::printf("  trim       %8.3f s  %zu quads kept\n", result.seconds.trim, result.quads);
  if (run.options.meshing.refinement.levels > 0)
    std::printf(
        "  refine     %8.3f s  %d pass%s, %zu ray stretches requested (%.3f s sampling), %zu cells "
        "grown, "
        "%zu faces removed\n",
        result.seconds.refine, result.refinement.passes, result.refinement.passes == 1 ? "" : "es",
        run.refine_rays(), result.refinement.sample_seconds, result.refinement.grown_cells,
        result.refinement.removed_faces);
  if (args.merge) {
    const MergeStats& merged = result.merging;
    std::printf("  bridge     %8.3f s  %zu boundary faces removed, %zu patches, %zu bridges\n",
                result.seconds.bridge, merged.boundary_faces, merged.patches, merged.bridges);
    std::printf("  sew        %8.3f s  %zu holes, %zu triangles added, %zu holes left open\n",
                result.seconds.sew, merged.holes, merged.fill_triangles, merged.unfilled_holes);
    std::printf(
        "  quality    %8.3f s  %zu quads split, %zu flips, %zu 3-to-1 merges, %zu edges split "
        "(%zu new vertices on the surface, %zu round trips); %zu piece%s\n",
        result.seconds.quality, merged.split_quads, merged.flips, merged.merges, merged.split_edges,
        merged.projected, merged.split_passes, merged.components,
        merged.components == 1 ? "" : "s");
    if (args.quads) {
      const QuadStats& q = merged.quads;
      std::printf(
          "  quads      %8.3f s  (in quality) %zu triangle pairs, %zu paths (%zu turns, %zu open "
          "edges split), %zu quad merges, %zu flips; %zu triangles left\n",
          q.seconds, q.paired, q.paths, q.turns, q.boundary_splits, q.quad_merges, q.flips,
          q.leftover_triangles);
    }
  }
  std::printf("  assemble   %8.3f s  %zu vertices, %zu %s\n", result.seconds.assemble,
              result.mesh.vertex_count(), result.mesh.face_count(),
              args.quads ? "quads" : "triangles");
  std::printf("  mesh+trim  %8.3f s\n", result.seconds.match + result.seconds.trim);
  if (!args.out.empty())
    std::printf("  wrote      %8.3f s  %s\n", run.write_seconds, args.out.c_str());
}

}  // namespace ldimesh::cli
