!> Collocated feedback controllers closed inside the rigid-body dynamics (docs/theory.md section 23.3):
!> the superposition models integrate the rigid motion first, so a controller that measures its own
!> joint's coordinate g_j and rate g_j' (collocated) closes its loop there.  Its output u_j
!> (flexmech_control: ctl_law, the continuous-time law with limits and clamping anti-windup) is a
!> generalized force u_j dg_j/dz on the coordinate of the force drive it acts through, added to Q of
!>   M z'' + Phi_z^T lambda = Q + sum_j u_j dg_j/dz,   Phi_z z'' = gamma,
!> and its integral I_j is one more state of the integration, I_j' = e_j (0 while clamped); so is the
!> work W of the force drives and controllers on the rigid-body motion, W' = sum_i (tau_i + u_i) g_i'
!> (tau_i a force drive's own law, u_i the outputs acting through it), for the energy balance.
!> State of flexmech_ode: y = [z (n), z' (n), I (nc), W].
!> Controllers are given in flexmech_control's flat layout with cint(1, :) the 1-based index among the
!> system's FORCE drives (kinematic drives not counted); sampled or delayed ones (cint(7:8) /= 0) and
!> non-collocated ones (cint(10) /= 0) are refused (ok false): they are the constrained models'.
module flexmech_mbs_control
  use, intrinsic :: ieee_arithmetic, only: ieee_is_nan
  use flexmech_kinds, only: dp
  use flexmech_lapack, only: STATUS_OK
  use flexmech_drivelaw, only: LAW_FORCE
  use flexmech_markers, only: MAXCOL
  use flexmech_mbs, only: mbs_system, mbs_constraints, mbs_forces, solve_dynamics, joint_coordinate, &
                          mbs_drive_values
  use flexmech_control, only: control_bank, ctl_setup, ctl_law, ctl_start, CTL_REF_START
  implicit none
  private
  public :: mbs_controlled, controlled_setup, controlled_start, controlled_eval

  !> The rigid-body system with its controllers (nc of them; their drives' indices among all drives).
  type, extends(mbs_system) :: mbs_controlled
    integer :: nc = 0
    type(control_bank) :: cb
    integer, allocatable :: drive(:)    !< (nc) the drive (1..nd) each controller acts through
  contains
    procedure :: rhs => controlled_rhs
  end type mbs_controlled

contains

  !> The controllers of sys (its mbs_system part built already) from the flat layout; ok false on bad
  !> input, on a sampled, delayed or non-collocated controller, or on an index past the force drives.
  subroutine controlled_setup(sys, cint, cpar, ctab_t, ctab_c, cst, h, ok)
    type(mbs_controlled), intent(inout) :: sys
    integer, intent(in) :: cint(:, :)
    real(dp), intent(in) :: cpar(:, :), ctab_t(:), ctab_c(:, :), cst(:, :), h
    logical, intent(out) :: ok
    integer, allocatable :: forces(:)
    integer :: k
    forces = pack([(k, k = 1, sys%nd)], sys%dv_kind == LAW_FORCE)
    call ctl_setup(sys%cb, cint, cpar, ctab_t, ctab_c, cst, h, size(forces), ok)
    if (.not. ok) return
    sys%nc = sys%cb%n
    ok = all(sys%cb%ci(7:8, :) == 0) .and. all(sys%cb%ci(10, :) == 0)
    if (.not. ok) return
    sys%drive = forces(sys%cb%ci(1, :))
  end subroutine controlled_setup

  !> The controllers' fresh start at (t0, z, zd): the reference starts (a start given as NaN: the
  !> measured coordinate) then, where start(j) is finite, start(j) instead (a continued run keeps the
  !> start of t = 0).
  subroutine controlled_start(sys, t0, z, zd, start)
    type(mbs_controlled), intent(inout) :: sys
    real(dp), intent(in) :: t0, z(:), zd(:), start(:)
    real(dp) :: y(sys%nc), yd(sys%nc), acc0, grad(2*MAXCOL)
    integer :: j, nc, cols(2*MAXCOL)
    call mbs_constraints(sys%mbs_system, z, zd, t0)            ! (the markers at (z, zd))
    do j = 1, sys%nc
      call joint_coordinate(sys%mbs_system, sys%dv_joint(sys%drive(j)), y(j), yd(j), acc0, nc, cols, grad)
    end do
    call ctl_start(sys%cb, t0, y, yd)
    do j = 1, sys%nc
      if (.not. ieee_is_nan(start(j))) sys%cb%st(CTL_REF_START, j) = start(j)
    end do
  end subroutine controlled_start

  !> At (t, y = [z, zd, I, W]): accelerations zdd, multipliers lam, the controllers' outputs u and the
  !> rates of the extra states xdot = [I' (the error, 0 while clamped), W' (the drives' power)].
  subroutine controlled_eval(sys, t, y, zdd, lam, u, xdot, status)
    type(mbs_controlled), intent(inout) :: sys
    real(dp), intent(in) :: t, y(:)
    real(dp), intent(out) :: zdd(:), lam(:), u(:), xdot(:)
    integer, intent(out) :: status
    real(dp) :: g, gd, acc0, grad(2*MAXCOL), e, dv(sys%nd)
    integer :: i, j, c, nc, cols(2*MAXCOL), n
    logical :: integ
    n = sys%n
    call mbs_constraints(sys%mbs_system, y(1:n), y(n + 1:2*n), t)      ! (the markers at y, for what follows)
    call mbs_forces(sys%mbs_system, t, sys%q)
    do j = 1, sys%nc
      call joint_coordinate(sys%mbs_system, sys%dv_joint(sys%drive(j)), g, gd, acc0, nc, cols, grad)
      call ctl_law(sys%cb, j, g, gd, t, y(2*n + j), u(j), e, integ)
      xdot(j) = merge(e, 0.0_dp, integ)
      do c = 1, nc
        sys%q(cols(c)) = sys%q(cols(c)) + u(j)*grad(c)
      end do
    end do
    call solve_dynamics(sys%mbs_system, zdd, lam, status)
    if (status /= STATUS_OK) return
    call mbs_drive_values(sys%mbs_system, t, lam, dv)
    do j = 1, sys%nc
      dv(sys%drive(j)) = dv(sys%drive(j)) + u(j)
    end do
    xdot(sys%nc + 1) = 0.0_dp
    do i = 1, sys%nd
      if (sys%dv_kind(i) /= LAW_FORCE) cycle
      call joint_coordinate(sys%mbs_system, sys%dv_joint(i), g, gd, acc0, nc, cols, grad)
      xdot(sys%nc + 1) = xdot(sys%nc + 1) + dv(i)*gd
    end do
  end subroutine controlled_eval

  !> Right-hand side for flexmech_ode: y = [z; zd; I], f = [zd; zdd; I'].
  subroutine controlled_rhs(self, t, y, f, status)
    class(mbs_controlled), intent(inout) :: self
    real(dp), intent(in) :: t, y(:)
    real(dp), intent(out) :: f(:)
    integer, intent(out) :: status
    real(dp) :: lam(self%nrow), u(self%nc)
    associate (n => self%n)
      f(1:n) = y(n + 1:2*n)
      call controlled_eval(self, t, y, f(n + 1:2*n), lam, u, f(2*n + 1:), status)
    end associate
  end subroutine controlled_rhs

end module flexmech_mbs_control
