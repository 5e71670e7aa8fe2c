#include "ldimesh/core/io/vtu.hpp"

#include <algorithm>
#include <cctype>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <limits>
#include <map>
#include <new>
#include <sstream>
#include <stdexcept>
#include <string_view>

#include <vtkCellData.h>
#include <vtkCellType.h>
#include <vtkCommand.h>
#include <vtkDataArray.h>
#include <vtkIdList.h>
#include <vtkLogger.h>
#include <vtkNew.h>
#include <vtkPointData.h>
#include <vtkPoints.h>
#include <vtkSmartPointer.h>
#include <vtkUnstructuredGrid.h>
#include <vtkXMLDataElement.h>
#include <vtkXMLDataParser.h>
#include <vtkXMLPUnstructuredGridReader.h>
#include <vtkXMLUnstructuredDataReader.h>
#include <vtkXMLUnstructuredGridReader.h>

namespace ldimesh {
namespace {

// Collects the reader's error messages instead of VTK's output window.
class ErrorCollector : public vtkCommand {
 public:
  static ErrorCollector* New() { return new ErrorCollector; }
  void Execute(vtkObject*, unsigned long, void* data) override {
    if (message.empty() && data) message = static_cast<const char*>(data);
  }
  std::string message;
};

// The first line of a VTK message, without the "ERROR: In file, line N" prefix VTK puts first.
std::string first_line(std::string text) {
  const std::size_t newline = text.find('\n');
  if (newline != std::string::npos && newline + 1 < text.size() && text.rfind("ERROR", 0) == 0)
    text = text.substr(newline + 1);
  text = text.substr(0, text.find('\n'));
  while (!text.empty() && std::isspace(static_cast<unsigned char>(text.back())))
    text.pop_back();
  return text;
}

const char* type_name(int type) {
  switch (type) {
    case VTK_TETRA:
      return "VTK_TETRA";
    case VTK_WEDGE:
      return "VTK_WEDGE";
    case VTK_PYRAMID:
      return "VTK_PYRAMID";
    case VTK_QUADRATIC_HEXAHEDRON:
      return "VTK_QUADRATIC_HEXAHEDRON";
    case VTK_TRIQUADRATIC_HEXAHEDRON:
      return "VTK_TRIQUADRATIC_HEXAHEDRON";
    case VTK_LAGRANGE_TETRAHEDRON:
      return "VTK_LAGRANGE_TETRAHEDRON";
    case VTK_LAGRANGE_WEDGE:
      return "VTK_LAGRANGE_WEDGE";
    case VTK_BEZIER_HEXAHEDRON:
      return "VTK_BEZIER_HEXAHEDRON";
    case VTK_HEXAHEDRON:
      return "VTK_HEXAHEDRON";
    case VTK_LAGRANGE_HEXAHEDRON:
      return "VTK_LAGRANGE_HEXAHEDRON";
    case VTK_QUADRATIC_TETRA:
      return "VTK_QUADRATIC_TETRA";
    case VTK_QUADRATIC_WEDGE:
      return "VTK_QUADRATIC_WEDGE";
    case VTK_BIQUADRATIC_QUADRATIC_WEDGE:
      return "VTK_BIQUADRATIC_QUADRATIC_WEDGE";
    case VTK_QUADRATIC_PYRAMID:
      return "VTK_QUADRATIC_PYRAMID";
    case VTK_LAGRANGE_PYRAMID:
      return "VTK_LAGRANGE_PYRAMID";
    case VTK_TRIQUADRATIC_PYRAMID:
      return "VTK_TRIQUADRATIC_PYRAMID";
    case VTK_BEZIER_TETRAHEDRON:
      return "VTK_BEZIER_TETRAHEDRON";
    case VTK_BEZIER_WEDGE:
      return "VTK_BEZIER_WEDGE";
    case VTK_VOXEL:
      return "VTK_VOXEL";
    case VTK_TRIANGLE:
      return "VTK_TRIANGLE";
    case VTK_QUAD:
      return "VTK_QUAD";
    default:
      return "a cell";
  }
}

}  // namespace

void quiet_vtk_logging() {
  vtkLogger::SetStderrVerbosity(vtkLogger::VERBOSITY_OFF);
}

HexBlock VtuElements::Group::block() const {
  HexBlock b;
  b.order = order;
  b.nodes = NodeSet::equispaced;
  b.ordering = NodeOrdering::vtk_lagrange;
  b.element_count = cells;
  b.values = values.data();
  b.type = ScalarType::float64;
  b.geometry_order = order;
  b.geometry = geometry.data();
  if (!colour.empty()) {
    b.colour = colour.data();
    b.colour_type = ScalarType::float64;
  }
  return b;
}

CellBlock VtuElements::Group::cell_block() const {
  CellBlock b;
  b.type = type;
  b.order = order;
  b.element_count = cells;
  b.points = geometry.data();
  b.values = values.data();
  b.value_type = ScalarType::float64;
  if (!colour.empty()) {
    b.colour = colour.data();
    b.colour_type = ScalarType::float64;
  }
  return b;
}

namespace {

// A name or attribute from the file, for a one-line message: its first 48 characters,
// anything but printable ASCII as '?'.
std::string shown(const char* text) {
  std::string q;
  const std::size_t n = std::strlen(text);
  for (std::size_t i = 0; i < n && i < 48; ++i)
    q += std::isprint(static_cast<unsigned char>(text[i])) ? text[i] : '?';
  return n > 48 ? q + "…" : q;
}

// The one-component point array `name` of `grid`; an error naming the file's point arrays where
// there is none of that name.
Status scalar_point_array(vtkUnstructuredGrid* grid, const std::string& path,
                          const std::string& name, vtkDataArray*& out) {
  out = grid->GetPointData()->GetArray(name.c_str());
  if (!out) {
    std::string names;
    const int arrays = grid->GetPointData()->GetNumberOfArrays();
    for (int a = 0; a < arrays && a < 12; ++a) {
      const char* n = grid->GetPointData()->GetArrayName(a);
      names += std::string(names.empty() ? "" : ", ") + (n ? shown(n) : "(unnamed)");
    }
    if (arrays > 12) names += ", …";
    return Status::invalid_argument("'" + path + "': no point array '" + shown(name.c_str()) +
                                    "' (point arrays: " + (names.empty() ? "none" : names) + ")");
  }
  if (out->GetNumberOfComponents() != 1)
    return Status::invalid_argument("'" + path + "': point array '" + shown(name.c_str()) +
                                    "' has " + std::to_string(out->GetNumberOfComponents()) +
                                    " components; give a scalar one");
  return Status::ok();
}

// An integer attribute as VTK reads it (std::istringstream into T: leading white space and
// trailing text ignored), or `fallback` where there is none. False where it is there but is not
// a number VTK can read into T (damaged digits, or out of T's range).
template <typename T>
bool count_attribute(vtkXMLDataElement* e, const char* name, T fallback, T& out) {
  const char* text = e->GetAttribute(name);
  if (!text) {
    out = fallback;
    return true;
  }
  std::istringstream in(text);
  return static_cast<bool>(in >> out);
}

// The child elements of `e` (each of any name: VTK reads `DataArray` and `Array` elements).
std::vector<vtkXMLDataElement*> children(vtkXMLDataElement* e) {
  std::vector<vtkXMLDataElement*> out;
  for (int i = 0; e && i < e->GetNumberOfNestedElements(); ++i)
    if (vtkXMLDataElement* c = e->GetNestedElement(i)) out.push_back(c);
  return out;
}

std::string_view tag(vtkXMLDataElement* e) {
  return e && e->GetName() ? e->GetName() : "";
}

// VTK builds a name string per component before it reads a value; no format we know has tuples
// of more components than this.
constexpr int kMaxComponents = 1 << 20;

// The XML's declared sizes and arrays, checked before VTK reads a value (for a .vtu; a .pvtu's
// pieces are read by VTK's parallel reader without these checks):
// - VTK allocates (and fills) every array at the size the XML declares: the first piece's
//   point data, cell data and points at NumberOfComponents times the points or cells of all
//   pieces, the cells' offsets and types, field data at its NumberOfTuples. A value takes at
//   least a byte in any of VTK's formats (an ASCII digit, a base64 character, a raw Int8; a Bit
//   array packs 8 in a byte), and a compressed file (a `compressor` attribute) shrinks by no
//   more than 10 000 : 1 with any compressor VTK writes (zlib at most 1 032 : 1; LZMA ≈ 7 000 : 1
//   on zeros). Sizes above what the file's bytes can hold cannot be the file's. An array of one
//   name is allocated once (time steps of it, or a repeated point data array, share it).
// - VTK 9.1's CreateArray reads NumberOfComponents into an int and builds a name per component
//   (found by fuzzing: a 45-digit count looped for minutes): every element's count must be a
//   whole number of 1 to kMaxComponents.
// - VTK 9.1's reader crashes (a segmentation fault in vtkXMLDataReader::ReadPieceData) on two
//   cell data arrays of one name (and time step), and on a piece without point data whose cell
//   data array is short (both found by fuzzing, on files otherwise valid): the first is refused,
//   and so is a piece without the field or the colour field among its point arrays (the second
//   then cannot reach VTK's data pass). Two point data arrays of one name VTK reads (the first
//   wins); refused only where that name is the field or the colour field, which would be
//   ambiguous.
Status check_xml(const std::string& path, std::uintmax_t bytes, vtkXMLDataElement* root,
                 vtkIdType points, vtkIdType cells, const std::string& field,
                 const std::string& colour_field) {
  const char* compressor = root ? root->GetAttribute("compressor") : nullptr;
  const double room = double(bytes) * (compressor && *compressor ? 10000.0 : 1.0);
  const std::string file = "'" + path + "': ";
  const std::string more =
      ", more than its " + std::to_string(bytes) + " bytes can hold (a damaged file?)";
  if (points < 0 || cells < 0 || 3.0 * double(points) + 2.0 * double(cells) > room)
    return Status::corrupt_input(file + "it declares " + std::to_string(points) + " points and " +
                                 std::to_string(cells) + " cells" + more);
  vtkXMLDataElement* grid = root ? root->FindNestedElementWithName("UnstructuredGrid") : nullptr;
  if (!grid) return Status::ok();  // VTK's information pass has refused such a file already

  // The values VTK allocates per array, by section and name (the largest where one repeats).
  std::map<std::pair<std::string, std::string>, double> allocated;
  const auto check_array = [&](vtkXMLDataElement* a, std::string_view section, double tuples,
                               bool allocates) -> Status {
    const char* name = a->GetAttribute("Name");
    const std::string label = "array '" + shown(name ? name : "(unnamed)") + "'";
    int components = 1;
    if (!count_attribute(a, "NumberOfComponents", 1, components) || components < 1 ||
        components > kMaxComponents)
      return Status::corrupt_input(file + label + " has NumberOfComponents \"" +
                                   shown(a->GetAttribute("NumberOfComponents")) +
                                   "\", not a count of 1 to " + std::to_string(kMaxComponents) +
                                   " (a damaged file?)");
    if (section == "FieldData") {
      long long own = 0;
      if (!count_attribute(a, "NumberOfTuples", 0LL, own) || own < 0)
        return Status::corrupt_input(file + label + " has NumberOfTuples \"" +
                                     shown(a->GetAttribute("NumberOfTuples")) +
                                     "\", not a count (a damaged file?)");
      tuples = double(own);
    }
    // Unnamed point and cell data arrays are not read; the points and cells' arrays are.
    if (!allocates || (!name && (section == "PointData" || section == "CellData")))
      return Status::ok();
    const char* type = a->GetAttribute("type");
    const double values = double(components) * tuples;
    const double need = values * (type && std::string_view(type) == "Bit" ? 0.125 : 1.0);
    if (need > room) {
      char text[32];
      std::snprintf(text, sizeof text, "%.17g", values);
      return Status::corrupt_input(file + label + " declares " + text + " values" + more);
    }
    double& slot = allocated[{std::string(section), name ? name : ""}];
    slot = std::max(slot, need);
    return Status::ok();
  };

  bool first_piece = true;
  for (vtkXMLDataElement* child : children(grid)) {
    if (tag(child) == "FieldData") {
      for (vtkXMLDataElement* a : children(child))
        if (Status st = check_array(a, "FieldData", 0, true); !st) return st;
      continue;
    }
    if (tag(child) != "Piece") continue;
    for (vtkXMLDataElement* section : children(child)) {
      const std::string_view kind = tag(section);
      if (kind != "PointData" && kind != "CellData" && kind != "Points" && kind != "Cells")
        continue;
      // VTK allocates the first piece's arrays at the counts of all pieces.
      const double all = double(kind == "PointData" || kind == "Points" ? points : cells);
      std::map<std::pair<std::string, std::string>, int> seen;  // (name, time step)
      for (vtkXMLDataElement* a : children(section)) {
        const char* name = a->GetAttribute("Name");
        const bool sized =
            kind != "Cells" ||
            (name && (std::string_view(name) == "offsets" || std::string_view(name) == "types"));
        if (Status st = check_array(a, kind, sized ? all : 0, first_piece); !st) return st;
        if (!name || (kind != "PointData" && kind != "CellData")) continue;
        const char* step = a->GetAttribute("TimeStep");
        const int n = ++seen[{name, step ? step : ""}];
        if (n == 2 && (kind == "CellData" || name == field || name == colour_field))
          return Status::corrupt_input(file + "two " + (kind == "CellData" ? "cell" : "point") +
                                       " data arrays named '" + shown(name) +
                                       "' (a damaged file?)");
      }
      if (kind != "PointData") continue;
      for (const std::string& wanted : {field, colour_field}) {
        if (wanted.empty() || std::any_of(seen.begin(), seen.end(),
                                          [&](const auto& s) { return s.first.first == wanted; }))
          continue;
        std::vector<std::string> names;  // seen is in order of (name, time step)
        for (const auto& [key, count] : seen)
          if (names.empty() || names.back() != key.first) names.push_back(key.first);
        std::string list;
        for (std::size_t i = 0; i < names.size() && i < 12; ++i)
          list += (i ? ", " : "") + shown(names[i].c_str());
        if (names.size() > 12) list += ", …";
        return Status::invalid_argument(file + "no point array '" + shown(wanted.c_str()) +
                                        "' (point arrays: " + (list.empty() ? "none" : list) + ")");
      }
    }
    // A piece without a PointData element has none of the point arrays.
    if (!child->FindNestedElementWithName("PointData"))
      for (const std::string& wanted : {field, colour_field})
        if (!wanted.empty())
          return Status::invalid_argument(file + "no point array '" + shown(wanted.c_str()) +
                                          "' (point arrays: none)");
    first_piece = false;
  }
  double total = 0;
  for (const auto& [key, need] : allocated)
    total += need;
  if (total > room) {
    char text[32];
    std::snprintf(text, sizeof text, "%.17g", total);
    return Status::corrupt_input(file + "its arrays take at least " + text + " bytes uncompressed" +
                                 more);
  }
  return Status::ok();
}

// VTK's two passes over a file, each in a function of its own that is never inlined: a crash
// inside VTK shows one of them as its caller (scripts/fuzz.sh tells VTK's own crashes from
// ours by that).
[[gnu::noinline]] void vtk_information_pass(vtkXMLUnstructuredDataReader* reader) {
  reader->UpdateInformation();
  reader->SetupUpdateExtent(0, 1, 0);  // the whole file, as Update reads it
}
[[gnu::noinline]] void vtk_data_pass(vtkXMLReader* reader) {
  reader->Update();
}

// Any double (an array may be a float one, with NaN or 1e300): compared as doubles and printed
// with %g, never converted to int.
std::string text(double x) {
  char b[32];
  std::snprintf(b, sizeof b, "%g", x);
  return std::string(b);
}

// Reads the file at `path`: its XML first, the sizes it declares checked against its bytes
// (check_xml), then its data. `grid` is `reader`'s output.
Status read_grid(const std::string& path, const std::string& field, const std::string& colour_field,
                 vtkSmartPointer<vtkXMLReader>& reader, vtkUnstructuredGrid*& grid) {
  std::error_code ec;
  if (!std::filesystem::is_regular_file(path, ec))
    return Status::io("'" + path + "': no such file");
  if (field.empty()) return Status::invalid_argument("give the point array to mesh (--field NAME)");
  const std::string ext = std::filesystem::path(path).extension().string();
  if (ext == ".pvtu")
    reader = vtkSmartPointer<vtkXMLPUnstructuredGridReader>::New();
  else
    reader = vtkSmartPointer<vtkXMLUnstructuredGridReader>::New();
  vtkNew<ErrorCollector> errors;
  reader->AddObserver(vtkCommand::ErrorEvent, errors);
  reader->SetFileName(path.c_str());
  // VTK allocates (and fills) its arrays at the sizes the file declares before it reads them: a
  // damaged or hostile file of a few KB can ask for gigabytes (found by fuzzing). The XML
  // structure first, then the declared sizes against what the file's bytes can hold at all.
  if (auto* data = vtkXMLUnstructuredDataReader::SafeDownCast(reader)) {
    vtk_information_pass(data);
    if (!errors->message.empty())
      return Status::corrupt_input("'" + path +
                                   "': VTK cannot read it: " + first_line(errors->message));
    const std::uintmax_t bytes = std::filesystem::file_size(path, ec);
    vtkXMLDataElement* root =
        data->GetXMLParser() ? data->GetXMLParser()->GetRootElement() : nullptr;
    if (Status st = check_xml(path, ec ? 0 : bytes, root, data->GetNumberOfPoints(),
                              data->GetNumberOfCells(), field, colour_field);
        !st)
      return st;
  }
  vtk_data_pass(reader);
  grid = vtkUnstructuredGrid::SafeDownCast(reader->GetOutputDataObject(0));
  if (!errors->message.empty())
    return Status::corrupt_input("'" + path +
                                 "': VTK cannot read it: " + first_line(errors->message));
  if (!grid || grid->GetNumberOfCells() == 0)
    return Status::corrupt_input("'" + path + "': no cells (not a VTK XML unstructured grid?)");
  return Status::ok();
}

// The family and order of cell c (VTK type `type`, `count` points; `cell` names it in
// messages), checked against HigherOrderDegrees (`degrees`, or null) and the node counts — or
// why it is not read.
Status cell_kind(int type, vtkIdType count, vtkIdType c, vtkDataArray* degrees,
                 const std::string& cell, CellType& kind, int& order) {
  // The smallest order whose node count is at least `count`, of a Lagrange family (0: none).
  const auto order_of = [&](CellType family) {
    for (int p = 1; p <= kMaxHexOrder; ++p)
      if (vtkIdType(cell_nodes(family, p)) >= count) return p;
    return 0;
  };
  kind = CellType::hexahedron;
  order = 1;
  switch (type) {
    case VTK_HEXAHEDRON:
      break;
    case VTK_TRIQUADRATIC_HEXAHEDRON:
      order = 2;
      break;
    case VTK_LAGRANGE_HEXAHEDRON:
      order = order_of(CellType::hexahedron);
      break;
    case VTK_QUADRATIC_HEXAHEDRON:
      kind = CellType::serendipity_hexahedron, order = 2;
      break;
    case VTK_TETRA:
      kind = CellType::tetrahedron;
      break;
    case VTK_QUADRATIC_TETRA:
      kind = CellType::tetrahedron, order = 2;
      break;
    case VTK_LAGRANGE_TETRAHEDRON:
      kind = CellType::tetrahedron, order = order_of(kind);
      if (count == 15)
        return Status::corrupt_input(cell +
                                     ": VTK's 15-node tetrahedron (a quadratic one with "
                                     "face and body bubbles) is not read");
      break;
    case VTK_WEDGE:
      kind = CellType::wedge;
      break;
    case VTK_BIQUADRATIC_QUADRATIC_WEDGE:
      kind = CellType::wedge, order = 2;
      break;
    case VTK_LAGRANGE_WEDGE:
      kind = CellType::wedge, order = order_of(kind);
      if (count == 21)
        return Status::corrupt_input(cell +
                                     ": VTK's 21-node wedge (a quadratic one with face "
                                     "and body bubbles) is not read");
      break;
    case VTK_QUADRATIC_WEDGE:
      kind = CellType::serendipity_wedge, order = 2;
      break;
    case VTK_PYRAMID:
      kind = CellType::pyramid;
      break;
    case VTK_QUADRATIC_PYRAMID:
      kind = CellType::pyramid, order = 2;
      break;
    default:
      return Status::corrupt_input(
          cell + " is " + type_name(type) + " (VTK type " + std::to_string(type) +
          "): hexahedra, tetrahedra, wedges and pyramids (linear, quadratic, Lagrange) are read");
  }
  if (degrees && (type == VTK_LAGRANGE_HEXAHEDRON || type == VTK_LAGRANGE_WEDGE)) {
    double d[3];
    degrees->GetTuple(c, d);
    // A wedge's first two are its triangle's order, the third its height's.
    if (d[0] != d[1] || d[1] != d[2])
      return Status::corrupt_input(cell + ": orders " + text(d[0]) + ", " + text(d[1]) + ", " +
                                   text(d[2]) + " differ along the axes (not supported)");
    if (d[0] != double(order))
      return Status::corrupt_input(cell + ": HigherOrderDegrees says order " + text(d[0]) +
                                   " but it has " + std::to_string(count) + " points");
  }
  const std::size_t nodes = cell_nodes(kind, order);
  if (nodes == 0 || vtkIdType(nodes) != count)
    return Status::corrupt_input(cell + " (" + type_name(type) + ") has " + std::to_string(count) +
                                 " points: not the node count of an " + "order of 1–" +
                                 std::to_string(kMaxHexOrder));
  return Status::ok();
}

Status read_vtu_unguarded(const std::string& path, const std::string& field, VtuElements& out,
                          const std::string& colour_field) {
  vtkSmartPointer<vtkXMLReader> reader;
  vtkUnstructuredGrid* grid = nullptr;
  LDIMESH_RETURN_IF_ERROR(read_grid(path, field, colour_field, reader, grid));

  vtkDataArray* values = nullptr;
  if (Status st = scalar_point_array(grid, path, field, values); !st) return st;
  vtkDataArray* colour = nullptr;
  if (!colour_field.empty())
    if (Status st = scalar_point_array(grid, path, colour_field, colour); !st) return st;
  vtkDataArray* degrees = grid->GetCellData()->GetArray("HigherOrderDegrees");
  if (degrees && (degrees->GetNumberOfComponents() != 3 ||
                  degrees->GetNumberOfTuples() < grid->GetNumberOfCells()))
    degrees = nullptr;

  // What VTK returns is as the file says: a cell may name a point the file does not have, and
  // an array may be shorter than the points (VTK checks neither).
  vtkPoints* points = grid->GetPoints();
  const vtkIdType point_count = points ? points->GetNumberOfPoints() : 0;
  if (point_count == 0) return Status::corrupt_input("'" + path + "': no points");
  for (const auto& [array, name] : {std::pair{values, field}, std::pair{colour, colour_field}})
    if (array && array->GetNumberOfTuples() < point_count)
      return Status::corrupt_input("'" + path + "': point array '" + name + "' has " +
                                   std::to_string(array->GetNumberOfTuples()) + " values for " +
                                   std::to_string(point_count) + " points");

  // Cells flagged as duplicates of another piece's (vtkGhostType bit 1, DUPLICATECELL) are
  // skipped: dolfinx and other parallel writers mark the cells a piece holds besides its own.
  vtkDataArray* ghosts = grid->GetCellData()->GetArray("vtkGhostType");
  if (ghosts && (ghosts->GetNumberOfComponents() != 1 ||
                 ghosts->GetNumberOfTuples() < grid->GetNumberOfCells()))
    ghosts = nullptr;

  std::map<std::pair<int, int>, VtuElements::Group> groups;  // by (type, order)
  vtkNew<vtkIdList> ids;
  out.bounds = {glm::dvec3(std::numeric_limits<double>::infinity()),
                glm::dvec3(-std::numeric_limits<double>::infinity())};
  out.min_value = std::numeric_limits<double>::infinity();
  out.max_value = -out.min_value;
  const vtkIdType n = grid->GetNumberOfCells();
  for (vtkIdType c = 0; c < n; ++c) {
    if (ghosts) {
      const double flag = ghosts->GetTuple1(c);
      if (flag >= 0.0 && flag < 256.0 && (int(flag) & 1)) {
        ++out.ghost_cells;
        continue;
      }
    }
    const int type = grid->GetCellType(c);
    const std::string cell = "'" + path + "': cell " + std::to_string(c);
    grid->GetCellPoints(c, ids);
    const vtkIdType count = ids->GetNumberOfIds();
    CellType kind = CellType::hexahedron;
    int order = 1;
    LDIMESH_RETURN_IF_ERROR(cell_kind(type, count, c, degrees, cell, kind, order));
    VtuElements::Group& g = groups[{int(kind), order}];
    g.type = kind;
    g.order = order;
    ++g.cells;
    for (vtkIdType k = 0; k < count; ++k)
      if (ids->GetId(k) < 0 || ids->GetId(k) >= point_count)
        return Status::corrupt_input(cell + " names point " + std::to_string(ids->GetId(k)) +
                                     " of " + std::to_string(point_count));
    for (vtkIdType k = 0; k < count; ++k) {
      double x[3];
      points->GetPoint(ids->GetId(k), x);
      if (!std::isfinite(x[0]) || !std::isfinite(x[1]) || !std::isfinite(x[2]))
        return Status::corrupt_input(cell + ": a point is not finite");
      g.geometry.insert(g.geometry.end(), {x[0], x[1], x[2]});
      out.bounds.lo = glm::min(out.bounds.lo, glm::dvec3(x[0], x[1], x[2]));
      out.bounds.hi = glm::max(out.bounds.hi, glm::dvec3(x[0], x[1], x[2]));
      const double v = values->GetTuple1(ids->GetId(k));
      g.values.push_back(v);
      if (colour) g.colour.push_back(colour->GetTuple1(ids->GetId(k)));
      if (std::isfinite(v))
        out.min_value = std::min(out.min_value, v), out.max_value = std::max(out.max_value, v);
    }
    ++out.cells;
  }
  if (out.cells == 0)
    return Status::corrupt_input("'" + path + "': every cell is a ghost (vtkGhostType)");
  for (auto& [key, g] : groups)
    out.groups.push_back(std::move(g));
  return Status::ok();
}

}  // namespace

// VTK allocates each array at the size the file declares and throws std::bad_alloc where that
// cannot be had (found by fuzzing: a mutated NumberOfPoints); that, like any exception from VTK
// or our containers, is an error Status here.
Status read_vtu(const std::string& path, const std::string& field, VtuElements& out,
                const std::string& colour_field) {
  out = {};
  try {
    return read_vtu_unguarded(path, field, out, colour_field);
  } catch (const std::bad_alloc&) {
    return Status::out_of_memory("'" + path +
                                 "': out of memory while reading it (a damaged size?)");
  } catch (const std::exception& e) {
    return Status::corrupt_input("'" + path + "': reading it failed: " + e.what());
  }
}

}  // namespace ldimesh
