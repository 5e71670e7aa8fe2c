#include "ldimesh/core/field/cell_source.hpp"

#include <atomic>
#include <cmath>
#include <cstdlib>
#include <cstring>
#include <limits>
#include <mutex>
#include <stdexcept>
#include <string>

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include "linear_tets.hpp"
#include "reference_cells.hpp"
#include "straight_tets.hpp"

namespace ldimesh {
namespace {

bool known_scalar(ScalarType t) {
  return t == ScalarType::float32 || t == ScalarType::float64;
}

double read_value(const void* values, ScalarType type, std::size_t index) {
  return type == ScalarType::float32 ? double(static_cast<const float*>(values)[index])
                                     : static_cast<const double*>(values)[index];
}

// rows × n matrix times the n nodal values → rows values.
void apply(const double* matrix, std::size_t rows, std::size_t n, const double* nodal,
           double* out) {
  for (std::size_t r = 0; r < rows; ++r) {
    const double* row = matrix + r * n;
    double s = 0.0;
    for (std::size_t i = 0; i < n; ++i)
      s += row[i] * nodal[i];
    out[r] = s;
  }
}

// The sub-hexahedra's block over `geometry` (their equispaced lattice points of degree
// `geometry_degree`), values (of degree `degree`) to be set.
HexBlock sub_hexahedra_block(std::size_t count, int degree, int geometry_degree,
                             const std::vector<double>& geometry) {
  HexBlock b;
  b.order = degree;
  b.nodes = NodeSet::equispaced;
  b.ordering = NodeOrdering::lexicographic;
  b.element_count = count;
  b.geometry_order = geometry_degree;
  b.geometry = geometry.data();
  b.type = ScalarType::float64;
  return b;
}

// A binding over a snapshot of the sub-hexahedra's values, which it keeps alive.
class CellGeometryBinding final : public GeometryBinding {
 public:
  CellGeometryBinding(std::shared_ptr<const CellElementSource::Snapshot> snapshot,
                      std::unique_ptr<GeometryBinding> inner, std::uint64_t nonfinite)
      : snapshot_(std::move(snapshot)), inner_(std::move(inner)), nonfinite_(nonfinite) {}
  RTCGeometry geometry() const override { return inner_->geometry(); }
  std::size_t primitive_count() const override { return inner_->primitive_count(); }
  std::uint64_t nonfinite_values() const override { return nonfinite_; }

 private:
  std::shared_ptr<const CellElementSource::Snapshot> snapshot_;
  std::unique_ptr<GeometryBinding> inner_;
  std::uint64_t nonfinite_;
};

class CellAxisCaster final : public AxisCaster {
 public:
  CellAxisCaster(std::shared_ptr<const CellElementSource::Snapshot> snapshot,
                 std::unique_ptr<AxisCaster> inner, std::uint64_t nonfinite)
      : snapshot_(std::move(snapshot)), inner_(std::move(inner)), nonfinite_(nonfinite) {}
  void cast(const AxisRays& rays, AxisHits& hits) const override { inner_->cast(rays, hits); }
  void prepare(int axis) const override { inner_->prepare(axis); }
  std::size_t primitive_count() const override { return inner_->primitive_count(); }
  bool prefers_column_tasks(const View& view) const override {
    return inner_->prefers_column_tasks(view);
  }
  std::uint64_t nonfinite_values() const override { return nonfinite_; }

 private:
  std::shared_ptr<const CellElementSource::Snapshot> snapshot_;
  std::unique_ptr<AxisCaster> inner_;
  std::uint64_t nonfinite_;
};

class CellScalarProbe final : public ScalarProbe {
 public:
  CellScalarProbe(std::shared_ptr<const CellElementSource::Snapshot> snapshot,
                  std::unique_ptr<ScalarProbe> inner)
      : snapshot_(std::move(snapshot)), inner_(std::move(inner)) {}
  double at(glm::dvec3 p) const override { return inner_->at(p); }
  double near(glm::dvec3 p) const override { return inner_->near(p); }

