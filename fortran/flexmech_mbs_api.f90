!> Flat API of the rigid multibody layer facing f2py: plain arrays and scalars only.  Python packs the
!> mechanism (flexmech_py/mechanism/packing.py) into ispec(ni), rspec(nr) (layout: flexmech_mbs,
!> mbs_build) and calls these through flexmech_py.kernels; every routine returns a status code
!> (flexmech_lapack: 7 singular position, 8 cannot assemble).
!>   n = 3 nb coordinates z = [x_C, y_C, phi] per moving body, nrow constraint rows (joints, then
!>   kinematic drives), nj joints, nd drives; samples: zf, zdf, zddf (n, ns), lamf (nrow, ns), jqf (3, nj, ns),
!>   dvf (nd, ns) the generalized force of every drive.
module flexmech_mbs_api
  use flexmech_kinds, only: dp
  use flexmech_lapack, only: STATUS_OK, STATUS_BAD_INPUT, STATUS_ASSEMBLY, dgetrf, dgetrs, lapack_status
  use flexmech_mbs, only: mbs_system, mbs_build, mbs_constraints, mbs_forces
  use flexmech_mbs_solve, only: mbs_residual
  use flexmech_motion, only: kinematic_samples, dynamic_start, dynamic_samples
  use flexmech_ode, only: ode_state_size
  use flexmech_mbs_control, only: mbs_controlled, controlled_setup, controlled_start
  use flexmech_control, only: CTL_NST, CTL_REF_START
  implicit none
  private
  public :: mbs_eval, mbs_assemble, mbs_kinematic, mbs_dynamic_start, mbs_dynamic, mbs_state_size
  public :: mbs_controlled_state_size, mbs_controlled_start, mbs_controlled_dynamic

