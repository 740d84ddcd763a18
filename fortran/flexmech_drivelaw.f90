!> Drive laws of flexmech: the time law of a kinematically driven joint coordinate and the
!> generalized force (torque or force) of a force drive.  docs/theory.md section 17.
!>
!> A kinematic law gives the joint coordinate f(t) [rad or m] and its first two derivatives:
!>   LAW_CONSTANT_SPEED  par = [start, speed]                 f = start + speed t
!>   LAW_SPINUP          par = [start, final_speed, T]        smooth start from rest, reaching final_speed at
!>                       t = T:  f = start + (w/T)(t^2/2 + (T/2 pi)^2 (cos(2 pi t/T) - 1)) for 0 <= t <= T,
!>                       start + w (t - T/2) after (at rest for t < 0)
!>   LAW_HARMONIC        par = [mean, amplitude, frequency, phase]   f = mean + amplitude sin(frequency t + phase)
!>   LAW_REST_CYCLOIDAL  par = [start, travel, duration T, start time t0]   rest to rest:
!>                       f = start + travel (s - sin(2 pi s)/(2 pi)), s = (t - t0)/T clipped to [0, 1]
!>   LAW_REST_QUINTIC    par as above, f = start + travel (10 s^3 - 15 s^4 + 6 s^5)
!>   LAW_TABLE           a cubic spline through samples (tab_t, tab_c; see spline_eval), held beyond its ends
!>                       by its end polynomials (the Python side checks the run stays inside the table)
!> A force law gives tau(theta, t) [N m or N] = par(1)
!>   + sum_k harm(k) sin(k theta) + harm(nh + k) cos(k theta)          (harmonics of the joint coordinate)
!>   + sum_j th(1, j) sin(th(2, j) t + th(3, j))                        (harmonics of time)
!>   + the spline through (tab_t, tab_c) at t, when the drive has a table.
module flexmech_drivelaw
  use flexmech_kinds, only: dp
  implicit none
  private
  public :: kinematic_law, force_law, spline_eval
  public :: LAW_CONSTANT_SPEED, LAW_SPINUP, LAW_HARMONIC, LAW_TABLE, LAW_FORCE, LAW_REST_CYCLOIDAL, LAW_REST_QUINTIC

  integer, parameter :: LAW_CONSTANT_SPEED = 1, LAW_SPINUP = 2, LAW_HARMONIC = 3, LAW_TABLE = 4, LAW_FORCE = 11
  integer, parameter :: LAW_REST_CYCLOIDAL = 5, LAW_REST_QUINTIC = 6
  real(dp), parameter :: two_pi = 6.283185307179586476925286766559_dp

