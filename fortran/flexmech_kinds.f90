!> Real kind used everywhere in flexmech.
!> f2py reads this file first, so `real(dp)` is wrapped as C double.
!> (`real(real64)` from iso_fortran_env is silently wrapped as single precision by f2py.)
module flexmech_kinds
  implicit none
  private
  public :: dp
  integer, parameter :: dp = selected_real_kind(15, 307)
end module flexmech_kinds
