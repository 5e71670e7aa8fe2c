// Meshes as glTF 2.0 binary (.glb) with KHR_draco_mesh_compression, the format the job
// publishes to the browser viewer (docs/api.md, "The GLB"). Encoding goes through libdraco's
// own glTF encoder (draco::GltfEncoder); decoding parses the GLB container and decodes the
// Draco buffer with draco::Decoder. docs/method.md, "Mesh encoding", explains the choices.
//
// One primitive of triangles with the attributes
//   POSITION    float VEC3, quantized by Draco to `position_bits` over the bounding cube;
//   NORMAL      float VEC3, octahedral, `normal_bits`;
//   COLOR_0     unsigned byte VEC3 (normalized), the colour of the view each vertex's faces
//               came from: views along ±x red, ±y yellow, ±z green, any other view k
//               view_colour(k, ·) from a fixed palette; stored exactly (not quantized);
//   _SCALAR     float SCALAR (an application-specific attribute; a Draco GENERIC one), u =
//               (scalar − min) / (max − min) clamped to [0, 1]; only when the mesh has scalars;
//               quantized to `scalar_bits`.
// and meshes[0].extras.ldimesh = {"view_dirs": [[x,y,z], …], "scalar_range": [min, max]}
// (scalar_range only with scalars, and where GlbOptions::scalar_groups are given only when one
// group has a range), so that a client can recover views and scalar units; with scalar_groups
// also "surface_scalar_ranges": [[min, max] or null per surface] (null: the surface has no
// _SCALAR).
//
// Threads: encode_glb and decode_glb are reentrant (each call has its own Draco objects) and
// deterministic (the same mesh and options give the same bytes).
#pragma once

#include <array>
#include <cstdint>
#include <optional>
#include <span>
#include <vector>

#include "ldimesh/core/base/mesh.hpp"
#include "ldimesh/core/base/status.hpp"
#include "ldimesh/core/base/view.hpp"

