!> Step-to-step sign alternation (a period-2 dt oscillation) of the quantities a time loop carries,
!> watched at every step: output frames taken every few steps sample one phase of such an
!> oscillation and show a smooth curve, so it must be caught where the steps are (docs/stability.md,
!> "Period-2·dt oscillation").  Its usual causes are numerical: the constraint multipliers of an
!> index-3 system under average acceleration (no numerical damping), or a mode the step does not
!> resolve and the integrator does not damp.
!>
!> Component i alternates at step n when its change d_n = x_n - x_{n-1} has flipped sign at each of
!> the last ALT_FLIPS steps; its alternating part there is |d_n - d_{n-1}|/4 = |x_n - 2 x_{n-1} + x_{n-2}|/4
!> (a sawtooth (-1)^n A gives A; a smooth x adds h^2 x''/4 and flips sign that often only where it is
!> constant to round-off, at round-off size).  The monitor keeps the largest alternating part of every
!> component since it was last read (alt_take), so a time loop reports it at its output frames.
module flexmech_alternation
  use flexmech_kinds, only: dp
  implicit none
  private
  public :: alternation_monitor, alt_setup, alt_step, alt_take, ALT_FLIPS

  !> consecutive sign flips of a component's change that make an alternation: an oscillation at the
  !> step's Nyquist frequency keeps flipping; a vibration resolved by 2.1 or more steps per period
  !> beats out of phase sooner, and round-off or Newton noise, a single kick (a sudden load) or the
  !> integrator's start-up do not flip the sign this long
  integer, parameter :: ALT_FLIPS = 20

  type :: alternation_monitor
    real(dp), allocatable :: x1(:)     !< x at the last step
    real(dp), allocatable :: d1(:)     !< the last step's change
    real(dp), allocatable :: amax(:)   !< largest alternating part since the last alt_take
    integer, allocatable :: flips(:)   !< consecutive sign flips of the change, per component
    integer :: seen = 0                !< steps seen since alt_setup (x1 valid from 1, d1 from 2)
  end type alternation_monitor

contains

  !> A fresh monitor of n components.
  pure subroutine alt_setup(mon, n)
    type(alternation_monitor), intent(out) :: mon
    integer, intent(in) :: n
    allocate (mon%x1(n), mon%d1(n), mon%amax(n), mon%flips(n))
    mon%x1 = 0.0_dp; mon%d1 = 0.0_dp; mon%amax = 0.0_dp; mon%flips = 0
    mon%seen = 0
  end subroutine alt_setup

  !> The components' values x (n) at the next step.
  pure subroutine alt_step(mon, x)
    type(alternation_monitor), intent(inout) :: mon
    real(dp), intent(in) :: x(:)
    integer :: i
    real(dp) :: d
    do i = 1, size(mon%x1)
      if (mon%seen >= 1) then
        d = x(i) - mon%x1(i)
        if (mon%seen >= 2) then
          if (d*mon%d1(i) < 0.0_dp) then
            mon%flips(i) = mon%flips(i) + 1
          else
            mon%flips(i) = 0
          end if
          if (mon%flips(i) >= ALT_FLIPS) mon%amax(i) = max(mon%amax(i), 0.25_dp*abs(d - mon%d1(i)))
        end if
        mon%d1(i) = d
      end if
      mon%x1(i) = x(i)
    end do
    mon%seen = mon%seen + 1
  end subroutine alt_step

  !> out (n) = the largest alternating part of every component since the last call (0: none); reset.
  pure subroutine alt_take(mon, out)
    type(alternation_monitor), intent(inout) :: mon
    real(dp), intent(out) :: out(:)
    out = mon%amax
    mon%amax = 0.0_dp
  end subroutine alt_take

end module flexmech_alternation
