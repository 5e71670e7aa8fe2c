// ldimesh-dealii: a deal.II program that hands its solution to the in situ adaptor, as a deal.II
// user would add ldimesh to their own code (miniapps/dealii/README.md).
//
// The heat equation ∂u/∂t = κ Δu (insulated walls) on the spherical shell 0.5 ≤ |x| ≤ 1:
// GridGenerator::hyper_shell (6 cells, refined --refinements times), a
// parallel::distributed::Triangulation over the ranks (p4est), FE_Q(p) with MappingQ(p) (the
// cells follow the spheres), the stiffness matrix assembled into a Trilinos matrix, the mass
// matrix lumped by Gauss–Lobatto quadrature (collocated with FE_Q's nodes: diagonal), explicit
// Euler with a time step from the largest eigenvalue of M⁻¹K (power iteration). Initially two
// Gaussian blobs on the sphere r = 0.75 (--initial blobs): the isosurface u = 0.5 shows them
// spread and fade. --initial radius starts from u = |x|² instead (a field with a known level
// set, for the tests: the isosurface u = c² of step 0 is the sphere of radius c up to FE_Q's
// interpolation of |x|²).
//
// What the adaptor gets, every --output-every steps: each rank's locally owned cells as
// high-order hexahedra. Geometry and solution are taken at the (p + 1)³ Gauss–Lobatto points of
// the reference cell through FEValues — QGaussLobatto<3> lists them lexicographically (x
// fastest), so the block's ordering is `lexicographic` with node set GLL. MappingQ(p) is the
// degree-p polynomial through the mapped Gauss–Lobatto points and FE_Q(p)'s shape functions are
// the degree-p Lagrange polynomials on them, so these samples give the adaptor the cell's
// geometry and solution exactly (no reordering of deal.II's hierarchical DoF numbering needed).
//
// Usage: mpiexec -n R ldimesh-dealii [--order P] [--refinements L] [--steps S]
//          [--output-every K] [--initial blobs|radius] [--isovalue V]
//          [--cells hex|tet|mixed] [--options FILE] [--vtu DIR]
// --cells tet runs the same equation on tetrahedra with FE_SimplexP, --cells mixed on a cube
// meshed with hexahedra, wedges, pyramids and tetrahedra (CellHeatSolver below). --order's
// default: 4 for hexahedra, 2 for tetrahedra, 1 (the only one deal.II 9.4 has for pyramids) for
// the mixed mesh.
// --vtu DIR also writes every output step as VTK XML files the way deal.II users write them
// (DataOut with write_higher_order_cells: VTK_LAGRANGE_HEXAHEDRON cells of order p, curved;
// DIR/solution_NNNN.pvtu over one .vtu per rank), the field named "u".
#include <deal.II/base/conditional_ostream.h>
#include <deal.II/base/function.h>
#include <deal.II/base/index_set.h>
#include <deal.II/base/mpi.h>
#include <deal.II/base/quadrature_lib.h>
#include <deal.II/base/utilities.h>
#include <deal.II/distributed/fully_distributed_tria.h>
#include <deal.II/distributed/tria.h>
#include <deal.II/dofs/dof_handler.h>
#include <deal.II/dofs/dof_tools.h>
#include <deal.II/fe/fe_pyramid_p.h>
#include <deal.II/fe/fe_q.h>
#include <deal.II/fe/fe_simplex_p.h>
#include <deal.II/fe/fe_values.h>
#include <deal.II/fe/fe_wedge_p.h>
#include <deal.II/fe/mapping_fe.h>
#include <deal.II/fe/mapping_q.h>
#include <deal.II/grid/grid_generator.h>
#include <deal.II/grid/tria.h>
#include <deal.II/grid/tria_description.h>
#include <deal.II/hp/fe_collection.h>
#include <deal.II/hp/fe_values.h>
#include <deal.II/hp/mapping_collection.h>
#include <deal.II/hp/q_collection.h>
#include <deal.II/lac/affine_constraints.h>
#include <deal.II/lac/dynamic_sparsity_pattern.h>
#include <deal.II/lac/full_matrix.h>
#include <deal.II/lac/solver_cg.h>
#include <deal.II/lac/sparsity_tools.h>
#include <deal.II/lac/trilinos_precondition.h>
#include <deal.II/lac/trilinos_solver.h>
#include <deal.II/lac/trilinos_sparse_matrix.h>
#include <deal.II/lac/trilinos_vector.h>
#include <deal.II/numerics/data_out.h>
#include <deal.II/numerics/vector_tools.h>

#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <memory>
#include <sstream>
#include <stdexcept>
#include <string>
#include <vector>

#include "ldimesh/adaptor.hpp"