contains

  !> Build and check the sizes the caller expects (n coordinates, nrow rows, nj joints).
  subroutine build_checked(ispec, rspec, n, nrow, nj, sys, status)
    integer, intent(in) :: ispec(:), n, nrow, nj
    real(dp), intent(in) :: rspec(:)
    type(mbs_system), intent(out) :: sys
    integer, intent(out) :: status
    call mbs_build(ispec, rspec, sys, status)
    if (status /= STATUS_OK) return
    if (sys%n /= n .or. (nrow >= 0 .and. sys%nrow /= nrow) .or. (nj >= 0 .and. sys%nj /= nj)) status = STATUS_BAD_INPUT
  end subroutine build_checked

  !> Length of the dynamic-mode state for n coordinates.
  subroutine mbs_state_size(n, nst)
    integer, intent(in) :: n
    integer, intent(out) :: nst
    nst = ode_state_size(2*n)
  end subroutine mbs_state_size

  !> Constraint values phi, Jacobian jac (nrow, n), acceleration and velocity right-hand sides gam, nu
  !> and applied generalized forces q at (z, zd, t).
  subroutine mbs_eval(ni, nr, n, nrow, ispec, rspec, z, zd, t, phi, jac, gam, nu, q, status)
    integer, intent(in) :: ni, nr, n, nrow
    integer, intent(in) :: ispec(ni)
    real(dp), intent(in) :: rspec(nr), z(n), zd(n), t
    real(dp), intent(out) :: phi(nrow), jac(nrow, n), gam(nrow), nu(nrow), q(n)
    integer, intent(out) :: status
    type(mbs_system) :: sys
    phi = 0.0_dp; jac = 0.0_dp; gam = 0.0_dp; nu = 0.0_dp; q = 0.0_dp
    call build_checked(ispec, rspec, n, nrow, -1, sys, status)
    if (status /= STATUS_OK) return
    call mbs_constraints(sys, z, zd, t)
    phi = sys%phi; jac = sys%jac(1:nrow, :); gam = sys%gam; nu = sys%nu
    call mbs_forces(sys, t, q)
  end subroutine mbs_eval

  !> Close the loops: Gauss-Newton with minimum-norm corrections dz = -W^-1 J^T (J W^-1 J^T)^-1 phi,
  !> W = diag(1, 1, lref^2) per body (the nearest configuration, rotations weighed by the mechanism's
  !> length), on every row (joints and kinematic drives at time t), until max |phi| <= tol [m; angle
  !> rows times lref].  resid: the final violation; STATUS_ASSEMBLY when maxit iterations do not reach
  !> tol (the mechanism cannot assemble near z), STATUS_SINGULAR when the rows are dependent there.
  subroutine mbs_assemble(ni, nr, n, ispec, rspec, z, t, tol, maxit, status, iters, resid)
    integer, intent(in) :: ni, nr, n, maxit
    integer, intent(in) :: ispec(ni)
    real(dp), intent(in) :: rspec(nr), t, tol
    real(dp), intent(inout) :: z(n)
    integer, intent(out) :: status, iters
    real(dp), intent(out) :: resid
    type(mbs_system) :: sys
    real(dp), allocatable :: g(:, :), y(:), winv(:), zd0(:)
    integer, allocatable :: ipiv(:)
    integer :: m, info
    iters = 0; resid = 0.0_dp
    call build_checked(ispec, rspec, n, -1, -1, sys, status)
    if (status /= STATUS_OK) return
    m = sys%nrow
    if (m == 0) return
    allocate (g(m, m), y(m), winv(n), zd0(n), ipiv(m))
    winv = 1.0_dp; winv(3:n:3) = 1.0_dp/sys%lref**2
    zd0 = 0.0_dp
    do
      call mbs_constraints(sys, z, zd0, t)
      resid = mbs_residual(sys)
      if (resid <= tol) return
      if (iters >= maxit .or. .not. resid < huge(1.0_dp)) then
        status = STATUS_ASSEMBLY
        return
      end if
      g = matmul(sys%jac(1:m, :), spread(winv, 2, m)*transpose(sys%jac(1:m, :)))
      y = -sys%phi
      call dgetrf(m, m, g, m, ipiv, info)
      status = lapack_status(info)
      if (status /= STATUS_OK) return
      call dgetrs('N', m, 1, g, m, ipiv, y, m, info)
      z = z + winv*matmul(transpose(sys%jac(1:m, :)), y)
      iters = iters + 1
    end do
  end subroutine mbs_assemble

  !> Kinematic mode at times ts (see flexmech_motion: kinematic_samples); state (2 + 3n).
  subroutine mbs_kinematic(ni, nr, n, nrow, nj, nd, ns, ispec, rspec, ts, state, tol, rcond_min, zf, zdf, zddf, &
                           lamf, jqf, dvf, nvalid, status, fail_t, rcond_low)
    integer, intent(in) :: ni, nr, n, nrow, nj, nd, ns
    integer, intent(in) :: ispec(ni)
    real(dp), intent(in) :: rspec(nr), ts(ns), tol, rcond_min
    real(dp), intent(inout) :: state(2 + 3*n)
    real(dp), intent(out) :: zf(n, ns), zdf(n, ns), zddf(n, ns), lamf(nrow, ns), jqf(3, nj, ns), dvf(nd, ns)
    integer, intent(out) :: nvalid, status
    real(dp), intent(out) :: fail_t, rcond_low
    type(mbs_system) :: sys
    zf = 0.0_dp; zdf = 0.0_dp; zddf = 0.0_dp; lamf = 0.0_dp; jqf = 0.0_dp; dvf = 0.0_dp
    nvalid = 0; fail_t = 0.0_dp; rcond_low = 0.0_dp
    call build_checked(ispec, rspec, n, nrow, nj, sys, status)
    if (status /= STATUS_OK) return
    if (sys%nd > nd) then      ! nd = max(drives, 1): f2py passes no empty arrays
      status = STATUS_BAD_INPUT
      return
    end if
    call kinematic_samples(sys, ts, state, tol, rcond_min, zf, zdf, zddf, lamf, jqf, dvf(1:sys%nd, :), nvalid, status, &
                           fail_t, rcond_low)
  end subroutine mbs_kinematic

  !> Start the dynamic mode at (t0, z0, zd0): state (nst = mbs_state_size(n)).
  subroutine mbs_dynamic_start(ni, nr, n, nst, ispec, rspec, t0, z0, zd0, rtol, atol, hmax, tol, state, status)
    integer, intent(in) :: ni, nr, n, nst
    integer, intent(in) :: ispec(ni)
    real(dp), intent(in) :: rspec(nr), t0, z0(n), zd0(n), rtol, atol, hmax, tol
    real(dp), intent(out) :: state(nst)
    integer, intent(out) :: status
    type(mbs_system) :: sys
    state = 0.0_dp
    call build_checked(ispec, rspec, n, -1, -1, sys, status)
    if (status /= STATUS_OK) return
    if (nst /= ode_state_size(2*n)) then
      status = STATUS_BAD_INPUT
      return
    end if
    call dynamic_start(sys, t0, z0, zd0, rtol, atol, hmax, tol, state, status)
  end subroutine mbs_dynamic_start

  !> Dynamic mode at times ts, continuing from state (see flexmech_motion: dynamic_samples).
  subroutine mbs_dynamic(ni, nr, n, nrow, nj, nd, ns, nst, ispec, rspec, ts, state, hmax, tol, gram_min, zf, zdf, &
                         zddf, lamf, jqf, dvf, nvalid, status, fail_t, rcond_low)
    integer, intent(in) :: ni, nr, n, nrow, nj, nd, ns, nst
    integer, intent(in) :: ispec(ni)
    real(dp), intent(in) :: rspec(nr), ts(ns), hmax, tol, gram_min
    real(dp), intent(inout) :: state(nst)
    real(dp), intent(out) :: zf(n, ns), zdf(n, ns), zddf(n, ns), lamf(nrow, ns), jqf(3, nj, ns), dvf(nd, ns)
    integer, intent(out) :: nvalid, status
    real(dp), intent(out) :: fail_t, rcond_low
    type(mbs_system) :: sys
    zf = 0.0_dp; zdf = 0.0_dp; zddf = 0.0_dp; lamf = 0.0_dp; jqf = 0.0_dp; dvf = 0.0_dp
    nvalid = 0; fail_t = 0.0_dp; rcond_low = 0.0_dp
    call build_checked(ispec, rspec, n, nrow, nj, sys, status)
    if (status /= STATUS_OK) return
    if (nst /= ode_state_size(2*n) .or. sys%nd > nd) then
      status = STATUS_BAD_INPUT
      return
    end if
    call dynamic_samples(sys, ts, state, hmax, tol, gram_min, zf, zdf, zddf, lamf, jqf, dvf(1:sys%nd, :), nvalid, &
                         status, fail_t, rcond_low)
  end subroutine mbs_dynamic

  !> Length of the controlled dynamic mode's state for n coordinates and nc controllers: the
  !> integrator's (states [z, zd, I, W]) and the controllers' reference starts.
  subroutine mbs_controlled_state_size(n, nc, nst)
    integer, intent(in) :: n, nc
    integer, intent(out) :: nst
    nst = ode_state_size(2*n + nc + 1) + nc
  end subroutine mbs_controlled_state_size

  !> Build the system with its collocated controllers (flexmech_mbs_control; layout: flexmech_control,
  !> cint(1, :) the index among the force drives); STATUS_BAD_INPUT when a controller is not one the
  !> rigid-body integration can close.
  subroutine build_controlled(ispec, rspec, n, nrow, nj, cint, cpar, ctab_t, ctab_c, h, sys, status)
    integer, intent(in) :: ispec(:), n, nrow, nj, cint(:, :)
    real(dp), intent(in) :: rspec(:), cpar(:, :), ctab_t(:), ctab_c(:, :), h
    type(mbs_controlled), intent(out) :: sys
    integer, intent(out) :: status
    real(dp), allocatable :: cst(:, :)
    logical :: ok
    call build_checked(ispec, rspec, n, nrow, nj, sys%mbs_system, status)
    if (status /= STATUS_OK) return
    allocate (cst(CTL_NST, size(cint, 2)))
    cst = 0.0_dp
    call controlled_setup(sys, cint, cpar, ctab_t, ctab_c, cst, h, ok)
    if (.not. ok .or. sys%nc /= size(cint, 2)) status = STATUS_BAD_INPUT
  end subroutine build_controlled

  !> Start the controlled dynamic mode at (t0, z0, zd0) with the integrals x0, the drives' work w0 [J]
  !> and the references' starts start (NaN: the measured coordinate, a fresh run): state
  !> (mbs_controlled_state_size).
  subroutine mbs_controlled_start(ni, nr, n, nc, nt, nst, ispec, rspec, cint, cpar, ctab_t, ctab_c, h, t0, z0, zd0, &
                                  x0, w0, start, rtol, atol, hmax, tol, state, status)
    integer, intent(in) :: ni, nr, n, nc, nt, nst
    integer, intent(in) :: ispec(ni), cint(12, nc)
    real(dp), intent(in) :: rspec(nr), cpar(17, nc), ctab_t(nt), ctab_c(4, nt), h, t0, z0(n), zd0(n), x0(nc), &
                            w0, start(nc), rtol, atol, hmax, tol
    real(dp), intent(out) :: state(nst)
    integer, intent(out) :: status
    type(mbs_controlled) :: sys
    state = 0.0_dp
    call build_controlled(ispec, rspec, n, -1, -1, cint, cpar, ctab_t, ctab_c, h, sys, status)
    if (status /= STATUS_OK) return
    if (nst /= ode_state_size(2*n + nc + 1) + nc) then
      status = STATUS_BAD_INPUT
      return
    end if
    call controlled_start(sys, t0, z0, zd0, start)
    call dynamic_start(sys, t0, z0, zd0, rtol, atol, hmax, tol, state(1:nst - nc), status, [x0, w0])
    state(nst - nc + 1:) = sys%cb%st(CTL_REF_START, :)
  end subroutine mbs_controlled_start

  !> Controlled dynamic mode at times ts, continuing from state (see flexmech_motion: dynamic_samples):
  !> dvf includes the controllers' outputs, uf (nc, ns) the outputs, xf (nc + 1, ns) the integrals and
  !> the drives' work [J].
  subroutine mbs_controlled_dynamic(ni, nr, n, nrow, nj, nd, nc, nt, ns, nst, ispec, rspec, cint, cpar, ctab_t, &
                                    ctab_c, h, ts, state, hmax, tol, gram_min, zf, zdf, zddf, lamf, jqf, dvf, uf, xf, &
                                    nvalid, status, fail_t, rcond_low)
    integer, intent(in) :: ni, nr, n, nrow, nj, nd, nc, nt, ns, nst
    integer, intent(in) :: ispec(ni), cint(12, nc)
    real(dp), intent(in) :: rspec(nr), cpar(17, nc), ctab_t(nt), ctab_c(4, nt), h, ts(ns), hmax, tol, gram_min
    real(dp), intent(inout) :: state(nst)
    real(dp), intent(out) :: zf(n, ns), zdf(n, ns), zddf(n, ns), lamf(nrow, ns), jqf(3, nj, ns), dvf(nd, ns), &
                             uf(nc, ns), xf(nc + 1, ns)
    integer, intent(out) :: nvalid, status
    real(dp), intent(out) :: fail_t, rcond_low
    type(mbs_controlled) :: sys
    zf = 0.0_dp; zdf = 0.0_dp; zddf = 0.0_dp; lamf = 0.0_dp; jqf = 0.0_dp; dvf = 0.0_dp; uf = 0.0_dp; xf = 0.0_dp
    nvalid = 0; fail_t = 0.0_dp; rcond_low = 0.0_dp
    call build_controlled(ispec, rspec, n, nrow, nj, cint, cpar, ctab_t, ctab_c, h, sys, status)
    if (status /= STATUS_OK) return
    if (nst /= ode_state_size(2*n + nc + 1) + nc .or. sys%nd > nd) then
      status = STATUS_BAD_INPUT
      return
    end if
    sys%cb%st(CTL_REF_START, :) = state(nst - nc + 1:)
    call dynamic_samples(sys, ts, state(1:nst - nc), hmax, tol, gram_min, zf, zdf, zddf, lamf, jqf, dvf(1:sys%nd, :), &
                         nvalid, status, fail_t, rcond_low, uf, xf)
  end subroutine mbs_controlled_dynamic

end module flexmech_mbs_api
