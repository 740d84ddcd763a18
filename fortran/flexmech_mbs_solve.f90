!> Position-level solvers of the rigid-body layer (flexmech_mbs): the projection of a state onto the
!> position and velocity constraints, the kinematic sample (Newton on the square position equations,
!> then velocities, accelerations and multipliers from the Jacobian) and the conditioning of the
!> constraint Jacobian, all scaled to length units by the mechanism's length lref (docs/theory.md
!> section 17).
module flexmech_mbs_solve
  use, intrinsic :: ieee_arithmetic, only: ieee_is_finite
  use flexmech_kinds, only: dp
  use flexmech_lapack, only: STATUS_OK, STATUS_SINGULAR, STATUS_NONFINITE, STATUS_SINGULAR_POSITION, STATUS_ASSEMBLY
  use flexmech_dense, only: lu_factor, lu_solve, pivot_ratio, det_sign
  use flexmech_mbs, only: mbs_system, mbs_constraints, mbs_forces, factor_augmented, solve_augmented
  implicit none
  private
  public :: mbs_project, mbs_residual, mbs_kinematic_sample, mbs_solve_positions, mbs_gram_rcond

contains

  !> Project (z, zd) onto the position and velocity constraints at t (M-orthogonally, with the
  !> augmented matrix): Newton on Phi(z) = 0 until max |phi| <= tol (lengths; angle rows times lref),
  !> then zd onto Phi_z zd = nu.  STATUS_ASSEMBLY when the positions do not converge in maxit.
  subroutine mbs_project(sys, z, zd, t, tol, maxit, status)
    type(mbs_system), intent(inout) :: sys
    real(dp), intent(inout) :: z(:), zd(:)
    real(dp), intent(in) :: t, tol
    integer, intent(in) :: maxit
    integer, intent(out) :: status
    integer :: it
    status = STATUS_OK
    if (sys%nrow == 0) return
    do it = 1, maxit + 1
      call mbs_constraints(sys, z, zd, t)
      if (mbs_residual(sys) <= tol) exit
      if (it > maxit) then
        status = STATUS_ASSEMBLY
        return
      end if
      call factor_augmented(sys, status)
      if (status /= STATUS_OK) return
      sys%sol(1:sys%n) = 0.0_dp
      sys%sol(sys%n + 1:) = -sys%phi
      call solve_augmented(sys, status)
      if (status /= STATUS_OK) return
      z = z + sys%sol(1:sys%n)
    end do
    call factor_augmented(sys, status)
    if (status /= STATUS_OK) return
    sys%sol(1:sys%n) = 0.0_dp
    sys%sol(sys%n + 1:) = sys%nu - matmul(sys%jac(1:sys%nrow, :), zd)
    call solve_augmented(sys, status)
    if (status /= STATUS_OK) return
    zd = zd + sys%sol(1:sys%n)
  end subroutine mbs_project

  !> Largest constraint violation [m] (angle rows scaled by lref) of the last mbs_constraints.
  pure real(dp) function mbs_residual(sys)
    type(mbs_system), intent(in) :: sys
    mbs_residual = 0.0_dp
    if (sys%nrow > 0) mbs_residual = maxval(abs(sys%phi)*sys%rscale)
  end function mbs_residual

  !> Kinematic positions: Newton on the square system Phi(z, t) = 0 (joints and kinematic drives,
  !> nrow = n) from the guess z; then zd, zdd from the Jacobian and lam from Phi_z^T lam = Q - M zdd.
  !> rcond: the pivot ratio of the scaled Jacobian (rotation columns times lref, angle rows times
  !> lref); dsign: the sign of its determinant (a change between neighbouring samples means the motion
  !> crossed a singular position).  STATUS_ASSEMBLY when Newton does not converge,
  !> STATUS_SINGULAR_POSITION when rcond < rcond_min.
  subroutine mbs_kinematic_sample(sys, z, t, tol, maxit, rcond_min, zd, zdd, lam, rcond, dsign, status)
    type(mbs_system), intent(inout) :: sys
    real(dp), intent(inout) :: z(:)
    real(dp), intent(in) :: t, tol, rcond_min
    integer, intent(in) :: maxit
    real(dp), intent(out) :: zd(:), zdd(:), lam(:), rcond
    integer, intent(out) :: dsign, status
    rcond = 0.0_dp
    dsign = 0
    call mbs_solve_positions(sys, z, t, tol, maxit, status)     ! leaves the constraints evaluated at z
    if (status /= STATUS_OK) return
    call square_factor(sys, rcond, status)
    if (status /= STATUS_OK .or. rcond < rcond_min) then
      status = STATUS_SINGULAR_POSITION
      return
    end if
    dsign = det_sign(sys%aug, sys%n, sys%ipiv)
    zd = sys%nu
    call square_solve(sys, zd, 'N', status)
    call mbs_constraints(sys, z, zd, t)                          ! gamma with the velocities (same Jacobian)
    zdd = sys%gam
    call square_solve(sys, zdd, 'N', status)
    call mbs_forces(sys, t, sys%q)
    lam = sys%q
    lam(1:sys%n:3) = lam(1:sys%n:3) - sys%mass*zdd(1:sys%n:3)
    lam(2:sys%n:3) = lam(2:sys%n:3) - sys%mass*zdd(2:sys%n:3)
    lam(3:sys%n:3) = lam(3:sys%n:3) - sys%inertia*zdd(3:sys%n:3)
    call square_solve(sys, lam, 'T', status)
  end subroutine mbs_kinematic_sample

  !> Newton on the square position equations (nrow = n) from z; max |phi| <= tol on return, with the
  !> constraints evaluated at the returned z (zd = 0).
  subroutine mbs_solve_positions(sys, z, t, tol, maxit, status)
    type(mbs_system), intent(inout) :: sys
    real(dp), intent(inout) :: z(:)
    real(dp), intent(in) :: t, tol
    integer, intent(in) :: maxit
    integer, intent(out) :: status
    real(dp) :: zd0(sys%n), dz(sys%n), rc
    integer :: it
    zd0 = 0.0_dp
    status = STATUS_OK
    do it = 1, maxit + 1
      call mbs_constraints(sys, z, zd0, t)
      if (mbs_residual(sys) <= tol) return
      if (it > maxit .or. .not. ieee_is_finite(sum(abs(sys%phi)))) exit
      call square_factor(sys, rc, status)
      if (status /= STATUS_OK) then     ! the Jacobian lost rank on the way: a singular position
        status = STATUS_SINGULAR_POSITION
        return
      end if
      dz = -sys%phi
      call square_solve(sys, dz, 'N', status)
      if (status /= STATUS_OK) exit
      z = z + dz
    end do
    status = STATUS_ASSEMBLY
  end subroutine mbs_solve_positions

  !> LU of the scaled square Jacobian S J D of the last mbs_constraints in sys%aug(1:n, 1:n) (S: angle
  !> rows times lref, D: rotation columns times lref, both in length units); rcond: its pivot ratio
  !> (flexmech_dense), 0 when singular (then STATUS_SINGULAR).
  subroutine square_factor(sys, rcond, status)
    type(mbs_system), intent(inout) :: sys
    real(dp), intent(out) :: rcond
    integer, intent(out) :: status
    integer :: info, n, r
    n = sys%n
    do r = 1, n
      sys%aug(r, 1:n) = sys%rscale(r)*sys%jac(r, :)
    end do
    sys%aug(1:n, 3:n:3) = sys%aug(1:n, 3:n:3)*sys%lref
    call lu_factor(sys%aug, n, sys%ipiv, info)
    rcond = pivot_ratio(sys%aug, n)
    status = STATUS_OK
    if (info > 0) then
      rcond = 0.0_dp
      status = STATUS_SINGULAR
    end if
  end subroutine square_factor

  !> Solve J x = b (trans 'N') or J^T x = b ('T') with square_factor's scaled factors, x overwritten.
  subroutine square_solve(sys, x, trans, status)
    type(mbs_system), intent(inout) :: sys
    real(dp), intent(inout) :: x(:)
    character, intent(in) :: trans
    integer, intent(out) :: status
    integer :: n
    n = sys%n
    if (trans == 'N') then
      x = x*sys%rscale
      call lu_solve(sys%aug, n, sys%ipiv, x, .false.)
      x(3:n:3) = x(3:n:3)*sys%lref
    else
      x(3:n:3) = x(3:n:3)*sys%lref
      call lu_solve(sys%aug, n, sys%ipiv, x, .true.)
      x = x*sys%rscale
    end if
    status = STATUS_OK
    if (.not. ieee_is_finite(sum(abs(x)))) status = STATUS_NONFINITE
  end subroutine square_solve

  !> Pivot ratio of the scaled Gram matrix G = S Phi_z D^2 Phi_z^T S of the last mbs_constraints (S, D as
  !> in square_factor): about (sigma_min / sigma_max)^2 of the scaled constraint Jacobian; 0 when G is
  !> singular.
  function mbs_gram_rcond(sys) result(rcond)
    type(mbs_system), intent(inout) :: sys
    real(dp) :: rcond
    real(dp) :: a(sys%nrow, sys%n), g(sys%nrow, sys%nrow)
    integer :: ipiv(sys%nrow), info, r, m
    m = sys%nrow
    rcond = 1.0_dp
    if (m == 0) return
    do r = 1, m
      a(r, :) = sys%rscale(r)*sys%jac(r, :)
    end do
    a(:, 3:sys%n:3) = a(:, 3:sys%n:3)*sys%lref
    g = matmul(a, transpose(a))
    call lu_factor(g, m, ipiv, info)
    rcond = 0.0_dp
    if (info == 0) rcond = pivot_ratio(g, m)
  end function mbs_gram_rcond

end module flexmech_mbs_solve