namespace {

using namespace dealii;
constexpr int dim = 3;

struct Args {
  unsigned int order = 4, refinements = 1;
  unsigned long steps = 200, output_every = 10;
  std::string initial = "blobs", options_path, vtu_dir;
  // or "tet" (FE_SimplexP on tetrahedra), "mixed" (hexahedra, wedges, pyramids, tetrahedra):
  // CellHeatSolver
  std::string cells = "hex";
  double isovalue = 0.5;
  bool isovalue_given = false, order_given = false;
};

// Parses the command line; throws std::invalid_argument with a one-line message.
Args parse(int argc, char** argv) {
  Args a;
  const auto number = [&](int& i) {
    if (i + 1 >= argc) throw std::invalid_argument(std::string(argv[i]) + " needs a value");
    const std::string option = argv[i], text = argv[++i];
    std::size_t used = 0;
    double v = 0.0;
    try {
      v = std::stod(text, &used);
    } catch (const std::exception&) {
      used = 0;
    }
    if (used != text.size()) throw std::invalid_argument(option + ": not a number: '" + text + "'");
    return v;
  };
  for (int i = 1; i < argc; ++i) {
    const std::string arg = argv[i];
    if (arg == "--order") {
      const double v = number(i);
      if (v < 1 || v > 8 || v != std::floor(v)) throw std::invalid_argument("--order: 1 to 8");
      a.order = unsigned(v), a.order_given = true;
    } else if (arg == "--refinements") {
      const double v = number(i);
      if (v < 0 || v > 4 || v != std::floor(v))
        throw std::invalid_argument("--refinements: 0 to 4");
      a.refinements = unsigned(v);
    } else if (arg == "--steps" || arg == "--output-every") {
      const double v = number(i);
      if (v < 1 || v != std::floor(v)) throw std::invalid_argument(arg + ": a positive integer");
      (arg == "--steps" ? a.steps : a.output_every) = (unsigned long)v;
    } else if (arg == "--isovalue") {
      a.isovalue = number(i), a.isovalue_given = true;
    } else if (arg == "--initial" && i + 1 < argc) {
      a.initial = argv[++i];
      if (a.initial != "blobs" && a.initial != "radius")
        throw std::invalid_argument("--initial: blobs or radius, not '" + a.initial + "'");
    } else if (arg == "--cells" && i + 1 < argc) {
      a.cells = argv[++i];
      if (a.cells != "hex" && a.cells != "tet" && a.cells != "mixed")
        throw std::invalid_argument("--cells: hex, tet or mixed, not '" + a.cells + "'");
    } else if (arg == "--options" && i + 1 < argc) {
      a.options_path = argv[++i];
    } else if (arg == "--vtu" && i + 1 < argc) {
      a.vtu_dir = argv[++i];
    } else {
      throw std::invalid_argument("unknown or incomplete option '" + arg +
                                  "' (--order, --refinements, --steps, --output-every, "
                                  "--initial, --isovalue, --cells, --options, --vtu)");
    }
  }
  if (a.initial == "radius" && !a.isovalue_given) a.isovalue = 0.5625;  // the sphere r = 0.75
  if (!a.order_given) a.order = a.cells == "hex" ? 4 : a.cells == "tet" ? 2 : 1;
  if (a.cells == "tet" && a.order > 3)
    throw std::invalid_argument("--order: 1 to 3 with --cells tet (deal.II 9.4's FE_SimplexP)");
  if (a.cells == "mixed" && a.order != 1)
    throw std::invalid_argument("--order: 1 with --cells mixed (deal.II 9.4's FE_PyramidP)");
  return a;
}

// The initial field.
class Initial : public Function<dim> {
 public:
  explicit Initial(std::string kind) : kind_(std::move(kind)) {}
  double value(const Point<dim>& x, unsigned int = 0) const override {
    if (kind_ == "radius") return x.norm_square();
    const Point<dim> a(0.75, 0.0, 0.0), b(0.0, 0.75 * std::sqrt(0.5), 0.75 * std::sqrt(0.5));
    const double s2 = 0.22 * 0.22;
    return 2.5 * (std::exp(-(x - a).norm_square() / s2) + std::exp(-(x - b).norm_square() / s2));
  }

