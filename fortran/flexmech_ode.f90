!> Explicit Runge-Kutta integration with step-size control and dense output for the rigid-body
!> dynamics of flexmech (docs/theory.md section 17.4).
!>
!> Method: the Dormand-Prince 5(4) pair with its fourth-order continuous extension (coefficients as
!> published in Hairer, Norsett & Wanner, "Solving Ordinary Differential Equations I", 2nd ed.,
!> Springer 1993, Table II.5.2 and eq. (II.6.12); the dense output is Shampine's (1986)).  Seven
!> stages, the last one evaluated at the new point and reused as the first of the next step.
!> Error control: the embedded fourth-order solution, err = rms((y5 - y4)_i / (atol + rtol max(|y0_i|, |y1_i|))),
!> a step is accepted when err <= 1; the next step is h * min(facmax, max(0.2, 0.9 err^(-1/5))),
!> facmax = 5 (1 after a rejection).
!>
!> The problem is a type extending ode_problem with a type-bound right-hand side, so no procedure
!> pointer or internal procedure crosses a call (gfortran would need an executable stack for those).
!> The integrator state (ode_state) is plain data: the caller can store it between calls as an array
!> (ode_pack / ode_unpack) and continue the same trajectory later, sample by sample.
module flexmech_ode
  use, intrinsic :: ieee_arithmetic, only: ieee_is_finite
  use flexmech_kinds, only: dp
  implicit none
  private
  public :: ode_problem, ode_state, ode_start, ode_step, ode_dense, ode_pack, ode_unpack, ode_state_size
  public :: ODE_OK, ODE_FAILED, ODE_STEP_TOO_SMALL

  integer, parameter :: ODE_OK = 0, ODE_FAILED = 1, ODE_STEP_TOO_SMALL = 2

  !> A first-order system y' = f(t, y); rhs returns status 0 on success.
  type, abstract :: ode_problem
  contains
    procedure(rhs_interface), deferred :: rhs
  end type ode_problem

  abstract interface
    subroutine rhs_interface(self, t, y, f, status)
      import :: ode_problem, dp
      class(ode_problem), intent(inout) :: self
      real(dp), intent(in) :: t, y(:)
      real(dp), intent(out) :: f(:)
      integer, intent(out) :: status
    end subroutine rhs_interface
  end interface

  !> State of the integration: the accepted point (t, y) with f = f(t, y), the proposed next step h,
  !> and what the dense output of the last accepted step [t_old, t_old + h_old] needs: its start
  !> y_old and its seven stage derivatives kst.
  type :: ode_state
    integer :: n = 0, naccept = 0, nreject = 0, nrhs = 0
    real(dp) :: t = 0.0_dp, h = 0.0_dp, t_old = 0.0_dp, h_old = 0.0_dp, rtol = 1e-10_dp, atol = 1e-12_dp
    real(dp), allocatable :: y(:), f(:), y_old(:), kst(:, :)   !< (n), (n), (n), (n, 7)
  end type ode_state

  ! Dormand-Prince 5(4): nodes, stage coefficients, fifth-order weights (= row 7), error weights
  real(dp), parameter :: c2 = 0.2_dp, c3 = 0.3_dp, c4 = 0.8_dp, c5 = 8.0_dp/9.0_dp
  real(dp), parameter :: a21 = 0.2_dp
  real(dp), parameter :: a31 = 3.0_dp/40.0_dp, a32 = 9.0_dp/40.0_dp
  real(dp), parameter :: a41 = 44.0_dp/45.0_dp, a42 = -56.0_dp/15.0_dp, a43 = 32.0_dp/9.0_dp
  real(dp), parameter :: a51 = 19372.0_dp/6561.0_dp, a52 = -25360.0_dp/2187.0_dp, a53 = 64448.0_dp/6561.0_dp, &
                         a54 = -212.0_dp/729.0_dp
  real(dp), parameter :: a61 = 9017.0_dp/3168.0_dp, a62 = -355.0_dp/33.0_dp, a63 = 46732.0_dp/5247.0_dp, &
                         a64 = 49.0_dp/176.0_dp, a65 = -5103.0_dp/18656.0_dp
  real(dp), parameter :: b1 = 35.0_dp/384.0_dp, b3 = 500.0_dp/1113.0_dp, b4 = 125.0_dp/192.0_dp, &
                         b5 = -2187.0_dp/6784.0_dp, b6 = 11.0_dp/84.0_dp
  real(dp), parameter :: e1 = 71.0_dp/57600.0_dp, e3 = -71.0_dp/16695.0_dp, e4 = 71.0_dp/1920.0_dp, &
                         e5 = -17253.0_dp/339200.0_dp, e6 = 22.0_dp/525.0_dp, e7 = -1.0_dp/40.0_dp
  ! continuous extension (eq. II.6.12): y(t_old + s h) = y_old + h sum_i b_i(s) k_i with
  !   b_i(s) = s^2 (3 - 2 s) b_i + s^2 (s - 1)^2 p_i(s)  (+ s (s - 1)^2 for i = 1, + s^2 (s - 1) for i = 7),
  !   p_i(s) = (q0_i + q1_i s) / den_i
  real(dp), parameter :: q0(7) = [-5.0_dp*2558722523.0_dp, 0.0_dp, 100.0_dp*882725551.0_dp, &
                                  -25.0_dp*443332067.0_dp, 32805.0_dp*23143187.0_dp, -55.0_dp*29972135.0_dp, &
                                  10.0_dp*7414447.0_dp]
  real(dp), parameter :: q1(7) = [5.0_dp*31403016.0_dp, 0.0_dp, -100.0_dp*15701508.0_dp, 25.0_dp*31403016.0_dp, &
                                  -32805.0_dp*3489224.0_dp, 55.0_dp*7076736.0_dp, -10.0_dp*829305.0_dp]
  real(dp), parameter :: den(7) = [11282082432.0_dp, 1.0_dp, 32700410799.0_dp, 1880347072.0_dp, &
                                   199316789632.0_dp, 822651844.0_dp, 29380423.0_dp]
  real(dp), parameter :: bw(7) = [b1, 0.0_dp, b3, b4, b5, b6, 0.0_dp]

contains

  !> Number of reals ode_pack writes for n unknowns.
  pure integer function ode_state_size(n)
    integer, intent(in) :: n
    ode_state_size = 11 + 10*n
  end function ode_state_size

  !> Store the state in a flat array (length ode_state_size(n)).
  subroutine ode_pack(st, buf)
    type(ode_state), intent(in) :: st
    real(dp), intent(out) :: buf(:)
    integer :: n
    n = st%n
    buf(1:11) = [real(n, dp), real(st%naccept, dp), real(st%nreject, dp), real(st%nrhs, dp), st%t, st%h, &
                 st%t_old, st%h_old, st%rtol, st%atol, 0.0_dp]
    buf(12:11 + n) = st%y
    buf(12 + n:11 + 2*n) = st%f
    buf(12 + 2*n:11 + 3*n) = st%y_old
    buf(12 + 3*n:11 + 10*n) = reshape(st%kst, [7*n])
  end subroutine ode_pack

  !> The state stored by ode_pack.
  subroutine ode_unpack(buf, st)
    real(dp), intent(in) :: buf(:)
    type(ode_state), intent(out) :: st
    integer :: n
    n = nint(buf(1))
    st%n = n
    st%naccept = nint(buf(2)); st%nreject = nint(buf(3)); st%nrhs = nint(buf(4))
    st%t = buf(5); st%h = buf(6); st%t_old = buf(7); st%h_old = buf(8); st%rtol = buf(9); st%atol = buf(10)
    st%y = buf(12:11 + n)
    st%f = buf(12 + n:11 + 2*n)
    st%y_old = buf(12 + 2*n:11 + 3*n)
    st%kst = reshape(buf(12 + 3*n:11 + 10*n), [n, 7])
  end subroutine ode_unpack

  !> Start at (t0, y0): f(t0, y0), an initial step from the local scales of y and f (a trial Euler
  !> step estimates the second derivative), no dense output yet (t_old = t, h_old = 0).
  subroutine ode_start(prob, t0, y0, rtol, atol, hmax, st, status)
    class(ode_problem), intent(inout) :: prob
    real(dp), intent(in) :: t0, y0(:), rtol, atol, hmax
    type(ode_state), intent(out) :: st
    integer, intent(out) :: status
    real(dp), allocatable :: sc(:), y1(:), f1(:)
    real(dp) :: d0, d1n, d2, h0, h1
    integer :: n
    n = size(y0)
    st%n = n; st%t = t0; st%t_old = t0; st%h_old = 0.0_dp; st%rtol = rtol; st%atol = atol
    st%y = y0
    allocate (st%f(n), st%kst(n, 7), sc(n), y1(n), f1(n))
    st%y_old = y0
    st%kst = 0.0_dp
    call prob%rhs(t0, y0, st%f, status)
    st%nrhs = 1
    if (status /= 0) return
    sc = atol + rtol*abs(y0)
    d0 = rms(y0/sc); d1n = rms(st%f/sc)
    if (d0 < 1e-5_dp .or. d1n < 1e-5_dp) then
      h0 = 1e-6_dp
    else
      h0 = 0.01_dp*d0/d1n
    end if
    h0 = min(h0, hmax)
    y1 = y0 + h0*st%f
    call prob%rhs(t0 + h0, y1, f1, status)
    st%nrhs = 2
    if (status /= 0) return
    d2 = rms((f1 - st%f)/sc)/h0
    if (max(d1n, d2) <= 1e-15_dp) then
      h1 = max(1e-6_dp, h0*1e-3_dp)
    else
      h1 = (0.01_dp/max(d1n, d2))**0.2_dp
    end if
    st%h = min(100.0_dp*h0, h1, hmax)
  end subroutine ode_start

  !> One accepted step (rejected trials repeated with smaller steps inside).  On return st holds the
  !> new point and the dense output of the step [st%t_old, st%t].  status: ODE_OK, ODE_FAILED (the
  !> right-hand side failed: rhs_status holds its code) or ODE_STEP_TOO_SMALL.
  subroutine ode_step(prob, st, hmax, status, rhs_status)
    class(ode_problem), intent(inout) :: prob
    type(ode_state), intent(inout) :: st
    real(dp), intent(in) :: hmax
    integer, intent(out) :: status, rhs_status
    real(dp) :: k2(st%n), k3(st%n), k4(st%n), k5(st%n), k6(st%n), k7(st%n), yt(st%n), y5(st%n), sc(st%n)
    real(dp) :: h, err, fac, facmax
    integer :: n
    n = st%n
    status = ODE_OK; rhs_status = 0
    facmax = 5.0_dp
    h = min(st%h, hmax)
    do
      if (h <= 1e-14_dp*max(abs(st%t), 1.0_dp)) then
        status = ODE_STEP_TOO_SMALL
        return
      end if
      associate (y => st%y, k1 => st%f, t => st%t)
        yt = y + h*a21*k1
        call stage(t + c2*h, yt, k2); if (rhs_status /= 0) exit
        yt = y + h*(a31*k1 + a32*k2)
        call stage(t + c3*h, yt, k3); if (rhs_status /= 0) exit
        yt = y + h*(a41*k1 + a42*k2 + a43*k3)
        call stage(t + c4*h, yt, k4); if (rhs_status /= 0) exit
        yt = y + h*(a51*k1 + a52*k2 + a53*k3 + a54*k4)
        call stage(t + c5*h, yt, k5); if (rhs_status /= 0) exit
        yt = y + h*(a61*k1 + a62*k2 + a63*k3 + a64*k4 + a65*k5)
        call stage(t + h, yt, k6); if (rhs_status /= 0) exit
        y5 = y + h*(b1*k1 + b3*k3 + b4*k4 + b5*k5 + b6*k6)
        call stage(t + h, y5, k7); if (rhs_status /= 0) exit
        sc = st%atol + st%rtol*max(abs(y), abs(y5))
        err = rms(h*(e1*k1 + e3*k3 + e4*k4 + e5*k5 + e6*k6 + e7*k7)/sc)
      end associate
      if (.not. ieee_is_finite(err)) err = 1e10_dp
      fac = min(facmax, max(0.2_dp, 0.9_dp*max(err, 1e-10_dp)**(-0.2_dp)))
      if (err <= 1.0_dp) then
        st%y_old = st%y
        st%kst(:, 1) = st%f; st%kst(:, 2) = k2; st%kst(:, 3) = k3; st%kst(:, 4) = k4
        st%kst(:, 5) = k5; st%kst(:, 6) = k6; st%kst(:, 7) = k7
        st%t_old = st%t; st%h_old = h
        st%t = st%t + h
        st%y = y5; st%f = k7
        st%h = h*fac
        st%naccept = st%naccept + 1
        return
      end if
      st%nreject = st%nreject + 1
      facmax = 1.0_dp
      h = h*fac
    end do
    status = ODE_FAILED

  contains

    subroutine stage(ts, ys, k)
      real(dp), intent(in) :: ts, ys(:)
      real(dp), intent(out) :: k(:)
      call prob%rhs(ts, ys, k, rhs_status)
      st%nrhs = st%nrhs + 1
    end subroutine stage

  end subroutine ode_step

  !> Dense output at t in [st%t_old, st%t] (the last accepted step; t = st%t gives st%y exactly when
  !> no step has been taken yet).
  pure subroutine ode_dense(st, t, y)
    type(ode_state), intent(in) :: st
    real(dp), intent(in) :: t
    real(dp), intent(out) :: y(:)
    real(dp) :: s, w(7)
    integer :: i
    if (st%h_old <= 0.0_dp) then
      y = st%y
      return
    end if
    s = (t - st%t_old)/st%h_old
    do i = 1, 7
      w(i) = s*s*(3.0_dp - 2.0_dp*s)*bw(i) + s*s*(s - 1.0_dp)**2*(q0(i) + q1(i)*s)/den(i)
    end do
    w(1) = w(1) + s*(s - 1.0_dp)**2
    w(7) = w(7) + s*s*(s - 1.0_dp)
    y = st%y_old
    do i = 1, 7
      y = y + (st%h_old*w(i))*st%kst(:, i)
    end do
  end subroutine ode_dense

  pure real(dp) function rms(x)
    real(dp), intent(in) :: x(:)
    rms = sqrt(sum(x**2)/max(size(x), 1))
  end function rms

end module flexmech_ode
