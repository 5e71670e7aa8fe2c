! The ldimesh in situ adaptor for Fortran solvers: a module over the C API (ldimesh.h), with
! iso_c_binding. The MPI communicator is the Fortran handle (an integer from `use mpi`, or
! comm%mpi_val of a TYPE(MPI_Comm) from `use mpi_f08`), as in Ascent's Fortran interface.
!
!   use ldimesh_mod
!   type(ldimesh_adaptor) :: insitu
!   call ldimesh_create(MPI_COMM_WORLD, '{"isovalues": [0.5]}', insitu, ierr)
!   call ldimesh_set_domain(insitu, lo, hi, ierr)
!   call ldimesh_add_uniform_grid(insitu, u, origin, spacing, ghost_lo, ghost_hi, ierr)
!   ! or elements: values((p+1)**3, n), corners(3, 8, n) or curved geometry(3, (q+1)**3, n)
!   call ldimesh_add_hex_elements(insitu, p, LDIMESH_NODES_GLL, values, ierr, corners=corners)
!   do step = 1, nsteps
!     ...; call ldimesh_execute(insitu, int(step, c_int64_t), t, ierr)
!   end do
!   call ldimesh_destroy(insitu)
!
! Every routine returns its status in ierr (LDIMESH_OK = 0) and keeps the message for
! ldimesh_last_error(); nothing stops the program. Arrays handed over are read in place at
! every due step: they need the TARGET attribute and must stay allocated while the adaptor
! lives (or until ldimesh_clear_blocks).
module ldimesh_mod
  use, intrinsic :: iso_c_binding
  implicit none
  private

  integer, parameter, public :: LDIMESH_OK = 0, LDIMESH_ERROR_ARGUMENT = 1, &
                                LDIMESH_ERROR_OPTIONS = 2, LDIMESH_ERROR_STEP = 3, &
                                LDIMESH_ERROR_RUNTIME = 4, LDIMESH_ERROR_CORRUPT = 5, &
                                LDIMESH_ERROR_IO = 6, LDIMESH_ERROR_MEMORY = 7
  integer(c_int), parameter, public :: LDIMESH_FLOAT32 = 0, LDIMESH_FLOAT64 = 1
  integer(c_int), parameter, public :: LDIMESH_NODES_GLL = 0, LDIMESH_NODES_GL = 1, &
                                       LDIMESH_NODES_EQUISPACED = 2
  integer(c_int), parameter, public :: LDIMESH_ORDER_LEXICOGRAPHIC = 0, LDIMESH_ORDER_VTK = 1
  integer(c_int), parameter, public :: LDIMESH_CELL_HEXAHEDRON = 0, LDIMESH_CELL_HEXAHEDRON20 = 1, &
                                       LDIMESH_CELL_TETRAHEDRON = 2, LDIMESH_CELL_WEDGE = 3, &
                                       LDIMESH_CELL_WEDGE15 = 4, LDIMESH_CELL_PYRAMID = 5, &
                                       LDIMESH_CELL_PYRAMID14 = 6
  integer(c_int), parameter, public :: LDIMESH_CELL_ORDER_VTK = 0, LDIMESH_CELL_ORDER_GMSH = 1

  ! ldimesh_grid_block of ldimesh.h, field by field (x is the first index, as in Fortran).
  type, bind(C), public :: ldimesh_grid_block
    integer(c_int64_t) :: dims(3) = 0
    type(c_ptr) :: values = c_null_ptr
    integer(c_int64_t) :: value_count = 0
    integer(c_int) :: type = LDIMESH_FLOAT64
    integer(c_int64_t) :: strides(3) = 0
    real(c_double) :: origin(3) = 0.0_c_double
    real(c_double) :: spacing(3) = 1.0_c_double
    type(c_ptr) :: coords(3) = c_null_ptr
    integer(c_int) :: ghost_lo(3) = 0
    integer(c_int) :: ghost_hi(3) = 0
  end type ldimesh_grid_block

  ! ldimesh_hex_block of ldimesh.h, field by field, with ldimesh_hex_block_init's defaults.
  type, bind(C), public :: ldimesh_hex_block
    integer(c_int) :: order = 0
    integer(c_int) :: nodes = LDIMESH_NODES_GLL
    integer(c_int64_t) :: element_count = 0
    type(c_ptr) :: corners = c_null_ptr
    type(c_ptr) :: values = c_null_ptr
    integer(c_int64_t) :: value_count = 0
    integer(c_int) :: type = LDIMESH_FLOAT64
    integer(c_int64_t) :: element_stride = 0
    integer(c_int) :: geometry_order = 0
    type(c_ptr) :: geometry = c_null_ptr
    integer(c_int64_t) :: geometry_count = 0
    integer(c_int) :: ordering = LDIMESH_ORDER_LEXICOGRAPHIC
  end type ldimesh_hex_block

  ! ldimesh_cell_block of ldimesh.h, field by field, with ldimesh_cell_block_init's defaults.
  type, bind(C), public :: ldimesh_cell_block
    integer(c_int) :: cell_type = LDIMESH_CELL_TETRAHEDRON
    integer(c_int) :: order = 1
    integer(c_int64_t) :: element_count = 0
    type(c_ptr) :: points = c_null_ptr
    integer(c_int64_t) :: point_count = 0
    type(c_ptr) :: values = c_null_ptr
    integer(c_int64_t) :: value_count = 0
    integer(c_int) :: type = LDIMESH_FLOAT64
    integer(c_int64_t) :: element_stride = 0
    integer(c_int) :: node_order = 0  ! LDIMESH_CELL_ORDER_VTK or LDIMESH_CELL_ORDER_GMSH
    integer(c_int) :: geometry_order = 0  ! 0: isoparametric; else the points' own order
  end type ldimesh_cell_block

  ! ldimesh_step_report of ldimesh.h.
  type, bind(C), public :: ldimesh_step_report
    integer(c_int64_t) :: step = 0
    integer(c_int) :: executed = 0
    integer(c_int) :: skipped_busy = 0
    integer(c_int) :: replaced_pending = 0
    real(c_double) :: blocked_seconds = 0.0_c_double
    real(c_double) :: max_blocked_seconds = 0.0_c_double
    integer(c_int64_t) :: nonfinite_values = 0
    integer(c_int) :: background = 0
    integer(c_int64_t) :: snapshot_bytes = 0
  end type ldimesh_step_report

  ! The adaptor handle; null until ldimesh_create succeeds.
  type, public :: ldimesh_adaptor
    type(c_ptr) :: handle = c_null_ptr
  end type ldimesh_adaptor

  interface
    function c_create(comm, options, out) bind(C, name='ldimesh_create_fortran')
      import :: c_int, c_char, c_ptr
      integer(c_int), value :: comm
      character(kind=c_char), dimension(*), intent(in) :: options
      type(c_ptr), intent(out) :: out
      integer(c_int) :: c_create
    end function c_create
    function c_create_from_file(comm, path, out) bind(C, name='ldimesh_create_from_file_fortran')
      import :: c_int, c_char, c_ptr
      integer(c_int), value :: comm
      character(kind=c_char), dimension(*), intent(in) :: path
      type(c_ptr), intent(out) :: out
      integer(c_int) :: c_create_from_file
    end function c_create_from_file
    function c_set_domain(a, lo, hi) bind(C, name='ldimesh_set_domain')
      import :: c_int, c_ptr, c_double
      type(c_ptr), value :: a
      real(c_double), intent(in) :: lo(3), hi(3)
      integer(c_int) :: c_set_domain
    end function c_set_domain
    function c_add_grid_block(a, block) bind(C, name='ldimesh_add_grid_block')
      import :: c_int, c_ptr, ldimesh_grid_block
      type(c_ptr), value :: a
      type(ldimesh_grid_block), intent(in) :: block
      integer(c_int) :: c_add_grid_block
    end function c_add_grid_block
    function c_add_hex_block(a, block) bind(C, name='ldimesh_add_hex_block')
      import :: c_int, c_ptr, ldimesh_hex_block
      type(c_ptr), value :: a
      type(ldimesh_hex_block), intent(in) :: block
      integer(c_int) :: c_add_hex_block
    end function c_add_hex_block
    function c_add_cell_block(a, block) bind(C, name='ldimesh_add_cell_block')
      import :: c_int, c_ptr, ldimesh_cell_block
      type(c_ptr), value :: a
      type(ldimesh_cell_block), intent(in) :: block
      integer(c_int) :: c_add_cell_block
    end function c_add_cell_block
    function c_add_field(a, name, values, value_count, type) bind(C, name='ldimesh_add_field')
      import :: c_int, c_ptr, c_char, c_int64_t
      type(c_ptr), value :: a
      character(kind=c_char), intent(in) :: name(*)
      type(c_ptr), value :: values
      integer(c_int64_t), value :: value_count
      integer(c_int), value :: type
      integer(c_int) :: c_add_field
    end function c_add_field
    function c_clear_blocks(a) bind(C, name='ldimesh_clear_blocks')
      import :: c_int, c_ptr
      type(c_ptr), value :: a
      integer(c_int) :: c_clear_blocks
    end function c_clear_blocks
    function c_execute(a, step, time) bind(C, name='ldimesh_execute')
      import :: c_int, c_ptr, c_int64_t, c_double
      type(c_ptr), value :: a
      integer(c_int64_t), value :: step
      real(c_double), value :: time
      integer(c_int) :: c_execute
    end function c_execute
    function c_finalize(a) bind(C, name='ldimesh_finalize')
      import :: c_int, c_ptr
      type(c_ptr), value :: a
      integer(c_int) :: c_finalize
    end function c_finalize
    subroutine c_destroy(a) bind(C, name='ldimesh_destroy')
      import :: c_ptr
      type(c_ptr), value :: a
    end subroutine c_destroy
    function c_last_error(a) bind(C, name='ldimesh_last_error')
      import :: c_ptr
      type(c_ptr), value :: a
      type(c_ptr) :: c_last_error
    end function c_last_error
    function c_url(a) bind(C, name='ldimesh_url')
      import :: c_ptr
      type(c_ptr), value :: a
      type(c_ptr) :: c_url
    end function c_url
    function c_last_report(a, out) bind(C, name='ldimesh_last_report')
      import :: c_int, c_ptr, ldimesh_step_report
      type(c_ptr), value :: a
      type(ldimesh_step_report), intent(out) :: out
      integer(c_int) :: c_last_report
    end function c_last_report
    function c_set_error(a, message) bind(C, name='ldimesh_set_error')
      import :: c_int, c_ptr, c_char
      type(c_ptr), value :: a
      character(kind=c_char), dimension(*), intent(in) :: message
      integer(c_int) :: c_set_error
    end function c_set_error
    function c_published_steps(a) bind(C, name='ldimesh_published_steps')
      import :: c_ptr, c_int64_t
      type(c_ptr), value :: a
      integer(c_int64_t) :: c_published_steps
    end function c_published_steps
    function c_strlen(s) bind(C, name='strlen')
      import :: c_ptr, c_size_t
      type(c_ptr), value :: s
      integer(c_size_t) :: c_strlen
    end function c_strlen
  end interface

  ! A uniform grid block from a 3D array of reals (kind 4 or 8), x the first index.
  interface ldimesh_add_uniform_grid
    module procedure add_uniform_grid_r8, add_uniform_grid_r4
  end interface ldimesh_add_uniform_grid

  ! Hexahedral elements from a 2D array of nodal values (kind 4 or 8), one column per element.
  interface ldimesh_add_hex_elements
    module procedure add_hex_elements_r8, add_hex_elements_r4
  end interface ldimesh_add_hex_elements

  ! A further named field of the block added last (ldimesh_add_field of ldimesh.h; option
  ! "colour_by" colours by it), in the block's layout: a 3D array shaped like the grid's, or a 2D
  ! array of nodal values shaped like the elements' values (one column per element).
  interface ldimesh_add_field
    module procedure add_field_grid_r8, add_field_grid_r4, add_field_nodal_r8, add_field_nodal_r4
  end interface ldimesh_add_field

  public :: ldimesh_create, ldimesh_create_from_file, ldimesh_set_domain, &
            ldimesh_add_grid_block, ldimesh_add_uniform_grid, ldimesh_add_hex_block, &
            ldimesh_add_hex_elements, ldimesh_add_cell_block, ldimesh_add_cells, &
            ldimesh_add_field, ldimesh_clear_blocks, &
            ldimesh_execute, ldimesh_finalize, ldimesh_destroy, ldimesh_last_error, &
            ldimesh_url, ldimesh_last_report, ldimesh_published_steps

