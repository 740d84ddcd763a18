!> The iteration matrix S = M + cc C_v + ck K_t of the coupled and nonlinear models, stored by segment
!> blocks (link_mats), and its factorization and solves: the whole free-DOF band (LAPACK), the
!> condensed form (every segment's interior DOFs eliminated onto the shared end positions;
!> docs/theory.md section 11.3, "The solve"), or the nonlinear model's bordered saddle band, into
!> which the one-element segments write straight (flexmech_saddle_band, docs/theory.md section 12.6).
module flexmech_coupled_storage
  use, intrinsic :: ieee_arithmetic, only: ieee_is_finite
  use flexmech_kinds, only: dp
  use flexmech_lapack, only: dgbtrf, dgbtrs, lapack_status, STATUS_OK, STATUS_NONFINITE
  use flexmech_assembly, only: band_rows, band_add_element6, half_bandwidth, band_to_dense
  use flexmech_coupled_system, only: coupled_system, elem_index
  use flexmech_saddle_band, only: saddle_system, saddle_setup, saddle_zero, saddle_add6, saddle_add_diag, &
                                  saddle_s_entry
  implicit none
  private
  public :: link_mats, lm_setup, lm_band_setup, lm_bordered_setup, lm_zero, lm_put_one, lm_band_finish, lm_dense
  public :: lm_add, lm_add_pair, lm_add_block, lm_block_get, lm_block_put, lm_factor, lm_solve

  !> Iteration matrix S = M + cc C_v + ck K_t stored by segment blocks.  Local DOFs of segment l:
  !> 1..4 the end positions ("boundary", B), 5..nl the elastic DOFs ("interior", I; ni_l = nl - 4),
  !> numbered off(l)+1..off(l)+ni_l in the interior arrays.
  !>   bb(4, 4, l)   S_BB block of the segment            bi(4, ni)  S_BI (rows: local 1..4)
  !>   ib(ni, 4)     S_IB (columns: local 1..4)           ai(ldi, ni) S_II, LAPACK band storage with
  !>                 kl = ku = kbi (row 2 kbi + 1 + i - j), factorized in place (ipi) by the condensed solve
  !>   dg(nfree)     diagonal of the rigid bodies (their DOFs are boundary DOFs coupled to nothing else)
  !> Condensed solve (cond = .true.: every interior DOF free and local to one segment):
  !>   z = S_II^-1 S_IB per segment, Schur complement sb = S_BB - S_BI z over the nb free boundary DOFs
  !>   (band kbb, LAPACK storage, ipb), workspaces yi(ni, nrhs), yb(nb, nrhs).
  type :: link_mats
    integer :: ni = 0, kbi = 0, ldi = 0, nb = 0, kbb = 0, ldb = 0, nrhs = 0
    logical :: cond = .false.
    integer, allocatable :: off(:), ifree(:), bfree(:, :), bglob(:), ipi(:), ipb(:)
    integer, allocatable :: fl(:, :)     !< (maxld, nseg) free-DOF number of each local DOF (0: fixed)
    !> the whole free-DOF band (LAPACK storage, kl = ku = sys%kl; lm_band_setup) when S is factorized
    !> as one band: one-element segments write their block straight into it (lm_put_one, inband(l)),
    !> the others and the rigid bodies through the blocks above (lm_band_finish)
    real(dp), allocatable :: ab(:, :)
    logical, allocatable :: inband(:)
    !> every segment went straight into lm%ab at the last lm_band_finish: the segment blocks were not
    !> written since they were zeroed, and lm_zero leaves them
    logical :: blocks_clean = .false.
    integer :: kd = 0                    !< lm%ab's diagonal row, kl + ku + 1
    !> the saddle-point system of the multipliers (flexmech_saddle_band); when bordered, S itself lives
    !> there (lm_bordered_setup: the one-element segments and rigid bodies write straight into it)
    type(saddle_system) :: sd
    logical :: bordered = .false.
    real(dp), allocatable :: bb(:, :, :), bi(:, :), ib(:, :), ai(:, :), z(:, :), sb(:, :), yi(:, :), yb(:, :), dg(:)
    !> assemble's work: a segment's all-DOF numbers and its local [R, q, v, a] (maxld; allocated once
    !> by lm_setup, so that no evaluation allocates; never referenced through lm by link_eval)
    integer, allocatable :: widx(:)
    real(dp), allocatable :: wl(:, :)
  end type link_mats