 private:
  std::string kind_;
};

// The adaptor's options document: the file (or "{}"), with "isovalues" set.
std::string options_document(const Args& a) {
  std::string text = "{}";
  if (!a.options_path.empty()) {
    std::ifstream in(a.options_path);
    if (!in) throw std::invalid_argument("--options: cannot read '" + a.options_path + "'");
    std::stringstream buffer;
    buffer << in.rdbuf();
    text = buffer.str();
  }
  // Insert the isovalue as the document's first key (the adaptor reports a repeated key).
  const std::size_t brace = text.find('{');
  if (brace == std::string::npos) throw std::invalid_argument("--options: not a JSON object");
  std::ostringstream iso;
  iso.precision(17);
  iso << "\"isovalues\": [" << a.isovalue << "]";
  const std::size_t next = text.find_first_not_of(" \t\r\n", brace + 1);
  const bool empty = next != std::string::npos && text[next] == '}';
  return text.substr(0, brace + 1) + iso.str() + (empty ? "" : ", ") + text.substr(brace + 1);
}

class HeatSolver {
 public:
  HeatSolver(const Args& args, MPI_Comm comm)
      : args_(args),
        comm_(comm),
        triangulation_(comm),
        fe_(args.order),
        mapping_(args.order),
        dof_handler_(triangulation_),
        out_(std::cout, Utilities::MPI::this_mpi_process(comm) == 0) {}

  void setup() {
    GridGenerator::hyper_shell(triangulation_, Point<dim>(), 0.5, 1.0, 6);
    triangulation_.refine_global(args_.refinements);
    dof_handler_.distribute_dofs(fe_);
    const IndexSet owned = dof_handler_.locally_owned_dofs();
    IndexSet relevant;
    DoFTools::extract_locally_relevant_dofs(dof_handler_, relevant);
    constraints_.reinit(relevant);
    DoFTools::make_hanging_node_constraints(dof_handler_, constraints_);
    constraints_.close();
    DynamicSparsityPattern dsp(relevant);
    DoFTools::make_sparsity_pattern(dof_handler_, dsp, constraints_, false);
    SparsityTools::distribute_sparsity_pattern(dsp, owned, comm_, relevant);
    stiffness_.reinit(owned, owned, dsp, comm_);
    solution_.reinit(owned, comm_);
    ghosted_.reinit(owned, relevant, comm_);
    inverse_mass_.reinit(owned, comm_);
    work_.reinit(owned, comm_);
    assemble();
    VectorTools::interpolate(mapping_, dof_handler_, Initial(args_.initial), solution_);
    time_step_ = stable_time_step();
    out_ << "ldimesh-dealii: " << triangulation_.n_global_active_cells() << " cells of FE_Q("
         << args_.order << ") with MappingQ(" << args_.order << "), " << dof_handler_.n_dofs()
         << " unknowns on " << Utilities::MPI::n_mpi_processes(comm_) << " rank(s), dt "
         << time_step_ << std::endl;
  }

  // One explicit Euler step: u ← u − dt κ M⁻¹ K u.
  void advance() {
    stiffness_.vmult(work_, solution_);
    work_.scale(inverse_mass_);
    solution_.add(-time_step_ * kKappa, work_);
    time_ += time_step_;
  }

  double time() const { return time_; }

  // The locally owned cells as one block of curved elements (see the file's comment).
  void hand_over(ldimesh::Adaptor& adaptor) {
    ghosted_ = solution_;
    const unsigned int p = args_.order;
    const QGaussLobatto<dim> nodes(p + 1);
    FEValues<dim> values(mapping_, fe_, nodes, update_values | update_quadrature_points);
    std::vector<double> cell_values(nodes.size());
    geometry_.clear();
    nodal_.clear();
    std::size_t cells = 0;
    for (const auto& cell : dof_handler_.active_cell_iterators()) {
      if (!cell->is_locally_owned()) continue;
      values.reinit(cell);
      values.get_function_values(ghosted_, cell_values);
      for (unsigned int q = 0; q < nodes.size(); ++q) {
        const Point<dim>& x = values.quadrature_point(q);
        geometry_.insert(geometry_.end(), {x[0], x[1], x[2]});
        nodal_.push_back(cell_values[q]);
      }
      ++cells;
    }
    ldimesh::HexBlock block;
    block.order = int(p);
    block.nodes = ldimesh::NodeSet::gauss_lobatto_legendre;
    block.ordering = ldimesh::NodeOrdering::lexicographic;
    block.element_count = cells;
    block.values = nodal_.data();
    block.type = ldimesh::ScalarType::float64;
    block.geometry_order = int(p);
    block.geometry = geometry_.data();
    adaptor.clear_blocks();
    if (cells > 0) check(adaptor.add_hex_block(block), "add_hex_block");
  }

