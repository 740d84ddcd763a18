!> Rigid-body motion of a mechanism sampled at requested times, continuing from a stored state so a
!> long run is sampled chunk by chunk in bounded memory (docs/theory.md section 17.3-17.4).
!>
!> Kinematic mode (every degree of freedom driven): at each sample the square position equations are
!> solved by Newton from the previous sample extrapolated to second order; velocities, accelerations
!> and multipliers follow from the Jacobian.  The motion stops at a singular position when the scaled
!> Jacobian's pivot ratio falls below rcond_min, when its determinant changes sign between two samples
!> (the motion crossed a singular position), or when Newton's correction of the extrapolated guess is
!> more than 1e-3 (rad, or lref) and more than half of the step's own motion while the extrapolation
!> predicted a motion of its own (a jump to another assembly branch at a change point, where the
!> velocities extrapolated from the near-singular configuration are wrong; on a resolved motion the
!> correction is about 1e-7 of the step at the seed cases' steps, and a start from rest, whose
!> extrapolation predicts no motion, is not mistaken for a jump).
!> State: [t_prev, det sign (0: none yet), z(n), zd(n), zdd(n)].
!> Dynamic mode (free degrees of freedom): the index-1 equations M z'' + Phi_z^T lam = Q, Phi_z z'' = gamma
!> integrated by flexmech_ode; after every accepted step (z, zd) are projected back onto the position
!> and velocity constraints (so they hold to the projection tolerance over any run length) and the
!> constraint Jacobian's conditioning is checked.  Samples come from the dense output, with the
!> accelerations and multipliers solved at the sampled state.  State: the packed flexmech_ode state.
!> Outputs per sample: z, zd, zdd (n), lam (nrow), the joint coordinates jq (3, nj) and the drives'
!> generalized forces dvf (nd) (flexmech_mbs: mbs_drive_values).
module flexmech_motion
  use flexmech_kinds, only: dp
  use flexmech_lapack, only: STATUS_OK, STATUS_BAD_INPUT, STATUS_SINGULAR_POSITION, STATUS_NONFINITE
  use flexmech_mbs, only: mbs_system, mbs_accelerations, mbs_joint_coordinates, mbs_constraints, mbs_drive_values, &
                          mbs_drive_change
  use flexmech_mbs_solve, only: mbs_kinematic_sample, mbs_project, mbs_gram_rcond
  use flexmech_ode, only: ode_state, ode_start, ode_step, ode_dense, ode_pack, ode_unpack, ODE_OK
  use flexmech_mbs_control, only: mbs_controlled, controlled_eval
  implicit none
  private
  public :: kinematic_samples, dynamic_start, dynamic_samples, POSITION_MAXIT

  integer, parameter :: POSITION_MAXIT = 25   !< Newton iterations allowed for positions and projections
  real(dp), parameter :: MAX_SUBSTEP_CHANGE = 0.05_dp   !< largest motion of a kinematic substep (rad, or lref)
  integer, parameter :: MAX_SUBSTEPS = 1000000          !< kinematic substeps allowed between two samples

