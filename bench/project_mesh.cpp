// Moves every vertex of a mesh onto a built-in analytic surface, or onto the exact isosurface of
// a VTU file's high-order cells, by Newton steps along the field's gradient, keeping the faces:
// bench/evaluate turns a fine Marching Cubes mesh (for VTU data: VTK's contour of the finely
// tessellated cells) into the reference for the backward distances this way, so that its
// vertices are exact samples of the surface (the linear interpolation's error is gone; what
// remains is the chord between the vertices, which vertex-only sampling never sees).
//
//   build/bin/ldimesh_project_mesh --surface marschner-lobb --in ref_mc.ply --out ref.ply
//       [--max-move D] [--threads N]
//   build/bin/ldimesh_project_mesh --vtu data.vtu --field f --iso 0.5 --in ref.ply --out ref2.ply
//
// p ← p − (f(p) − iso) ∇f(p) / |∇f(p)|², at most 50 steps, until |f − iso| / |∇f| is below
// 1e-12 of the domain diagonal or the step below 1e-14 of it. A vertex whose projection fails
// (vanishing gradient, no convergence) or would move further than --max-move (default 1 % of the
// domain diagonal) stays where it was and is counted; with --drop-failed it is removed with the
// faces that use it (a reference whose vertices all lie on the surface). One JSON line on
// stdout ("vertices": those written).
#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <functional>
#include <iostream>
#include <limits>
#include <memory>
#include <stdexcept>
#include <string>
#include <vector>

#include <tbb/global_control.h>
#include <tbb/info.h>
#include <tbb/parallel_for.h>
#include <CLI/CLI.hpp>
#include <nlohmann/json.hpp>

#include "ldimesh/core/field/surfaces.hpp"
#include "ldimesh/core/io/mesh_io.hpp"
#ifdef LDIMESH_WITH_VTU
#include "ldimesh/core/io/vtu.hpp"
#endif