  // The solution as VTK Lagrange hexahedra of order p (curved by the mapping), one .vtu per rank
  // and a .pvtu record: DIR/solution_NNNN.*
  void write_vtu(const std::string& dir, unsigned int counter) {
    ghosted_ = solution_;
    DataOut<dim> data_out;
    DataOutBase::VtkFlags flags;
    flags.time = time_;
    flags.write_higher_order_cells = true;
    data_out.set_flags(flags);
    data_out.attach_dof_handler(dof_handler_);
    data_out.add_data_vector(ghosted_, "u");
    data_out.build_patches(mapping_, fe_.degree, DataOut<dim>::curved_inner_cells);
    data_out.write_vtu_with_pvtu_record(dir + "/", "solution", counter, comm_, 4);
  }

  void check(const ldimesh::Status& s, const char* what) const {
    if (!s) std::cerr << "ldimesh-dealii: " << what << ": " << s.message() << std::endl;
  }

 private:
  static constexpr double kKappa = 0.02;

  // The stiffness matrix K, and the lumped mass matrix's inverse diagonal (Gauss–Lobatto
  // quadrature at FE_Q's nodes: the mass matrix is diagonal).
  void assemble() {
    const QGauss<dim> quadrature(fe_.degree + 1);
    const QGaussLobatto<dim> lobatto(fe_.degree + 1);
    FEValues<dim> fv(mapping_, fe_, quadrature, update_gradients | update_JxW_values);
    FEValues<dim> mv(mapping_, fe_, lobatto, update_values | update_JxW_values);
    const unsigned int n = fe_.n_dofs_per_cell();
    FullMatrix<double> local(n, n);
    Vector<double> local_mass(n);
    std::vector<types::global_dof_index> indices(n);
    TrilinosWrappers::MPI::Vector mass(dof_handler_.locally_owned_dofs(), comm_);
    for (const auto& cell : dof_handler_.active_cell_iterators()) {
      if (!cell->is_locally_owned()) continue;
      fv.reinit(cell);
      mv.reinit(cell);
      local = 0.0;
      local_mass = 0.0;
      for (unsigned int q = 0; q < quadrature.size(); ++q)
        for (unsigned int i = 0; i < n; ++i)
          for (unsigned int j = 0; j < n; ++j)
            local(i, j) += fv.shape_grad(i, q) * fv.shape_grad(j, q) * fv.JxW(q);
      for (unsigned int q = 0; q < lobatto.size(); ++q)
        for (unsigned int i = 0; i < n; ++i)
          local_mass(i) += mv.shape_value(i, q) * mv.JxW(q);
      cell->get_dof_indices(indices);
      constraints_.distribute_local_to_global(local, indices, stiffness_);
      constraints_.distribute_local_to_global(local_mass, indices, mass);
    }
    stiffness_.compress(VectorOperation::add);
    mass.compress(VectorOperation::add);
    for (const auto i : mass.locally_owned_elements())
      inverse_mass_[i] = 1.0 / mass[i];
    inverse_mass_.compress(VectorOperation::insert);
  }

  // Explicit Euler is stable for dt κ λ_max(M⁻¹K) < 2: λ_max by power iteration, dt at 40 % of
  // the limit.
  double stable_time_step() {
    TrilinosWrappers::MPI::Vector v(work_), w(work_);
    for (const auto i : v.locally_owned_elements())
      v[i] = 1.0 + 0.37 * std::sin(double(i));
    v.compress(VectorOperation::insert);
    double lambda = 0.0;
    for (int k = 0; k < 40; ++k) {
      v /= v.l2_norm();
      stiffness_.vmult(w, v);
      w.scale(inverse_mass_);
      lambda = w * v;
      v = w;
    }
    return 0.4 * 2.0 / (kKappa * 1.1 * lambda);
  }

