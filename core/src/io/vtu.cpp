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

namespace {

// The one-component point array `name` of `grid`; an error naming the file's point arrays where
// there is none of that name.
Status scalar_point_array(vtkUnstructuredGrid* grid, const std::string& path,
                          const std::string& name, vtkDataArray*& out) {
  out = grid->GetPointData()->GetArray(name.c_str());
  if (!out) {
    std::string names;
    for (int a = 0; a < grid->GetPointData()->GetNumberOfArrays(); ++a) {
      const char* n = grid->GetPointData()->GetArrayName(a);
      names += std::string(names.empty() ? "" : ", ") + (n ? n : "(unnamed)");
    }
    return Status::invalid_argument("'" + path + "': no point array '" + name +
                                    "' (point arrays: " + (names.empty() ? "none" : names) + ")");
  }
  if (out->GetNumberOfComponents() != 1)
    return Status::invalid_argument("'" + path + "': point array '" + name + "' has " +
                                    std::to_string(out->GetNumberOfComponents()) +
                                    " components; give a scalar one");
  return Status::ok();
}

// One DataArray's declared size, for check_declared_sizes.
struct DeclaredArray {
  std::string name;
  double values = 0;  // components × tuples
  double bytes_per_value = 1;
};

// An integer attribute as VTK reads it (std::istringstream into an integer: leading white
// space, trailing text ignored), or `fallback` where there is none. False where it is there but
// is not a whole number VTK can read (damaged digits, or more than 64 bits of them).
bool count_attribute(vtkXMLDataElement* e, const char* name, long long fallback, long long& out) {
  const char* text = e->GetAttribute(name);
  if (!text) {
    out = fallback;
    return true;
  }
  std::istringstream in(text);
  return static_cast<bool>(in >> out);
}

// An attribute's text for a one-line message: quoted, its first 24 characters, anything but
// printable ASCII as '?'.
std::string quoted(const char* text) {
  std::string q = "\"";
  for (const char* c = text; *c && q.size() <= 24; ++c)
    q += std::isprint(static_cast<unsigned char>(*c)) ? *c : '?';
  return q + (std::strlen(text) > 24 ? "…\"" : "\"");
}

// VTK allocates (and fills) every array at the size the file's XML declares before it reads a
// value: the points, a cell's offset and type, every point, cell and field data array at its
// NumberOfComponents times the points, cells or NumberOfTuples. A value takes at
// least a byte in any of VTK's formats (an ASCII digit, a base64 character, a raw Int8; a Bit
// array packs 8 in a byte), and a compressed file (a `compressor` attribute) shrinks by no more
// than 10 000 : 1 with any compressor VTK writes (zlib at most 1 032 : 1; LZMA ≈ 7 000 : 1 on
// zeros). Declared sizes above what the file's bytes can hold cannot be the file's: refused
// before VTK allocates them. A component count VTK cannot parse makes VTK 9.1's CreateArray loop
// over 2³¹ component names (found by fuzzing): refused too.
Status check_declared_sizes(const std::string& path, std::uintmax_t bytes, vtkXMLDataElement* root,
                            vtkIdType points, vtkIdType cells) {
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
  std::vector<DeclaredArray> arrays;
  // The arrays of `section`, each with `tuples` (FieldData: its own NumberOfTuples; Cells: the
  // offsets and types one per cell, the connectivity's size is not declared).
  const auto add_arrays = [&](vtkXMLDataElement* section, double tuples) -> Status {
    const std::string_view kind = section->GetName() ? section->GetName() : "";
    for (int a = 0; a < section->GetNumberOfNestedElements(); ++a) {
      vtkXMLDataElement* da = section->GetNestedElement(a);
      if (!da || std::string_view(da->GetName() ? da->GetName() : "") != "DataArray") continue;
      const char* name = da->GetAttribute("Name");
      DeclaredArray d{name ? name : "(unnamed)"};
      long long components = 0, own_tuples = 0;
      if (!count_attribute(da, "NumberOfComponents", 1, components) || components < 1)
        return Status::corrupt_input(file + "array '" + d.name + "' has NumberOfComponents " +
                                     quoted(da->GetAttribute("NumberOfComponents")) +
                                     ", not a count (a damaged file?)");
      double n = tuples;
      if (kind == "FieldData") {
        if (!count_attribute(da, "NumberOfTuples", 0, own_tuples) || own_tuples < 0)
          return Status::corrupt_input(file + "array '" + d.name + "' has NumberOfTuples " +
                                       quoted(da->GetAttribute("NumberOfTuples")) +
                                       ", not a count (a damaged file?)");
        n = double(own_tuples);
      } else if (kind == "Cells" && d.name != "offsets" && d.name != "types") {
        n = 0;
      }
      const char* type = da->GetAttribute("type");
      if (type && std::string_view(type) == "Bit") d.bytes_per_value = 0.125;
      d.values = double(components) * n;
      arrays.push_back(std::move(d));
    }
    return Status::ok();
  };
  for (int e = 0; e < grid->GetNumberOfNestedElements(); ++e) {
    vtkXMLDataElement* child = grid->GetNestedElement(e);
    const std::string_view kind = child && child->GetName() ? child->GetName() : "";
    if (kind == "FieldData") {
      if (Status st = add_arrays(child, 0); !st) return st;
    } else if (kind == "Piece") {
      long long piece_points = 0, piece_cells = 0;
      // VTK's information pass has read (and checked) both counts already.
      count_attribute(child, "NumberOfPoints", 0, piece_points);
      count_attribute(child, "NumberOfCells", 0, piece_cells);
      for (int k = 0; k < child->GetNumberOfNestedElements(); ++k) {
        vtkXMLDataElement* section = child->GetNestedElement(k);
        const std::string_view name = section && section->GetName() ? section->GetName() : "";
        if (name == "PointData" || name == "Points" || name == "CellData" || name == "Cells")
          if (Status st = add_arrays(
                  section,
                  double(name == "PointData" || name == "Points" ? piece_points : piece_cells));
              !st)
            return st;
      }
    }
  }
  double total = 0;
  for (const DeclaredArray& d : arrays) {
    const double need = d.values * d.bytes_per_value;
    if (need > room) {
      char values[32];
      std::snprintf(values, sizeof values, "%.17g", d.values);
      return Status::corrupt_input(file + "array '" + d.name + "' declares " + values + " values" +
                                   more);
    }
    total += need;
  }
  if (total > room) {
    char need[32];
    std::snprintf(need, sizeof need, "%.17g", total);
    return Status::corrupt_input(file + "its arrays take at least " + need + " bytes uncompressed" +
                                 more);
  }
  return Status::ok();
}

// What read_vtu needs of every piece, checked in the XML before VTK reads any data: the point
// arrays `field` and `colour_field`, each once, and no two cell data arrays of one name. VTK
// 9.1's reader crashes (a segmentation fault in vtkXMLDataReader::ReadPieceData) on a file with
// two cell data arrays of one name, and on one without point data whose cell data array is short
// (both found by fuzzing, on files otherwise valid). Two point data arrays of one name VTK reads
// (the first wins); refused only where that name is the field or the colour field, which would
// be ambiguous. Unnamed arrays are not compared.
Status check_piece_arrays(const std::string& path, vtkXMLDataElement* root,
                          const std::string& field, const std::string& colour_field) {
  vtkXMLDataElement* grid = root ? root->FindNestedElementWithName("UnstructuredGrid") : nullptr;
  if (!grid) return Status::ok();
  const auto names_of = [](vtkXMLDataElement* section) {
    std::vector<std::string> names;
    for (int a = 0; section && a < section->GetNumberOfNestedElements(); ++a) {
      vtkXMLDataElement* da = section->GetNestedElement(a);
      if (da && da->GetName() && std::string_view(da->GetName()) == "DataArray" &&
          da->GetAttribute("Name"))
        names.push_back(da->GetAttribute("Name"));
    }
    return names;
  };
  for (int e = 0; e < grid->GetNumberOfNestedElements(); ++e) {
    vtkXMLDataElement* piece = grid->GetNestedElement(e);
    if (!piece || !piece->GetName() || std::string_view(piece->GetName()) != "Piece") continue;
    const std::vector<std::string> point_names =
        names_of(piece->FindNestedElementWithName("PointData"));
    std::vector<std::string> cell_names = names_of(piece->FindNestedElementWithName("CellData"));
    std::sort(cell_names.begin(), cell_names.end());
    if (const auto twice = std::adjacent_find(cell_names.begin(), cell_names.end());
        twice != cell_names.end())
      return Status::corrupt_input("'" + path + "': two cell data arrays named '" + *twice +
                                   "' (a damaged file?)");
    for (const std::string& name : {field, colour_field}) {
      if (name.empty()) continue;
      const auto count = std::count(point_names.begin(), point_names.end(), name);
      if (count > 1)
        return Status::corrupt_input("'" + path + "': two point data arrays named '" + name +
                                     "' (a damaged file?)");
      if (count == 1) continue;
      std::string list;
      for (const std::string& n : point_names)
        list += (list.empty() ? "" : ", ") + (n.empty() ? std::string("(unnamed)") : n);
      return Status::invalid_argument("'" + path + "': no point array '" + name +
                                      "' (point arrays: " + (list.empty() ? "none" : list) + ")");
    }
  }
  return Status::ok();
}

Status read_vtu_unguarded(const std::string& path, const std::string& field, VtuElements& out,
                          const std::string& colour_field) {
  std::error_code ec;
  if (!std::filesystem::is_regular_file(path, ec))
    return Status::io("'" + path + "': no such file");
  if (field.empty()) return Status::invalid_argument("give the point array to mesh (--field NAME)");
  const std::string ext = std::filesystem::path(path).extension().string();
  vtkSmartPointer<vtkXMLReader> reader;
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
    data->UpdateInformation();
    data->SetupUpdateExtent(0, 1, 0);  // the whole file, as Update reads it
    if (!errors->message.empty())
      return Status::corrupt_input("'" + path +
                                   "': VTK cannot read it: " + first_line(errors->message));
    const std::uintmax_t bytes = std::filesystem::file_size(path, ec);
    vtkXMLDataElement* root =
        data->GetXMLParser() ? data->GetXMLParser()->GetRootElement() : nullptr;
    if (Status st = check_declared_sizes(path, ec ? 0 : bytes, root, data->GetNumberOfPoints(),
                                         data->GetNumberOfCells());
        !st)
      return st;
    if (Status st = check_piece_arrays(path, root, field, colour_field); !st) return st;
  }
  reader->Update();
  vtkUnstructuredGrid* grid = vtkUnstructuredGrid::SafeDownCast(reader->GetOutputDataObject(0));
  if (!errors->message.empty())
    return Status::corrupt_input("'" + path +
                                 "': VTK cannot read it: " + first_line(errors->message));
  if (!grid || grid->GetNumberOfCells() == 0)
    return Status::corrupt_input("'" + path + "': no cells (not a VTK XML unstructured grid?)");

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

