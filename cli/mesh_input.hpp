// What one rank of `ldimesh mesh` meshes: a built-in surface, a raw volume or a VTU file's
// elements.
#pragma once

#include <memory>
#include <string>
#include <vector>

#include "ldimesh/core/field/field_source.hpp"
#include "ldimesh/core/io/raw_volume.hpp"
#include "ldimesh/core/raycast/decomposition.hpp"
#ifdef LDIMESH_WITH_VTU
#include "ldimesh/core/io/vtu.hpp"
#endif
#include "mesh_command.hpp"

namespace ldimesh::cli {

// What this rank meshes: a built-in surface, a raw volume or a VTU file's elements, its sources
// (for a volume: this rank's part of it; elements: one source per order), its subdomain and the
// default isovalue.
struct Input {
  std::string name;
  std::vector<std::unique_ptr<ldimesh::FieldSource>> sources;
  ldimesh::Subdomain subdomain;
  double default_isovalue = 0.0;
  // Of a --vtu input: building the element sources from the cells read (their geometry's
  // Bernstein form, the Jacobian checks), part of "load".
  double prepare_seconds = 0.0;
  ldimesh::RawVolume volume;  // owns the values of a --grid input
  ldimesh::RawVolume colour;  // and of its --colour-by volume
#ifdef LDIMESH_WITH_VTU
  ldimesh::VtuElements elements;  // owns the arrays of a --vtu input
#endif
  std::vector<const ldimesh::FieldSource*> source_list() const {
    std::vector<const ldimesh::FieldSource*> list;
    for (const auto& s : sources)
      list.push_back(s.get());
    return list;
  }
};

// The name of the field the mesh is coloured by: --colour-by's point array, or for --grid the
// colour file's name without folder and extension.
std::string colour_name(const MeshArgs& args);

// Reads this rank's input (rank `rank` of `ranks`) as `args` names it. Throws on failure.
void load_input(const MeshArgs& args, int rank, int ranks, Input& input);

}  // namespace ldimesh::cli