  Args args_;
  MPI_Comm comm_;
  parallel::distributed::Triangulation<dim> triangulation_;
  FE_Q<dim> fe_;
  MappingQ<dim> mapping_;
  DoFHandler<dim> dof_handler_;
  AffineConstraints<double> constraints_;
  TrilinosWrappers::SparseMatrix stiffness_;
  TrilinosWrappers::MPI::Vector solution_, ghosted_, inverse_mass_, work_;
  double time_ = 0.0, time_step_ = 0.0;
  std::vector<double> geometry_, nodal_;
  ConditionalOStream out_;
};

// The cube [−1, 1]³ of n³ subcubes as a conforming mesh of all four shapes, for --cells mixed.
// Columns of subcubes (i, j) with i + j even are hexahedra. The others alternate along z: a
// subcube split into two wedges by its diagonal plane from (i, j) to (i + 1, j + 1), then a
// subcube split into six pyramids on its faces with the apex at its centre, of which the bottom
// and top ones are split again into two tetrahedra along that same diagonal. Every face between
// columns is a whole square (a hexahedron's, a wedge's or a pyramid's), every face inside a
// column a pair of triangles cut by the same diagonal (the wedges' ends, the tetrahedra's
// bases), so the mesh is conforming. Vertices in deal.II's order: hexahedra and pyramid bases
// lexicographic, the apex on the side of the base's normal (b₁ − b₀) × (b₂ − b₀), wedges'
// triangles counter-clockwise seen from their other triangle, tetrahedra positively oriented.
void mixed_cube(unsigned int n, Triangulation<dim>& out) {
  std::vector<Point<dim>> vertices;
  const auto grid = [n](unsigned int i, unsigned int j, unsigned int k) {
    return i + (n + 1) * (j + (n + 1) * k);
  };
  for (unsigned int k = 0; k <= n; ++k)
    for (unsigned int j = 0; j <= n; ++j)
      for (unsigned int i = 0; i <= n; ++i)
        vertices.emplace_back(-1.0 + 2.0 * i / n, -1.0 + 2.0 * j / n, -1.0 + 2.0 * k / n);
  std::vector<CellData<dim>> cells;
  const auto add = [&cells](std::initializer_list<unsigned int> v) {
    CellData<dim> cell(unsigned(v.size()));
    std::copy(v.begin(), v.end(), cell.vertices.begin());
    cells.push_back(cell);
  };
  for (unsigned int k = 0; k < n; ++k)  // layer by layer: runs of cells are slabs
    for (unsigned int j = 0; j < n; ++j)
      for (unsigned int i = 0; i < n; ++i) {
        // c[a + 2b + 4c]: the subcube's corner (i + a, j + b, k + c)
        unsigned int c[8];
        for (unsigned int m = 0; m < 8; ++m)
          c[m] = grid(i + (m & 1), j + (m >> 1 & 1), k + (m >> 2));
        if ((i + j) % 2 == 0) {
          add({c[0], c[1], c[2], c[3], c[4], c[5], c[6], c[7]});
        } else if (k % 2 == 0) {
          add({c[0], c[1], c[3], c[4], c[5], c[7]});
          add({c[0], c[3], c[2], c[4], c[7], c[6]});
        } else {
          const unsigned int m = unsigned(vertices.size());
          vertices.push_back(Point<dim>(-1.0 + (2.0 * i + 1) / n, -1.0 + (2.0 * j + 1) / n,
                                        -1.0 + (2.0 * k + 1) / n));
          add({c[0], c[2], c[4], c[6], m});  // x = i
          add({c[1], c[5], c[3], c[7], m});  // x = i + 1
          add({c[0], c[4], c[1], c[5], m});  // y = j
          add({c[2], c[3], c[6], c[7], m});  // y = j + 1
          add({c[0], c[1], c[3], m});        // z = k, cut along c₀ c₃
          add({c[0], c[3], c[2], m});
          add({c[4], c[7], c[5], m});  // z = k + 1, cut along c₄ c₇
          add({c[4], c[6], c[7], m});
        }
      }
  out.create_triangulation(vertices, cells, SubCellData());
}

// The same heat equation on the cells deal.II 9.4 has beside hexahedra: --cells tet, the refined
// shell's hexahedra split into tetrahedra (GridGenerator::convert_hypercube_to_simplex_mesh),
// FE_SimplexP(p) with a linear MappingFE (straight tetrahedra); --cells mixed, the cube [−1, 1]³
// as a conforming mesh of hexahedra, wedges, pyramids and tetrahedra (mixed_cube below), each
// cell with its own linear element — FE_Q(1), FE_WedgeP(1), FE_PyramidP(1), FE_SimplexP(1) in one
// hp::FECollection (deal.II 9.4's pyramid is linear only), the finite-element index chosen by
// the cell's reference cell. Either way the mesh is dealt to the ranks in runs of cells
// (parallel::fullydistributed::Triangulation from a partitioned serial mesh: p4est has neither
// simplices nor mixed meshes), the mass and stiffness matrices are integrated with each shape's
// Gauss rule, and backward Euler ((M + dt κ K) u' = M u) is solved by conjugate gradients: a
// simplex mass matrix has no diagonal lumping that stays positive for p ≥ 2.
//
// What the adaptor gets: each rank's locally owned cells as one ldimesh::CellBlock per shape, of
// order p, the solution and the mapped positions evaluated by FEValues at the nodes of VTK's
// cell of that shape (cell_reference_nodes, mapped to deal.II's reference cell: the same for
// tetrahedra, wedges and hexahedra; deal.II's pyramid has its base on [−1, 1]²): the cell's
// polynomial exactly, in the order the block wants.
class CellHeatSolver {
 public:
  CellHeatSolver(const Args& args, MPI_Comm comm)
      : args_(args),
        comm_(comm),
        triangulation_(comm),
        dof_handler_(triangulation_),
        out_(std::cout, Utilities::MPI::this_mpi_process(comm) == 0) {
    const unsigned int p = args.order;
    if (args.cells == "tet") {
      add_shape(ReferenceCells::Tetrahedron, ldimesh::CellType::tetrahedron, FE_SimplexP<dim>(p),
                MappingFE<dim>(FE_SimplexP<dim>(1)), QGaussSimplex<dim>(p + 1));
    } else {  // mixed, p = 1
      add_shape(ReferenceCells::Hexahedron, ldimesh::CellType::hexahedron, FE_Q<dim>(p),
                MappingQ<dim>(1), QGauss<dim>(p + 1));
      add_shape(ReferenceCells::Wedge, ldimesh::CellType::wedge, FE_WedgeP<dim>(p),
                MappingFE<dim>(FE_WedgeP<dim>(1)), QGaussWedge<dim>(p + 1));
      add_shape(ReferenceCells::Pyramid, ldimesh::CellType::pyramid, FE_PyramidP<dim>(p),
                MappingFE<dim>(FE_PyramidP<dim>(1)), QGaussPyramid<dim>(p + 1));
      add_shape(ReferenceCells::Tetrahedron, ldimesh::CellType::tetrahedron, FE_SimplexP<dim>(p),
                MappingFE<dim>(FE_SimplexP<dim>(1)), QGaussSimplex<dim>(p + 1));
    }
  }

