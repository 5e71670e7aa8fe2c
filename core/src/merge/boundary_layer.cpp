// §5 before bridging: removing the views' boundary layer (merge_state.hpp).
#include <algorithm>
#include <cmath>
#include <queue>
#include <unordered_map>
#include <vector>

#include "../base/mesh_util.hpp"
#include "ldimesh/core/base/geometry.hpp"
#include "merge_state.hpp"

namespace ldimesh::merge_detail {

void remove_boundary_layer(MergeState& ms) {
  std::vector<FH> layer;
  for (const auto& f : ms.mesh_.faces())
    for (const auto& h : f.halfedges())
      if (ms.is_open(h.opp())) {
        layer.push_back(f);
        break;
      }
  for (FH f : layer)
    ms.erase(f, true);
  ms.stats_.boundary_faces = layer.size();
}

}  // namespace ldimesh::merge_detail