contains

  !> Value, first and second derivative of the cubic spline through the knots tab_t(1:n) at t:
  !> on [tab_t(i), tab_t(i+1)] the value is c(1,i) + c(2,i) s + c(3,i) s^2 + c(4,i) s^3, s = t - tab_t(i)
  !> (c(:, n) unused); below tab_t(1) the first piece and above tab_t(n) the last piece continue.
  pure function spline_eval(tab_t, tab_c, t) result(f)
    real(dp), intent(in) :: tab_t(:)      !< (n) knots [s], increasing
    real(dp), intent(in) :: tab_c(:, :)   !< (4, n) piece coefficients
    real(dp), intent(in) :: t             !< time [s]
    real(dp) :: f(3)
    integer :: lo, hi, mid, n
    real(dp) :: s
    n = size(tab_t)
    lo = 1; hi = n - 1
    do while (lo < hi)            ! the piece i with tab_t(i) <= t < tab_t(i+1) (bisection)
      mid = (lo + hi + 1)/2
      if (tab_t(mid) <= t) then
        lo = mid
      else
        hi = mid - 1
      end if
    end do
    s = t - tab_t(lo)
    f(1) = tab_c(1, lo) + s*(tab_c(2, lo) + s*(tab_c(3, lo) + s*tab_c(4, lo)))
    f(2) = tab_c(2, lo) + s*(2.0_dp*tab_c(3, lo) + 3.0_dp*s*tab_c(4, lo))
    f(3) = 2.0_dp*tab_c(3, lo) + 6.0_dp*s*tab_c(4, lo)
  end function spline_eval

  !> [f, f', f''] of a kinematic law at time t [s] (units of the joint coordinate: rad or m).
  pure function kinematic_law(kind, par, tab_t, tab_c, t) result(f)
    integer, intent(in) :: kind           !< LAW_* (kinematic)
    real(dp), intent(in) :: par(:)        !< law parameters (layout above)
    real(dp), intent(in) :: tab_t(:), tab_c(:, :)   !< spline of LAW_TABLE (ignored otherwise)
    real(dp), intent(in) :: t
    real(dp) :: f(3), w, tt, k, tc
    select case (kind)
    case (LAW_CONSTANT_SPEED)
      f = [par(1) + par(2)*t, par(2), 0.0_dp]
    case (LAW_SPINUP)
      w = par(2); tt = par(3)
      k = two_pi/tt
      tc = max(t, 0.0_dp)
      if (tc <= tt) then
        f = [par(1) + w/tt*(0.5_dp*tc*tc + (cos(k*tc) - 1.0_dp)/k**2), w/tt*(tc - sin(k*tc)/k), &
             w/tt*(1.0_dp - cos(k*tc))]
      else
        f = [par(1) + w*(tc - 0.5_dp*tt), w, 0.0_dp]
      end if
    case (LAW_HARMONIC)
      f = [par(1) + par(2)*sin(par(3)*t + par(4)), par(2)*par(3)*cos(par(3)*t + par(4)), &
           -par(2)*par(3)**2*sin(par(3)*t + par(4))]
    case (LAW_TABLE)
      f = spline_eval(tab_t, tab_c, t)
    case (LAW_REST_CYCLOIDAL, LAW_REST_QUINTIC)
      f = rest_to_rest(kind, par, t)
    case default
      f = 0.0_dp
    end select
  end function kinematic_law

  !> [f, f', f''] of a rest-to-rest profile (LAW_REST_*, par = [start, travel, T, t0]) at time t [s].
  pure function rest_to_rest(kind, par, t) result(f)
    integer, intent(in) :: kind
    real(dp), intent(in) :: par(:), t
    real(dp) :: f(3), s, d, tt
    tt = par(3); d = par(2)
    s = min(max((t - par(4))/tt, 0.0_dp), 1.0_dp)
    if (s <= 0.0_dp .or. s >= 1.0_dp) then
      f = [par(1) + d*s, 0.0_dp, 0.0_dp]
    else if (kind == LAW_REST_CYCLOIDAL) then
      f = [par(1) + d*(s - sin(two_pi*s)/two_pi), d/tt*(1.0_dp - cos(two_pi*s)), d/tt**2*two_pi*sin(two_pi*s)]
    else
      f = [par(1) + d*s**3*(10.0_dp - 15.0_dp*s + 6.0_dp*s*s), d/tt*30.0_dp*s*s*(1.0_dp - s)**2, &
           d/tt**2*(60.0_dp*s - 180.0_dp*s*s + 120.0_dp*s**3)]
    end if
  end function rest_to_rest

  !> Generalized force [N m or N] of a force law at joint coordinate theta and time t (layout above).
  pure real(dp) function force_law(par, harm, th, tab_t, tab_c, theta, t) result(tau)
    real(dp), intent(in) :: par(:)        !< par(1): constant part
    real(dp), intent(in) :: harm(:)       !< (2 nh) [sin_1..sin_nh, cos_1..cos_nh]
    real(dp), intent(in) :: th(:, :)      !< (3, nth) [amplitude, angular frequency rad/s, phase rad]
    real(dp), intent(in) :: tab_t(:), tab_c(:, :)   !< spline in time (size(tab_t) < 2: none)
    real(dp), intent(in) :: theta, t
    integer :: k, nh
    real(dp) :: f(3)
    tau = par(1)
    nh = size(harm)/2
    do k = 1, nh
      tau = tau + harm(k)*sin(k*theta) + harm(nh + k)*cos(k*theta)
    end do
    do k = 1, size(th, 2)
      tau = tau + th(1, k)*sin(th(2, k)*t + th(3, k))
    end do
    if (size(tab_t) >= 2) then
      f = spline_eval(tab_t, tab_c, t)
      tau = tau + f(1)
    end if
  end function force_law

end module flexmech_drivelaw