  void setup() {
    Triangulation<dim> serial;
    if (args_.cells == "tet") {
      Triangulation<dim> hexahedra;
      GridGenerator::hyper_shell(hexahedra, Point<dim>(), 0.5, 1.0, 6);
      hexahedra.refine_global(args_.refinements);
      GridGenerator::convert_hypercube_to_simplex_mesh(hexahedra, serial);
    } else {
      mixed_cube(4u << args_.refinements, serial);
    }
    // Runs of cells per rank (the cells' order is the mesh's: compact pieces).
    const unsigned int ranks = Utilities::MPI::n_mpi_processes(comm_);
    const std::size_t total = serial.n_active_cells();
    std::size_t index = 0;
    for (const auto& cell : serial.active_cell_iterators())
      cell->set_subdomain_id(types::subdomain_id(index++ * ranks / total));
    triangulation_.create_triangulation(
        TriangulationDescription::Utilities::create_description_from_triangulation(serial, comm_));
    for (const auto& cell : dof_handler_.active_cell_iterators())
      if (cell->is_locally_owned()) cell->set_active_fe_index(shape_index(cell->reference_cell()));
    dof_handler_.distribute_dofs(fe_);
    const IndexSet owned = dof_handler_.locally_owned_dofs();
    IndexSet relevant;
    DoFTools::extract_locally_relevant_dofs(dof_handler_, relevant);
    DynamicSparsityPattern dsp(relevant);
    DoFTools::make_sparsity_pattern(dof_handler_, dsp);
    SparsityTools::distribute_sparsity_pattern(dsp, owned, comm_, relevant);
    mass_.reinit(owned, owned, dsp, comm_);
    system_.reinit(owned, owned, dsp, comm_);
    solution_.reinit(owned, comm_);
    ghosted_.reinit(owned, relevant, comm_);
    rhs_.reinit(owned, comm_);
    assemble();
    VectorTools::interpolate(mapping_, dof_handler_, Initial(args_.initial), solution_);
    std::vector<std::size_t> counts(shapes_.size(), 0);
    for (const auto& cell : dof_handler_.active_cell_iterators())
      if (cell->is_locally_owned()) ++counts[cell->active_fe_index()];
    out_ << "ldimesh-dealii: ";
    for (std::size_t i = 0; i < shapes_.size(); ++i)
      out_ << (i ? ", " : "") << Utilities::MPI::sum(counts[i], comm_) << " "
           << ldimesh::cell_type_name(shapes_[i].type) << " cells of " << fe_[i].get_name();
    out_ << " with linear mappings, " << dof_handler_.n_dofs() << " unknowns on "
         << Utilities::MPI::n_mpi_processes(comm_) << " rank(s), dt " << kTimeStep << std::endl;
  }

  // One backward Euler step.
  void advance() {
    mass_.vmult(rhs_, solution_);
    SolverControl control(1000, 1e-12 * rhs_.l2_norm());
    TrilinosWrappers::SolverCG cg(control);
    TrilinosWrappers::PreconditionJacobi jacobi;
    jacobi.initialize(system_);
    cg.solve(system_, solution_, rhs_, jacobi);
    time_ += kTimeStep;
  }

  double time() const { return time_; }

