! The Fortran side of tests/adaptor/fortran_api_test.cpp: a solver's element arrays handed to the
! adaptor through the Fortran module (ldimesh_add_hex_elements), as a Fortran code would. The C++
! test creates the adaptor through the C API and passes its handle here.
module fortran_hex_elements
  use, intrinsic :: iso_c_binding
  use ldimesh_mod
  implicit none
  private

  integer, parameter :: n = 2, p = 2, q = 2  ! 2³ elements over [0, 1]³, field and geometry order 2
  ! Read by the adaptor at every due step: kept here, with the TARGET attribute.
  real(c_double), allocatable, target, save :: values(:, :), geometry(:, :, :), corners(:, :, :)
  real(c_float), allocatable, target, save :: values4(:, :)
  ! The field y beside x (ldimesh_add_field), double and float.
  real(c_double), allocatable, target, save :: y(:, :)
  real(c_float), allocatable, target, save :: y4(:, :)
  ! Wedges of the field x with the field y (fortran_add_cells).
  real(c_double), allocatable, target, save :: wedge_points(:, :, :), wedge_x(:, :), wedge_y(:, :)
  ! Quadratic tetrahedra given by their corners, the fields x and y (fortran_add_tets_by_corners).
  real(c_double), allocatable, target, save :: tet_corners(:, :, :), tet_x(:, :), tet_y(:, :)
  ! A grid block of the field x with its field y (fortran_add_grid_field).
  real(c_float), allocatable, target, save :: gx(:, :, :), gy(:, :, :)

