!> The saddle-point system of a constrained Newton step,
!>   [S  G] [x]   [b]
!>   [G' 0] [y] = [c] ,
!> over n free DOFs and m constraint rows, as a bordered band (docs/theory.md sections 11.3, 12.6):
!> the *interior* unknowns (ni of them: free DOFs 1..n - nbd and the rows not flagged as border rows,
!> every multiplier numbered in the middle of the interior DOFs its row touches) form one band of
!> half width ka, factorized by LAPACK's band LU with partial pivoting (the zero block of the
!> multipliers needs it); the *border* (nb: the last nbd free DOFs and the border rows) couples to it
!> through A_IB, A_BI and is eliminated densely,
!>   A_II = F^-1 U (dgbtrf: F the forward elimination with its row interchanges),
!>   W = F A_IB,  V = U^-T A_BI',  S_B = A_BB - V' W  (dense LU),
!> so a solve is z = F r_I, S_B x_B = r_B - V' z, x_I = U^-1 (z - W x_B).  W(:, j) and V(:, j) are
!> computed and stored on the interior rows they can fill only: in every *stretch* of the band the
!> border unknown j couples to (unknowns that no band entry joins to the next: one chain of
!> elements), from its first coupling there (less ka for the row interchanges) to the stretch's end.
!> Numbered with the border at the far end of every chain (flexmech_py/coupled_ordering.py) these
!> ranges are short and the cost per factorization is linear in the unknowns for any mechanism;
!> with nb = 0 this is the plain saddle band.  For many local rows (the nonlinear model's welds between consecutive elements) the
!> band's cost grows linearly with their number, where eliminating the multipliers by their dense
!> Schur complement G' S^-1 G grows with the cube.
!> S enters either entry by entry over its pattern (saddle_add6, saddle_add_diag: the nonlinear
!> model's one-element segments and rigid bodies, straight from the assembly) or from a free-DOF band
!> in LAPACK factor layout (saddle_take_band: entry (i, j) at row 2 kl + 1 + i - j).  G: the m
!> constraint gradients on their patterns: g(k, i) the entry of free DOF gnz(k, i), k <= ngnz(i).
module flexmech_saddle_band
  use flexmech_kinds, only: dp
  use flexmech_lapack, only: dgbtrf, dgbtrs, dgetrf, dgetrs, dtbsv, lapack_status, STATUS_OK
  implicit none
  private
  public :: saddle_system, saddle_setup, saddle_zero, saddle_add6, saddle_add_diag, saddle_take_band
  public :: saddle_factor, saddle_solve, saddle_s_entry, saddle_work, saddle_flops

  !> The couplings found while setting up: the band's reach per interior position and the border's
  !> couplings to the interior as pairs [border unknown, interior position].
  type :: couplings
    integer :: np = 0
    integer, allocatable :: reach(:), pair(:, :)
  end type couplings

  !> Ordering, factors and work vector of one bordered saddle-point system.
  type :: saddle_system
    integer :: n = 0, m = 0, ni = 0, nb = 0, ka = 0, kd = 0
    !> kl of a free-DOF band whose every pair within kl lies in the interior band (saddle_take_band
    !> copies it straight; -1: not known, -2: does not fit)
    integer :: kl_fits = -1
    integer, allocatable :: pos(:)           !< (n + m) position of free DOF f (1..n) and of multiplier n + i
    !> the interior rows of W(:, j) and V(:, j): ranges rlo(r)..rhi(r), r = rptr(j)..rptr(j + 1) - 1
    integer, allocatable :: rptr(:), rlo(:), rhi(:)
    integer, allocatable :: ipiv(:), ipb(:)  !< pivots of the band LU (ni) and of the border's LU (nb)
    real(dp), allocatable :: ab(:, :)        !< (3 ka + 1, ni) the interior band, factorized in place
    real(dp), allocatable :: w(:, :), v(:, :)  !< (ni, nb) A_IB -> W and A_BI' -> V
    real(dp), allocatable :: bb(:, :)        !< (nb, nb) A_BB -> S_B -> its LU
    real(dp), allocatable :: z(:)            !< (ni + nb) right-hand side and solution by position
  end type saddle_system

contains

  !> The ordering, the band's half width ka and the border's fill ranges; allocates the storage.
  !> nbd: the last nbd free DOFs are border DOFs; rowb(i) /= 0: row i is a border row.  S's pattern:
  !> every free-DOF pair within kl of each other (kl present), or within one column of cliques
  !> (free numbers, 0 = none).
  subroutine saddle_setup(n, m, nbd, rowb, ngnz, gnz, sd, kl, cliques)
    integer, intent(in) :: n, m, nbd, rowb(:), ngnz(:), gnz(:, :)
    type(saddle_system), intent(out) :: sd
    integer, intent(in), optional :: kl, cliques(:, :)
    type(couplings) :: cp
    integer :: p
    sd%n = n; sd%m = m
    allocate (sd%pos(n + m))
    call interior_order(n, m, nbd, rowb, ngnz, gnz, sd)
    allocate (cp%reach(sd%ni), cp%pair(2, 64))
    do p = 1, sd%ni
      cp%reach(p) = p
    end do
    sd%ka = 0
    if (present(kl)) call visit_band(sd, kl, cp)
    if (present(cliques)) call visit_cliques(sd, cliques, cp)
    call visit_rows(sd, ngnz, gnz, cp)
    call fill_ranges(sd, cp)
    sd%kd = 2*sd%ka + 1
    allocate (sd%ab(3*sd%ka + 1, sd%ni), sd%ipiv(sd%ni), sd%w(sd%ni, sd%nb), sd%v(sd%ni, sd%nb), &
              sd%bb(sd%nb, sd%nb), sd%ipb(sd%nb), sd%z(sd%ni + sd%nb))
    sd%w = 0.0_dp; sd%v = 0.0_dp
    call saddle_zero(sd)
  end subroutine saddle_setup

  !> Positions: interior DOFs in free order with every interior row's multiplier after the DOF halfway
  !> between the smallest and the largest interior DOF of its pattern (which halves its reach against
  !> placing it after the last; one that touches none first), then the border DOFs and border rows.
  subroutine interior_order(n, m, nbd, rowb, ngnz, gnz, sd)
    integer, intent(in) :: n, m, nbd, rowb(:), ngnz(:), gnz(:, :)
    type(saddle_system), intent(inout) :: sd
    integer :: key(m), count(0:n), next(0:n), f, i, k, cum, nid, lo, hi, nbr
    nid = n - nbd
    count = 0
    nbr = 0
    do i = 1, m
      key(i) = -1
      if (rowb(i) /= 0) cycle
      lo = huge(1); hi = 0
      do k = 1, ngnz(i)
        if (gnz(k, i) > nid) cycle
        lo = min(lo, gnz(k, i)); hi = max(hi, gnz(k, i))
      end do
      key(i) = 0
      if (hi > 0) key(i) = (lo + hi)/2
      count(key(i)) = count(key(i)) + 1
    end do
    cum = 0            ! the order: [multipliers keyed 0], DOF 1, [keyed 1], DOF 2, ..., DOF nid, [keyed nid]
    do f = 1, nid
      sd%pos(f) = count(0) + f + cum
      cum = cum + count(f)
    end do
    sd%ni = count(0) + nid + cum
    next(0) = 0
    next(1:nid) = sd%pos(1:nid)
    do f = nid + 1, n
      sd%pos(f) = sd%ni + f - nid
    end do
    do i = 1, m
      if (key(i) < 0) then
        nbr = nbr + 1
        sd%pos(n + i) = sd%ni + nbd + nbr
      else
        next(key(i)) = next(key(i)) + 1
        sd%pos(n + i) = next(key(i))
      end if
    end do
    sd%nb = nbd + nbr
  end subroutine interior_order

  !> A structurally nonzero entry between positions p and q: the band's reach (both interior) or a
  !> border unknown's coupling to the interior (kept as a pair).
  pure subroutine visit(sd, p, q, cp)
    type(saddle_system), intent(inout) :: sd
    integer, intent(in) :: p, q
    type(couplings), intent(inout) :: cp
    integer, allocatable :: grown(:, :)
    if (p <= sd%ni .and. q <= sd%ni) then
      sd%ka = max(sd%ka, abs(p - q))
      cp%reach(min(p, q)) = max(cp%reach(min(p, q)), max(p, q))
    else if (p <= sd%ni .or. q <= sd%ni) then
      if (cp%np == size(cp%pair, 2)) then
        allocate (grown(2, 2*cp%np))
        grown(:, 1:cp%np) = cp%pair
        call move_alloc(grown, cp%pair)
      end if
      cp%np = cp%np + 1
      cp%pair(:, cp%np) = [max(p, q) - sd%ni, min(p, q)]     ! [border unknown, interior position]
    end if
  end subroutine visit

  pure subroutine visit_band(sd, kl, cp)
    type(saddle_system), intent(inout) :: sd
    integer, intent(in) :: kl
    type(couplings), intent(inout) :: cp
    integer :: f, k
    do f = 1, sd%n
      do k = f + 1, min(sd%n, f + kl)
        call visit(sd, sd%pos(f), sd%pos(k), cp)
      end do
    end do
  end subroutine visit_band

  pure subroutine visit_cliques(sd, cliques, cp)
    type(saddle_system), intent(inout) :: sd
    integer, intent(in) :: cliques(:, :)
    type(couplings), intent(inout) :: cp
    integer :: c, i, j
    do c = 1, size(cliques, 2)
      do j = 1, size(cliques, 1)
        if (cliques(j, c) <= 0) cycle
        do i = 1, j - 1
          if (cliques(i, c) > 0) call visit(sd, sd%pos(cliques(i, c)), sd%pos(cliques(j, c)), cp)
        end do
      end do
    end do
  end subroutine visit_cliques

  pure subroutine visit_rows(sd, ngnz, gnz, cp)
    type(saddle_system), intent(inout) :: sd
    integer, intent(in) :: ngnz(:), gnz(:, :)
    type(couplings), intent(inout) :: cp
    integer :: i, k
    do i = 1, sd%m
      do k = 1, ngnz(i)
        call visit(sd, sd%pos(gnz(k, i)), sd%pos(sd%n + i), cp)
      end do
    end do
  end subroutine visit_rows

  !> The fill ranges of every border unknown: per stretch of the band it couples to (unknowns no band
  !> entry joins to the next), from its first coupling there less ka (a row interchange of the band LU
  !> reaches ka ahead), not before the stretch's start, to the stretch's end.
  pure subroutine fill_ranges(sd, cp)
    type(saddle_system), intent(inout) :: sd
    type(couplings), intent(in) :: cp
    integer :: sbeg(sd%ni), send(sd%ni), first(sd%ni), p, q, top, j, k, nr
    top = 0; q = 1
    do p = 1, sd%ni
      top = max(top, cp%reach(p))
      if (top == p) then
        sbeg(q:p) = q; send(q:p) = p
        q = p + 1
      end if
    end do
    allocate (sd%rptr(sd%nb + 1), sd%rlo(cp%np), sd%rhi(cp%np))
    first = 0
    nr = 0
    do j = 1, sd%nb              ! (a border unknown couples to a few positions: the pairs are scanned per unknown)
      sd%rptr(j) = nr + 1
      do k = 1, cp%np
        if (cp%pair(1, k) /= j) cycle
        p = cp%pair(2, k)
        if (first(send(p)) == 0) then
          nr = nr + 1
          first(send(p)) = nr
          sd%rlo(nr) = p; sd%rhi(nr) = send(p)
        end if
        sd%rlo(first(send(p))) = min(sd%rlo(first(send(p))), p)
      end do
      do k = sd%rptr(j), nr
        first(sd%rhi(k)) = 0
        sd%rlo(k) = max(sbeg(sd%rlo(k)), sd%rlo(k) - sd%ka)
      end do
    end do
    sd%rptr(sd%nb + 1) = nr + 1
  end subroutine fill_ranges

  !> Zero the stored S before an assembly (the band, the border's fill ranges and its block).
  subroutine saddle_zero(sd)
    type(saddle_system), intent(inout) :: sd
    integer :: j, r
    sd%ab = 0.0_dp
    do j = 1, sd%nb
      do r = sd%rptr(j), sd%rptr(j + 1) - 1
        sd%w(sd%rlo(r):sd%rhi(r), j) = 0.0_dp
        sd%v(sd%rlo(r):sd%rhi(r), j) = 0.0_dp
      end do
    end do
    sd%bb = 0.0_dp
  end subroutine saddle_zero

  !> The entry at positions (p, q) += val, in the band, W, V or the border block.
  pure subroutine put(sd, p, q, val)
    type(saddle_system), intent(inout) :: sd
    integer, intent(in) :: p, q
    real(dp), intent(in) :: val
    if (q <= sd%ni) then
      if (p <= sd%ni) then
        sd%ab(sd%kd + p - q, q) = sd%ab(sd%kd + p - q, q) + val
      else
        sd%v(q, p - sd%ni) = sd%v(q, p - sd%ni) + val
      end if
    else if (p <= sd%ni) then
      sd%w(p, q - sd%ni) = sd%w(p, q - sd%ni) + val
    else
      sd%bb(p - sd%ni, q - sd%ni) = sd%bb(p - sd%ni, q - sd%ni) + val
    end if
  end subroutine put

  !> S(f(i), f(j)) += s6(i, j) for the free DOFs f (0: fixed, skipped) of one clique given to
  !> saddle_setup.
  pure subroutine saddle_add6(sd, f, s6)
    type(saddle_system), intent(inout) :: sd
    integer, intent(in) :: f(6)
    real(dp), intent(in) :: s6(6, 6)
    integer :: i, j, p(6)
    do i = 1, 6
      p(i) = 0
      if (f(i) > 0) p(i) = sd%pos(f(i))
    end do
    do j = 1, 6
      if (p(j) == 0) cycle
      do i = 1, 6
        if (p(i) == 0) cycle
        if (p(i) <= sd%ni .and. p(j) <= sd%ni) then     ! (the interior, inline: most entries)
          sd%ab(sd%kd + p(i) - p(j), p(j)) = sd%ab(sd%kd + p(i) - p(j), p(j)) + s6(i, j)
        else
          call put(sd, p(i), p(j), s6(i, j))
        end if
      end do
    end do
  end subroutine saddle_add6

  !> S(f, f) += val.
  pure subroutine saddle_add_diag(sd, f, val)
    type(saddle_system), intent(inout) :: sd
    integer, intent(in) :: f
    real(dp), intent(in) :: val
    call put(sd, sd%pos(f), sd%pos(f), val)
  end subroutine saddle_add_diag

  !> S from a free-DOF band (LAPACK factor layout, half width kl); its nonzero entries must lie in the
  !> pattern saddle_setup was given (the same kl, or the cliques the band was assembled from).
  subroutine saddle_take_band(sd, s_band, kl)
    type(saddle_system), intent(inout) :: sd
    real(dp), intent(in) :: s_band(:, :)
    integer, intent(in) :: kl
    integer :: i, j, ds, p, q
    real(dp) :: val
    ds = 2*kl + 1
    call saddle_zero(sd)
    if (sd%kl_fits == -1) sd%kl_fits = merge(kl, -2, band_fits(sd, kl))
    if (sd%kl_fits == kl) then      ! (a single chain: straight into the band, as fast as a copy)
      do j = 1, sd%n
        q = sd%pos(j)
        do i = max(1, j - kl), min(sd%n, j + kl)
          sd%ab(sd%kd + sd%pos(i) - q, q) = s_band(ds + i - j, j)
        end do
      end do
      return
    end if
    do j = 1, sd%n
      q = sd%pos(j)
      do i = max(1, j - kl), min(sd%n, j + kl)
        val = s_band(ds + i - j, j)
        if (val == 0.0_dp) cycle
        p = sd%pos(i)
        if (p <= sd%ni .and. q <= sd%ni) then     ! (the interior, inline: most entries)
          sd%ab(sd%kd + p - q, q) = sd%ab(sd%kd + p - q, q) + val
        else
          call put(sd, p, q, val)
        end if
      end do
    end do
  end subroutine saddle_take_band

  !> Every free-DOF pair within kl of each other lies in the interior band.
  pure logical function band_fits(sd, kl)
    type(saddle_system), intent(in) :: sd
    integer, intent(in) :: kl
    integer :: i, j
    band_fits = .true.
    do j = 1, sd%n
      do i = max(1, j - kl), min(sd%n, j + kl)
        if (sd%pos(i) > sd%ni .or. sd%pos(j) > sd%ni .or. abs(sd%pos(i) - sd%pos(j)) > sd%ka) then
          band_fits = .false.
          return
        end if
      end do
    end do
  end function band_fits

  !> S's entry (f, g) as stored (before saddle_factor): the dense matrices of the tests.
  pure real(dp) function saddle_s_entry(sd, f, g) result(val)
    type(saddle_system), intent(in) :: sd
    integer, intent(in) :: f, g
    integer :: p, q
    p = sd%pos(f); q = sd%pos(g)
    val = 0.0_dp
    if (q <= sd%ni .and. p <= sd%ni) then
      if (abs(p - q) <= sd%ka) val = sd%ab(sd%kd + p - q, q)
    else if (q <= sd%ni) then
      if (in_ranges(sd, p - sd%ni, q)) val = sd%v(q, p - sd%ni)
    else if (p <= sd%ni) then
      if (in_ranges(sd, q - sd%ni, p)) val = sd%w(p, q - sd%ni)
    else
      val = sd%bb(p - sd%ni, q - sd%ni)
    end if
  end function saddle_s_entry

  !> Interior position p lies in a fill range of border unknown j.
  pure logical function in_ranges(sd, j, p)
    type(saddle_system), intent(in) :: sd
    integer, intent(in) :: j, p
    integer :: r
    in_ranges = .false.
    do r = sd%rptr(j), sd%rptr(j + 1) - 1
      in_ranges = in_ranges .or. (p >= sd%rlo(r) .and. p <= sd%rhi(r))
    end do
  end function in_ranges

  !> Add G (g(k, i): the entry of free DOF gnz(k, i) in row i) to the stored S and factorize: the band LU, then the border's W, V
  !> and Schur complement, its dense LU.  status STATUS_OK or the LAPACK status (singular: the rows
  !> are dependent at this configuration).
  subroutine saddle_factor(sd, g, ngnz, gnz, status)
    type(saddle_system), intent(inout) :: sd
    real(dp), intent(in) :: g(:, :)
    integer, intent(in) :: ngnz(:), gnz(:, :)
    integer, intent(out) :: status
    integer :: i, j, k, c, r, info
    do i = 1, sd%m
      c = sd%pos(sd%n + i)
      do k = 1, ngnz(i)
        r = sd%pos(gnz(k, i))
        if (r <= sd%ni .and. c <= sd%ni) then     ! (the interior, inline: most entries)
          sd%ab(sd%kd + r - c, c) = sd%ab(sd%kd + r - c, c) + g(k, i)
          sd%ab(sd%kd + c - r, r) = sd%ab(sd%kd + c - r, r) + g(k, i)
        else
          call put(sd, r, c, g(k, i))      ! G: row of the DOF, column of the multiplier
          call put(sd, c, r, g(k, i))      ! G'
        end if
      end do
    end do
    info = 0
    if (sd%ni > 0) call dgbtrf(sd%ni, sd%ni, sd%ka, sd%ka, sd%ab, size(sd%ab, 1), sd%ipiv, info)
    status = lapack_status(info)
    if (status /= STATUS_OK .or. sd%nb == 0) return
    do j = 1, sd%nb
      do r = sd%rptr(j), sd%rptr(j + 1) - 1
        call forward_f(sd, sd%rlo(r), sd%rhi(r), sd%w(:, j))
        call forward_ut(sd, sd%rlo(r), sd%rhi(r), sd%v(:, j))
      end do
    end do
    do j = 1, sd%nb
      do i = 1, sd%nb
        sd%bb(i, j) = sd%bb(i, j) - range_dot(sd, i, j)
      end do
    end do
    call dgetrf(sd%nb, sd%nb, sd%bb, sd%nb, sd%ipb, info)
    status = lapack_status(info)
  end subroutine saddle_factor

  !> V(:, i)' W(:, j) over the overlaps of their ranges.
  pure real(dp) function range_dot(sd, i, j) result(d)
    type(saddle_system), intent(in) :: sd
    integer, intent(in) :: i, j
    integer :: r, s, a, b
    d = 0.0_dp
    do r = sd%rptr(i), sd%rptr(i + 1) - 1
      do s = sd%rptr(j), sd%rptr(j + 1) - 1
        a = max(sd%rlo(r), sd%rlo(s)); b = min(sd%rhi(r), sd%rhi(s))
        if (b >= a) d = d + dot_product(sd%v(a:b, i), sd%w(a:b, j))
      end do
    end do
  end function range_dot

  !> y(k0:k1) <- F y(k0:k1): the band LU's forward elimination with its row interchanges, over an
  !> interior stretch (y zero before k0 + ka, the stretch ending at k1).
  pure subroutine forward_f(sd, k0, k1, y)
    type(saddle_system), intent(in) :: sd
    integer, intent(in) :: k0, k1
    real(dp), intent(inout) :: y(:)
    integer :: k, l, lm, i
    real(dp) :: t
    do k = k0, k1 - 1
      l = sd%ipiv(k)
      if (l /= k) then
        t = y(l); y(l) = y(k); y(k) = t
      end if
      t = y(k)
      if (t == 0.0_dp) cycle
      lm = min(sd%ka, k1 - k)
      do i = 1, lm
        y(k + i) = y(k + i) - sd%ab(sd%kd + i, k)*t
      end do
    end do
  end subroutine forward_f

  !> y(k0:k1) <- U^-T y(k0:k1) (y zero before k0; U: the band LU's upper factor, 2 ka superdiagonals).
  pure subroutine forward_ut(sd, k0, k1, y)
    type(saddle_system), intent(in) :: sd
    integer, intent(in) :: k0, k1
    real(dp), intent(inout) :: y(:)
    integer :: i, j
    real(dp) :: s
    do j = k0, k1
      s = y(j)
      do i = max(k0, j - 2*sd%ka), j - 1
        s = s - sd%ab(sd%kd + i - j, j)*y(i)
      end do
      y(j) = s/sd%ab(sd%kd, j)
    end do
  end subroutine forward_ut

  !> Solve with the factorized system: x (n) holds b on entry and the DOF part on return, y (m) holds
  !> c and the multipliers.
  subroutine saddle_solve(sd, x, y, status)
    type(saddle_system), intent(inout) :: sd
    real(dp), intent(inout) :: x(:), y(:)
    integer, intent(out) :: status
    integer :: f, i, j, r, info, ni
    ni = sd%ni
    do f = 1, sd%n
      sd%z(sd%pos(f)) = x(f)
    end do
    do i = 1, sd%m
      sd%z(sd%pos(sd%n + i)) = y(i)
    end do
    info = 0
    if (sd%nb == 0) then
      call dgbtrs('N', ni, sd%ka, sd%ka, 1, sd%ab, size(sd%ab, 1), sd%ipiv, sd%z, max(1, ni), info)
    else
      call forward_f(sd, 1, ni, sd%z)
      do j = 1, sd%nb
        do r = sd%rptr(j), sd%rptr(j + 1) - 1
          sd%z(ni + j) = sd%z(ni + j) - dot_product(sd%v(sd%rlo(r):sd%rhi(r), j), sd%z(sd%rlo(r):sd%rhi(r)))
        end do
      end do
      call dgetrs('N', sd%nb, 1, sd%bb, sd%nb, sd%ipb, sd%z(ni + 1), sd%nb, info)
      do j = 1, sd%nb
        do r = sd%rptr(j), sd%rptr(j + 1) - 1
          do i = sd%rlo(r), sd%rhi(r)
            sd%z(i) = sd%z(i) - sd%w(i, j)*sd%z(ni + j)
          end do
        end do
      end do
      if (ni > 0) call dtbsv('U', 'N', 'N', ni, 2*sd%ka, sd%ab, size(sd%ab, 1), sd%z, 1)
    end if
    status = lapack_status(info)
    do f = 1, sd%n
      x(f) = sd%z(sd%pos(f))
    end do
    do i = 1, sd%m
      y(i) = sd%z(sd%pos(sd%n + i))
    end do
  end subroutine saddle_solve

  !> Floating-point operations of one factorization and of one solve as this system does them
  !> (multiply and add count 1 each): the band LU ni (4 ka^2 + ka) (its upper band grows to 2 ka
  !> under pivoting), W and V over their ranges (2 ka and 4 ka per row), the border's Schur products
  !> and dense LU (2 nb^3 / 3); per solve the band substitutions 2 ni (3 ka) + ni, the border
  !> products over the ranges and the dense substitutions 2 nb^2.  Machine-independent: the tests
  !> read its growth with the mesh.
  pure function saddle_work(sd) result(fl)
    type(saddle_system), intent(in) :: sd
    real(dp) :: fl(2)
    integer :: i, j, r, s
    real(dp) :: rng
    fl(1) = real(sd%ni, dp)*(4.0_dp*sd%ka**2 + sd%ka) + 2.0_dp*real(sd%nb, dp)**3/3.0_dp
    fl(2) = real(sd%ni, dp)*(6.0_dp*sd%ka + 1.0_dp) + 2.0_dp*real(sd%nb, dp)**2
    do j = 1, sd%nb
      do r = sd%rptr(j), sd%rptr(j + 1) - 1
        rng = real(sd%rhi(r) - sd%rlo(r) + 1, dp)
        fl(1) = fl(1) + rng*6.0_dp*sd%ka
        fl(2) = fl(2) + 4.0_dp*rng
      end do
      do i = 1, sd%nb
        do r = sd%rptr(i), sd%rptr(i + 1) - 1
          do s = sd%rptr(j), sd%rptr(j + 1) - 1
            fl(1) = fl(1) + 2.0_dp*max(0, min(sd%rhi(r), sd%rhi(s)) - max(sd%rlo(r), sd%rlo(s)) + 1)
          end do
        end do
      end do
    end do
  end function saddle_work

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