namespace ldimesh {

struct GlbOptions {
  // Position quantization bits, 1..30; 0 = automatic: the fewest bits (at most 24, a float's
  // precision) whose quantization step is at most a tenth of `pixel_size`.
  int position_bits = 0;
  // The LDI pixel size (world units) for the automatic choice; 0 = take a step of 10⁻⁴ of the
  // bounding-box diagonal instead.
  double pixel_size = 0.0;
  // Octahedral normal quantization bits, 2..30 (Draco's octahedron transform needs ≥ 2).
  int normal_bits = 10;
  // _SCALAR (normalized scalar) quantization bits, 1..30.
  int scalar_bits = 12;
  // Draco compression level 0..10 (GltfEncoder maps it to speed 10 − level; 0 = sequential
  // encoding that keeps the vertex order — of a mesh of up to 200 000 triangles; a larger one,
  // in parts (`threads`), also keeps two unused points per part at its box's corners — ≥ 1 =
  // Edgebreaker, which reorders vertices and drops unused ones).
  int compression_level = 7;
  // The scalar values mapped to u = 0 and u = 1 (min < max, both finite), e.g. fixed over a
  // run so that colours mean the same at every step; unset = the mesh's own min and max (a
  // constant scalar then gives u = 0 everywhere).
  std::optional<std::array<float, 2>> scalar_range;
  // Threads that encode a mesh of more than 200 000 triangles, which goes in parts (slabs along
  // its longest axis, about 200 000 triangles each, at most 8) as primitives of one mesh; 0: one
  // per core. The GLB is the same for any number.
  int threads = 0;
  // Several surfaces (a step's isovalues), each a glTF mesh of its own that a viewer can show
  // or hide: surfaces[s] is the first vertex of surface s (surfaces[0] = 0, non-decreasing; a
  // face belongs to the surface of its first vertex and must use only its vertices). Each mesh
  // sits on a node of the scene whose extras are {"ldimesh_surface": s} (three.js:
  // node.userData.ldimesh_surface); an empty surface has none. Empty or one entry: one mesh.
  std::vector<std::uint32_t> surfaces;
  // The surfaces' colour fields where they differ (a step's isovalues coloured by different
  // fields, or some not at all): scalar_groups[s] is surface s's group (one entry per surface:
  // as many as `surfaces` has, or one), −1 where surface s carries no _SCALAR (its scalars, which
  // the mesh must still have, are ignored). The surfaces of one group share a range: the group's
  // min and max, or scalar_range. Empty: every surface in one group where the mesh has scalars.
  std::vector<int> scalar_groups;
};

// What a GLB holds, as encode_glb wrote it or decode_glb read it.
struct GlbInfo {
  std::size_t triangles = 0;          // triangles in the GLB (after Draco dropped degenerate ones)
  std::size_t vertices = 0;           // vertices in the GLB (Draco may split non-manifold ones)
  int position_bits = 0;              // encode only (0 from decode_glb): the bits used
  double position_error_bound = 0.0;  // encode only (0 from decode_glb): the bound used
  bool has_scalar = false;            // _SCALAR (or an older GLB's TEXCOORD_0) present
  // The scalar range behind u ∈ [0, 1] when has_scalar (decode_glb: from extras.ldimesh,
  // 0 and 0 when a GLB from elsewhere lacks it).
  float scalar_min = 0.0f;
  float scalar_max = 0.0f;
  // Per surface, the range behind its _SCALAR (absent: it has none): encode_glb with
  // GlbOptions::scalar_groups, decode_glb from extras.ldimesh.surface_scalar_ranges; else empty.
  // scalar_min and scalar_max are then those of the one group that has a range (0 and 0 when
  // several have).
  std::vector<std::optional<std::array<float, 2>>> surface_scalar_ranges;
};

// What a published step's GLB trades between bytes and precision (the adaptor's "glb" options,
// the CLI's --glb-* flags): Draco's compression level and the bits of the normals and of the
// colour field's _SCALAR. The defaults are draco_encoder's own (-cl 7, -qn 8, -qg 8): normals
// within 0.96°, the scalar within 1/510 of its range, half an entry of the viewer's 256-entry
// colour map. What they save against 10 and 10 bits, and how little they change the viewer's
// picture: docs/history/benchmarks-log.md, "Eight bits for the published normals and colour
// field".
struct StepGlbSettings {
  int compression_level = 7;
  int normal_bits = 8;
  int scalar_bits = 8;
};

// The options of a published step's GLB, the same for the CLI and the adaptor: positions
// quantized to a tenth of `view`'s pixel (the step's first view), the rest from `settings`.
inline GlbOptions step_glb_options(const View& view, const StepGlbSettings& settings = {}) {
  GlbOptions options;
  options.pixel_size = view.spacing;
  options.compression_level = settings.compression_level;
  options.normal_bits = settings.normal_bits;
  options.scalar_bits = settings.scalar_bits;
  return options;
}

// Encodes `mesh` into `out` (replaced). Quads are split into two triangles along their shorter
// diagonal (same winding); the triangles follow, quads' triangles first. A vertex takes the
// colour of the view of the first face that uses it (quads first); our meshes never share a
// vertex between views. A mesh without faces gives a valid GLB without meshes (a scene with
// no nodes, no extension used) that decode_glb reads as an empty mesh.
// Errors (Status, `out` unchanged): options out of range; a mesh whose arrays disagree in
// size (normals, scalars, quad_view, triangle_view), an index out of range, non-finite
// positions, normals or scalars, more than 2³¹ − 1 vertices or triangles; Draco failing.
// Deterministic: the same mesh and options give the same bytes. `info`, when given, is
// filled on success. Never throws (allocation failure included).
Status encode_glb(const Mesh& mesh, const GlbOptions& options, std::vector<std::uint8_t>& out,
                  GlbInfo* info = nullptr);

// The position quantization bits encode_glb uses for `mesh` and `options`.
int glb_position_bits(const Mesh& mesh, const GlbOptions& options);

// The largest distance between a vertex of `mesh` and its decoded position. Draco quantizes
// each coordinate over the bounding cube: range r = the largest side of the bounding box,
// q = ⌊(x − min)·(2^b − 1)/r + ½⌋, x' = q·r/(2^b − 1) + min (draco/attributes/
// attribute_quantization_transform.cc, draco/core/quantization_utils.cc, Draco 1.5.5), so a
// coordinate moves by at most r / (2·(2^b − 1)) and a point by √3 times that; plus 8 float
// spacings of max(r, |coordinate|) for Draco's float arithmetic. b = glb_position_bits.
double glb_position_error_bound(const Mesh& mesh, const GlbOptions& options);

// The largest angle (radians) between a unit normal and its decoded value, for Draco's
// octahedral quantization with n = options.normal_bits (step 2/(2^n − 2) on the octahedron,
// draco/compression/attributes/normal_compression_utils.h): 3·√2 / (2^n − 2) + 2⁻²⁰.
double glb_normal_error_bound(const GlbOptions& options);

// The largest error of a decoded _SCALAR (normalized scalar): 1 / (2·(2^s − 1)) + 2⁻²⁰,
// s = options.scalar_bits (u ∈ [0, 1], quantized like positions).
double glb_scalar_error_bound(const GlbOptions& options);

// The colour (8-bit RGB) COLOR_0 gives the faces of view `k` with direction `dir`: ±x red
// (255, 0, 0), ±y yellow (255, 215, 0), ±z green (0, 170, 0), other directions the fixed
// palette entry k mod 8 (blue, magenta, cyan, orange, purple, teal, pink, grey).
std::array<std::uint8_t, 3> view_colour(std::size_t k, const glm::dvec3& dir);

// Decodes a GLB into `out` (replaced): positions, unit normals, triangles, per-vertex scalars
// = _SCALAR (normalized, in [0, 1]; TEXCOORD_0.u in GLBs written before it) when some primitive
// has it (NaN at the vertices of a primitive that has none), view_dirs
// from extras.ldimesh when present, and per triangle the view whose view_colour matches the colour
// of its first vertex (view 0 when none does). Vertices come in Draco's decoding order, which for
// Edgebreaker (compression level ≥ 1) differs from the encoder's input order.
// Accepts GLBs whose every primitive (of every mesh; they are concatenated; node transforms
// are ignored) is a KHR_draco_mesh_compression triangle primitive with POSITION and NORMAL;
// a GLB without meshes gives an empty mesh. Validates the container, the JSON, every index,
// offset and count against the bytes there are, and Draco's output (attribute types, counts,
// finite values, face indices): garbage, truncated or hostile input returns an error Status
// and never crashes; Draco's decoder itself is fuzzed upstream (OSS-Fuzz, draco/tools/fuzz/)
// and guarded here against exceptions. `info`, when given, gets counts and the scalar range
// from extras. On error `out` is left unchanged.
Status decode_glb(std::span<const std::uint8_t> glb, Mesh& out, GlbInfo* info = nullptr);

// decode_glb in a child process (run_isolated, core/base/isolated.hpp) whose CPU time is limited to
// `cpu_seconds` (rounded up to whole seconds; 0: glb_decode_cpu_limit(glb.size())), for tools that
// read GLBs from elsewhere (ldimesh-fetch, `ldimesh distance`): Debian's Draco 1.5.5 spends up to ≈
// 15 s on a hostile stream of a few KB (an unchecked count in its texture-coordinate predictor;
// docs/reliability.md), which the limit turns into an error. The same mesh and info as
// decode_glb, or its error; beyond that a corrupt_input Status when the limit stops the decoder
// ("took more than N s of CPU") or the decoder dies of a signal, out_of_memory, io when no
// process can be started or its CPU cannot be limited, internal when it makes no progress for 4×
// the limit in wall time (it is then killed). `out` changes only on success. The child and what
// a multithreaded caller may expect of it: run_isolated. cpu_seconds outside [1, 10⁶] is
// invalid_argument.
Status decode_glb_isolated(std::span<const std::uint8_t> glb, Mesh& out, GlbInfo* info = nullptr,
                           double cpu_seconds = 0.0);

// The automatic CPU limit of decode_glb_isolated, in whole seconds: 2 s + 5 s per MiB of GLB
// (rounded down): several times what Draco takes to decode a real file of that size on one core
// (docs/performance.md, "GLB delivery against PLY").
double glb_decode_cpu_limit(std::size_t glb_bytes);

}  // namespace ldimesh