contains

  ! The position of GLL node (i, j, k) (nodes 0, 1/2, 1 per axis) of element e, x bent inside the
  ! cube (the nodes on its faces stay): x + 0.05 sin(πx) sin(πy) sin(πz).
  function node(e, i, j, k, bent) result(x)
    integer, intent(in) :: e, i, j, k
    logical, intent(in) :: bent
    real(c_double) :: x(3), pi
    pi = acos(-1.0_c_double)
    x = (real([mod(e, n), mod(e/n, n), e/(n*n)], c_double) + &
         0.5_c_double*real([i, j, k], c_double))/real(n, c_double)
    if (bent) x(1) = x(1) + 0.05_c_double*sin(pi*x(2))*sin(pi*x(3))*sin(pi*x(1))
  end function node

  ! Adds this rank's elements (element e on rank mod(e, ranks)) of the field x: curved elements
  ! (geometry of order 2, double values) when curved /= 0, else the straight cubes from their 8
  ! corners (x fastest, then y, then z) with float values; and the field y as their field "y"
  ! (of the same type). Returns the module's status.
  integer(c_int) function fortran_add_hex_elements(handle, rank, ranks, curved) &
      bind(C, name='fortran_add_hex_elements')
    type(c_ptr), value :: handle
    integer(c_int), value :: rank, ranks, curved
    type(ldimesh_adaptor) :: insitu
    integer :: e, i, j, k, c, m, count, ierr
    real(c_double) :: x(3)
    insitu%handle = handle
    count = 0
    do e = 0, n**3 - 1
      if (mod(e, ranks) == rank) count = count + 1
    end do
    if (allocated(values)) deallocate (values, values4, geometry, corners, y, y4)
    allocate (values((p + 1)**3, count), values4((p + 1)**3, count), &
              geometry(3, (q + 1)**3, count), corners(3, 8, count), y((p + 1)**3, count), &
              y4((p + 1)**3, count))
    count = 0
    do e = 0, n**3 - 1
      if (mod(e, ranks) /= rank) cycle
      count = count + 1
      m = 0
      do k = 0, 2
        do j = 0, 2
          do i = 0, 2
            m = m + 1
            x = node(e, i, j, k, curved /= 0)
            geometry(:, m, count) = x
            values(m, count) = x(1)
            values4(m, count) = real(x(1), c_float)
            y(m, count) = x(2)
            y4(m, count) = real(x(2), c_float)
          end do
        end do
      end do
      do c = 0, 7
        corners(:, c + 1, count) = node(e, 2*mod(c, 2), 2*mod(c/2, 2), 2*(c/4), .false.)
      end do
    end do
    if (curved /= 0) then
      call ldimesh_add_hex_elements(insitu, p, LDIMESH_NODES_GLL, values, ierr, &
                                    geometry=geometry, geometry_order=q)
      if (ierr == LDIMESH_OK) call ldimesh_add_field(insitu, 'y', y, ierr)
    else
      call ldimesh_add_hex_elements(insitu, p, LDIMESH_NODES_GLL, values4, ierr, corners=corners)
      if (ierr == LDIMESH_OK) call ldimesh_add_field(insitu, 'y', y4, ierr)
    end if
    fortran_add_hex_elements = int(ierr, c_int)
  end function fortran_add_hex_elements

  ! Adds this rank's cubes (cube e on rank mod(e, ranks)) of 2³ over [0, 1]³, each as 2 linear
  ! wedges (VTK's node order: the triangle at z = 0, then at z = 1) through ldimesh_add_cells, the
  ! field x with the field y; then a call whose shapes do not fit the type (refused) and a field
  ! after it (refused: no block is current). Returns the module's status, -1 where the wrong
  ! shapes were accepted, -2 where the field after them was.
  integer(c_int) function fortran_add_cells(handle, rank, ranks) bind(C, name='fortran_add_cells')
    type(c_ptr), value :: handle
    integer(c_int), value :: rank, ranks
    type(ldimesh_adaptor) :: insitu
    integer :: e, w, v, count, ierr
    integer, parameter :: tri(3, 2) = reshape([0, 1, 2, 0, 2, 3], [3, 2])
    real(c_double) :: corner(3, 0:3), o(3)
    character(len=:), allocatable :: message
    insitu%handle = handle
    count = 0
    do e = 0, n**3 - 1
      if (mod(e, ranks) == rank) count = count + 2
    end do
    if (allocated(wedge_points)) deallocate (wedge_points, wedge_x, wedge_y)
    allocate (wedge_points(3, 6, count), wedge_x(6, count), wedge_y(6, count))
    count = 0
    do e = 0, n**3 - 1
      if (mod(e, ranks) /= rank) cycle
      o = real([mod(e, n), mod(e/n, n), e/(n*n)], c_double)/real(n, c_double)
      corner(:, 0) = o
      corner(:, 1) = o + [0.5_c_double, 0.0_c_double, 0.0_c_double]
      corner(:, 2) = o + [0.5_c_double, 0.5_c_double, 0.0_c_double]
      corner(:, 3) = o + [0.0_c_double, 0.5_c_double, 0.0_c_double]
      do w = 1, 2
        count = count + 1
        do v = 1, 3
          wedge_points(:, v, count) = corner(:, tri(v, w))
          wedge_points(:, v + 3, count) = corner(:, tri(v, w)) + [0.0_c_double, 0.0_c_double, &
                                                                  0.5_c_double]
        end do
        wedge_x(:, count) = wedge_points(1, :, count)
        wedge_y(:, count) = wedge_points(2, :, count)
      end do
    end do
    call ldimesh_add_cells(insitu, int(LDIMESH_CELL_WEDGE), 1, wedge_points, wedge_x, ierr)
    if (ierr == LDIMESH_OK) call ldimesh_add_field(insitu, 'y', wedge_y, ierr)
    if (ierr /= LDIMESH_OK) then
      fortran_add_cells = int(ierr, c_int)
      return
    end if
    ! A tetrahedron has 4 nodes, not 6: refused; then no block is current, so a field is refused
    ! too (it would otherwise go to the wedges added before).
    call ldimesh_add_cells(insitu, int(LDIMESH_CELL_TETRAHEDRON), 1, wedge_points, wedge_x, ierr)
    message = ldimesh_last_error(insitu)
    if (ierr /= LDIMESH_ERROR_ARGUMENT .or. &
        index(message, 'nodes the cell type''s node count') == 0) then
      fortran_add_cells = -1
      return
    end if
    call ldimesh_add_field(insitu, 'y', wedge_x, ierr)
    if (ierr == LDIMESH_OK) then
      fortran_add_cells = -2
      return
    end if
    fortran_add_cells = LDIMESH_OK
  end function fortran_add_cells

  ! Adds this rank's cubes (cube e on rank mod(e, ranks)) of 2³ over [0, 1]³, each as Kuhn's 6
  ! tetrahedra, as quadratic tetrahedra (VTK_QUADRATIC_TETRA's 10 nodes: the corners, then the
  ! midpoints of edges 01, 12, 02, 03, 13, 23) whose points are their 4 corners
  ! (geometry_order = 1), the field x with the field y. First the same arrays without
  ! geometry_order: refused (the points would be 10 per cell). Returns the module's status, or -1
  ! where the call without geometry_order was accepted.
  integer(c_int) function fortran_add_tets_by_corners(handle, rank, ranks) &
      bind(C, name='fortran_add_tets_by_corners')
    type(c_ptr), value :: handle
    integer(c_int), value :: rank, ranks
    type(ldimesh_adaptor) :: insitu
    integer :: e, t, v, count, ierr
    ! Kuhn's tetrahedra as walks from corner (0, 0, 0) to (1, 1, 1): the axes in each order.
    integer, parameter :: walk(3, 6) = reshape([1, 2, 3, 2, 1, 3, 2, 3, 1, 3, 2, 1, 3, 1, 2, &
                                                1, 3, 2], [3, 6])
    integer, parameter :: edge(2, 6) = reshape([1, 2, 2, 3, 1, 3, 1, 4, 2, 4, 3, 4], [2, 6])
    real(c_double) :: o(3), x(3, 10)
    insitu%handle = handle
    count = 0
    do e = 0, n**3 - 1
      if (mod(e, ranks) == rank) count = count + 6
    end do
    if (allocated(tet_corners)) deallocate (tet_corners, tet_x, tet_y)
    allocate (tet_corners(3, 4, count), tet_x(10, count), tet_y(10, count))
    count = 0
    do e = 0, n**3 - 1
      if (mod(e, ranks) /= rank) cycle
      o = real([mod(e, n), mod(e/n, n), e/(n*n)], c_double)/real(n, c_double)
      do t = 1, 6
        count = count + 1
        x(:, 1) = o
        do v = 1, 3
          x(:, v + 1) = x(:, v)
          x(walk(v, t), v + 1) = x(walk(v, t), v) + 1.0_c_double/real(n, c_double)
        end do
        do v = 1, 6
          x(:, v + 4) = 0.5_c_double*(x(:, edge(1, v)) + x(:, edge(2, v)))
        end do
        tet_corners(:, :, count) = x(:, 1:4)
        tet_x(:, count) = x(1, :)
        tet_y(:, count) = x(2, :)
      end do
    end do
    call ldimesh_add_cells(insitu, int(LDIMESH_CELL_TETRAHEDRON), 2, tet_corners, tet_x, ierr)
    if (ierr /= LDIMESH_ERROR_ARGUMENT) then
      fortran_add_tets_by_corners = -1
      return
    end if
    call ldimesh_add_cells(insitu, int(LDIMESH_CELL_TETRAHEDRON), 2, tet_corners, tet_x, ierr, &
                           geometry_order=1)
    if (ierr == LDIMESH_OK) call ldimesh_add_field(insitu, 'y', tet_y, ierr)
    fortran_add_tets_by_corners = int(ierr, c_int)
  end function fortran_add_tets_by_corners

  ! Rank 0 adds a 9³ uniform grid over [0, 1]³ of the field x (float) with the field y as its
  ! field "y" (ldimesh_add_field of a 3D array); the other ranks add nothing. Returns the status.
  integer(c_int) function fortran_add_grid_field(handle, rank) bind(C, name='fortran_add_grid_field')
    type(c_ptr), value :: handle
    integer(c_int), value :: rank
    type(ldimesh_adaptor) :: insitu
    integer :: i, j, k, ierr
    insitu%handle = handle
    fortran_add_grid_field = LDIMESH_OK
    if (rank /= 0) return
    if (allocated(gx)) deallocate (gx, gy)
    allocate (gx(9, 9, 9), gy(9, 9, 9))
    do k = 1, 9
      do j = 1, 9
        do i = 1, 9
          gx(i, j, k) = real(i - 1, c_float)/8.0_c_float
          gy(i, j, k) = real(j - 1, c_float)/8.0_c_float
        end do
      end do
    end do
    call ldimesh_add_uniform_grid(insitu, gx, [0.0_c_double, 0.0_c_double, 0.0_c_double], &
                                  [0.125_c_double, 0.125_c_double, 0.125_c_double], [0, 0, 0], &
                                  [0, 0, 0], ierr)
    if (ierr == LDIMESH_OK) call ldimesh_add_field(insitu, 'y', gy, ierr)
    fortran_add_grid_field = int(ierr, c_int)
  end function fortran_add_grid_field

  ! Wrong shapes and degenerate geometry, each refused with LDIMESH_ERROR_ARGUMENT and a message
  ! saying why. Returns how many calls did not do so (0: all refused as they should be).
  integer(c_int) function fortran_refused_shapes(handle) bind(C, name='fortran_refused_shapes')
    type(c_ptr), value :: handle
    type(ldimesh_adaptor) :: insitu
    real(c_double), target :: good(27, 1), short(26, 1), cube(3, 8, 1), seven(3, 7, 1), &
                              curved(3, 27, 1), thin(3, 26, 1), flat(3, 27, 1)
    integer :: ierr, failures, c
    insitu%handle = handle
    failures = 0
    good = 0.5_c_double
    short = 0.5_c_double
    flat = 0.0_c_double
    do c = 0, 7
      cube(:, c + 1, 1) = real([mod(c, 2), mod(c/2, 2), c/4], c_double)
    end do
    seven = cube(:, 1:7, :)
    curved = 0.0_c_double
    thin = 0.0_c_double
    call ldimesh_add_hex_elements(insitu, 2, LDIMESH_NODES_GLL, short, ierr, corners=cube)
    call expect_refused('(order+1)**3 rows')
    call ldimesh_add_hex_elements(insitu, 2, LDIMESH_NODES_GLL, good, ierr)
    call expect_refused('either corners or geometry')
    call ldimesh_add_hex_elements(insitu, 2, LDIMESH_NODES_GLL, good, ierr, corners=cube, &
                                  geometry=curved, geometry_order=2)
    call expect_refused('either corners or geometry')
    call ldimesh_add_hex_elements(insitu, 2, LDIMESH_NODES_GLL, good, ierr, corners=seven)
    call expect_refused('(3, 8, elements)')
    call ldimesh_add_hex_elements(insitu, 2, LDIMESH_NODES_GLL, good, ierr, geometry=curved)
    call expect_refused('geometry_order')
    call ldimesh_add_hex_elements(insitu, 2, LDIMESH_NODES_GLL, good, ierr, geometry=thin, &
                                  geometry_order=2)
    call expect_refused('(3, (q+1)**3, elements)')
    ! Shapes right, geometry degenerate (every node at the origin): the C API's own check.
    call ldimesh_add_hex_elements(insitu, 2, LDIMESH_NODES_GLL, good, ierr, geometry=flat, &
                                  geometry_order=2)
    call expect_refused('degenerate')
    call ldimesh_add_hex_elements(insitu, 9, LDIMESH_NODES_GLL, good, ierr, corners=cube)
    call expect_refused('order must lie in 1..8')
    fortran_refused_shapes = int(failures, c_int)

  contains

    subroutine expect_refused(words)
      character(len=*), intent(in) :: words
      character(len=:), allocatable :: message
      message = ldimesh_last_error(insitu)
      if (ierr /= LDIMESH_ERROR_ARGUMENT .or. index(message, words) == 0) then
        write (0, '(a,i0,a)') 'fortran_refused_shapes: expected a refusal naming "'//words// &
          '", got status ', ierr, ': '//message
        failures = failures + 1
      end if
    end subroutine expect_refused

  end function fortran_refused_shapes

end module fortran_hex_elements
