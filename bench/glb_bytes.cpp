// Where a GLB's bytes go: each GLB given (a published step, `ldimesh mesh --out .glb`) is decoded
// and its mesh re-encoded with Draco's ExpertEncoder, one attribute set or prediction scheme at
// a time, as GltfEncoder encodes it (the same speed, quantization and attribute types); printed
// in bytes per triangle (docs/history/benchmarks-log.md, "The colour field as a generic
// attribute").
//   ldimesh_bench_glb_bytes [--position-bits 11] [--normal-bits 8] [--scalar-bits 8]
//                           [--level 7] STEP.glb...
// The position bits are not in the file: give those it was written with (the published steps':
// a tenth of a pixel over the mesh's box, GlbInfo::position_bits; the log of `ldimesh mesh`).
#include <algorithm>
#include <array>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <iterator>
#include <string>
#include <vector>

#include <draco/compression/config/compression_shared.h>
#include <draco/compression/expert_encode.h>
#include <draco/mesh/mesh.h>
#include <CLI/CLI.hpp>

#include "ldimesh/transport/glb.hpp"

namespace {

using namespace ldimesh;

enum class Scalar { none, texcoord, generic };

struct Setting {
  const char* name;
  bool normals = true, colours = true;
  Scalar scalar = Scalar::none;
  int scalar_prediction = -2;  // -2: Draco's choice for the speed
};

struct Bits {
  // The published steps' settings (StepGlbSettings) but for the position bits, not in the file.
  int position = 11, normal = StepGlbSettings{}.normal_bits, scalar = StepGlbSettings{}.scalar_bits,
      level = StepGlbSettings{}.compression_level;
};

// The Draco bytes of `m` encoded with setting `s`.
std::size_t encoded_bytes(const Mesh& m, const Setting& s, const Bits& bits) {
  draco::Mesh dm;
  const std::size_t n = m.vertex_count();
  dm.set_num_points(std::uint32_t(n));
  const auto add = [&](draco::GeometryAttribute::Type type, int components, draco::DataType dt,
                       bool normalized, const void* data) {
    draco::GeometryAttribute ga;
    ga.Init(type, nullptr, std::uint8_t(components), dt, normalized,
            std::int64_t(draco::DataTypeLength(dt)) * components, 0);
    const int id = dm.AddAttribute(ga, true, std::uint32_t(n));
    dm.attribute(id)->buffer()->Write(0, data, n * draco::DataTypeLength(dt) * components);
    return id;
  };
  const int position =
      add(draco::GeometryAttribute::POSITION, 3, draco::DT_FLOAT32, false, m.positions.data());
  int normal = -1, scalar = -1;
  if (s.normals)
    normal = add(draco::GeometryAttribute::NORMAL, 3, draco::DT_FLOAT32, false, m.normals.data());
  if (s.colours) {
    std::vector<std::array<std::uint8_t, 3>> colour(n, {255, 255, 255});
    for (std::size_t f = 0; f < m.triangle_count(); ++f)
      for (int c = 0; c < 3; ++c) {
        const std::uint8_t k = m.triangle_view[f];
        colour[m.triangles[3 * f + c]] =
            view_colour(k, k < m.view_dirs.size() ? m.view_dirs[k] : glm::dvec3(0.0));
      }
    add(draco::GeometryAttribute::COLOR, 3, draco::DT_UINT8, true, colour.data());
  }
  if (s.scalar == Scalar::texcoord && !m.scalars.empty()) {
    std::vector<std::array<float, 2>> uv(n);
    for (std::size_t i = 0; i < n; ++i)
      uv[i] = {m.scalars[i], 1.0f};
    scalar = add(draco::GeometryAttribute::TEX_COORD, 2, draco::DT_FLOAT32, false, uv.data());
  } else if (s.scalar == Scalar::generic && !m.scalars.empty()) {
    scalar = add(draco::GeometryAttribute::GENERIC, 1, draco::DT_FLOAT32, false, m.scalars.data());
  }
  dm.SetNumFaces(m.triangle_count());
  for (std::size_t f = 0; f < m.triangle_count(); ++f)
    dm.SetFace(draco::FaceIndex(std::uint32_t(f)),
               {draco::PointIndex(m.triangles[3 * f]), draco::PointIndex(m.triangles[3 * f + 1]),
                draco::PointIndex(m.triangles[3 * f + 2])});
  draco::ExpertEncoder encoder(dm);
  encoder.SetSpeedOptions(10 - bits.level, 10 - bits.level);
  encoder.SetAttributeQuantization(position, bits.position);
  if (normal >= 0) encoder.SetAttributeQuantization(normal, bits.normal);
  if (scalar >= 0) {
    encoder.SetAttributeQuantization(scalar, bits.scalar);
    if (s.scalar_prediction != -2)
      (void)encoder.SetAttributePredictionScheme(scalar, s.scalar_prediction);
  }
  draco::EncoderBuffer buffer;
  if (const draco::Status st = encoder.EncodeToBuffer(&buffer); !st.ok()) {
    std::fprintf(stderr, "glb_bytes: Draco failed: %s\n", st.error_msg());
    std::exit(1);
  }
  return buffer.size();
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App cli{"Where a GLB's bytes go: its mesh re-encoded attribute by attribute"};
  Bits bits;
  std::vector<std::string> files;
  cli.add_option("--position-bits", bits.position, "position quantization bits")
      ->capture_default_str();
  cli.add_option("--normal-bits", bits.normal, "normal quantization bits")->capture_default_str();
  cli.add_option("--scalar-bits", bits.scalar, "scalar quantization bits")->capture_default_str();
  cli.add_option("--level", bits.level, "Draco compression level (speed 10 - level)")
      ->capture_default_str();
  cli.add_option("glb", files, "GLB files")->required();
  CLI11_PARSE(cli, argc, argv);

  const Setting settings[] = {
      {"positions and connectivity", false, false},
      {"+ normals", true, false},
      {"+ view colours", true, true},
      {"+ scalar as TEXCOORD_0 (u, 1)", true, true, Scalar::texcoord},
      {"+ scalar as TEXCOORD_0, parallelogram", true, true, Scalar::texcoord,
       draco::MESH_PREDICTION_PARALLELOGRAM},
      {"+ scalar as _SCALAR (generic)", true, true, Scalar::generic},
  };
  for (const std::string& file : files) {
    std::ifstream in(file, std::ios::binary);
    const std::vector<std::uint8_t> glb((std::istreambuf_iterator<char>(in)), {});
    Mesh mesh;
    if (const Status s = decode_glb(glb, mesh); !s) {
      std::fprintf(stderr, "glb_bytes: %s: %s\n", file.c_str(), s.message().c_str());
      return 1;
    }
    const double t = double(std::max<std::size_t>(mesh.triangle_count(), 1));
    std::printf("%s: %zu triangles, %zu vertices (%.2f per triangle), file %.3f bytes/triangle%s\n",
                file.c_str(), mesh.triangle_count(), mesh.vertex_count(),
                double(mesh.vertex_count()) / t, double(glb.size()) / t,
                mesh.scalars.empty() ? " (no scalar)" : "");
    for (const Setting& s : settings) {
      if (s.scalar != Scalar::none && mesh.scalars.empty()) continue;
      const std::size_t bytes = encoded_bytes(mesh, s, bits);
      std::printf("  %-42s %9zu bytes  %.3f bytes/triangle\n", s.name, bytes, double(bytes) / t);
    }
  }
  return 0;
}