contains

  !> Allocate the segment-block storage of S (see link_mats) and, when every segment's elastic DOFs
  !> are free and its own, the condensed solve's arrays for up to nrhs right-hand sides.
  subroutine lm_setup(sys, nrhs, lm)
    type(coupled_system), intent(in) :: sys
    integer, intent(in) :: nrhs
    type(link_mats), intent(out) :: lm
    integer, allocatable :: bnum(:)
    allocate (lm%off(sys%nseg), lm%bfree(4, sys%nseg), lm%widx(sys%maxld), lm%wl(sys%maxld, 4))
    allocate (lm%fl(sys%maxld, sys%nseg))
    call interior_layout(sys, lm)
    lm%nrhs = max(1, nrhs)
    allocate (lm%bb(4, 4, sys%nseg), lm%bi(4, lm%ni), lm%ib(lm%ni, 4), lm%ai(lm%ldi, lm%ni), lm%ifree(lm%ni))
    allocate (lm%dg(sys%nfree))
    lm%dg = 0.0_dp
    call boundary_dofs(sys, lm, bnum)
    call boundary_band(sys, lm, bnum)
    if (lm%cond) then
      allocate (lm%z(lm%ni, 4), lm%sb(lm%ldb, lm%nb), lm%ipi(lm%ni), lm%ipb(lm%nb), lm%yi(lm%ni, lm%nrhs), &
                lm%yb(lm%nb, lm%nrhs))
    end if
  end subroutine lm_setup

  !> Every segment's free-DOF numbers per local DOF (lm%fl), its interior offset (lm%off), the
  !> number of interior DOFs (lm%ni) and their band (lm%kbi, lm%ldi: coupling is element by element).
  pure subroutine interior_layout(sys, lm)
    type(coupled_system), intent(in) :: sys
    type(link_mats), intent(inout) :: lm
    integer :: l, n, nl, e, idx(6)
    lm%fl = 0
    lm%ni = 0; lm%kbi = 0
    do l = 1, sys%nseg
      n = sys%n_el(l); nl = 3*n + 3
      lm%fl(1:nl, l) = sys%free_of(sys%ld(1:nl, l))
      lm%off(l) = lm%ni
      lm%ni = lm%ni + nl - 4
      do e = 1, n
        idx = elem_index(n, e)
        lm%kbi = max(lm%kbi, maxval(idx) - minval(idx, mask=idx > 0))
      end do
    end do
    lm%ldi = 3*lm%kbi + 1
  end subroutine interior_layout

  !> The interior DOFs' free numbers (lm%ifree), the boundary DOFs (segment ends and rigid bodies)
  !> numbered in free order (bnum, lm%bglob, lm%nb), and whether the condensed solve applies (lm%cond:
  !> interior DOFs free, in one segment only, never an end position; every free DOF one or the other).
  subroutine boundary_dofs(sys, lm, bnum)
    type(coupled_system), intent(in) :: sys
    type(link_mats), intent(inout) :: lm
    integer, allocatable, intent(out) :: bnum(:)
    integer, allocatable :: cnt(:)
    logical, allocatable :: isb(:)
    integer :: l, nl, k, f
    allocate (cnt(sys%nfree), isb(sys%nfree), bnum(sys%nfree))
    cnt = 0; isb = .false.
    lm%cond = .true.
    do l = 1, sys%nseg
      nl = 3*sys%n_el(l) + 3
      do k = 1, 4
        f = sys%free_of(sys%ld(k, l))
        if (f > 0) isb(f) = .true.
      end do
      do k = 5, nl
        f = sys%free_of(sys%ld(k, l))
        lm%ifree(lm%off(l) + k - 4) = f
        if (f > 0) then
          cnt(f) = cnt(f) + 1
        else
          lm%cond = .false.
        end if
      end do
    end do
    do l = 1, sys%nrb        ! rigid-body DOFs: boundary DOFs with a diagonal block
      do k = 1, 3
        f = sys%free_of(sys%rb_dof(k, l))
        if (f > 0) isb(f) = .true.
      end do
    end do
    if (any(cnt > 1) .or. any(cnt > 0 .and. isb) .or. any(cnt == 0 .and. .not. isb)) lm%cond = .false.
    lm%nb = count(isb)
    if (lm%nb == 0) lm%cond = .false.
    bnum = 0
    allocate (lm%bglob(lm%nb))
    k = 0
    do f = 1, sys%nfree      ! boundary DOFs in the order of the free numbering (its band carries over)
      if (.not. isb(f)) cycle
      k = k + 1
      bnum(f) = k; lm%bglob(k) = f
    end do
  end subroutine boundary_dofs

  !> Every segment's boundary numbers per end-position DOF (lm%bfree) and the condensed band
  !> (lm%kbb, lm%ldb).
  pure subroutine boundary_band(sys, lm, bnum)
    type(coupled_system), intent(in) :: sys
    type(link_mats), intent(inout) :: lm
    integer, intent(in) :: bnum(:)
    integer :: l, k, f
    do l = 1, sys%nseg
      do k = 1, 4
        f = sys%free_of(sys%ld(k, l))
        lm%bfree(k, l) = 0
        if (f > 0) lm%bfree(k, l) = bnum(f)
      end do
    end do
    lm%kbb = half_bandwidth(lm%bfree)
    lm%ldb = 3*lm%kbb + 1
  end subroutine boundary_band

  !> S(i, j) += val for the local DOFs i, j of segment l (the entry must lie in the block structure).
  pure subroutine lm_add(lm, l, i, j, val)
    type(link_mats), intent(inout) :: lm
    integer, intent(in) :: l, i, j
    real(dp), intent(in) :: val
    if (i <= 4) then
      if (j <= 4) then
        lm%bb(i, j, l) = lm%bb(i, j, l) + val
      else
        lm%bi(i, lm%off(l) + j - 4) = lm%bi(i, lm%off(l) + j - 4) + val
      end if
    else if (j <= 4) then
      lm%ib(lm%off(l) + i - 4, j) = lm%ib(lm%off(l) + i - 4, j) + val
    else
      lm%ai(2*lm%kbi + 1 + i - j, lm%off(l) + j - 4) = lm%ai(2*lm%kbi + 1 + i - j, lm%off(l) + j - 4) + val
    end if
  end subroutine lm_add

  !> S(fi, fj) += val at free DOFs fi, fj, when S's storage holds that entry (stored true): a pair within
  !> the band when S is one band, else a pair within one segment or a rigid body's diagonal entry (dg).
  !> With add false only whether it is stored.
  pure subroutine lm_add_pair(sys, lm, fi, fj, val, add, stored)
    type(coupled_system), intent(in) :: sys
    type(link_mats), intent(inout) :: lm
    integer, intent(in) :: fi, fj
    real(dp), intent(in) :: val
    logical, intent(in) :: add
    logical, intent(out) :: stored
    integer :: l, li, lj
    real(dp) :: s6(6, 6)
    if (allocated(lm%ab) .and. .not. lm%bordered) then
      stored = fi - fj <= sys%kl .and. fj - fi <= sys%ku
      if (stored .and. add) lm%ab(lm%kd + fi - fj, fj) = lm%ab(lm%kd + fi - fj, fj) + val
      return
    end if
    stored = .false.
    do l = 1, sys%nseg
      li = findloc(lm%fl(1:3*sys%n_el(l) + 3, l), fi, 1)
      lj = findloc(lm%fl(1:3*sys%n_el(l) + 3, l), fj, 1)
      stored = li > 0 .and. lj > 0
      if (stored) exit
    end do
    if (.not. stored .and. fi == fj) then    ! a rigid body's DOF: its diagonal
      stored = .true.
      if (add) lm%dg(fi) = lm%dg(fi) + val
      return
    end if
    if (.not. (stored .and. add)) return
    if (lm%bordered) then
      s6 = 0.0_dp
      s6(li, lj) = val
      call saddle_add6(lm%sd, lm%fl(1:6, l), s6)
    else
      call lm_add(lm, l, li, lj, val)
    end if
  end subroutine lm_add_pair

  !> S(cl(i), cl(j)) += blk(i, j), i, j = 1..ncl, local DOFs of segment l.
  pure subroutine lm_add_block(lm, l, ncl, cl, blk)
    type(link_mats), intent(inout) :: lm
    integer, intent(in) :: l, ncl, cl(:)
    real(dp), intent(in) :: blk(:, :)
    integer :: i, j, o, d
    if (.not. ends_first(ncl, cl)) then
      do j = 1, ncl          ! any order: entry by entry
        do i = 1, ncl
          call lm_add(lm, l, cl(i), cl(j), blk(i, j))
        end do
      end do
      return
    end if
    o = lm%off(l) - 4; d = 2*lm%kbi + 1   ! the end positions first, then elastic DOFs: by quadrant
    lm%bb(:, :, l) = lm%bb(:, :, l) + blk(1:4, 1:4)
    do j = 5, ncl
      lm%bi(:, o + cl(j)) = lm%bi(:, o + cl(j)) + blk(1:4, j)
      lm%ib(o + cl(j), :) = lm%ib(o + cl(j), :) + blk(j, 1:4)
      do i = 5, ncl
        lm%ai(d + cl(i) - cl(j), o + cl(j)) = lm%ai(d + cl(i) - cl(j), o + cl(j)) + blk(i, j)
      end do
    end do
  end subroutine lm_add_block

  !> cl(1:4) are the end positions 1..4 and cl(5:ncl) elastic DOFs (> 4): lm_add_block by quadrant.
  pure logical function ends_first(ncl, cl)
    integer, intent(in) :: ncl, cl(:)
    integer :: k
    ends_first = ncl >= 4
    if (.not. ends_first) return
    do k = 1, 4
      ends_first = ends_first .and. cl(k) == k
    end do
    ends_first = ends_first .and. all(cl(5:ncl) > 4)
  end function ends_first

  !> The 6 x 6 block of one-element segment l (local DOFs [xs ys xe ye th_0 th_1]) out of its
  !> storage in lm, and back (lm_block_put), for dense work on it.
  pure subroutine lm_block_get(lm, l, s6)
    type(link_mats), intent(in) :: lm
    integer, intent(in) :: l
    real(dp), intent(out) :: s6(6, 6)
    integer :: o, d, i, j
    o = lm%off(l); d = 2*lm%kbi + 1
    s6(1:4, 1:4) = lm%bb(:, :, l)
    s6(1:4, 5:6) = lm%bi(1:4, o + 1:o + 2)
    s6(5:6, 1:4) = lm%ib(o + 1:o + 2, 1:4)
    do j = 5, 6
      do i = 5, 6
        s6(i, j) = lm%ai(d + i - j, o + j - 4)
      end do
    end do
  end subroutine lm_block_get

  pure subroutine lm_block_put(lm, l, s6)
    type(link_mats), intent(inout) :: lm
    integer, intent(in) :: l
    real(dp), intent(in) :: s6(6, 6)
    integer :: o, d, i, j
    o = lm%off(l); d = 2*lm%kbi + 1
    lm%bb(:, :, l) = s6(1:4, 1:4)
    lm%bi(1:4, o + 1:o + 2) = s6(1:4, 5:6)
    lm%ib(o + 1:o + 2, 1:4) = s6(5:6, 1:4)
    do j = 5, 6
      do i = 5, 6
        lm%ai(d + i - j, o + j - 4) = s6(i, j)
      end do
    end do
  end subroutine lm_block_put

  !> The whole free-DOF band lm%ab for the solves that factorize S as one band (see link_mats).
  subroutine lm_band_setup(sys, lm)
    type(coupled_system), intent(in) :: sys
    type(link_mats), intent(inout) :: lm
    allocate (lm%ab(band_rows(sys%kl, sys%ku), sys%nfree), lm%inband(sys%nseg))
    lm%kd = sys%kl + sys%ku + 1
    lm%ab = 0.0_dp
    lm%inband = .false.
  end subroutine lm_band_setup

  !> S in the nonlinear model's bordered saddle band (sys%nbd >= 0; every segment one element): its
  !> order from the free numbering, the border flags and the rows' gradient patterns ngnz, gnz
  !> (flexmech_coupled_rows: row_patterns), S's pattern the segments' cliques.
  subroutine lm_bordered_setup(sys, lm, ngnz, gnz)
    type(coupled_system), intent(in) :: sys
    type(link_mats), intent(inout) :: lm
    integer, intent(in) :: ngnz(:), gnz(:, :)
    call saddle_setup(sys%nfree, sys%nc, sys%nbd, sys%row_border, ngnz, gnz, lm%sd, cliques=lm%fl(1:6, :))
    allocate (lm%inband(sys%nseg))
    lm%inband = .false.
    lm%bordered = .true.
  end subroutine lm_bordered_setup

  !> S as a dense matrix over the free DOFs (after lm_band_finish; the tests' matrices).
  subroutine lm_dense(sys, lm, s)
    type(coupled_system), intent(in) :: sys
    type(link_mats), intent(in) :: lm
    real(dp), intent(out) :: s(:, :)
    integer :: i, j
    if (.not. lm%bordered) then
      s = band_to_dense(lm%ab, sys%kl, sys%ku, sys%nfree)
      return
    end if
    do j = 1, sys%nfree
      do i = 1, sys%nfree
        s(i, j) = saddle_s_entry(lm%sd, i, j)
      end do
    end do
  end subroutine lm_dense

  !> S = 0 before an assembly: the segment blocks (unless no segment wrote them, blocks_clean), the
  !> rigid bodies' diagonal and lm%ab if there is one.
  subroutine lm_zero(lm)
    type(link_mats), intent(inout) :: lm
    if (.not. lm%blocks_clean) then
      lm%bb = 0.0_dp; lm%bi = 0.0_dp; lm%ib = 0.0_dp; lm%ai = 0.0_dp
    end if
    lm%dg = 0.0_dp
    if (lm%bordered) then
      call saddle_zero(lm%sd)
      lm%inband = .false.
    end if
    if (.not. allocated(lm%ab)) return
    lm%ab = 0.0_dp
    lm%inband = .false.
  end subroutine lm_zero

  !> The whole 6 x 6 block s6 of one-element segment l (local DOFs [xs ys xe ye th_0 th_1]): straight
  !> into the bordered saddle band or lm%ab when there is one, else into the segment blocks.
  pure subroutine lm_put_one(sys, lm, l, s6)
    type(coupled_system), intent(in) :: sys
    type(link_mats), intent(inout) :: lm
    integer, intent(in) :: l
    real(dp), intent(in) :: s6(6, 6)
    if (lm%bordered) then
      call saddle_add6(lm%sd, lm%fl(1:6, l), s6)
      lm%inband(l) = .true.
      return
    end if
    if (.not. allocated(lm%ab)) then
      call lm_block_put(lm, l, s6)
      return
    end if
    call band_add_element6(lm%ab, size(lm%ab, 1), sys%kl, sys%ku, lm%fl(1:6, l), s6)
    lm%inband(l) = .true.
  end subroutine lm_put_one

  !> lm%ab += the segment blocks of the segments not written into it and the rigid bodies' diagonal:
  !> the whole band S (LAPACK storage, kl = ku = sys%kl, over the free DOFs), ready to factorize.
  subroutine lm_band_finish(sys, lm)
    type(coupled_system), intent(in) :: sys
    type(link_mats), intent(inout) :: lm
    integer :: l, nl, m, o, i, j, ii, jj, fi, fj, d
    real(dp) :: s6(6, 6)
    if (lm%bordered) then     ! every segment is one element (those of the Gauss-point path: by block)
      do l = 1, sys%nseg
        if (lm%inband(l)) cycle
        call lm_block_get(lm, l, s6)
        call saddle_add6(lm%sd, lm%fl(1:6, l), s6)
      end do
      do fi = 1, sys%nfree
        if (lm%dg(fi) /= 0.0_dp) call saddle_add_diag(lm%sd, fi, lm%dg(fi))
      end do
      lm%blocks_clean = all(lm%inband)
      return
    end if
    d = lm%kd
    do l = 1, sys%nseg
      if (lm%inband(l)) cycle
      nl = 3*sys%n_el(l) + 3; m = nl - 4; o = lm%off(l)
      do j = 1, 4
        fj = lm%fl(j, l)
        if (fj == 0) cycle
        do i = 1, 4
          fi = lm%fl(i, l)
          if (fi > 0) lm%ab(d + fi - fj, fj) = lm%ab(d + fi - fj, fj) + lm%bb(i, j, l)
        end do
        do ii = 1, m
          fi = lm%fl(4 + ii, l)
          if (fi > 0) lm%ab(d + fi - fj, fj) = lm%ab(d + fi - fj, fj) + lm%ib(o + ii, j)
        end do
      end do
      do jj = 1, m
        fj = lm%fl(4 + jj, l)
        if (fj == 0) cycle
        do i = 1, 4
          fi = lm%fl(i, l)
          if (fi > 0) lm%ab(d + fi - fj, fj) = lm%ab(d + fi - fj, fj) + lm%bi(i, o + jj)
        end do
        do ii = max(1, jj - lm%kbi), min(m, jj + lm%kbi)
          fi = lm%fl(4 + ii, l)
          if (fi > 0) lm%ab(d + fi - fj, fj) = lm%ab(d + fi - fj, fj) + lm%ai(2*lm%kbi + 1 + ii - jj, o + jj)
        end do
      end do
    end do
    do fi = 1, sys%nfree
      lm%ab(d, fi) = lm%ab(d, fi) + lm%dg(fi)
    end do
    lm%blocks_clean = all(lm%inband)
  end subroutine lm_band_finish

  !> Condensed factorization: per segment S_II = LU (in place) and z = S_II^-1 S_IB; the Schur
  !> complement sb = S_BB - S_BI z on the boundary DOFs, assembled and factorized (band kbb).
  subroutine lm_factor(sys, lm, status)
    type(coupled_system), intent(in) :: sys
    type(link_mats), intent(inout) :: lm
    integer, intent(out) :: status
    integer :: l, m, o, i, j, ii, bi, bj, info, d
    real(dp) :: val
    d = 2*lm%kbb + 1
    lm%sb = 0.0_dp
    do l = 1, sys%nseg
      m = 3*sys%n_el(l) - 1; o = lm%off(l)
      call dgbtrf(m, m, lm%kbi, lm%kbi, lm%ai(1, o + 1), lm%ldi, lm%ipi(o + 1), info)
      status = lapack_status(info)
      if (status /= STATUS_OK) return
      lm%z(o + 1:o + m, :) = lm%ib(o + 1:o + m, :)
      call dgbtrs('N', m, lm%kbi, lm%kbi, 4, lm%ai(1, o + 1), lm%ldi, lm%ipi(o + 1), lm%z(o + 1, 1), lm%ni, info)
      do j = 1, 4
        bj = lm%bfree(j, l)
        if (bj == 0) cycle
        do i = 1, 4
          bi = lm%bfree(i, l)
          if (bi == 0) cycle
          val = lm%bb(i, j, l)
          do ii = 1, m
            val = val - lm%bi(i, o + ii)*lm%z(o + ii, j)
          end do
          lm%sb(d + bi - bj, bj) = lm%sb(d + bi - bj, bj) + val
        end do
      end do
    end do
    do bi = 1, lm%nb
      lm%sb(d, bi) = lm%sb(d, bi) + lm%dg(lm%bglob(bi))
    end do
    call dgbtrf(lm%nb, lm%nb, lm%kbb, lm%kbb, lm%sb, lm%ldb, lm%ipb, info)
    status = lapack_status(info)
  end subroutine lm_factor

  !> Solve S x = xx(:, k), k = 1..nrhs (nrhs <= lm%nrhs), with the condensed factorization, in place:
  !> interior solves y = S_II^-1 r_I, boundary system sb x_B = r_B - S_BI y, back substitution
  !> x_I = y - z x_B.
  subroutine lm_solve(sys, lm, nrhs, xx, ldx, status)
    type(coupled_system), intent(in) :: sys
    type(link_mats), intent(inout) :: lm
    integer, intent(in) :: nrhs, ldx
    real(dp), intent(inout) :: xx(ldx, *)
    integer, intent(out) :: status
    integer :: l, m, o, i, j, k, b, info
    status = STATUS_OK
    do k = 1, nrhs
      do i = 1, lm%ni
        lm%yi(i, k) = xx(lm%ifree(i), k)
      end do
      do i = 1, lm%nb
        lm%yb(i, k) = xx(lm%bglob(i), k)
      end do
    end do
    do l = 1, sys%nseg
      m = 3*sys%n_el(l) - 1; o = lm%off(l)
      call dgbtrs('N', m, lm%kbi, lm%kbi, nrhs, lm%ai(1, o + 1), lm%ldi, lm%ipi(o + 1), lm%yi(o + 1, 1), lm%ni, info)
      do k = 1, nrhs
        do i = 1, 4
          b = lm%bfree(i, l)
          if (b > 0) lm%yb(b, k) = lm%yb(b, k) - dot_product(lm%bi(i, o + 1:o + m), lm%yi(o + 1:o + m, k))
        end do
      end do
    end do
    call dgbtrs('N', lm%nb, lm%kbb, lm%kbb, nrhs, lm%sb, lm%ldb, lm%ipb, lm%yb, lm%nb, info)
    do l = 1, sys%nseg
      m = 3*sys%n_el(l) - 1; o = lm%off(l)
      do k = 1, nrhs
        do j = 1, 4
          b = lm%bfree(j, l)
          if (b > 0) lm%yi(o + 1:o + m, k) = lm%yi(o + 1:o + m, k) - lm%z(o + 1:o + m, j)*lm%yb(b, k)
        end do
      end do
    end do
    do k = 1, nrhs
      do i = 1, lm%ni
        xx(lm%ifree(i), k) = lm%yi(i, k)
      end do
      do i = 1, lm%nb
        xx(lm%bglob(i), k) = lm%yb(i, k)
      end do
    end do
    if (.not. ieee_is_finite(sum(abs(lm%yb(:, 1:nrhs))) + sum(abs(lm%yi(:, 1:nrhs))))) status = STATUS_NONFINITE
  end subroutine lm_solve

end module flexmech_coupled_storage