int main(int argc, char** argv) {
  CLI::App app{
      "project a mesh's vertices onto a built-in analytic surface or a VTU file's "
      "isosurface (Newton steps)"};
  std::string name, vtu, field_name, in, out;
  bool drop_failed = false;
  double max_move = 0.0, isovalue = std::numeric_limits<double>::quiet_NaN();
  int threads = 0;
  CLI::Option* surface_option =
      app.add_option("--surface", name, "built-in surface (ldimesh surfaces)");
  CLI::Option* vtu_option =
      app.add_option("--vtu", vtu,
                     "or a VTU file's cells (VTK_LAGRANGE_HEXAHEDRON, VTK_HEXAHEDRON)")
          ->excludes(surface_option);
  app.add_option("--field", field_name, "point array of --vtu")->needs(vtu_option);
  app.add_option("--iso", isovalue, "isovalue (default: the surface's; needed with --vtu)");
  app.add_option("--in", in, "input PLY")->required();
  app.add_option("--out", out, "output PLY (binary)")->required();
  app.add_option("--max-move", max_move, "largest move kept (default: 1 % of the diagonal)");
  app.add_flag("--drop-failed", drop_failed,
               "remove each vertex whose projection failed or went too far, and its faces");
  app.add_option("--threads", threads, "threads (default: all cores)")->check(CLI::Range(1, 4096));
  CLI11_PARSE(app, argc, argv);

  try {
    // The field: a built-in surface's, or the polynomials of the file's cells at each point.
    std::function<double(const glm::dvec3&, glm::dvec3&)> field;
    double diagonal = 0.0, iso = isovalue;
#ifdef LDIMESH_WITH_VTU
    ldimesh::VtuField data;  // owns what `field` reads
#endif
    if (!vtu.empty()) {
#ifdef LDIMESH_WITH_VTU
      if (field_name.empty() || std::isnan(isovalue))
        throw std::runtime_error("--vtu needs --field NAME and --iso V");
      ldimesh::quiet_vtk_logging();
      if (const ldimesh::Status st = ldimesh::read_vtu_field(vtu, field_name, data); !st)
        throw std::runtime_error(st.message());
      field = data.lookup->field();
      diagonal = data.lookup->bounds().diagonal();
      name = vtu + ":" + field_name;
#else
      throw std::runtime_error("--vtu: built without VTK (libvtk9-dev)");
#endif
    } else {
      const ldimesh::SurfaceInfo* s = ldimesh::find_surface(name);
      if (!s) throw std::runtime_error("give --surface NAME (see 'ldimesh surfaces') or --vtu");
      field = s->field;
      diagonal = s->domain.diagonal();
      if (std::isnan(iso)) iso = s->isovalue;
    }
    if (threads == 0) threads = tbb::info::default_concurrency();
    tbb::global_control limit(tbb::global_control::max_allowed_parallelism, std::size_t(threads));
    if (max_move <= 0.0) max_move = 0.01 * diagonal;

    ldimesh::Mesh mesh;
    if (const ldimesh::Status st = ldimesh::read_ply(in, mesh); !st)
      throw std::runtime_error(st.message());

    const auto start = std::chrono::steady_clock::now();
    std::atomic<std::size_t> failed{0}, too_far{0};
    std::vector<double> moves(mesh.positions.size(), 0.0);
    std::vector<std::uint8_t> kept(mesh.positions.size(), 1);
    tbb::parallel_for(std::size_t(0), mesh.positions.size(), [&](std::size_t i) {
      const glm::dvec3 p0(mesh.positions[i]);
      glm::dvec3 p = p0, g(0.0);
      bool ok = false;
      for (int it = 0; it < 50; ++it) {
        const double f = field(p, g) - iso;
        const double g2 = glm::dot(g, g);
        if (!(g2 > 0.0) || !std::isfinite(f)) break;
        const glm::dvec3 step = (f / g2) * g;
        p -= step;
        const double len = glm::length(step);
        if (std::abs(f) / std::sqrt(g2) < 1e-12 * diagonal || len < 1e-14 * diagonal) {
          ok = true;
          break;
        }
      }
      const double move = glm::length(p - p0);
      if (!ok || !std::isfinite(move)) {
        ++failed;
        kept[i] = 0;
      } else if (move > max_move) {
        ++too_far;
        kept[i] = 0;
      } else {
        mesh.positions[i] = glm::vec3(p);
        moves[i] = move;
      }
    });
    const double seconds =
        std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    // Normals: the field's gradient direction at the (new) position.
    for (std::size_t i = 0; i < mesh.positions.size() && !mesh.normals.empty(); ++i) {
      glm::dvec3 g(0.0);
      if (!std::isfinite(field(glm::dvec3(mesh.positions[i]), g))) continue;
      const double len = glm::length(g);
      if (len > 0.0) mesh.normals[i] = glm::vec3(g / len);
    }
    std::size_t dropped = 0;
    if (drop_failed) {
      const auto keep_faces = [&](std::vector<std::uint32_t>& faces,
                                  std::vector<std::uint8_t>& view, std::size_t corners) {
        std::vector<std::uint32_t> kept_faces;
        std::vector<std::uint8_t> kept_view;
        for (std::size_t f = 0; f * corners < faces.size(); ++f) {
          const std::uint32_t* v = &faces[f * corners];
          if (!std::all_of(v, v + corners, [&](std::uint32_t i) { return kept[i] != 0; })) {
            ++dropped;
            continue;
          }
          kept_faces.insert(kept_faces.end(), v, v + corners);
          if (f < view.size()) kept_view.push_back(view[f]);
        }
        faces = std::move(kept_faces);
        view = std::move(kept_view);
      };
      keep_faces(mesh.triangles, mesh.triangle_view, 3);
      keep_faces(mesh.quads, mesh.quad_view, 4);
      // The vertices left where they were go too (readers that take every point see only
      // points on the surface); the faces' indices follow.
      std::vector<std::uint32_t> index(mesh.positions.size(), 0);
      std::size_t next = 0;
      for (std::size_t i = 0; i < mesh.positions.size(); ++i) {
        if (!kept[i]) continue;
        index[i] = std::uint32_t(next);
        mesh.positions[next] = mesh.positions[i];
        if (mesh.normals.size() == kept.size()) mesh.normals[next] = mesh.normals[i];
        if (mesh.scalars.size() == kept.size()) mesh.scalars[next] = mesh.scalars[i];
        ++next;
      }
      mesh.positions.resize(next);
      if (mesh.normals.size() == kept.size()) mesh.normals.resize(next);
      if (mesh.scalars.size() == kept.size()) mesh.scalars.resize(next);
      for (std::uint32_t& v : mesh.triangles)
        v = index[v];
      for (std::uint32_t& v : mesh.quads)
        v = index[v];
    }
    if (const ldimesh::Status st = ldimesh::write_ply(out, mesh); !st)
      throw std::runtime_error(st.message());

    double sum = 0.0, largest = 0.0;
    for (double m : moves) {
      sum += m;
      largest = std::max(largest, m);
    }
    nlohmann::json j;
    j["surface"] = name;
    j["in"] = in;
    j["out"] = out;
    j["vertices"] = mesh.positions.size();
    j["faces"] = mesh.face_count();
    j["failed"] = failed.load();
    j["too_far"] = too_far.load();
    j["dropped_faces"] = dropped;
    j["mean_move"] = mesh.positions.empty() ? 0.0 : sum / double(mesh.positions.size());
    j["max_move"] = largest;
    j["threads"] = threads;
    j["seconds"] = seconds;
    std::cout << j.dump() << std::endl;
    return 0;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "ldimesh_project_mesh: error: %s\n", e.what());
    return 1;
  }
}
