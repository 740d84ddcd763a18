!> Banded assembly in LAPACK general-band storage.
!>
!> A banded n x n matrix with kl sub- and ku super-diagonals is stored, as
!> `dgbtrf` expects, in ab(2*kl+ku+1, n) with A(i,j) at ab(kl+ku+1+i-j, j);
!> the first kl rows are workspace for the LU fill-in.
!> Index arrays hold 1-based free-DOF numbers; 0 marks a constrained DOF
!> whose row and column are dropped.
module flexmech_assembly
  use flexmech_kinds, only: dp
  implicit none
  private
  public :: band_rows, band_add_element6, band_add_general, band_add_diagonal, half_bandwidth, band_to_dense

contains

  !> Leading dimension of the band storage for kl, ku.
  pure integer function band_rows(kl, ku)
    integer, intent(in) :: kl, ku
    band_rows = 2*kl + ku + 1
  end function band_rows

  !> Half bandwidth max |i - j| over the free DOFs that share an element.
  pure integer function half_bandwidth(idx) result(kb)
    integer, intent(in) :: idx(:, :)  !< (dofs per element, elements) free-DOF numbers, 0 = constrained
    integer :: e, lo, hi
    kb = 0
    do e = 1, size(idx, 2)
      if (all(idx(:, e) == 0)) cycle
      hi = maxval(idx(:, e))
      lo = minval(idx(:, e), mask=idx(:, e) > 0)
      kb = max(kb, hi - lo)
    end do
  end function half_bandwidth

  !> ab += the 6 x 6 element matrix ke scattered to the free DOFs idx (explicit shapes: the time
  !> loop's assembly, no array descriptors).
  pure subroutine band_add_element6(ab, ldab, kl, ku, idx, ke)
    integer, intent(in) :: ldab, kl, ku
    real(dp), intent(inout) :: ab(ldab, *)  !< band storage (2kl+ku+1, n)
    integer, intent(in) :: idx(6)           !< free-DOF numbers of the element DOFs, 0 = constrained
    real(dp), intent(in) :: ke(6, 6)        !< element matrix
    integer :: a, b, i, j, d
    d = kl + ku + 1
    do b = 1, 6
      j = idx(b)
      if (j == 0) cycle
      do a = 1, 6
        i = idx(a)
        if (i == 0) cycle
        ab(d + i - j, j) = ab(d + i - j, j) + ke(a, b)
      end do
    end do
  end subroutine band_add_element6

  !> ab += the n x n matrix ke scattered to the free DOFs idx(n) (all > 0): the assembly of an item
  !> whose local DOFs are expressed on n free DOFs through slave relations (flexmech_ked).
  pure subroutine band_add_general(ab, ldab, kl, ku, n, idx, ke)
    integer, intent(in) :: ldab, kl, ku, n
    real(dp), intent(inout) :: ab(ldab, *)  !< band storage (2kl+ku+1, nfree)
    integer, intent(in) :: idx(n)           !< free-DOF numbers (1-based, none 0)
    real(dp), intent(in) :: ke(n, n)
    integer :: a, b, d
    d = kl + ku + 1
    do b = 1, n
      do a = 1, n
        ab(d + idx(a) - idx(b), idx(b)) = ab(d + idx(a) - idx(b), idx(b)) + ke(a, b)
      end do
    end do
  end subroutine band_add_general

  !> ab(i,i) += val for a free DOF i (no-op for i = 0).
  pure subroutine band_add_diagonal(ab, kl, ku, i, val)
    real(dp), intent(inout) :: ab(:, :)
    integer, intent(in) :: kl, ku, i
    real(dp), intent(in) :: val
    if (i > 0) ab(kl + ku + 1, i) = ab(kl + ku + 1, i) + val
  end subroutine band_add_diagonal

  !> Dense copy of a band matrix (for tests and analysis, not for the time loop).
  pure function band_to_dense(ab, kl, ku, n) result(a)
    real(dp), intent(in) :: ab(:, :)
    integer, intent(in) :: kl, ku, n
    real(dp) :: a(n, n)
    integer :: i, j
    a = 0.0_dp
    do j = 1, n
      do i = max(1, j - ku), min(n, j + kl)
        a(i, j) = ab(kl + ku + 1 + i - j, j)
      end do
    end do
  end function band_to_dense

end module flexmech_assembly