 private:
  std::shared_ptr<const CellElementSource::Snapshot> snapshot_;
  std::unique_ptr<ScalarProbe> inner_;
};

// The index of the element a HexElementSource message names ("… element 17 …"), or −1.
long named_element(const std::string& message) {
  const std::string key = "element ";
  const std::size_t at = message.find(key);
  if (at == std::string::npos) return -1;
  char* end = nullptr;
  const long e = std::strtol(message.c_str() + at + key.size(), &end, 10);
  return end != message.c_str() + at + key.size() ? e : -1;
}

}  // namespace

struct CellElementSource::Counted {
  std::shared_ptr<const Snapshot> snapshot;
  std::uint64_t nonfinite = 0;
};

CellElementSource::CellElementSource(const CellBlock& block) : block_(block) {
  const cells::ReferenceCell& cell = cells::reference_cell(block.type, block.order);
  nodes_ = cell.nodes.size();
  sub_per_cell_ = cell.sub_hexahedra;
  degree_ = cell.degree;
  const std::string what = std::string("cell source: ") + cell_type_name(block.type) + "s";
  if (block.element_count == 0) throw std::invalid_argument(what + ": no cells");
  if (!block.points) throw std::invalid_argument(what + ": null point array");
  check_values(what);
  // The geometry's cell: the field's, or the same shape at the points' own order.
  geometry_order_ = block.geometry_order == 0 ? block.order : block.geometry_order;
  geometry_type_ = cell_geometry_type(block.type, block.order, block.geometry_order);
  const cells::ReferenceCell* geometry_cell = nullptr;
  try {
    if (block.geometry_order < 0) throw std::invalid_argument("negative");
    geometry_cell = &cells::reference_cell(geometry_type_, geometry_order_);
  } catch (const std::invalid_argument&) {
    throw std::invalid_argument(what + ": geometry order " + std::to_string(block.geometry_order) +
                                " is not one of theirs");
  }
  geometry_nodes_ = geometry_cell->nodes.size();
  geometry_degree_ = geometry_cell->degree;
  const auto order_of_nodes = [&](CellType type, int order, std::size_t count) {
    std::vector<int> from;
    if (block.node_order == CellNodeOrder::gmsh) {
      from = cell_gmsh_permutation(type, order);
      if (from.empty())
        throw std::invalid_argument(what + " of order " + std::to_string(order) +
                                    ": gmsh's node order is not taken for them (VTK's is)");
    } else if (block.node_order != CellNodeOrder::vtk) {
      throw std::invalid_argument(what + ": unknown node order");
    } else {
      for (std::size_t i = 0; i < count; ++i)
        from.push_back(int(i));
    }
    return from;
  };
  from_ = order_of_nodes(block.type, block.order, nodes_);
  geometry_from_ = order_of_nodes(geometry_type_, geometry_order_, geometry_nodes_);

  geometry_ = std::make_shared<Geometry>();
  if (block.type == CellType::tetrahedron && block.order == 1 && geometry_order_ == 1) {
    // Linear tetrahedra: cast directly (linear_tets.hpp); the sub-hexahedra only where a lookup
    // or a colour field needs them.
    std::vector<double>& v = geometry_->tets;
    v.resize(12 * block.element_count);
    constexpr double inf = std::numeric_limits<double>::infinity();
    geometry_->bounds = {glm::dvec3(inf), glm::dvec3(-inf)};
    for (std::size_t e = 0; e < block.element_count; ++e) {
      const double* p = block.points + 12 * e;
      for (int i = 0; i < 4; ++i)
        for (int a = 0; a < 3; ++a) {
          const double x = p[3 * geometry_from_[i] + a];
          if (!std::isfinite(x))
            throw std::invalid_argument(what + ": cell " + std::to_string(e) +
                                        " has a non-finite point");
          v[12 * e + 3 * i + a] = x;
          geometry_->bounds.lo[a] = std::min(geometry_->bounds.lo[a], x);
          geometry_->bounds.hi[a] = std::max(geometry_->bounds.hi[a], x);
        }
      if (!cells::linear_tet_is_valid(&v[12 * e]))
        throw std::invalid_argument(what + ": cell " + std::to_string(e) +
                                    " is inverted or degenerate (its Jacobian determinant "
                                    "vanishes or changes sign)");
    }
    return;
  }
  if (block.type == CellType::tetrahedron && block.order >= 2 &&
      take_straight_tetrahedra(block.points))
    return;
  std::call_once(geometry_->once, [&] {
    geometry_->sub_hexahedra = build_sub_hexahedra(block.points, geometry_from_);
  });
  geometry_->bounds = geometry_->sub_hexahedra->bounds();
}

bool CellElementSource::take_straight_tetrahedra(const double* points) {
  // Straight when every geometry node lies where the affine map of the vertices puts it, up to
  // the rounding of the coordinates: a cell whose coordinates are all floats (files often hold
  // float32 points, VTK's default) within 2·√3·2⁻²³ of their magnitude (the node and the
  // vertices each rounded to float), any other within 16 ulps of it; and 10⁻¹² of the cell's
  // size. A cell that differs from straight by less is meshed as straight, its surface moved by
  // no more than that rounding. First the check (one curved cell ends it), then the vertices.
  const cells::ReferenceCell& geometry = cells::reference_cell(geometry_type_, geometry_order_);
  const auto node = [&](std::size_t e, std::size_t i) {
    const double* x = points + 3 * geometry_nodes_ * e + 3 * geometry_from_[i];
    return glm::dvec3(x[0], x[1], x[2]);
  };
  for (std::size_t e = 0; e < block_.element_count; ++e) {
    double corners[12];
    double coords = 0.0, size = 0.0;
    bool floats = true;
    for (std::size_t i = 0; i < geometry_nodes_; ++i) {
      const glm::dvec3 x = node(e, i);
      for (int a = 0; a < 3; ++a) {
        if (!std::isfinite(x[a])) return false;  // refused by the general path
        coords = std::max(coords, std::abs(x[a]));
        floats = floats && double(float(x[a])) == x[a];
        if (i < 4) corners[3 * i + a] = x[a];
      }
    }
    if (!cells::linear_tet_is_valid(corners)) return false;
    const glm::dvec3 v0 = node(e, 0), e1 = node(e, 1) - v0, e2 = node(e, 2) - v0,
                     e3 = node(e, 3) - v0;
    size = std::max({glm::length(e1), glm::length(e2), glm::length(e3)});
    const double rounding = floats ? 2.0 * std::sqrt(3.0) * 0x1p-23 : 16.0 * 0x1p-52;
    const double tolerance = rounding * coords + 1e-12 * size;
    for (std::size_t i = 4; i < geometry_nodes_; ++i) {
      const glm::dvec3 r = geometry.nodes[i];
      const glm::dvec3 at = v0 + r.x * e1 + r.y * e2 + r.z * e3;
      if (!(glm::length(node(e, i) - at) <= tolerance)) return false;
    }
  }
  // The geometry is now that of linear tetrahedra: their vertices, in VTK's order.
  std::vector<double> v(12 * block_.element_count);
  constexpr double inf = std::numeric_limits<double>::infinity();
  Box bounds{glm::dvec3(inf), glm::dvec3(-inf)};
  for (std::size_t e = 0; e < block_.element_count; ++e)
    for (std::size_t i = 0; i < 4; ++i) {
      const glm::dvec3 x = node(e, i);
      for (int a = 0; a < 3; ++a)
        v[12 * e + 3 * i + std::size_t(a)] = x[a];
      bounds.lo = glm::min(bounds.lo, x), bounds.hi = glm::max(bounds.hi, x);
    }
  geometry_->tets = std::move(v);
  geometry_->straight = true;
  geometry_->bounds = bounds;
  geometry_type_ = CellType::tetrahedron;
  geometry_order_ = 1;
  geometry_nodes_ = 4;
  geometry_degree_ = cells::reference_cell(CellType::tetrahedron, 1).degree;
  geometry_from_ = {0, 1, 2, 3};
  return true;
}

std::shared_ptr<const HexElementSource> CellElementSource::build_sub_hexahedra(
    const double* points, const std::vector<int>& from) const {
  const cells::ReferenceCell& cell = cells::reference_cell(geometry_type_, geometry_order_);
  const std::string what = std::string("cell source: ") + cell_type_name(block_.type) + "s";
  // The sub-hexahedra's lattice points (of the geometry's degree), cell after cell.
  const std::size_t g = std::size_t(geometry_degree_) + 1, nodes = geometry_nodes_;
  const std::size_t rows = g * g * g * sub_per_cell_;
  const std::size_t count = block_.element_count * sub_per_cell_;
  std::vector<double> geometry(3 * rows * block_.element_count);
  std::vector<double> nodal(nodes), out(rows);
  for (std::size_t e = 0; e < block_.element_count; ++e) {
    const double* p = points + 3 * nodes * e;
    for (std::size_t i = 0; i < 3 * nodes; ++i)
      if (!std::isfinite(p[i]))
        throw std::invalid_argument(what + ": cell " + std::to_string(e) +
                                    " has a non-finite point");
    for (int axis = 0; axis < 3; ++axis) {
      for (std::size_t i = 0; i < nodes; ++i)
        nodal[i] = p[3 * from[i] + axis];
      apply(cell.sampling.data(), rows, nodes, nodal.data(), out.data());
      for (std::size_t r = 0; r < rows; ++r)
        geometry[3 * (e * rows + r) + axis] = out[r];
    }
  }
  HexBlock hex = sub_hexahedra_block(count, degree_, geometry_degree_, geometry);
  hex.values = geometry.data();  // not read by the constructor, which needs a non-null array
  try {
    // It keeps what it needs of the geometry; the sources made from it do not read the lattice
    // points (hex_source.hpp), which go with this function.
    return std::make_shared<const HexElementSource>(hex, cell.top_collapsed);
  } catch (const std::invalid_argument& error) {
    const long sub = named_element(error.what());
    if (sub < 0) throw;
    const std::string cell_name = what + ": cell " + std::to_string(sub / sub_per_cell_);
    if (std::string(error.what()).find("non-finite") != std::string::npos)
      throw std::invalid_argument(cell_name + " has points too large to sample (not finite)");
    throw std::invalid_argument(cell_name +
                                " is inverted or degenerate (its Jacobian determinant vanishes "
                                "or changes sign)");
  }
}

const HexElementSource& CellElementSource::sub_hexahedra() const {
  std::call_once(geometry_->once, [&] {
    std::vector<int> identity(geometry_nodes_);
    for (std::size_t i = 0; i < geometry_nodes_; ++i)
      identity[i] = int(i);
    try {
      geometry_->sub_hexahedra = build_sub_hexahedra(geometry_->tets.data(), identity);
    } catch (const std::invalid_argument& e) {
      geometry_->failure = e.what();  // kept: every later call refuses at once
    }
  });
  if (!geometry_->sub_hexahedra) throw std::invalid_argument(geometry_->failure);
  return *geometry_->sub_hexahedra;
}

void CellElementSource::check_values(const std::string& what) {
  if (!block_.values) throw std::invalid_argument(what + ": null value array");
  if (!known_scalar(block_.value_type)) throw std::invalid_argument(what + ": unknown scalar type");
  if (block_.colour && !known_scalar(block_.colour_type))
    throw std::invalid_argument(what + ": unknown scalar type of the colour field");
  if (block_.element_stride == 0) block_.element_stride = nodes_;
  if (block_.element_stride < nodes_)
    throw std::invalid_argument(what + ": element stride " + std::to_string(block_.element_stride) +
                                " below the " + std::to_string(nodes_) + " nodes of a cell");
}

CellElementSource::CellElementSource(const CellElementSource& prepared, const CellBlock& block)
    : block_(block),
      nodes_(prepared.nodes_),
      sub_per_cell_(prepared.sub_per_cell_),
      degree_(prepared.degree_),
      from_(prepared.from_),
      geometry_type_(prepared.geometry_type_),
      geometry_order_(prepared.geometry_order_),
      geometry_nodes_(prepared.geometry_nodes_),
      geometry_degree_(prepared.geometry_degree_),
      geometry_from_(prepared.geometry_from_),
      geometry_(prepared.geometry_) {
  const CellBlock& p = prepared.block_;
  const std::string what = std::string("cell source: ") + cell_type_name(p.type) + "s";
  if (block.type != p.type || block.order != p.order || block.element_count != p.element_count ||
      block.node_order != p.node_order || block.geometry_order != p.geometry_order)
    throw std::invalid_argument(what +
                                ": the block's layout (type, order, geometry order, cell count, "
                                "node order) differs from the prepared source's");
  check_values(what);
}

Box CellElementSource::bounds() const {
  return geometry_->bounds;
}

CellElementSource::Counted CellElementSource::convert(bool colour) const {
  const cells::ReferenceCell& cell = cells::reference_cell(block_.type, block_.order);
  const std::size_t lattice = std::size_t(degree_ + 1) * (degree_ + 1) * (degree_ + 1);
  const std::size_t rows = lattice * sub_per_cell_;
  auto snapshot = std::make_shared<Snapshot>();
  const auto fill = [&](const void* values, ScalarType type, std::vector<double>& to) {
    to.resize(rows * block_.element_count);
    std::atomic<std::uint64_t> bad{0};
    tbb::parallel_for(
        tbb::blocked_range<std::size_t>(0, block_.element_count, 256),
        [&](const tbb::blocked_range<std::size_t>& range) {
          std::vector<double> nodal(nodes_);
          std::uint64_t nonfinite = 0;
          for (std::size_t e = range.begin(); e != range.end(); ++e) {
            for (std::size_t i = 0; i < nodes_; ++i) {
              nodal[i] = read_value(values, type, e * block_.element_stride + from_[i]);
              nonfinite += !std::isfinite(nodal[i]);
            }
            apply(cell.sampling.data(), rows, nodes_, nodal.data(), to.data() + e * rows);
          }
          if (nonfinite > 0) bad.fetch_add(nonfinite, std::memory_order_relaxed);
        });
    return bad.load();
  };
  Counted result;
  result.nonfinite = fill(block_.values, block_.value_type, snapshot->values);
  if (colour && block_.colour) fill(block_.colour, block_.colour_type, snapshot->colour);
  static const std::vector<double> no_points;  // the prepared source's copies read none
  HexBlock hex = sub_hexahedra_block(block_.element_count * sub_per_cell_, degree_,
                                     geometry_degree_, no_points);
  hex.values = snapshot->values.data();
  if (!snapshot->colour.empty()) hex.colour = snapshot->colour.data();
  snapshot->source = std::make_unique<HexElementSource>(sub_hexahedra(), hex);
  result.snapshot = std::move(snapshot);
  return result;
}

std::shared_ptr<const CellElementSource::Snapshot> CellElementSource::snapshot() const {
  return convert(true).snapshot;
}

std::vector<cells::LinearTet> CellElementSource::active_tets(double isovalue,
                                                             std::uint64_t& nonfinite) const {
  const void* values = block_.values;
  const ScalarType type = block_.value_type;
  const std::size_t stride = block_.element_stride;
  const int from[4] = {from_[0], from_[1], from_[2], from_[3]};
  // One instance per value type: the scan reads every cell's 4 values.
  if (type == ScalarType::float64) {
    const auto* v = static_cast<const double*>(values);
    return cells::active_linear_tets(
        geometry_->tets, isovalue, [&](std::size_t e, int i) { return v[e * stride + from[i]]; },
        nonfinite);
  }
  const auto* v = static_cast<const float*>(values);
  return cells::active_linear_tets(
      geometry_->tets, isovalue,
      [&](std::size_t e, int i) { return double(v[e * stride + from[i]]); }, nonfinite);
}

cells::StraightTets CellElementSource::active_straight_tets(double isovalue) const {
  const cells::ReferenceCell& cell = cells::reference_cell(block_.type, block_.order);
  const std::size_t stride = block_.element_stride;
  const int* from = from_.data();
  if (block_.value_type == ScalarType::float64) {
    const auto* v = static_cast<const double*>(block_.values);
    return cells::active_straight_tets(cell, geometry_->tets, isovalue, [&](std::size_t e, int i) {
      return v[e * stride + from[i]];
    });
  }
  const auto* v = static_cast<const float*>(block_.values);
  return cells::active_straight_tets(cell, geometry_->tets, isovalue, [&](std::size_t e, int i) {
    return double(v[e * stride + from[i]]);
  });
}

std::unique_ptr<GeometryBinding> CellElementSource::bind(RTCDevice device, double isovalue) const {
  if (geometry_->straight) return cells::bind_straight_tets(device, active_straight_tets(isovalue));
  if (!geometry_->tets.empty()) {
    std::uint64_t nonfinite = 0;
    std::vector<cells::LinearTet> tets = active_tets(isovalue, nonfinite);
    return cells::bind_linear_tets(device, std::move(tets), nonfinite);
  }
  Counted c = convert(false);
  auto inner = c.snapshot->source->bind(device, isovalue);
  return std::make_unique<CellGeometryBinding>(std::move(c.snapshot), std::move(inner),
                                               c.nonfinite);
}

std::unique_ptr<AxisCaster> CellElementSource::bind_axis(double isovalue) const {
  if (geometry_->straight) return cells::bind_axis_straight_tets(active_straight_tets(isovalue));
  if (!geometry_->tets.empty()) {
    std::uint64_t nonfinite = 0;
    std::vector<cells::LinearTet> tets = active_tets(isovalue, nonfinite);
    return cells::bind_axis_linear_tets(std::move(tets), nonfinite);
  }
  Counted c = convert(false);
  auto inner = c.snapshot->source->bind_axis(isovalue);
  if (!inner) return nullptr;
  return std::make_unique<CellAxisCaster>(std::move(c.snapshot), std::move(inner), c.nonfinite);
}

std::unique_ptr<ScalarProbe> CellElementSource::bind_scalar() const {
  if (!block_.colour) return nullptr;
  Counted c = convert(true);
  auto inner = c.snapshot->source->bind_scalar();
  if (!inner) return nullptr;
  return std::make_unique<CellScalarProbe>(std::move(c.snapshot), std::move(inner));
}

}  // namespace ldimesh
