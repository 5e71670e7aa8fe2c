// read_vtu_field: the cells read_vtu_isolated returns as sources and a lookup over them. A file of
// its own, apart from the reader, so that the reader builds without the rest of the core (the fuzz
// target, scripts/fuzz.sh vtu).
#include <memory>
#include <new>
#include <stdexcept>
#include <vector>

#include "ldimesh/core/io/vtu.hpp"

namespace ldimesh {

std::unique_ptr<FieldSource> make_vtu_source(const VtuElements::Group& group) {
  if (group.type == CellType::hexahedron) return std::make_unique<HexElementSource>(group.block());
  return std::make_unique<CellElementSource>(group.cell_block());
}

Status read_vtu_field(const std::string& path, const std::string& field, VtuField& out) {
  out = {};
  if (Status st = read_vtu_isolated(path, field, out.elements); !st) return st;
  try {
    std::vector<const HexElementSource*> list;
    for (const VtuElements::Group& g : out.elements.groups) {
      out.sources.push_back(make_vtu_source(g));
      if (const auto* hex = dynamic_cast<const HexElementSource*>(out.sources.back().get())) {
        list.push_back(hex);
      } else {
        const auto& cells = dynamic_cast<const CellElementSource&>(*out.sources.back());
        out.snapshots.push_back(cells.snapshot());
        list.push_back(out.snapshots.back()->source.get());
      }
    }
    out.lookup = std::make_unique<HexFieldLookup>(list);
  } catch (const std::invalid_argument& e) {
    return Status::invalid_argument(path + ": " + e.what());
  } catch (const std::bad_alloc&) {
    return Status::out_of_memory(path + ": out of memory while preparing its cells");
  }
  return Status::ok();
}

}  // namespace ldimesh