  // The locally owned cells as one block per shape, of order p, VTK's node order.
  void hand_over(ldimesh::Adaptor& adaptor) {
    ghosted_ = solution_;
    const int p = int(args_.order);
    adaptor.clear_blocks();
    for (Shape& shape : shapes_) {
      std::vector<Point<dim>> points;
      for (const glm::dvec3& r : ldimesh::cell_reference_nodes(shape.type, p))
        points.push_back(shape.reference == ReferenceCells::Pyramid  // base [−1, 1]², apex e₃
                             ? Point<dim>((2 * r.x - 1) * (1 - r.z), (2 * r.y - 1) * (1 - r.z), r.z)
                             : Point<dim>(r.x, r.y, r.z));
      const Quadrature<dim> nodes(points);
      const unsigned int index = unsigned(&shape - shapes_.data());
      FEValues<dim> values(mapping_[index], fe_[index], nodes,
                           update_values | update_quadrature_points);
      std::vector<double> cell_values(nodes.size());
      shape.points.clear();
      shape.values.clear();
      std::size_t cells = 0;
      for (const auto& cell : dof_handler_.active_cell_iterators()) {
        if (!cell->is_locally_owned() || cell->active_fe_index() != index) continue;
        values.reinit(cell);
        values.get_function_values(ghosted_, cell_values);
        for (unsigned int q = 0; q < nodes.size(); ++q) {
          const Point<dim>& x = values.quadrature_point(q);
          shape.points.insert(shape.points.end(), {x[0], x[1], x[2]});
          shape.values.push_back(cell_values[q]);
        }
        ++cells;
      }
      if (cells == 0) continue;
      ldimesh::CellBlock block;
      block.type = shape.type;
      block.order = p;
      block.element_count = cells;
      block.points = shape.points.data();
      block.values = shape.values.data();
      check(adaptor.add_cell_block(block), "add_cell_block");
    }
  }

  // The solution as deal.II writes simplex and mixed meshes: DataOut's patches — VTK_TETRA,
  // VTK_WEDGE, VTK_PYRAMID and VTK_HEXAHEDRON for p = 1, VTK_QUADRATIC_TETRA otherwise (p = 3 is
  // written quadratic: deal.II 9.4 has no higher simplex output) — one .vtu per rank and a
  // .pvtu record: DIR/solution_NNNN.*
  void write_vtu(const std::string& dir, unsigned int counter) {
    ghosted_ = solution_;
    DataOut<dim> data_out;
    DataOutBase::VtkFlags flags;
    flags.time = time_;
    // deal.II 9.4 writes simplex patches of 2 subdivisions as VTK_QUADRATIC_TETRA; with
    // write_higher_order_cells its simplex .vtu files are unreadable (VTK: "the offsets array is
    // not long enough"), so it stays off here.
    flags.write_higher_order_cells = false;
    data_out.set_flags(flags);
    data_out.attach_dof_handler(dof_handler_);
    data_out.add_data_vector(ghosted_, "u");
    data_out.build_patches(mapping_, std::min(args_.order, 2u));
    data_out.write_vtu_with_pvtu_record(dir + "/", "solution", counter, comm_, 4);
  }

  void check(const ldimesh::Status& s, const char* what) const {
    if (!s) std::cerr << "ldimesh-dealii: " << what << ": " << s.message() << std::endl;
  }

 private:
  static constexpr double kKappa = 0.02, kTimeStep = 0.005;

  // One shape of the mesh: its finite element, mapping and quadrature sit at the same index of
  // fe_, mapping_ and quadrature_.
  struct Shape {
    ReferenceCell reference;
    ldimesh::CellType type;
    std::vector<double> points, values;  // hand_over's arrays for the adaptor's block
  };

  void add_shape(ReferenceCell reference, ldimesh::CellType type, const FiniteElement<dim>& fe,
                 const Mapping<dim>& mapping, const Quadrature<dim>& quadrature) {
    shapes_.push_back({reference, type, {}, {}});
    fe_.push_back(fe);
    mapping_.push_back(mapping);
    quadrature_.push_back(quadrature);
  }

  unsigned int shape_index(ReferenceCell reference) const {
    for (std::size_t i = 0; i < shapes_.size(); ++i)
      if (shapes_[i].reference == reference) return unsigned(i);
    throw std::runtime_error("a cell of an unexpected shape");
  }