contains

  !> Kinematic mode at the increasing times ts.  rcond_min: the scaled Jacobian's reciprocal condition
  !> below which the position is singular.  nvalid samples are valid; on failure status /= 0 and fail_t
  !> is the time of the sample that failed.  rcond_low: the smallest rcond met.
  subroutine kinematic_samples(sys, ts, state, tol, rcond_min, zf, zdf, zddf, lamf, jqf, dvf, nvalid, status, &
                               fail_t, rcond_low)
    type(mbs_system), intent(inout) :: sys
    real(dp), intent(in) :: ts(:), tol, rcond_min
    real(dp), intent(inout) :: state(:)      !< (2 + 3n) [t_prev, det sign, z, zd, zdd]
    real(dp), intent(out) :: zf(:, :), zdf(:, :), zddf(:, :), lamf(:, :), jqf(:, :, :), dvf(:, :)
    integer, intent(out) :: nvalid, status
    real(dp), intent(out) :: fail_t, rcond_low
    real(dp) :: z(sys%n), zd(sys%n), zdd(sys%n), lam(sys%nrow), scale(sys%n)
    integer :: i, n
    n = sys%n
    scale = 1.0_dp/sys%lref
    scale(3:n:3) = 1.0_dp     ! angles in rad, positions in units of the mechanism's length
    nvalid = 0; fail_t = 0.0_dp; rcond_low = huge(1.0_dp)
    status = STATUS_OK
    if (sys%nrow /= n .or. size(state) /= 2 + 3*n) then
      status = STATUS_BAD_INPUT
      return
    end if
    do i = 1, size(ts)
      call advance(sys, ts(i), state, tol, rcond_min, scale, z, zd, zdd, lam, rcond_low, status)
      if (status /= STATUS_OK) then
        fail_t = ts(i)
        return
      end if
      zf(:, i) = z; zdf(:, i) = zd; zddf(:, i) = zdd; lamf(:, i) = lam
      call mbs_joint_coordinates(sys, zdd, ts(i), jqf(:, :, i))     ! advance left the constraints at (z, zd)
      call mbs_drive_values(sys, ts(i), lam, dvf(:, i))
      nvalid = i
    end do

  end subroutine kinematic_samples

  !> From the state to time tn in substeps, each short enough that neither the second-order
  !> extrapolation of any coordinate from the last solution nor the kinematic drives' prescribed
  !> coordinates move more than MAX_SUBSTEP_CHANGE (rad, or lref for positions), so Newton follows
  !> the assembly branch however far apart the samples are (a start from rest, whose rates predict no
  !> motion, is stepped by the drive laws); a substep that crosses a singular position stops the
  !> motion (see the module's header).  scale: 1/lref for positions, 1 for angles; (z, zd, zdd, lam)
  !> the solution at tn; rcond_low: the smallest rcond met so far.
  subroutine advance(sys, tn, state, tol, rcond_min, scale, z, zd, zdd, lam, rcond_low, stat)
    type(mbs_system), intent(inout) :: sys
    real(dp), intent(in) :: tn, tol, rcond_min, scale(:)
    real(dp), intent(inout) :: state(:), rcond_low
    real(dp), intent(out) :: z(:), zd(:), zdd(:), lam(:)
    integer, intent(out) :: stat
    real(dp) :: tk, h, guess(sys%n), corr, moved, predicted, rc
    integer :: k, dsign, n
    n = sys%n
    stat = STATUS_OK
    do k = 1, MAX_SUBSTEPS
      h = substep(sys, state, scale, tn - state(1))
      tk = state(1) + h
      if (tn - tk <= 1e-12_dp*max(1.0_dp, abs(tn))) tk = tn
      h = tk - state(1)
      guess = state(3:2 + n) + h*state(3 + n:2 + 2*n) + (0.5_dp*h*h)*state(3 + 2*n:2 + 3*n)
      z = guess
      call mbs_kinematic_sample(sys, z, tk, tol, POSITION_MAXIT, rcond_min, zd, zdd, lam, rc, dsign, stat)
      rcond_low = min(rcond_low, rc)
      if (stat /= STATUS_OK) return
      if (nint(state(2)) /= 0) then
        corr = maxval(abs(z - guess)*scale)
        moved = maxval(abs(z - state(3:2 + n))*scale)
        predicted = maxval(abs(guess - state(3:2 + n))*scale)
        if (dsign /= nint(state(2)) .or. &
            (corr > 1e-3_dp .and. corr > 0.5_dp*moved .and. predicted > 0.1_dp*moved)) then
          stat = STATUS_SINGULAR_POSITION
          return
        end if
      end if
      state = [tk, real(dsign, dp), z, zd, zdd]
      if (tk == tn) return
    end do
    stat = STATUS_SINGULAR_POSITION      ! the substeps shrank without reaching tn
  end subroutine advance

  !> The longest substep from the state, at most hmax_k, that keeps the extrapolated and the
  !> prescribed motion within MAX_SUBSTEP_CHANGE (halving from hmax_k).
  real(dp) function substep(sys, state, scale, hmax_k) result(hs)
    type(mbs_system), intent(in) :: sys
    real(dp), intent(in) :: state(:), scale(:), hmax_k
    real(dp) :: change
    integer :: k, n
    n = sys%n
    hs = hmax_k
    do k = 1, 60
      change = maxval((abs(state(3 + n:2 + 2*n))*abs(hs) + 0.5_dp*abs(state(3 + 2*n:2 + 3*n))*hs*hs)*scale)
      change = max(change, mbs_drive_change(sys, state(1), state(1) + hs))
      if (change <= MAX_SUBSTEP_CHANGE) return
      hs = 0.5_dp*hs
    end do
  end function substep

  !> Start the dynamic mode at (t0, z0, zd0) (projected onto the constraints first): the packed
  !> integrator state in state (length ode_state_size(2n + nx)); x0 (nx): the initial values of the
  !> system's extra states (a controlled system's integrals, flexmech_mbs_control).
  subroutine dynamic_start(sys, t0, z0, zd0, rtol, atol, hmax, tol, state, status, x0)
    class(mbs_system), intent(inout) :: sys
    real(dp), intent(in) :: t0, z0(:), zd0(:), rtol, atol, hmax, tol
    real(dp), intent(out) :: state(:)
    integer, intent(out) :: status
    real(dp), intent(in), optional :: x0(:)
    type(ode_state) :: st
    real(dp) :: z(sys%n), zd(sys%n)
    z = z0; zd = zd0
    call mbs_project(sys, z, zd, t0, tol, POSITION_MAXIT, status)
    if (status /= STATUS_OK) return
    if (present(x0)) then
      call ode_start(sys, t0, [z, zd, x0], rtol, atol, hmax, st, status)
    else
      call ode_start(sys, t0, [z, zd], rtol, atol, hmax, st, status)
    end if
    if (status /= STATUS_OK) return
    call ode_pack(st, state)
  end subroutine dynamic_start

  !> Dynamic mode at the increasing times ts (>= the start of the last step), continuing from state.
  !> gram_min: the Gram matrix's reciprocal condition (about (sigma_min/sigma_max)^2 of the scaled
  !> constraint Jacobian) below which the position is singular.  rcond_low: the smallest value met.
  !> A controlled system (flexmech_mbs_control) adds its controllers' outputs to the drives they act
  !> through in dvf and returns them in uf (nc, ns), and its extra states (the integrals, the drives'
  !> work) in xf (nc + 1, ns).
  subroutine dynamic_samples(sys, ts, state, hmax, tol, gram_min, zf, zdf, zddf, lamf, jqf, dvf, nvalid, status, &
                             fail_t, rcond_low, uf, xf)
    class(mbs_system), intent(inout) :: sys
    real(dp), intent(in) :: ts(:), hmax, tol, gram_min
    real(dp), intent(inout) :: state(:)
    real(dp), intent(out) :: zf(:, :), zdf(:, :), zddf(:, :), lamf(:, :), jqf(:, :, :), dvf(:, :)
    integer, intent(out) :: nvalid, status
    real(dp), intent(out) :: fail_t, rcond_low
    real(dp), intent(out), optional :: uf(:, :), xf(:, :)
    type(ode_state) :: st
    real(dp), allocatable :: y(:)
    real(dp) :: lam(sys%nrow), gr
    integer :: i, n, ost, rst
    n = sys%n
    nvalid = 0; fail_t = 0.0_dp; rcond_low = huge(1.0_dp)
    status = STATUS_OK
    call ode_unpack(state, st)
    if (st%n /= 2*n + extra_states(sys)) then
      status = STATUS_BAD_INPUT
      return
    end if
    do i = 1, size(ts)
      if (ts(i) < st%t_old - 1e-12_dp*max(1.0_dp, abs(ts(i)))) then
        status = STATUS_BAD_INPUT
        exit
      end if
      do while (ts(i) > st%t)
        call ode_step(sys, st, hmax, ost, rst)
        if (ost /= ODE_OK) then   ! the step size collapsed or the augmented system failed: a singularity
          status = STATUS_SINGULAR_POSITION
          if (rst == STATUS_NONFINITE) status = STATUS_NONFINITE
          fail_t = st%t
          exit
        end if
        call settle(status)        ! projection, new f, conditioning
        if (status /= STATUS_OK) then
          fail_t = st%t
          exit
        end if
      end do
      if (status /= STATUS_OK) exit
      y = st%y
      if (ts(i) < st%t) call ode_dense(st, ts(i), y)
      call sample(i, status)
      if (status /= STATUS_OK) then
        fail_t = ts(i)
        exit
      end if
      nvalid = i
    end do
    call ode_pack(st, state)

  contains

    !> Sample i at y (its time ts(i)): accelerations, multipliers, joint coordinates, drive values.
    subroutine sample(i, stat)
      integer, intent(in) :: i
      integer, intent(out) :: stat
      real(dp), allocatable :: u(:), xdot(:)
      integer :: k
      select type (sys)
      type is (mbs_controlled)
        allocate (u(sys%nc), xdot(sys%nc + 1))
        call controlled_eval(sys, ts(i), y, zddf(:, i), lam, u, xdot, stat)
      class default
        call mbs_accelerations(sys, y(1:n), y(n + 1:2*n), ts(i), zddf(:, i), lam, stat)
      end select
      if (stat /= STATUS_OK) return
      zf(:, i) = y(1:n); zdf(:, i) = y(n + 1:2*n); lamf(:, i) = lam
      call mbs_joint_coordinates(sys, zddf(:, i), ts(i), jqf(:, :, i))     ! at y, as the accelerations
      call mbs_drive_values(sys, ts(i), lam, dvf(:, i))
      select type (sys)
      type is (mbs_controlled)
        do k = 1, sys%nc
          dvf(sys%drive(k), i) = dvf(sys%drive(k), i) + u(k)
        end do
        if (present(uf)) uf(1:sys%nc, i) = u
        if (present(xf)) xf(1:sys%nc + 1, i) = y(2*n + 1:)
      end select
    end subroutine sample

    subroutine settle(stat)
      integer, intent(out) :: stat
      real(dp) :: z(n), zd(n)
      z = st%y(1:n); zd = st%y(n + 1:2*n)
      call mbs_project(sys, z, zd, st%t, tol, 3, stat)
      if (stat /= STATUS_OK) return
      st%y(1:2*n) = [z, zd]
      call sys%rhs(st%t, st%y, st%f, stat)        ! leaves the constraints evaluated at the new point
      if (stat /= STATUS_OK) return
      gr = mbs_gram_rcond(sys)
      rcond_low = min(rcond_low, gr)
      if (gr < gram_min) stat = STATUS_SINGULAR_POSITION
    end subroutine settle

  end subroutine dynamic_samples

  !> States of the integration beyond [z, zd]: a controlled system's integrals and work, none otherwise.
  integer function extra_states(sys) result(nx)
    class(mbs_system), intent(in) :: sys
    nx = 0
    select type (sys)
    type is (mbs_controlled)
      nx = sys%nc + 1
    end select
  end function extra_states

end module flexmech_motion