contains

  ! Collective. options: a JSON document ('' for the defaults); on failure the handle stays
  ! null, ierr /= 0 on every rank and ldimesh_last_error(adaptor) tells why.
  subroutine ldimesh_create(comm, options, adaptor, ierr)
    integer, intent(in) :: comm
    character(len=*), intent(in) :: options
    type(ldimesh_adaptor), intent(out) :: adaptor
    integer, intent(out) :: ierr
    ierr = c_create(int(comm, c_int), trim(options)//c_null_char, adaptor%handle)
  end subroutine ldimesh_create

  ! Collective. The options from a file ('': the file named by LDIMESH_OPTIONS, or defaults).
  subroutine ldimesh_create_from_file(comm, path, adaptor, ierr)
    integer, intent(in) :: comm
    character(len=*), intent(in) :: path
    type(ldimesh_adaptor), intent(out) :: adaptor
    integer, intent(out) :: ierr
    ierr = c_create_from_file(int(comm, c_int), trim(path)//c_null_char, adaptor%handle)
  end subroutine ldimesh_create_from_file

  subroutine ldimesh_set_domain(adaptor, lo, hi, ierr)
    type(ldimesh_adaptor), intent(in) :: adaptor
    real(c_double), intent(in) :: lo(3), hi(3)
    integer, intent(out) :: ierr
    ierr = c_set_domain(adaptor%handle, lo, hi)
  end subroutine ldimesh_set_domain

  ! Any grid block, described field by field (strides, rectilinear coordinates, …).
  subroutine ldimesh_add_grid_block(adaptor, block, ierr)
    type(ldimesh_adaptor), intent(in) :: adaptor
    type(ldimesh_grid_block), intent(in) :: block
    integer, intent(out) :: ierr
    ierr = c_add_grid_block(adaptor%handle, block)
  end subroutine ldimesh_add_grid_block

  subroutine add_uniform_grid_r8(adaptor, field, origin, spacing, ghost_lo, ghost_hi, ierr)
    type(ldimesh_adaptor), intent(in) :: adaptor
    real(c_double), intent(in), target :: field(:, :, :)
    real(c_double), intent(in) :: origin(3), spacing(3)
    integer, intent(in) :: ghost_lo(3), ghost_hi(3)
    integer, intent(out) :: ierr
    type(ldimesh_grid_block) :: block
    block%type = LDIMESH_FLOAT64
    if (.not. contiguous_block(adaptor, field, 'ldimesh_add_uniform_grid')) then
      ierr = LDIMESH_ERROR_ARGUMENT
      return
    end if
    block%values = c_loc(field(1, 1, 1))
    call describe_uniform(block, shape(field), size(field, kind=c_int64_t), origin, spacing, &
                          ghost_lo, ghost_hi)
    ierr = c_add_grid_block(adaptor%handle, block)
  end subroutine add_uniform_grid_r8

  subroutine add_uniform_grid_r4(adaptor, field, origin, spacing, ghost_lo, ghost_hi, ierr)
    type(ldimesh_adaptor), intent(in) :: adaptor
    real(c_float), intent(in), target :: field(:, :, :)
    real(c_double), intent(in) :: origin(3), spacing(3)
    integer, intent(in) :: ghost_lo(3), ghost_hi(3)
    integer, intent(out) :: ierr
    type(ldimesh_grid_block) :: block
    block%type = LDIMESH_FLOAT32
    if (.not. contiguous_block(adaptor, field, 'ldimesh_add_uniform_grid')) then
      ierr = LDIMESH_ERROR_ARGUMENT
      return
    end if
    block%values = c_loc(field(1, 1, 1))
    call describe_uniform(block, shape(field), size(field, kind=c_int64_t), origin, spacing, &
                          ghost_lo, ghost_hi)
    ierr = c_add_grid_block(adaptor%handle, block)
  end subroutine add_uniform_grid_r4

  ! A strided section would need strides the module cannot see: the caller passes a whole
  ! array or a range of its last index.
  logical function contiguous_block(adaptor, field, what)
    type(ldimesh_adaptor), intent(in) :: adaptor
    class(*), intent(in) :: field(:, :, :)
    character(len=*), intent(in) :: what
    integer :: ignored
    contiguous_block = is_contiguous(field)
    if (.not. contiguous_block) ignored = fail(adaptor, &
      what//': the array is not contiguous (pass a whole array or a range of its last index)')
  end function contiguous_block

  subroutine describe_uniform(block, dims, count, origin, spacing, ghost_lo, ghost_hi)
    type(ldimesh_grid_block), intent(inout) :: block
    integer, intent(in) :: dims(3)
    integer(c_int64_t), intent(in) :: count
    real(c_double), intent(in) :: origin(3), spacing(3)
    integer, intent(in) :: ghost_lo(3), ghost_hi(3)
    block%dims = int(dims, c_int64_t)
    block%value_count = count
    block%origin = origin
    block%spacing = spacing
    block%ghost_lo = int(ghost_lo, c_int)
    block%ghost_hi = int(ghost_hi, c_int)
  end subroutine describe_uniform

  ! Any hex block, described field by field (element strides, …).
  subroutine ldimesh_add_hex_block(adaptor, block, ierr)
    type(ldimesh_adaptor), intent(in) :: adaptor
    type(ldimesh_hex_block), intent(in) :: block
    integer, intent(out) :: ierr
    ierr = c_add_hex_block(adaptor%handle, block)
  end subroutine ldimesh_add_hex_block

  ! Any cell block, described field by field.
  subroutine ldimesh_add_cell_block(adaptor, block, ierr)
    type(ldimesh_adaptor), intent(in) :: adaptor
    type(ldimesh_cell_block), intent(in) :: block
    integer, intent(out) :: ierr
    ierr = c_add_cell_block(adaptor%handle, block)
  end subroutine ldimesh_add_cell_block

  ! Cells of type `cell_type` (LDIMESH_CELL_*) and order `order`: points(:, i, e) is node i of
  ! cell e, values(i, e) its value, in VTK's node order or, with node_order =
  ! LDIMESH_CELL_ORDER_GMSH, gmsh's. With geometry_order = q (1..8) the points are the nodes of
  ! the cell of the same shape and order q (q = 1: the corners of straight cells; the 20- and
  ! 15-node cells then take the linear hexahedron's or wedge's corners), otherwise the values'.
  subroutine ldimesh_add_cells(adaptor, cell_type, order, points, values, ierr, node_order, &
                               geometry_order)
    type(ldimesh_adaptor), intent(in) :: adaptor
    integer, intent(in) :: cell_type, order
    real(c_double), intent(in), target, contiguous :: points(:, :, :), values(:, :)
    integer, intent(out) :: ierr
    integer, intent(in), optional :: node_order, geometry_order
    type(ldimesh_cell_block) :: block
    integer :: nodes, point_nodes
    nodes = cell_node_count(cell_type, order)
    point_nodes = nodes
    if (present(geometry_order)) then
      if (geometry_order > 0 .and. geometry_order /= order) then
        select case (cell_type)
        case (LDIMESH_CELL_HEXAHEDRON20)
          point_nodes = cell_node_count(LDIMESH_CELL_HEXAHEDRON, geometry_order)
        case (LDIMESH_CELL_WEDGE15)
          point_nodes = cell_node_count(LDIMESH_CELL_WEDGE, geometry_order)
        case (LDIMESH_CELL_PYRAMID14)
          point_nodes = cell_node_count(LDIMESH_CELL_PYRAMID, geometry_order)
        case default
          point_nodes = cell_node_count(cell_type, geometry_order)
        end select
      end if
    end if
    if (size(points, 1) /= 3 .or. size(points, 2) /= point_nodes .or. &
        size(values, 1) /= nodes .or. size(points, 3) /= size(values, 2)) then
      call forget_block(adaptor)
      ierr = fail(adaptor, 'ldimesh_add_cells: points must have the shape (3, nodes, cells) '// &
                  'and values (nodes, cells), nodes the cell type''s node count (the '// &
                  'geometry order''s for the points where geometry_order is given)')
      return
    end if
    block%cell_type = int(cell_type, c_int)
    block%order = int(order, c_int)
    block%element_count = size(values, 2, kind=c_int64_t)
    block%element_stride = size(values, 1, kind=c_int64_t)
    if (size(points) > 0) block%points = c_loc(points)
    block%point_count = size(points, kind=c_int64_t)
    if (size(values) > 0) block%values = c_loc(values)
    block%value_count = size(values, kind=c_int64_t)
    if (present(node_order)) block%node_order = int(node_order, c_int)
    if (present(geometry_order)) block%geometry_order = int(geometry_order, c_int)
    ierr = c_add_cell_block(adaptor%handle, block)
  end subroutine ldimesh_add_cells

  ! Nodes of a cell of type `cell_type` (LDIMESH_CELL_*) and order `order` (the C API checks
  ! that the order exists).
  pure integer function cell_node_count(cell_type, order) result(nodes)
    integer, intent(in) :: cell_type, order
    select case (cell_type)
    case (LDIMESH_CELL_HEXAHEDRON)
      nodes = (order + 1)**3
    case (LDIMESH_CELL_TETRAHEDRON)
      nodes = (order + 1)*(order + 2)*(order + 3)/6
    case (LDIMESH_CELL_WEDGE)
      nodes = (order + 1)**2*(order + 2)/2
    case (LDIMESH_CELL_HEXAHEDRON20)
      nodes = 20
    case (LDIMESH_CELL_WEDGE15)
      nodes = 15
    case (LDIMESH_CELL_PYRAMID14)
      nodes = 14
    case default
      nodes = merge(5, 13, order == 1)
    end select
  end function cell_node_count

  ! Elements of order `order` (1..8) with nodes `node_set` (LDIMESH_NODES_*): values(:, e) are
  ! element e's (order+1)**3 nodal values. Their geometry is either corners(3, 8, e) — the 8
  ! corners, x fastest then y then z (affine or trilinear elements) — or, for curved elements,
  ! geometry(3, (q+1)**3, e) with q = geometry_order (1..8), at the same node set. `ordering`
  ! (LDIMESH_ORDER_*, default lexicographic) orders the values and the geometry nodes.
  subroutine add_hex_elements_r8(adaptor, order, node_set, values, ierr, corners, geometry, &
                                 geometry_order, ordering)
    type(ldimesh_adaptor), intent(in) :: adaptor
    integer, intent(in) :: order, node_set
    real(c_double), intent(in), target, contiguous :: values(:, :)
    integer, intent(out) :: ierr
    real(c_double), intent(in), target, contiguous, optional :: corners(:, :, :), geometry(:, :, :)
    integer, intent(in), optional :: geometry_order, ordering
    type(ldimesh_hex_block) :: block
    block%type = LDIMESH_FLOAT64
    if (size(values) > 0) block%values = c_loc(values)
    call add_hex_elements(adaptor, block, order, node_set, shape(values), ierr, corners, &
                          geometry, geometry_order, ordering)
  end subroutine add_hex_elements_r8

  subroutine add_hex_elements_r4(adaptor, order, node_set, values, ierr, corners, geometry, &
                                 geometry_order, ordering)
    type(ldimesh_adaptor), intent(in) :: adaptor
    integer, intent(in) :: order, node_set
    real(c_float), intent(in), target, contiguous :: values(:, :)
    integer, intent(out) :: ierr
    real(c_double), intent(in), target, contiguous, optional :: corners(:, :, :), geometry(:, :, :)
    integer, intent(in), optional :: geometry_order, ordering
    type(ldimesh_hex_block) :: block
    block%type = LDIMESH_FLOAT32
    if (size(values) > 0) block%values = c_loc(values)
    call add_hex_elements(adaptor, block, order, node_set, shape(values), ierr, corners, &
                          geometry, geometry_order, ordering)
  end subroutine add_hex_elements_r4

  ! The shared part: the shapes checked here (the C API checks the counts it is given).
  subroutine add_hex_elements(adaptor, block, order, node_set, value_shape, ierr, corners, &
                              geometry, geometry_order, ordering)
    type(ldimesh_adaptor), intent(in) :: adaptor
    type(ldimesh_hex_block), intent(inout) :: block
    integer, intent(in) :: order, node_set, value_shape(2)
    integer, intent(out) :: ierr
    real(c_double), intent(in), target, contiguous, optional :: corners(:, :, :), geometry(:, :, :)
    integer, intent(in), optional :: geometry_order, ordering
    character(len=*), parameter :: what = 'ldimesh_add_hex_elements: '
    integer :: q
    block%order = int(order, c_int)
    block%nodes = int(node_set, c_int)
    block%element_count = int(value_shape(2), c_int64_t)
    block%value_count = int(value_shape(1), c_int64_t)*int(value_shape(2), c_int64_t)
    if (present(ordering)) block%ordering = int(ordering, c_int)
    if (order >= 1 .and. order <= 8) then
      if (value_shape(1) /= (order + 1)**3) then
        call forget_block(adaptor)
        ierr = fail(adaptor, what//'values must have (order+1)**3 rows, one column per element')
        return
      end if
    end if
    if (present(corners) .eqv. present(geometry)) then
      call forget_block(adaptor)
      ierr = fail(adaptor, what//'give either corners or geometry')
      return
    end if
    if (present(corners)) then
      if (size(corners, 1) /= 3 .or. size(corners, 2) /= 8 .or. &
          size(corners, 3) /= value_shape(2)) then
        call forget_block(adaptor)
        ierr = fail(adaptor, what//'corners must have the shape (3, 8, elements)')
        return
      end if
      if (size(corners) > 0) block%corners = c_loc(corners)
    else
      if (.not. present(geometry_order)) then
        call forget_block(adaptor)
        ierr = fail(adaptor, what//'geometry needs geometry_order')
        return
      end if
      q = geometry_order
      if (size(geometry, 1) /= 3 .or. size(geometry, 3) /= value_shape(2) .or. &
          (q >= 1 .and. q <= 8 .and. size(geometry, 2) /= (q + 1)**3)) then
        call forget_block(adaptor)
        ierr = fail(adaptor, what//'geometry must have the shape (3, (q+1)**3, elements)')
        return
      end if
      block%geometry_order = int(q, c_int)
      if (size(geometry) > 0) block%geometry = c_loc(geometry)
      block%geometry_count = size(geometry, kind=c_int64_t)
    end if
    ierr = c_add_hex_block(adaptor%handle, block)
  end subroutine add_hex_elements

  subroutine add_field_grid_r8(adaptor, name, field, ierr)
    type(ldimesh_adaptor), intent(in) :: adaptor
    character(len=*), intent(in) :: name
    real(c_double), intent(in), target :: field(:, :, :)
    integer, intent(out) :: ierr
    call add_grid_field(adaptor, name, field, c_loc(field(1, 1, 1)), LDIMESH_FLOAT64, ierr)
  end subroutine add_field_grid_r8

  subroutine add_field_grid_r4(adaptor, name, field, ierr)
    type(ldimesh_adaptor), intent(in) :: adaptor
    character(len=*), intent(in) :: name
    real(c_float), intent(in), target :: field(:, :, :)
    integer, intent(out) :: ierr
    call add_grid_field(adaptor, name, field, c_loc(field(1, 1, 1)), LDIMESH_FLOAT32, ierr)
  end subroutine add_field_grid_r4

  ! The shared part of the grid fields: `first` is the address of field(1, 1, 1).
  subroutine add_grid_field(adaptor, name, field, first, type, ierr)
    type(ldimesh_adaptor), intent(in) :: adaptor
    character(len=*), intent(in) :: name
    class(*), intent(in) :: field(:, :, :)
    type(c_ptr), intent(in) :: first
    integer(c_int), intent(in) :: type
    integer, intent(out) :: ierr
    if (.not. contiguous_block(adaptor, field, 'ldimesh_add_field')) then
      ierr = LDIMESH_ERROR_ARGUMENT
      return
    end if
    ierr = c_add_field(adaptor%handle, trim(name)//c_null_char, first, &
                       size(field, kind=c_int64_t), type)
  end subroutine add_grid_field

  subroutine add_field_nodal_r8(adaptor, name, values, ierr)
    type(ldimesh_adaptor), intent(in) :: adaptor
    character(len=*), intent(in) :: name
    real(c_double), intent(in), target :: values(:, :)
    integer, intent(out) :: ierr
    if (size(values) == 0) then
      ierr = fail(adaptor, 'ldimesh_add_field: the array is empty')
    else
      call add_nodal_field(adaptor, name, values, c_loc(values(1, 1)), LDIMESH_FLOAT64, ierr)
    end if
  end subroutine add_field_nodal_r8

  subroutine add_field_nodal_r4(adaptor, name, values, ierr)
    type(ldimesh_adaptor), intent(in) :: adaptor
    character(len=*), intent(in) :: name
    real(c_float), intent(in), target :: values(:, :)
    integer, intent(out) :: ierr
    if (size(values) == 0) then
      ierr = fail(adaptor, 'ldimesh_add_field: the array is empty')
    else
      call add_nodal_field(adaptor, name, values, c_loc(values(1, 1)), LDIMESH_FLOAT32, ierr)
    end if
  end subroutine add_field_nodal_r4

  ! The shared part of the nodal fields: `first` is the address of values(1, 1). No copy-in: a
  ! strided section is refused, as the adaptor keeps the address.
  subroutine add_nodal_field(adaptor, name, values, first, type, ierr)
    type(ldimesh_adaptor), intent(in) :: adaptor
    character(len=*), intent(in) :: name
    class(*), intent(in) :: values(:, :)
    type(c_ptr), intent(in) :: first
    integer(c_int), intent(in) :: type
    integer, intent(out) :: ierr
    if (.not. is_contiguous(values)) then
      ierr = fail(adaptor, 'ldimesh_add_field: the array is not contiguous (pass a whole array '// &
                  'or a range of its last index)')
      return
    end if
    ierr = c_add_field(adaptor%handle, trim(name)//c_null_char, first, &
                       size(values, kind=c_int64_t), type)
  end subroutine add_nodal_field

  ! Keeps `message` as the adaptor's last error; returns LDIMESH_ERROR_ARGUMENT.
  ! A block refused here, before the C API saw it: the C API is handed one it refuses too, so
  ! that no block is current and a following ldimesh_add_field is refused, not given to the block
  ! added before (as after a block the C API refuses).
  subroutine forget_block(adaptor)
    type(ldimesh_adaptor), intent(in) :: adaptor
    type(ldimesh_cell_block) :: empty
    integer(c_int) :: ignored
    empty%element_count = 0
    ignored = c_add_cell_block(adaptor%handle, empty)
  end subroutine forget_block

  integer function fail(adaptor, message)
    type(ldimesh_adaptor), intent(in) :: adaptor
    character(len=*), intent(in) :: message
    integer(c_int) :: ignored
    ignored = c_set_error(adaptor%handle, message//c_null_char)
    fail = LDIMESH_ERROR_ARGUMENT
  end function fail

  subroutine ldimesh_clear_blocks(adaptor, ierr)
    type(ldimesh_adaptor), intent(in) :: adaptor
    integer, intent(out) :: ierr
    ierr = c_clear_blocks(adaptor%handle)
  end subroutine ldimesh_clear_blocks

  ! Collective. Runs the in situ step if it is due.
  subroutine ldimesh_execute(adaptor, step, time, ierr)
    type(ldimesh_adaptor), intent(in) :: adaptor
    integer(c_int64_t), intent(in) :: step
    real(c_double), intent(in) :: time
    integer, intent(out) :: ierr
    ierr = c_execute(adaptor%handle, step, time)
  end subroutine ldimesh_execute

  ! Collective. Waits for pending work; ierr /= 0 if a background step failed.
  subroutine ldimesh_finalize(adaptor, ierr)
    type(ldimesh_adaptor), intent(in) :: adaptor
    integer, intent(out) :: ierr
    ierr = c_finalize(adaptor%handle)
  end subroutine ldimesh_finalize

  ! Collective. Finalizes if needed and frees the adaptor; the handle becomes null.
  subroutine ldimesh_destroy(adaptor)
    type(ldimesh_adaptor), intent(inout) :: adaptor
    call c_destroy(adaptor%handle)
    adaptor%handle = c_null_ptr
  end subroutine ldimesh_destroy

  ! The last error's message ('' if none); for a null handle, of the last failed create.
  function ldimesh_last_error(adaptor) result(message)
    type(ldimesh_adaptor), intent(in) :: adaptor
    character(len=:), allocatable :: message
    message = from_c_string(c_last_error(adaptor%handle))
  end function ldimesh_last_error

  ! Root: the viewer's URL with its token ('' elsewhere or without a server).
  function ldimesh_url(adaptor) result(url)
    type(ldimesh_adaptor), intent(in) :: adaptor
    character(len=:), allocatable :: url
    url = from_c_string(c_url(adaptor%handle))
  end function ldimesh_url

  ! Root: steps published so far.
  function ldimesh_published_steps(adaptor) result(count)
    type(ldimesh_adaptor), intent(in) :: adaptor
    integer(c_int64_t) :: count
    count = c_published_steps(adaptor%handle)
  end function ldimesh_published_steps

  subroutine ldimesh_last_report(adaptor, report, ierr)
    type(ldimesh_adaptor), intent(in) :: adaptor
    type(ldimesh_step_report), intent(out) :: report
    integer, intent(out) :: ierr
    ierr = c_last_report(adaptor%handle, report)
  end subroutine ldimesh_last_report

  function from_c_string(p) result(s)
    type(c_ptr), intent(in) :: p
    character(len=:), allocatable :: s
    character(kind=c_char), pointer :: chars(:)
    integer :: n, i
    if (.not. c_associated(p)) then
      s = ''
      return
    end if
    n = int(c_strlen(p))
    call c_f_pointer(p, chars, [n])
    allocate (character(len=n) :: s)
    do i = 1, n
      s(i:i) = chars(i)
    end do
  end function from_c_string

end module ldimesh_mod