  // M and M + dt κ K.
  void assemble() {
    hp::FEValues<dim> hp_values(mapping_, fe_, quadrature_,
                                update_values | update_gradients | update_JxW_values);
    FullMatrix<double> mass, system;
    std::vector<types::global_dof_index> indices;
    for (const auto& cell : dof_handler_.active_cell_iterators()) {
      if (!cell->is_locally_owned()) continue;
      hp_values.reinit(cell);
      const FEValues<dim>& fv = hp_values.get_present_fe_values();
      const unsigned int n = cell->get_fe().n_dofs_per_cell();
      mass.reinit(n, n);
      system.reinit(n, n);
      for (unsigned int q = 0; q < fv.n_quadrature_points; ++q)
        for (unsigned int i = 0; i < n; ++i)
          for (unsigned int j = 0; j < n; ++j) {
            const double m = fv.shape_value(i, q) * fv.shape_value(j, q) * fv.JxW(q);
            mass(i, j) += m;
            system(i, j) +=
                m + kTimeStep * kKappa * (fv.shape_grad(i, q) * fv.shape_grad(j, q)) * fv.JxW(q);
          }
      indices.resize(n);
      cell->get_dof_indices(indices);
      mass_.add(indices, mass);
      system_.add(indices, system);
    }
    mass_.compress(VectorOperation::add);
    system_.compress(VectorOperation::add);
  }

  Args args_;
  MPI_Comm comm_;
  parallel::fullydistributed::Triangulation<dim> triangulation_;
  std::vector<Shape> shapes_;
  hp::FECollection<dim> fe_;
  hp::MappingCollection<dim> mapping_;
  hp::QCollection<dim> quadrature_;
  DoFHandler<dim> dof_handler_;
  TrilinosWrappers::SparseMatrix mass_, system_;
  TrilinosWrappers::MPI::Vector solution_, ghosted_, rhs_;
  double time_ = 0.0;
  ConditionalOStream out_;
};

// The time loop of either solver.
template <class Solver>
void run(Solver& solver, const Args& args, ldimesh::Adaptor& adaptor) {
  solver.setup();
  solver.check(adaptor.set_domain({{-1.0, -1.0, -1.0}, {1.0, 1.0, 1.0}}), "set_domain");
  for (unsigned long step = 0; step <= args.steps; ++step) {
    if (step % args.output_every == 0) {
      solver.hand_over(adaptor);
      solver.check(adaptor.execute(step, solver.time()), "execute");
      if (!args.vtu_dir.empty()) solver.write_vtu(args.vtu_dir, unsigned(step / args.output_every));
    }
    if (step < args.steps) solver.advance();
  }
}

}  // namespace

int main(int argc, char** argv) {
  // deal.II's MPI start-up asks for MPI_THREAD_SERIALIZED: the adaptor then takes its
  // synchronous path (the solver waits for the step's cast and reduction; its log says so).
  // The background path needs MPI_THREAD_MULTIPLE (docs/adaptor.md).
  Utilities::MPI::MPI_InitFinalize mpi(argc, argv, numbers::invalid_unsigned_int);
  const MPI_Comm comm = MPI_COMM_WORLD;
  const bool root = Utilities::MPI::this_mpi_process(comm) == 0;
  Args args;
  std::string options;
  try {
    args = parse(argc, argv);
    options = options_document(args);
  } catch (const std::exception& e) {
    if (root) std::cerr << "ldimesh-dealii: " << e.what() << std::endl;
    return 1;
  }
  std::unique_ptr<ldimesh::Adaptor> adaptor;
  if (ldimesh::Status s = ldimesh::Adaptor::create(comm, options, adaptor); !s) {
    if (root) std::cerr << "ldimesh-dealii: options: " << s.message() << std::endl;
    return 2;
  }
  if (root && !adaptor->url().empty())
    std::cout << "ldimesh-dealii: viewer at " << adaptor->url() << std::endl;
  try {
    if (!args.vtu_dir.empty()) {  // every rank (one may run elsewhere); write_vtu reports failure
      std::error_code ec;
      std::filesystem::create_directories(args.vtu_dir, ec);
    }
    if (args.cells != "hex") {
      CellHeatSolver solver(args, comm);
      run(solver, args, *adaptor);
    } else {
      HeatSolver solver(args, comm);
      run(solver, args, *adaptor);
    }
  } catch (const std::exception& e) {
    // Possibly on this rank alone (a file it cannot write): the others may wait in a collective
    // call, so the job stops here, as deal.II programs do on an error.
    std::cerr << "ldimesh-dealii: rank " << Utilities::MPI::this_mpi_process(comm) << ": "
              << e.what() << std::endl;
    MPI_Abort(comm, 3);
  }
  if (ldimesh::Status s = adaptor->finalize(); !s && root)
    std::cerr << "ldimesh-dealii: finalize: " << s.message() << std::endl;
  if (root)
    std::cout << "ldimesh-dealii: " << adaptor->published_steps() << " step(s) published"
              << std::endl;
  return 0;
}
