!> The saddle-point system of a constrained Newton step,
!>   [S  G] [x]   [b]
!>   [G' 0] [y] = [c] ,
!> solved as one band matrix in which every multiplier y_i is numbered in the middle of the free DOFs
!> its constraint row touches (after the DOF halfway between the first and the last), factorized
!> by LAPACK's band LU with partial pivoting (the zero block needs the pivoting).  For many local
!> rows (the nonlinear model's welds between consecutive elements) its cost grows linearly with
!> their number; eliminating the multipliers by their dense Schur complement G' S^-1 G grows with
!> the cube (docs/theory.md section 11.3, "The solve").
!> S: n x n over the free DOFs in LAPACK factor layout with half width kl (entry (i, j) at row
!> 2 kl + 1 + i - j); G: (n, m) constraint gradients by free DOF, nonzero on the patterns
!> gnz(1:ngnz(i), i) only.
module flexmech_saddle_band
  use flexmech_kinds, only: dp
  use flexmech_lapack, only: dgbtrf, dgbtrs, lapack_status, STATUS_OK
  implicit none
  private
  public :: saddle_system, saddle_setup, saddle_factor, saddle_solve, saddle_flops

  !> Ordering, band LU and work vector of one saddle-point system.
  type :: saddle_system
    integer :: n = 0, m = 0, kl = 0, ka = 0
    integer, allocatable :: pos(:)      !< (n + m) position of free DOF f (1..n) and of multiplier n + i
    integer, allocatable :: ipiv(:)     !< (n + m) pivots of the band LU
    real(dp), allocatable :: ab(:, :)   !< (3 ka + 1, n + m) the band matrix, factorized in place
    real(dp), allocatable :: w(:)       !< (n + m) right-hand side and solution in the band order
  end type saddle_system

contains

  !> The ordering (multiplier i after the free DOF halfway between the smallest and the largest of its
  !> pattern, which halves its reach against placing it after the last; one that touches none first)
  !> and the half width ka of the ordered matrix; allocates the band.
  subroutine saddle_setup(n, m, kl, ngnz, gnz, sd)
    integer, intent(in) :: n, m, kl, ngnz(:), gnz(:, :)
    type(saddle_system), intent(out) :: sd
    integer :: key(m), count(0:n), next(0:n), f, i, k, cum
    sd%n = n; sd%m = m; sd%kl = kl
    allocate (sd%pos(n + m))
    do i = 1, m
      key(i) = 0
      if (ngnz(i) > 0) key(i) = (minval(gnz(1:ngnz(i), i)) + maxval(gnz(1:ngnz(i), i)))/2
    end do
    count = 0
    do i = 1, m
      count(key(i)) = count(key(i)) + 1
    end do
    cum = 0            ! the order: [multipliers keyed 0], DOF 1, [keyed 1], DOF 2, ..., DOF n, [keyed n]
    do f = 1, n
      sd%pos(f) = count(0) + f + cum
      cum = cum + count(f)
    end do
    next(0) = 0
    next(1:n) = sd%pos(1:n)
    do i = 1, m
      next(key(i)) = next(key(i)) + 1
      sd%pos(n + i) = next(key(i))
    end do
    sd%ka = 0
    do f = 1, n
      do k = f + 1, min(n, f + kl)
        sd%ka = max(sd%ka, sd%pos(k) - sd%pos(f))
      end do
    end do
    do i = 1, m
      do k = 1, ngnz(i)
        sd%ka = max(sd%ka, abs(sd%pos(gnz(k, i)) - sd%pos(n + i)))
      end do
    end do
    allocate (sd%ab(3*sd%ka + 1, n + m), sd%ipiv(n + m), sd%w(n + m))
  end subroutine saddle_setup

  !> Fill the band from S (s_band) and G (g over the patterns) and factorize it; status STATUS_OK or
  !> the LAPACK status (singular: the rows are dependent at this configuration).
  subroutine saddle_factor(sd, s_band, g, ngnz, gnz, status)
    type(saddle_system), intent(inout) :: sd
    real(dp), intent(in) :: s_band(:, :), g(:, :)
    integer, intent(in) :: ngnz(:), gnz(:, :)
    integer, intent(out) :: status
    integer :: i, j, k, d, ds, r, c, info
    d = 2*sd%ka + 1; ds = 2*sd%kl + 1
    sd%ab = 0.0_dp
    do j = 1, sd%n
      do i = max(1, j - sd%kl), min(sd%n, j + sd%kl)
        sd%ab(d + sd%pos(i) - sd%pos(j), sd%pos(j)) = s_band(ds + i - j, j)
      end do
    end do
    do i = 1, sd%m
      c = sd%pos(sd%n + i)
      do k = 1, ngnz(i)
        r = sd%pos(gnz(k, i))
        sd%ab(d + r - c, c) = g(gnz(k, i), i)      ! G: row of the DOF, column of the multiplier
        sd%ab(d + c - r, r) = g(gnz(k, i), i)      ! G'
      end do
    end do
    call dgbtrf(sd%n + sd%m, sd%n + sd%m, sd%ka, sd%ka, sd%ab, size(sd%ab, 1), sd%ipiv, info)
    status = lapack_status(info)
  end subroutine saddle_factor

  !> Solve with the factorized band: x (n) holds b on entry and the DOF part on return, y (m) holds c
  !> and the multipliers.
  subroutine saddle_solve(sd, x, y, status)
    type(saddle_system), intent(inout) :: sd
    real(dp), intent(inout) :: x(:), y(:)
    integer, intent(out) :: status
    integer :: f, i, info
    do f = 1, sd%n
      sd%w(sd%pos(f)) = x(f)
    end do
    do i = 1, sd%m
      sd%w(sd%pos(sd%n + i)) = y(i)
    end do
    call dgbtrs('N', sd%n + sd%m, sd%ka, sd%ka, 1, sd%ab, size(sd%ab, 1), sd%ipiv, sd%w, sd%n + sd%m, info)
    status = lapack_status(info)
    do f = 1, sd%n
      x(f) = sd%w(sd%pos(f))
    end do
    do i = 1, sd%m
      y(i) = sd%w(sd%pos(sd%n + i))
    end do
  end subroutine saddle_solve

  !> Flop estimates of a Newton step (one factorization, two solves) by the two ways to the
  !> multipliers, for n free DOFs of half width kl, m rows and the saddle band's half width ka:
  !> [Schur complement, saddle band].  Schur: the band LU of S (2 n kl^2), S^-1 G (m solves of
  !> 4 n kl), the dense LU of G' S^-1 G (2 m^3 / 3), per solve 4 n kl + 2 m^2 + 2 n m; band: LU of
  !> n + m unknowns whose upper band grows to 2 ka under pivoting (4 (n + m) ka^2), per solve
  !> 6 (n + m) ka.
  pure function saddle_flops(n, m, kl, ka) result(fl)
    integer, intent(in) :: n, m, kl, ka
    real(dp) :: fl(2), rn, rm
    rn = real(n, dp); rm = real(m, dp)
    fl(1) = 2.0_dp*rn*kl*kl + rm*4.0_dp*rn*kl + 2.0_dp*rm**3/3.0_dp + 2.0_dp*(4.0_dp*rn*kl + 2.0_dp*rm*rm + 2.0_dp*rn*rm)
    fl(2) = 4.0_dp*(rn + rm)*ka*ka + 2.0_dp*6.0_dp*(rn + rm)*ka
  end function saddle_flops

end module flexmech_saddle_band
