// The adaptor's options document (docs/adaptor.md): the values and their parser. Internal to
// the adaptor library; a header of its own so that the parser can be tested and fuzzed
// without MPI (tests/fuzz/options_fuzz.cpp).
#pragma once

#include <cstddef>
#include <cstdint>
#include <string>
#include <string_view>
#include <vector>

#include "ldimesh/core/base/status.hpp"
#include "ldimesh/transport/fragment_codec.hpp"
#include "ldimesh/transport/glb.hpp"

namespace ldimesh {

struct AdaptorOptions {
  std::vector<double> isovalues{0.5};
  // "colour_by": the fields the isosurfaces are coloured by (add_field), each named once, in
  // the order the option names them (empty: nothing is coloured), and each isovalue's field as
  // an index into them (−1: that isosurface is not coloured; empty when colour_fields is).
  std::vector<std::string> colour_fields;
  std::vector<int> surface_field;
  std::string views = "xyz";
  int resolution = 256;
  double r = 0.5;
  int refinement_levels = 0;  // §4: levels of refinement (0 off), with samples from every rank
  // §5: one merged mesh per isovalue (trimmed with r = 1). Automatic: on the steps that run in
  // the background (the caster threads serve the merge's samples, not the solver), else the
  // trimmed views.
  enum class Merging { off, on, automatic };
  Merging merging = Merging::automatic;
  std::uint64_t every_steps = 1;
  double every_seconds = 0.0;
  bool coalesce = false;
  bool server = true;
  std::string bind = "127.0.0.1";
  bool allow_remote = false;
  int port = 0;
  std::string token;
  std::string output_dir;
  std::size_t keep = 16;
  std::size_t memory_mb = 512;
  FragmentEncoding encoding;
  StepGlbSettings glb;  // the published GLB: Draco level, normal and scalar bits
  bool log = true;
  bool background = true;          // with MPI_THREAD_MULTIPLE: the solver waits for a snapshot only
  double slow_root_seconds = 0.0;  // testing only: the worker sleeps this long per step
  // Testing only: a fault injected into step `fault_step` on rank `fault_rank`.
  std::string fault;  // "", "out_of_memory", "exception" or "corrupt_message"
  std::uint64_t fault_step = 0;
  int fault_rank = 0;
};

// Reads the JSON document `json` into `out` (defaults for what it leaves out). Errors
// (invalid_options, `out` then unspecified): not JSON, not an object, an unknown key (named),
// a value of the wrong type or out of range (named, with the range). Never throws.
Status parse_adaptor_options(std::string_view json, AdaptorOptions& out);

}  // namespace ldimesh
