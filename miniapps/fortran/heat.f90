! ldimesh-heat-fortran: the heat-equation solver of miniapps/c/heat.c in Fortran, linking the
! adaptor through the Fortran module ldimesh_mod (adaptor/fortran/ldimesh_mod.f90). The same
! model, decomposition and arithmetic, so both publish identical meshes (tests/miniapps).
!
! Usage: mpiexec -n R ldimesh-heat-fortran [--size N] [--steps S] [--substeps K] [--options FILE]
program heat
  use, intrinsic :: iso_c_binding, only: c_double, c_int64_t
  use mpi
  use ldimesh_mod
  implicit none

  character(len=*), parameter :: name = 'ldimesh-heat-fortran'
  real(c_double), parameter :: dt = 0.15_c_double
  real(c_double), allocatable, target :: u(:, :, :), v(:, :, :)
  type(ldimesh_adaptor) :: insitu
  type(ldimesh_step_report) :: report
  integer :: provided, rank, nranks, ierr, status, below, above, step, s
  integer :: n, steps, substeps, z0, z1, kfirst, klast, ghost_lo(3), ghost_hi(3)
  character(len=4096) :: options
  real(c_double) :: h, time, lo(3), hi(3), origin(3), spacing(3)
  logical :: in_u

  call MPI_Init_thread(MPI_THREAD_FUNNELED, provided, ierr)
  call MPI_Comm_rank(MPI_COMM_WORLD, rank, ierr)
  call MPI_Comm_size(MPI_COMM_WORLD, nranks, ierr)
  call parse_arguments(status)
  if (status == 0 .and. n < 2*nranks) then
    if (rank == 0) write (0, '(a)') name//': --size must be at least 2 × ranks'
    status = 1
  end if
  if (status /= 0) then
    call MPI_Finalize(ierr)
    if (status > 0) stop 1
    stop
  end if

  ! Rank r owns the point layers z0 .. z1 - 1 and stores z0 - 2 .. z1 + 1 (two halo layers each
  ! side: the Laplacian reads one, the adaptor's normals the second, as in heat.c).
  z0 = int(int(rank, 8)*n/nranks)
  z1 = int(int(rank + 1, 8)*n/nranks)
  allocate (u(0:n - 1, 0:n - 1, z0 - 2:z1 + 1), v(0:n - 1, 0:n - 1, z0 - 2:z1 + 1))
  call initialise(u)
  v = u
  below = merge(rank - 1, MPI_PROC_NULL, rank > 0)
  above = merge(rank + 1, MPI_PROC_NULL, rank < nranks - 1)
  h = 1.0_c_double/real(n - 1, c_double)

  if (rank == 0) write (*, '(a,i0,a,i0,a,i0,a)') name//': ', n, '³ points on ', nranks, &
    ' ranks, ', steps, ' steps'
  call ldimesh_create_from_file(MPI_COMM_WORLD, trim(options), insitu, ierr)
  if (ierr /= LDIMESH_OK) then
    ! The same verdict on every rank: a configuration error stops the run before it starts.
    if (rank == 0) write (0, '(a)') name//': in situ adaptor not created: '// &
      ldimesh_last_error(insitu)
    call MPI_Finalize(ierr)
    stop 2
  end if
  if (rank == 0) then
    if (len(ldimesh_url(insitu)) > 0) then
      write (*, '(a)') 'viewer: '//ldimesh_url(insitu)
    else
      write (*, '(a)') 'viewer: none (server disabled)'
    end if
    flush (6)
  end if
  lo = 0.0_c_double
  hi = 1.0_c_double
  call ldimesh_set_domain(insitu, lo, hi, ierr)
  if (ierr /= LDIMESH_OK .and. rank == 0) write (0, '(a)') name//': set_domain: '// &
    ldimesh_last_error(insitu)

  ! The block: from the halo layers below (a neighbour there) or the first owned layer, to the
  ! halo layers above (a neighbour there) or the last owned layer.
  kfirst = merge(z0 - 2, z0, below /= MPI_PROC_NULL)
  klast = merge(z1 + 1, z1 - 1, above /= MPI_PROC_NULL)
  ghost_lo = [0, 0, merge(2, 0, below /= MPI_PROC_NULL)]
  ghost_hi = [0, 0, merge(2, 0, above /= MPI_PROC_NULL)]
  origin = [0.0_c_double, 0.0_c_double, real(kfirst, c_double)*h]
  spacing = h

  in_u = .true.
  do step = 1, steps
    do s = 1, substeps
      if (in_u) then
        call advance(u, v)
      else
        call advance(v, u)
      end if
      in_u = .not. in_u
    end do
    ! The field of this step is in u or v: describe the block anew (a pointer, no copy).
    call ldimesh_clear_blocks(insitu, ierr)
    if (in_u) then
      call exchange(u, 2)
      call ldimesh_add_uniform_grid(insitu, u(:, :, kfirst:klast), origin, spacing, ghost_lo, &
                                    ghost_hi, ierr)
    else
      call exchange(v, 2)
      call ldimesh_add_uniform_grid(insitu, v(:, :, kfirst:klast), origin, spacing, ghost_lo, &
                                    ghost_hi, ierr)
    end if
    if (ierr /= LDIMESH_OK) write (0, '(a,i0,a)') name//': rank ', rank, ': add_grid_block: '// &
      ldimesh_last_error(insitu)
    time = real(step*substeps, c_double)*dt*h*h
    ! A failed in situ step is reported and the simulation goes on.
    call ldimesh_execute(insitu, int(step, c_int64_t), time, ierr)
    if (ierr /= LDIMESH_OK .and. rank == 0) write (0, '(a,i0,a)') name//': step ', step, &
      ': in situ: '//ldimesh_last_error(insitu)
    call ldimesh_last_report(insitu, report, ierr)
    if (rank == 0 .and. report%nonfinite_values > 0) write (*, '(a,i0,a,i0,a)') name// &
      ': step ', step, ': the field held ', report%nonfinite_values, ' non-finite values'
  end do
  call ldimesh_finalize(insitu, ierr)
  if (ierr /= LDIMESH_OK .and. rank == 0) write (0, '(a)') name//': in situ finalize: '// &
    ldimesh_last_error(insitu)
  if (rank == 0) write (*, '(a,i0,a,i0,a)') name//': done, ', steps, ' steps, ', &
    ldimesh_published_steps(insitu), ' published'
  call ldimesh_destroy(insitu)
  call MPI_Finalize(ierr)

contains

  ! --size N, --steps S, --substeps K, --options FILE; status 0, 1 (usage) or -1 (--help).
  subroutine parse_arguments(status)
    integer, intent(out) :: status
    character(len=4096) :: arg, value
    integer :: i, nargs, io
    n = 48
    steps = 40
    substeps = 5
    options = ''
    status = 0
    nargs = command_argument_count()
    i = 1
    do while (i <= nargs)
      call get_command_argument(i, arg)
      if (arg == '--help') then
        if (rank == 0) write (*, '(a)') 'usage: '//name// &
          ' [--size N] [--steps S] [--substeps K] [--options FILE]'
        status = -1
        return
      end if
      if (i == nargs) then
        if (rank == 0) write (0, '(a)') name//': '//trim(arg)//' needs a value'
        status = 1
        return
      end if
      call get_command_argument(i + 1, value)
      io = 0
      select case (trim(arg))
      case ('--options')
        options = value
      case ('--size')
        read (value, *, iostat=io) n
      case ('--steps')
        read (value, *, iostat=io) steps
      case ('--substeps')
        read (value, *, iostat=io) substeps
      case default
        if (rank == 0) write (0, '(a)') name//': unknown argument '//trim(arg)//' (see --help)'
        status = 1
        return
      end select
      if (io /= 0) then
        if (rank == 0) write (0, '(a)') name//': '//trim(arg)//': not a number: '//trim(value)
        status = 1
        return
      end if
      i = i + 2
    end do
    if (n < 4 .or. steps < 1 .or. substeps < 1) then
      if (rank == 0) write (0, '(a)') name//': --size must be ≥ 4, --steps and --substeps ≥ 1'
      status = 1
    end if
  end subroutine parse_arguments

  ! Three Gaussian blobs, u = 0 on the boundary.
  subroutine initialise(a)
    real(c_double), intent(out) :: a(0:, 0:, z0 - 2:)
    real(c_double), parameter :: centres(3, 3) = reshape([0.35_c_double, 0.4_c_double, &
      0.45_c_double, 0.65_c_double, 0.45_c_double, 0.55_c_double, 0.5_c_double, 0.68_c_double, &
      0.5_c_double], [3, 3])
    real(c_double) :: step_h, x, y, z, dx, dy, dz, value
    integer :: i, j, k, b
    step_h = 1.0_c_double/real(n - 1, c_double)
    a = 0.0_c_double
    do k = max(z0 - 2, 1), min(z1 + 1, n - 2)
      do j = 1, n - 2
        do i = 1, n - 2
          x = real(i, c_double)*step_h
          y = real(j, c_double)*step_h
          z = real(k, c_double)*step_h
          value = 0.0_c_double
          do b = 1, 3
            dx = x - centres(1, b)
            dy = y - centres(2, b)
            dz = z - centres(3, b)
            value = value + exp(-(dx*dx + dy*dy + dz*dz)/0.02_c_double)
          end do
          a(i, j, k) = value
        end do
      end do
    end do
  end subroutine initialise

  ! One explicit Euler step from a into b (halo layers of a exchanged first).
  subroutine advance(a, b)
    real(c_double), intent(inout) :: a(0:, 0:, z0 - 2:)
    real(c_double), intent(inout) :: b(0:, 0:, z0 - 2:)
    real(c_double) :: lap
    integer :: i, j, k
    call exchange(a, 0)
    do k = max(z0, 1), min(z1 - 1, n - 2)
      do j = 1, n - 2
        do i = 1, n - 2
          lap = (a(i - 1, j, k) + a(i + 1, j, k)) + (a(i, j - 1, k) + a(i, j + 1, k)) + &
                (a(i, j, k - 1) + a(i, j, k + 1)) - 6.0_c_double*a(i, j, k)
          b(i, j, k) = a(i, j, k) + dt*lap
        end do
      end do
    end do
  end subroutine advance

  ! Fills the halo layers z0 - 2, z0 - 1 and z1, z1 + 1 from the neighbours.
  subroutine exchange(a, tag)
    real(c_double), intent(inout) :: a(0:, 0:, z0 - 2:)
    integer, intent(in) :: tag
    integer :: count, e
    count = 2*n*n
    call MPI_Sendrecv(a(:, :, z1 - 2:z1 - 1), count, MPI_DOUBLE_PRECISION, above, tag, &
                      a(:, :, z0 - 2:z0 - 1), count, MPI_DOUBLE_PRECISION, below, tag, &
                      MPI_COMM_WORLD, MPI_STATUS_IGNORE, e)
    call MPI_Sendrecv(a(:, :, z0:z0 + 1), count, MPI_DOUBLE_PRECISION, below, tag + 1, &
                      a(:, :, z1:z1 + 1), count, MPI_DOUBLE_PRECISION, above, tag + 1, &
                      MPI_COMM_WORLD, MPI_STATUS_IGNORE, e)
  end subroutine exchange

end program heat