  std::map<int, VtuElements::Group> groups;
  vtkNew<vtkIdList> ids;
  out.bounds = {glm::dvec3(std::numeric_limits<double>::infinity()),
                glm::dvec3(-std::numeric_limits<double>::infinity())};
  out.min_value = std::numeric_limits<double>::infinity();
  out.max_value = -out.min_value;
  const vtkIdType n = grid->GetNumberOfCells();
  for (vtkIdType c = 0; c < n; ++c) {
    const int type = grid->GetCellType(c);
    const std::string cell = "'" + path + "': cell " + std::to_string(c);
    if (type != VTK_LAGRANGE_HEXAHEDRON && type != VTK_HEXAHEDRON)
      return Status::corrupt_input(cell + " is " + type_name(type) + " (VTK type " +
                                   std::to_string(type) +
                                   "): only VTK_LAGRANGE_HEXAHEDRON and VTK_HEXAHEDRON are read");
    grid->GetCellPoints(c, ids);
    const vtkIdType count = ids->GetNumberOfIds();
    int order = 1;
    if (type == VTK_LAGRANGE_HEXAHEDRON) {
      order = int(std::lround(std::cbrt(double(count)))) - 1;
      if (degrees) {
        double d[3];
        degrees->GetTuple(c, d);
        // Any double (the array may be a float one, with NaN or 1e300): compared as doubles and
        // printed with %g, never converted to int.
        const auto text = [](double x) {
          char b[32];
          std::snprintf(b, sizeof b, "%g", x);
          return std::string(b);
        };
        if (d[0] != d[1] || d[1] != d[2])
          return Status::corrupt_input(cell + ": orders " + text(d[0]) + ", " + text(d[1]) + ", " +
                                       text(d[2]) + " differ along the axes (not supported)");
        if (d[0] != double(order))
          return Status::corrupt_input(cell + ": HigherOrderDegrees says order " + text(d[0]) +
                                       " but it has " + std::to_string(count) + " points");
      }
    }
    if (order < 1 || order > kMaxHexOrder ||
        vtkIdType(order + 1) * (order + 1) * (order + 1) != count)
      return Status::corrupt_input(cell + " has " + std::to_string(count) +
                                   " points: not (p + 1)³ for an order p of 1–" +
                                   std::to_string(kMaxHexOrder));
    VtuElements::Group& g = groups[order];
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
  for (auto& [order, g] : groups)
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
