// What the adaptor tests read back: a published step's metadata from its output_dir files.
#pragma once

#include <cstdint>
#include <string>

#include <gtest/gtest.h>

#include "ldimesh/core/base/mesh.hpp"
#include "ldimesh/transport/glb.hpp"
#include "ldimesh/transport/snapshot_store.hpp"

namespace ldimesh::testing {

// The metadata of step `step` written into `dir` (read_step_files: GLB and metadata checked);
// a test failure and empty metadata (step 0) when the files are missing or invalid.
inline StepMetadata published_step(const std::string& dir, std::uint64_t step) {
  Snapshot snapshot;
  StepMetadata meta;
  if (Status s = read_step_files(dir, step, snapshot); !s) {
    ADD_FAILURE() << "step " << step << " in " << dir << ": " << s.message();
    return meta;
  }
  if (Status s = metadata_from_json(snapshot.metadata_json, meta); !s)
    ADD_FAILURE() << "step " << step << ": " << s.message();
  return meta;
}

// The mesh of step `step` in `dir`, decoded from its GLB; a test failure and an empty mesh when
// the files are missing or the GLB does not decode.
inline Mesh published_mesh(const std::string& dir, std::uint64_t step) {
  Snapshot snapshot;
  Mesh mesh;
  if (Status s = read_step_files(dir, step, snapshot); !s || !snapshot.glb) {
    ADD_FAILURE() << "step " << step << " in " << dir << ": " << s.message();
    return mesh;
  }
  if (Status s = decode_glb(*snapshot.glb, mesh); !s)
    ADD_FAILURE() << "step " << step << ": " << s.message();
  return mesh;
}

}  // namespace ldimesh::testing
