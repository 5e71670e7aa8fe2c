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
//          [--output-every K] [--initial blobs|radius] [--isovalue V] [--cells hex|tet]
//          [--options FILE] [--vtu DIR]
// --cells tet runs the same equation on tetrahedra with FE_SimplexP (SimplexHeatSolver below).
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
#include <deal.II/fe/fe_q.h>
#include <deal.II/fe/fe_simplex_p.h>
#include <deal.II/fe/fe_values.h>
#include <deal.II/fe/mapping_fe.h>
#include <deal.II/fe/mapping_q.h>
#include <deal.II/grid/grid_generator.h>
#include <deal.II/grid/tria_description.h>
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
  std::string cells = "hex";  // or "tet": FE_SimplexP on tetrahedra (SimplexHeatSolver)
  double isovalue = 0.5;
  bool isovalue_given = false;
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
      a.order = unsigned(v);
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
      if (a.cells != "hex" && a.cells != "tet")
        throw std::invalid_argument("--cells: hex or tet, not '" + a.cells + "'");
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
  if (a.cells == "tet" && a.order > 3)
    throw std::invalid_argument("--order: 1 to 3 with --cells tet (deal.II 9.4's FE_SimplexP)");
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

// The same heat equation on tetrahedra (--cells tet), as a deal.II 9.4 user with a simplex mesh
// writes it: the refined shell's hexahedra split into tetrahedra
// (GridGenerator::convert_hypercube_to_simplex_mesh), dealt to the ranks in runs of cells
// (parallel::fullydistributed::Triangulation from a partitioned serial mesh: p4est has no
// simplices), FE_SimplexP(p) with a linear MappingFE (straight tetrahedra), the mass and
// stiffness matrices with QGaussSimplex, and backward Euler ((M + dt κ K) u' = M u, conjugate
// gradients): a simplex mass matrix has no diagonal lumping that stays positive for p ≥ 2.
//
// What the adaptor gets: each rank's locally owned cells as one block of tetrahedra of order p
// (ldimesh::CellBlock), the solution and the mapped positions evaluated by FEValues at the
// nodes of VTK's Lagrange tetrahedron (cell_reference_nodes; deal.II's reference tetrahedron is
// VTK's: vertices 0, e₁, e₂, e₃): the cell's polynomial exactly, in the order the block wants.
class SimplexHeatSolver {
 public:
  SimplexHeatSolver(const Args& args, MPI_Comm comm)
      : args_(args),
        comm_(comm),
        triangulation_(comm),
        fe_(args.order),
        mapping_(FE_SimplexP<dim>(1)),
        dof_handler_(triangulation_),
        out_(std::cout, Utilities::MPI::this_mpi_process(comm) == 0) {}

  void setup() {
    Triangulation<dim> hexahedra, tetrahedra;
    GridGenerator::hyper_shell(hexahedra, Point<dim>(), 0.5, 1.0, 6);
    hexahedra.refine_global(args_.refinements);
    GridGenerator::convert_hypercube_to_simplex_mesh(hexahedra, tetrahedra);
    // Runs of cells per rank (cell order is the coarse cells', refined: compact pieces).
    const unsigned int ranks = Utilities::MPI::n_mpi_processes(comm_);
    const std::size_t total = tetrahedra.n_active_cells();
    std::size_t index = 0;
    for (const auto& cell : tetrahedra.active_cell_iterators())
      cell->set_subdomain_id(types::subdomain_id(index++ * ranks / total));
    triangulation_.create_triangulation(
        TriangulationDescription::Utilities::create_description_from_triangulation(tetrahedra,
                                                                                   comm_));
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
    out_ << "ldimesh-dealii: " << triangulation_.n_global_active_cells()
         << " tetrahedra of FE_SimplexP(" << args_.order << ") with MappingFE(FE_SimplexP(1)), "
         << dof_handler_.n_dofs() << " unknowns on " << Utilities::MPI::n_mpi_processes(comm_)
         << " rank(s), dt " << kTimeStep << std::endl;
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

  // The locally owned cells as one block of tetrahedra of order p, VTK's node order.
  void hand_over(ldimesh::Adaptor& adaptor) {
    ghosted_ = solution_;
    const int p = int(args_.order);
    std::vector<Point<dim>> points;
    for (const glm::dvec3& r : ldimesh::cell_reference_nodes(ldimesh::CellType::tetrahedron, p))
      points.emplace_back(r.x, r.y, r.z);
    const Quadrature<dim> nodes(points);
    FEValues<dim> values(mapping_, fe_, nodes, update_values | update_quadrature_points);
    std::vector<double> cell_values(nodes.size());
    points_.clear();
    nodal_.clear();
    std::size_t cells = 0;
    for (const auto& cell : dof_handler_.active_cell_iterators()) {
      if (!cell->is_locally_owned()) continue;
      values.reinit(cell);
      values.get_function_values(ghosted_, cell_values);
      for (unsigned int q = 0; q < nodes.size(); ++q) {
        const Point<dim>& x = values.quadrature_point(q);
        points_.insert(points_.end(), {x[0], x[1], x[2]});
        nodal_.push_back(cell_values[q]);
      }
      ++cells;
    }
    ldimesh::CellBlock block;
    block.type = ldimesh::CellType::tetrahedron;
    block.order = p;
    block.element_count = cells;
    block.points = points_.data();
    block.values = nodal_.data();
    adaptor.clear_blocks();
    if (cells > 0) check(adaptor.add_cell_block(block), "add_cell_block");
  }

  // The solution as deal.II writes simplex meshes: DataOut's patches, VTK_TETRA for p = 1 and
  // VTK_QUADRATIC_TETRA otherwise (p = 3 is written quadratic: deal.II 9.4 has no higher
  // simplex output), one .vtu per rank and a .pvtu record: DIR/solution_NNNN.*
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

  // M and M + dt κ K.
  void assemble() {
    const QGaussSimplex<dim> quadrature(fe_.degree + 1);
    FEValues<dim> fv(mapping_, fe_, quadrature,
                     update_values | update_gradients | update_JxW_values);
    const unsigned int n = fe_.n_dofs_per_cell();
    FullMatrix<double> mass(n, n), system(n, n);
    std::vector<types::global_dof_index> indices(n);
    for (const auto& cell : dof_handler_.active_cell_iterators()) {
      if (!cell->is_locally_owned()) continue;
      fv.reinit(cell);
      mass = 0.0;
      system = 0.0;
      for (unsigned int q = 0; q < quadrature.size(); ++q)
        for (unsigned int i = 0; i < n; ++i)
          for (unsigned int j = 0; j < n; ++j) {
            const double m = fv.shape_value(i, q) * fv.shape_value(j, q) * fv.JxW(q);
            mass(i, j) += m;
            system(i, j) +=
                m + kTimeStep * kKappa * (fv.shape_grad(i, q) * fv.shape_grad(j, q)) * fv.JxW(q);
          }
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
  FE_SimplexP<dim> fe_;
  MappingFE<dim> mapping_;
  DoFHandler<dim> dof_handler_;
  TrilinosWrappers::SparseMatrix mass_, system_;
  TrilinosWrappers::MPI::Vector solution_, ghosted_, rhs_;
  double time_ = 0.0;
  std::vector<double> points_, nodal_;
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
    if (args.cells == "tet") {
      SimplexHeatSolver solver(args, comm);
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
