!> LU factorization with partial pivoting, Cholesky factorization, and solves for the small dense systems of the rigid-body
!> layer (a mechanism's constraint Jacobian and augmented matrix: tens of unknowns).  At these sizes
!> the reference LAPACK's blocked, recursive dgetrf spends most of its time in call overhead
!> (measured with callgrind: dtrsm/dgemm/dlaswp/lsame dominate a 9 x 9 factorization), so the
!> textbook unblocked algorithm is written out here; the banded systems of the finite-element models
!> stay with LAPACK.
module flexmech_dense
  use flexmech_kinds, only: dp
  implicit none
  private
  public :: lu_factor, lu_solve, pivot_ratio, det_sign, chol_factor, chol_solve

contains

  !> In-place LU of a(1:n, 1:n) with row pivoting (piv(k): the row swapped with k at step k).
  !> info = k > 0 when the pivot of column k is exactly zero (a is singular).
  pure subroutine lu_factor(a, n, piv, info)
    integer, intent(in) :: n
    real(dp), intent(inout) :: a(:, :)
    integer, intent(out) :: piv(:), info
    integer :: k, p, i, j
    real(dp) :: t
    info = 0
    do k = 1, n
      p = k - 1 + maxloc(abs(a(k:n, k)), dim=1)
      piv(k) = p
      if (a(p, k) == 0.0_dp) then
        if (info == 0) info = k
        cycle
      end if
      if (p /= k) then
        do j = 1, n
          t = a(k, j); a(k, j) = a(p, j); a(p, j) = t
        end do
      end if
      t = 1.0_dp/a(k, k)
      do i = k + 1, n
        a(i, k) = a(i, k)*t
      end do
      do j = k + 1, n
        if (a(k, j) == 0.0_dp) cycle
        do i = k + 1, n
          a(i, j) = a(i, j) - a(i, k)*a(k, j)
        end do
      end do
    end do
  end subroutine lu_factor

  !> Solve A x = b (trans = .false.) or A^T x = b with the factors of lu_factor (P A = L U, rows swapped
  !> whole), b overwritten.
  pure subroutine lu_solve(a, n, piv, b, trans)
    integer, intent(in) :: n, piv(:)
    real(dp), intent(in) :: a(:, :)
    real(dp), intent(inout) :: b(:)
    logical, intent(in) :: trans
    integer :: k, i
    real(dp) :: t
    if (.not. trans) then
      do k = 1, n                 ! P b
        if (piv(k) /= k) then
          t = b(k); b(k) = b(piv(k)); b(piv(k)) = t
        end if
      end do
      do k = 1, n                 ! L y = P b
        do i = k + 1, n
          b(i) = b(i) - a(i, k)*b(k)
        end do
      end do
      do k = n, 1, -1             ! U x = y
        b(k) = b(k)/a(k, k)
        do i = 1, k - 1
          b(i) = b(i) - a(i, k)*b(k)
        end do
      end do
    else
      do k = 1, n                 ! U^T y = b
        do i = 1, k - 1
          b(k) = b(k) - a(i, k)*b(i)
        end do
        b(k) = b(k)/a(k, k)
      end do
      do k = n, 1, -1             ! L^T w = y
        do i = k + 1, n
          b(k) = b(k) - a(i, k)*b(i)
        end do
      end do
      do k = n, 1, -1             ! x = P^T w
        if (piv(k) /= k) then
          t = b(k); b(k) = b(piv(k)); b(piv(k)) = t
        end if
      end do
    end if
  end subroutine lu_solve

  !> Smallest over largest |pivot| of an LU factorization: a cheap indicator of how close the
  !> (suitably scaled) matrix is to singular (0 when singular).
  pure real(dp) function pivot_ratio(a, n)
    integer, intent(in) :: n
    real(dp), intent(in) :: a(:, :)
    integer :: k
    real(dp) :: lo, hi
    lo = huge(1.0_dp); hi = 0.0_dp
    do k = 1, n
      lo = min(lo, abs(a(k, k))); hi = max(hi, abs(a(k, k)))
    end do
    pivot_ratio = 0.0_dp
    if (hi > 0.0_dp) pivot_ratio = lo/hi
  end function pivot_ratio

  !> Sign of the determinant of the matrix factorized by lu_factor (+1, -1; 0 when singular).
  pure integer function det_sign(a, n, piv)
    integer, intent(in) :: n, piv(:)
    real(dp), intent(in) :: a(:, :)
    integer :: k
    det_sign = 1
    do k = 1, n
      if (a(k, k) == 0.0_dp) then
        det_sign = 0
        return
      end if
      if (a(k, k) < 0.0_dp) det_sign = -det_sign
      if (piv(k) /= k) det_sign = -det_sign
    end do
  end function det_sign

  !> In-place Cholesky factor L (lower triangle, A = L L^T) of the symmetric a(1:n, 1:n) given by its
  !> lower triangle.  info = k > 0 when the pivot of column k is not above rtol times the column's
  !> diagonal entry (a is not positive definite to that tolerance: dependent rows of a Gram matrix).
  pure subroutine chol_factor(a, n, rtol, info)
    integer, intent(in) :: n
    real(dp), intent(inout) :: a(:, :)
    real(dp), intent(in) :: rtol
    integer, intent(out) :: info
    integer :: i, j, k
    real(dp) :: d
    info = 0
    do k = 1, n
      d = a(k, k)
      do j = 1, k - 1
        d = d - a(k, j)**2
      end do
      if (.not. d > rtol*a(k, k)) then
        info = k
        return
      end if
      d = sqrt(d)
      a(k, k) = d
      do i = k + 1, n
        do j = 1, k - 1
          a(i, k) = a(i, k) - a(i, j)*a(k, j)
        end do
        a(i, k) = a(i, k)/d
      end do
    end do
  end subroutine chol_factor

  !> Solve A x = b with the factor of chol_factor, b overwritten.
  pure subroutine chol_solve(a, n, b)
    integer, intent(in) :: n
    real(dp), intent(in) :: a(:, :)
    real(dp), intent(inout) :: b(:)
    integer :: i, j
    do i = 1, n                   ! L y = b
      do j = 1, i - 1
        b(i) = b(i) - a(i, j)*b(j)
      end do
      b(i) = b(i)/a(i, i)
    end do
    do i = n, 1, -1               ! L^T x = y
      do j = i + 1, n
        b(i) = b(i) - a(j, i)*b(j)
      end do
      b(i) = b(i)/a(i, i)
    end do
  end subroutine chol_solve

end module flexmech_dense
