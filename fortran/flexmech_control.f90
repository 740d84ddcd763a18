!> Feedback controllers evaluated inside the time loops (docs/theory.md section 23): a PID law on the
!> error between a reference trajectory r(t) (any kinematic law of flexmech_drivelaw) and a measured
!> joint coordinate y and its rate y' (collocated: the coordinate of the force drive the controller
!> acts through), with a feedforward spline ff(t), output limits [umin, umax] and anti-windup by
!> clamping (conditional integration: the integral does not grow while the output is saturated and
!> the error pushes it further into the limit).
!>
!> Discrete-time law (h = the run's step dt; s >= 1 steps per sample; m >= 0 steps of measurement delay):
!>   continuous (s = 0, m = 0), implicit in the step's state:
!>     u(t_n+1) = sat(ff + kp e + kd e' + ki (I_n + h e)),  e = r(t_n+1) - y_n+1,  e' = r' - y'_n+1
!>     I_n+1 = I_n + h e   unless clamped
!>   sampled (s >= 1) or delayed (m >= 1; then s >= 1): at the sample instants t_k (every s steps, and t0)
!>     u_k = sat(ff(t_k) + kp e_k + kd e'_k + ki I_k) from the measurement m steps back,
!>     I_k+1 = I_k + s h e_k   unless clamped;   u held constant (zero-order hold) until the next sample.
!> Units: u [N m or N]; kp [u/rad or u/m], ki [u/(rad s)], kd [u s/rad]; y [rad or m].
!>
!> Flat description (plain arrays across f2py; padding controllers have drive index 0 and are skipped):
!>   cint(NCI, nctl) = [drive (force drive it adds to, 1-based), reference law kind, reference table
!>                      first knot, knots (0: none), feedforward table first knot, knots, s, m,
!>                      1: an angle (the error wrapped to (-pi, pi]: a joint that turns whole revolutions),
!>                      measured row: kind (0: the drive's own coordinate, collocated; else a row kind of
!>                      flexmech_markers, non-collocated), its markers a, b]
!>   cpar(NCP, nctl) = [kp, ki, kd, umin, umax, reference par(4) (flexmech_drivelaw layout),
!>                      shaper amplitudes A(3), times t(3) [s]]: the reference is sum_i A_i r0(t - t_i)
!>                      (r0 the law; before its start, t - t_i < 0, its value at 0 at rest); no shaper:
!>                      A = [1, 0, 0], t = [0, 0, 0]; the measured row's direction d(2) (a's frame)]
!>   ctab_t(nt), ctab_c(4, nt): the splines of the reference and feedforward tables
!>   cst(NST, nctl) = [I, u (the output now), steps since the start, ring head, the reference's start,
!>                     measurement ring (2, 0:MAXDELAY)]
!> A reference start (par(1); a harmonic law's mean) given as NaN is the joint coordinate measured at
!> the run's start (the mechanism starts where the reference does).
module flexmech_control
  use, intrinsic :: ieee_arithmetic, only: ieee_is_finite, ieee_is_nan
  use flexmech_kinds, only: dp
  use flexmech_drivelaw, only: kinematic_law, spline_eval, LAW_HARMONIC
  implicit none
  private
  public :: control_bank, ctl_setup, ctl_output, ctl_slopes, ctl_start, ctl_commit, ctl_save, ctl_places, ctl_active
  public :: ctl_law, CTL_REF_START
  public :: CTL_NCI, CTL_NCP, CTL_NST, CTL_MAXDELAY

  integer, parameter :: CTL_NCI = 12, CTL_NCP = 17, CTL_MAXDELAY = 2000
  integer, parameter :: HEAD = 4, START = 5, RING = 6
  integer, parameter :: CTL_REF_START = START   !< the place of the reference's start in a controller's state
  integer, parameter :: CTL_NST = RING - 1 + 2*(CTL_MAXDELAY + 1)

  !> The controllers of a run and their state.
  type :: control_bank
    integer :: n = 0
    real(dp) :: h = 0.0_dp                    !< the run's step [s]
    integer, allocatable :: ci(:, :)          !< (CTL_NCI, n)
    real(dp), allocatable :: cp(:, :)         !< (CTL_NCP, n)
    real(dp), allocatable :: tt(:), tc(:, :)  !< the tables' splines
    real(dp), allocatable :: st(:, :)         !< (CTL_NST, n)
  end type control_bank

contains

  !> Copy the flat description (controllers with drive index 0 left out); ok false on bad input
  !> (indices outside the tables, s < 0, m outside 0..CTL_MAXDELAY, a delay without a sample, h <= 0).
  subroutine ctl_setup(cb, cint, cpar, ctab_t, ctab_c, cst, h, nd, ok)
    type(control_bank), intent(out) :: cb
    integer, intent(in) :: cint(:, :), nd
    real(dp), intent(in) :: cpar(:, :), ctab_t(:), ctab_c(:, :), cst(:, :), h
    logical, intent(out) :: ok
    integer :: j, nt
    integer, allocatable :: idx(:)
    ok = size(cint, 1) == CTL_NCI .and. size(cpar, 1) == CTL_NCP .and. size(cst, 1) == CTL_NST .and. &
         size(cpar, 2) == size(cint, 2) .and. size(cst, 2) == size(cint, 2) .and. h > 0.0_dp
    if (.not. ok) return
    idx = ctl_places(cint)
    cb%n = size(idx); cb%h = h
    cb%ci = cint(:, idx)
    cb%cp = cpar(:, idx)
    cb%st = cst(:, idx)
    cb%tt = ctab_t; cb%tc = ctab_c
    nt = size(ctab_t)
    do j = 1, cb%n
      associate (c => cb%ci(:, j))
        ok = ok .and. c(1) <= nd .and. c(7) >= 0 .and. c(8) >= 0 .and. c(8) <= CTL_MAXDELAY .and. &
             (c(8) == 0 .or. c(7) >= 1) .and. all(c(3:6) >= 0) .and. c(3) + c(4) - 1 <= nt .and. &
             c(5) + c(6) - 1 <= nt .and. (c(4) == 0 .or. c(4) >= 2) .and. (c(6) == 0 .or. c(6) >= 2)
        ok = ok .and. all(ieee_is_finite(cb%cp([1, 2, 3, 7, 8, 9, 10, 11, 12, 13, 14, 15, 16, 17], j))) .and. &
             cb%cp(4, j) <= cb%cp(5, j)
      end associate
    end do
  end subroutine ctl_setup

  !> Whether the bank has controllers.
  pure logical function ctl_active(cb)
    type(control_bank), intent(in) :: cb
    ctl_active = cb%n > 0
  end function ctl_active

  !> The state back into the flat array (the caller's copy, for a continued run).
  subroutine ctl_save(cb, cint, cst)
    type(control_bank), intent(in) :: cb
    integer, intent(in) :: cint(:, :)
    real(dp), intent(inout) :: cst(:, :)
    cst(:, ctl_places(cint)) = cb%st
  end subroutine ctl_save

  !> The places in the flat layout of the active controllers (drive index > 0), in the bank's order.
  pure function ctl_places(cint) result(idx)
    integer, intent(in) :: cint(:, :)
    integer, allocatable :: idx(:)
    integer :: k
    idx = pack([(k, k = 1, size(cint, 2))], cint(1, :) > 0)
  end function ctl_places

  !> [r, r', r''] of controller j's reference and ff(t), at time t [s].
  pure subroutine reference(cb, j, t, r, ff)
    type(control_bank), intent(in) :: cb
    integer, intent(in) :: j
    real(dp), intent(in) :: t
    real(dp), intent(out) :: r(3), ff
    integer :: k, nk, i
    real(dp) :: f(3)
    r = 0.0_dp
    do i = 1, 3                        ! the shaper's impulses (one of amplitude 1 at 0 without one)
      if (cb%cp(9 + i, j) == 0.0_dp) cycle
      if (t - cb%cp(12 + i, j) >= 0.0_dp) then
        r = r + cb%cp(9 + i, j)*law_at(cb, j, t - cb%cp(12 + i, j))
      else
        f = law_at(cb, j, 0.0_dp)
        r(1) = r(1) + cb%cp(9 + i, j)*f(1)
      end if
    end do
    ff = 0.0_dp
    k = cb%ci(5, j); nk = cb%ci(6, j)
    if (nk > 0) then
      f = spline_eval(cb%tt(k:k + nk - 1), cb%tc(:, k:k + nk - 1), t)
      ff = f(1)
    end if
  end subroutine reference

  !> [r0, r0', r0''] of controller j's reference law (unshaped) at time t [s].
  pure function law_at(cb, j, t) result(r)
    type(control_bank), intent(in) :: cb
    integer, intent(in) :: j
    real(dp), intent(in) :: t
    real(dp) :: r(3), par(4)
    integer :: k, nk
    par = cb%cp(6:9, j)
    if (ieee_is_nan(par(1))) par(1) = cb%st(START, j)
    k = cb%ci(3, j); nk = cb%ci(4, j)
    if (nk > 0) then
      r = kinematic_law(cb%ci(2, j), par, cb%tt(k:k + nk - 1), cb%tc(:, k:k + nk - 1), t)
    else
      r = kinematic_law(cb%ci(2, j), par, cb%tt(1:0), cb%tc(:, 1:0), t)
    end if
  end function law_at

  !> The error r - y of controller j (wrapped to (-pi, pi] for an angle).
  pure real(dp) function error(cb, j, r, y) result(e)
    type(control_bank), intent(in) :: cb
    integer, intent(in) :: j
    real(dp), intent(in) :: r, y
    real(dp), parameter :: two_pi = 6.283185307179586476925286766559_dp
    e = r - y
    if (cb%ci(9, j) == 1) e = e - two_pi*anint(e/two_pi)
  end function error

  !> Saturated output and whether the integral may grow: the raw law ur clamped to [umin, umax];
  !> integrate false when clamped and the error e pushes further into the limit.
  pure subroutine saturate(cb, j, ur, e, u, integrate)
    type(control_bank), intent(in) :: cb
    integer, intent(in) :: j
    real(dp), intent(in) :: ur, e
    real(dp), intent(out) :: u
    logical, intent(out) :: integrate
    u = min(max(ur, cb%cp(4, j)), cb%cp(5, j))
    integrate = .not. ((ur > cb%cp(5, j) .and. e*cb%cp(2, j) > 0.0_dp) .or. &
                       (ur < cb%cp(4, j) .and. e*cb%cp(2, j) < 0.0_dp))
  end subroutine saturate

  !> Output [N m or N] of controller j with its measured signal y and rate yd at time t: the continuous
  !> law at this state, or the output held since the last sample.
  pure real(dp) function ctl_output(cb, j, y, yd, t) result(u)
    type(control_bank), intent(in) :: cb
    integer, intent(in) :: j
    real(dp), intent(in) :: y, yd, t
    real(dp) :: e
    logical :: integ
    if (cb%ci(7, j) == 0) then
      call continuous_law(cb, j, y, yd, t, u, e, integ)
    else
      u = cb%st(2, j)
    end if
  end function ctl_output

  !> Derivatives of controller j's output with respect to its measured signal and rate at (y, yd, t),
  !> for the Newton iteration matrix (docs/theory.md 23.2): the continuous law off its limits gives
  !> du/dy = -(kp + ki h) (ki h only while the integral grows: backward Euler) and du/dy' = -kd; a
  !> sampled or delayed law (held output) or a saturated one gives zero.
  pure subroutine ctl_slopes(cb, j, y, yd, t, dudy, dudyd)
    type(control_bank), intent(in) :: cb
    integer, intent(in) :: j
    real(dp), intent(in) :: y, yd, t
    real(dp), intent(out) :: dudy, dudyd
    real(dp) :: u, e
    logical :: integ
    dudy = 0.0_dp; dudyd = 0.0_dp
    if (cb%ci(7, j) /= 0) return
    call continuous_law(cb, j, y, yd, t, u, e, integ)
    if (u <= cb%cp(4, j) .or. u >= cb%cp(5, j)) return
    dudy = -cb%cp(1, j)
    if (integ) dudy = dudy - cb%cp(2, j)*cb%h
    dudyd = -cb%cp(3, j)
  end subroutine ctl_slopes

  !> The continuous law of controller j at (y, yd, t): output u, error e, whether I may grow.
  pure subroutine continuous_law(cb, j, y, yd, t, u, e, integrate)
    type(control_bank), intent(in) :: cb
    integer, intent(in) :: j
    real(dp), intent(in) :: y, yd, t
    real(dp), intent(out) :: u, e
    logical, intent(out) :: integrate
    call pid_law(cb, j, y, yd, t, cb%st(1, j), cb%h, u, e, integrate)
  end subroutine continuous_law

  !> The continuous-time law of controller j with its integral I given (the superposition models carry
  !> I as a state of their rigid-body integration, I' = e while integrate, docs/theory.md 23.3):
  !>   u = sat(ff + kp e + kd e' + ki I),  integrate false when clamped and e pushes further into the limit.
  pure subroutine ctl_law(cb, j, y, yd, t, integral, u, e, integrate)
    type(control_bank), intent(in) :: cb
    integer, intent(in) :: j
    real(dp), intent(in) :: y, yd, t, integral
    real(dp), intent(out) :: u, e
    logical, intent(out) :: integrate
    call pid_law(cb, j, y, yd, t, integral, 0.0_dp, u, e, integrate)
  end subroutine ctl_law

  !> The law of controller j at (y, yd, t) from the integral i0 extended by the step h with the new
  !> error (backward Euler; h = 0: the integral as given): output u, error e, whether I may grow.
  pure subroutine pid_law(cb, j, y, yd, t, i0, h, u, e, integrate)
    type(control_bank), intent(in) :: cb
    integer, intent(in) :: j
    real(dp), intent(in) :: y, yd, t, i0, h
    real(dp), intent(out) :: u, e
    logical, intent(out) :: integrate
    real(dp) :: r(3), ff, ur
    call reference(cb, j, t, r, ff)
    e = error(cb, j, r(1), y)
    ur = ff + cb%cp(1, j)*e + cb%cp(3, j)*(r(2) - yd) + cb%cp(2, j)*(i0 + h*e)
    call saturate(cb, j, ur, e, u, integrate)
    if (.not. integrate) then
      ur = ff + cb%cp(1, j)*e + cb%cp(3, j)*(r(2) - yd) + cb%cp(2, j)*i0
      u = min(max(ur, cb%cp(4, j)), cb%cp(5, j))
    end if
  end subroutine pid_law

  !> A fresh start at t0 with the measurements y(:), yd(:) (per controller j): integral zero, the
  !> delay ring filled with the initial measurement, the first sample taken.
  subroutine ctl_start(cb, t0, y, yd)
    type(control_bank), intent(inout) :: cb
    real(dp), intent(in) :: t0, y(:), yd(:)
    integer :: j, k
    do j = 1, cb%n
      cb%st(:, j) = 0.0_dp
      cb%st(START, j) = y(j)          ! (read only where the reference's start is NaN)
      if (cb%ci(2, j) == LAW_HARMONIC) cb%st(START, j) = y(j) - cb%cp(7, j)*sin(cb%cp(9, j))
      do k = 0, CTL_MAXDELAY
        cb%st(RING + 2*k, j) = y(j); cb%st(RING + 2*k + 1, j) = yd(j)
      end do
      call take_sample(cb, j, t0, y(j), yd(j))
    end do
  end subroutine ctl_start

  !> After an accepted step to time t with the measurements y(:), yd(:): the integral of the
  !> continuous law, the delay ring, and a new held output at a sample instant.
  subroutine ctl_commit(cb, t, y, yd)
    type(control_bank), intent(inout) :: cb
    real(dp), intent(in) :: t, y(:), yd(:)
    integer :: j, hd
    real(dp) :: u, e
    logical :: integ
    do j = 1, cb%n
      cb%st(3, j) = cb%st(3, j) + 1.0_dp
      hd = mod(nint(cb%st(HEAD, j)) + 1, CTL_MAXDELAY + 1)
      cb%st(HEAD, j) = real(hd, dp)
      cb%st(RING + 2*hd, j) = y(j); cb%st(RING + 2*hd + 1, j) = yd(j)
      if (cb%ci(7, j) == 0) then
        call continuous_law(cb, j, y(j), yd(j), t, u, e, integ)
        cb%st(2, j) = u
        if (integ) cb%st(1, j) = cb%st(1, j) + cb%h*e
      else if (mod(nint(cb%st(3, j)), cb%ci(7, j)) == 0) then
        hd = modulo(hd - cb%ci(8, j), CTL_MAXDELAY + 1)
        call take_sample(cb, j, t, cb%st(RING + 2*hd, j), cb%st(RING + 2*hd + 1, j))
      end if
    end do
  end subroutine ctl_commit

  !> Sample of controller j at t from the measurement (ym, ydm): the held output and the integral.
  subroutine take_sample(cb, j, t, ym, ydm)
    type(control_bank), intent(inout) :: cb
    integer, intent(in) :: j
    real(dp), intent(in) :: t, ym, ydm
    real(dp) :: r(3), ff, e, u
    logical :: integ
    if (cb%ci(7, j) == 0) then          ! continuous: the output at the start state
      call continuous_law(cb, j, ym, ydm, t, u, e, integ)
      cb%st(2, j) = u
      return
    end if
    call reference(cb, j, t, r, ff)
    e = error(cb, j, r(1), ym)
    call saturate(cb, j, ff + cb%cp(1, j)*e + cb%cp(3, j)*(r(2) - ydm) + cb%cp(2, j)*cb%st(1, j), e, u, integ)
    cb%st(2, j) = u
    if (integ) cb%st(1, j) = cb%st(1, j) + cb%ci(7, j)*cb%h*e
  end subroutine take_sample

end module flexmech_control
