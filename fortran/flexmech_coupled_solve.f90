!> The linear algebra of a Newton correction of the coupled and nonlinear models (the time loop:
!> flexmech_coupled_run): the iteration matrix S (assembled into link_mats) with the gradients G of
!> the constraint rows, factorized once per matrix and solved for every iteration,
!>   [S  G] [da  ]   [-R    ]
!>   [G' 0] [dlam] = [-shift] ,
!> by one of four structures (docs/theory.md sections 11.3 and 12.6):
!>   PATH_BAND_SCHUR    S as one free-DOF band (LAPACK), the multipliers by their dense Schur
!>                      complement G' S^-1 G (nc solves and an nc x nc LU per factorization);
!>   PATH_BAND_SADDLE   S from that band into one saddle band with the multipliers interleaved;
!>   PATH_CONDENSED     every segment's elastic DOFs condensed onto the shared end positions
!>                      (flexmech_coupled_storage), the multipliers by their Schur complement;
!>   PATH_BORDERED      the nonlinear model's bordered saddle band (flexmech_saddle_band): chains of
!>                      elements as one narrow band, the few junction and body unknowns a dense
!>                      border; linear in the elements for any mechanism.
!> The choice (solver_mode, multiplier_mode; module-wide, settable for tests and benchmarks) is made
!> once per run by ns_setup; ns_structure reports it with its operation counts.
module flexmech_coupled_solve
  use, intrinsic :: ieee_arithmetic, only: ieee_is_finite
  use flexmech_kinds, only: dp
  use flexmech_lapack, only: dgbtrf, dgbtrs, dgetrf, dgetrs, lapack_status, STATUS_OK, STATUS_NONFINITE, &
                             STATUS_BAD_INPUT
  use flexmech_markers, only: marker_state, MAXCOL, con_residual
  use flexmech_coupled_system, only: coupled_system, set_mode
  use flexmech_coupled_rows, only: eval_row, row_patterns
  use flexmech_coupled_storage, only: link_mats, lm_setup, lm_band_setup, lm_bordered_setup, lm_band_finish, &
                                      lm_factor, lm_solve
  use flexmech_saddle_band, only: saddle_setup, saddle_take_band, saddle_factor, saddle_solve, saddle_flops, &
                                  saddle_work
  implicit none
  private
  public :: newton_solver, ns_setup, ns_factor, ns_rows, ns_correction, ns_gdot, ns_structure
  public :: coupled_set_solver, SOLVER_AUTO, SOLVER_BAND, SOLVER_CONDENSED, SOLVER_BORDERED
  public :: coupled_set_multipliers, MULT_AUTO, MULT_SCHUR, MULT_SADDLE
  public :: PATH_BAND_SCHUR, PATH_BAND_SADDLE, PATH_CONDENSED, PATH_BORDERED

  !> Linear solver of the iteration matrix: SOLVER_CONDENSED eliminates every segment's elastic DOFs (a
  !> band of half width <= 5) onto the shared end-position DOFs and solves the condensed band system;
  !> SOLVER_BAND factorizes the whole free-DOF band matrix (half bandwidth 3 x elements per segment +
  !> 2); SOLVER_BORDERED the bordered saddle band of a layout that has one (the nonlinear model);
  !> SOLVER_AUTO (default) the bordered band where the layout has a border (the nonlinear model of a
  !> mechanism whose elements are not one chain), the whole band for the nonlinear model of a single
  !> chain (numbered as one band: a loop fixed to the ground, a serial arm), else the condensed solve
  !> when the whole band is wider than the interior band + 4 (the coupled model's arrowheads widen it:
  !> 2 or more elements per segment), else the whole band.
  integer, parameter :: SOLVER_AUTO = -1, SOLVER_BAND = 0, SOLVER_CONDENSED = 1, SOLVER_BORDERED = 2
  integer :: solver_mode = SOLVER_AUTO
  !> How the whole band reaches the constraint rows' multipliers: MULT_SCHUR by the dense Schur
  !> complement (cheap for the few rows of a mechanism's joints), MULT_SADDLE by the band LU of the
  !> whole saddle-point system (linear in the number of rows), MULT_AUTO (default) the one of fewer
  !> flops by saddle_flops.  The condensed solve always uses the Schur complement.
  integer, parameter :: MULT_AUTO = -1, MULT_SCHUR = 0, MULT_SADDLE = 1
  integer :: multiplier_mode = MULT_AUTO
  integer, parameter :: PATH_BAND_SCHUR = 0, PATH_BAND_SADDLE = 1, PATH_CONDENSED = 2, PATH_BORDERED = 3

  !> One run's solver: its path, the constraint gradients on their patterns (gc(k, i): the entry of
  !> free DOF gnz(k, i) in row i, k = 1..ngnz(i); memory linear in the rows), the Schur paths' X =
  !> S^-1 G (free DOFs x rows), its dense matrix and pivots (allocated on those paths only: the
  !> band saddle and bordered paths keep the memory linear in the mesh), the rows' errors gval and
  !> velocity parts acc0, and the work vectors of a correction.
  type :: newton_solver
    integer :: nf = 0, nc = 0, path = PATH_BAND_SCHUR
    !> S was factorized since the gradients were last taken in (ns_rows completes the factorization)
    logical :: refactor = .false.
    integer, allocatable :: freeidx(:), ipiv(:), ipc(:), gnz(:, :), ngnz(:)
    !> slot(j, i): the pattern slot the j-th column of row i's evaluation took last (checked, then
    !> searched on a miss: the columns come in the same order at every evaluation)
    integer, allocatable :: slot(:, :)
    real(dp), allocatable :: gc(:, :), x(:, :), amat(:, :), rf(:), dlam(:), gval(:), acc0(:)
  end type newton_solver

contains

  !> Select the linear solver (SOLVER_*; module-wide).  status STATUS_BAD_INPUT for another value.
  subroutine coupled_set_solver(mode, status)
    integer, intent(in) :: mode
    integer, intent(out) :: status
    call set_mode(mode, SOLVER_AUTO, SOLVER_BORDERED, solver_mode, status)
  end subroutine coupled_set_solver

  !> Select how the whole band reaches the multipliers (MULT_*); status STATUS_BAD_INPUT otherwise.
  subroutine coupled_set_multipliers(mode, status)
    integer, intent(in) :: mode
    integer, intent(out) :: status
    call set_mode(mode, MULT_AUTO, MULT_SADDLE, multiplier_mode, status)
  end subroutine coupled_set_multipliers

  !> The storage of S (lm), the rows' gradient patterns at (q, v), the path and its work arrays.
  subroutine ns_setup(sys, q, v, lm, ns)
    type(coupled_system), intent(in) :: sys
    real(dp), intent(in) :: q(:), v(:)
    type(link_mats), intent(out) :: lm
    type(newton_solver), intent(out) :: ns
    integer :: i, nc1, zero(max(1, sys%nc))
    real(dp) :: fl(2)
    logical :: bordered
    ns%nf = sys%nfree; ns%nc = sys%nc; nc1 = max(1, sys%nc)
    allocate (ns%gc(2*MAXCOL, nc1), ns%gnz(2*MAXCOL, nc1), ns%ngnz(nc1), ns%slot(2*MAXCOL, nc1), &
              ns%rf(ns%nf), ns%dlam(nc1), ns%gval(nc1), ns%acc0(nc1), ns%freeidx(ns%nf), ns%ipiv(ns%nf))
    ns%gc = 0.0_dp
    ns%slot = 1
    do i = 1, sys%ndof
      if (sys%free_of(i) > 0) ns%freeidx(sys%free_of(i)) = i
    end do
    call row_patterns(sys, q, v, ns%ngnz, ns%gnz)
    ! the bordered band where the layout has a border; a layout without one (a single chain) keeps the
    ! whole band, numbered as it always was, and its choice of the multipliers' path below
    bordered = solver_mode == SOLVER_BORDERED .or. solver_mode == SOLVER_AUTO .and. sys%nbd > 0
    if (sys%nbd == 0 .and. solver_mode == SOLVER_AUTO) bordered = any(sys%row_border(1:sys%nc) /= 0)
    bordered = bordered .and. sys%nbd >= 0
    ! the condensed solve's columns for the rows (nc of them) only where it may be taken: the coupled
    ! model, or forced
    call lm_setup(sys, merge(ns%nc, 1, .not. bordered .and. (sys%nbd < 0 .or. solver_mode == SOLVER_CONDENSED)), &
                  lm)
    if (bordered) then
      call lm_bordered_setup(sys, lm, ns%ngnz, ns%gnz)
      ns%path = PATH_BORDERED
      return
    end if
    if (lm%cond .and. (solver_mode == SOLVER_CONDENSED .or. &
                       (solver_mode == SOLVER_AUTO .and. sys%nbd < 0 .and. sys%kl > lm%kbi + 4))) then
      ns%path = PATH_CONDENSED
      call schur_storage(ns)
      return
    end if
    call lm_band_setup(sys, lm)     ! S as one band, in lm%ab
    ns%path = PATH_BAND_SCHUR
    if (ns%nc == 0 .or. multiplier_mode == MULT_SCHUR) then
      call schur_storage(ns)
      return
    end if
    zero = 0           ! S's pattern: the segments' blocks (one-element segments), else its whole band
    if (sys%maxn == 1) then
      call saddle_setup(ns%nf, ns%nc, 0, zero, ns%ngnz, ns%gnz, lm%sd, cliques=lm%fl(1:6, :))
    else
      call saddle_setup(ns%nf, ns%nc, 0, zero, ns%ngnz, ns%gnz, lm%sd, kl=sys%kl)
    end if
    fl = saddle_flops(ns%nf, ns%nc, sys%kl, lm%sd%ka)
    if (multiplier_mode == MULT_SADDLE .or. fl(2) < fl(1)) then
      ns%path = PATH_BAND_SADDLE
    else
      call schur_storage(ns)
    end if
  end subroutine ns_setup

  !> The Schur paths' X = S^-1 G (free DOFs x rows), their dense matrix and its pivots.
  subroutine schur_storage(ns)
    type(newton_solver), intent(inout) :: ns
    allocate (ns%x(ns%nf, max(1, ns%nc)), ns%amat(max(1, ns%nc), max(1, ns%nc)), ns%ipc(max(1, ns%nc)))
  end subroutine schur_storage

  !> Factorize the assembled S (the condensed segments, or the whole band; the saddle and bordered
  !> bands once the gradients are known, in ns_rows).
  subroutine ns_factor(sys, lm, ns, status)
    type(coupled_system), intent(in) :: sys
    type(link_mats), intent(inout) :: lm
    type(newton_solver), intent(inout) :: ns
    integer, intent(out) :: status
    integer :: info
    status = STATUS_OK
    if (ns%path == PATH_CONDENSED) then
      call lm_factor(sys, lm, status)
    else
      call lm_band_finish(sys, lm)
      if (ns%path == PATH_BAND_SCHUR) then
        call dgbtrf(ns%nf, ns%nf, sys%kl, sys%ku, lm%ab, size(lm%ab, 1), ns%ipiv, info)
        status = lapack_status(info)
      end if
    end if
    ns%refactor = .true.
  end subroutine ns_factor

  !> The rows at (q, v): gradients gc, errors gval = g - cv (cv: the rows' values at this time; angles
  !> to their principal value), velocity parts acc0 of g'', and G^T lam added to res; after a
  !> factorization the rest of it (the saddle or bordered band's LU with G, or X = S^-1 G and the
  !> Schur matrix).
  subroutine ns_rows(sys, lm, ns, q, v, cv, lam, res, status)
    type(coupled_system), intent(in) :: sys
    type(link_mats), intent(inout) :: lm
    type(newton_solver), intent(inout) :: ns
    real(dp), intent(in) :: q(:), v(:), cv(:), lam(:)
    real(dp), intent(inout) :: res(:)
    integer, intent(out) :: status
    integer :: ic, j, k, f, ncl, cols(2*MAXCOL)
    real(dp) :: gv, gd, grad(2*MAXCOL)
    type(marker_state) :: ma, mb
    status = STATUS_OK
    do ic = 1, ns%nc
      call eval_row(sys, sys%con(1, ic), sys%con(4, ic), sys%con_dir(:, ic), sys%con(2, ic), sys%con(3, ic), &
                    q, v, gv, gd, ns%acc0(ic), ncl, cols, grad, ma, mb)
      ns%gval(ic) = con_residual(sys%con(1, ic), sys%con_dir(:, ic), gv - cv(ic))
      ns%gc(1:ns%ngnz(ic), ic) = 0.0_dp
      do j = 1, ncl
        res(cols(j)) = res(cols(j)) + lam(ic)*grad(j)
        f = sys%free_of(cols(j))
        if (f == 0) cycle
        k = ns%slot(j, ic)
        if (ns%gnz(k, ic) /= f) then
          k = pattern_slot(ns, ic, f)
          if (k == 0) then            ! a gradient off the pattern the run set up with (not expected)
            status = STATUS_BAD_INPUT
            return
          end if
          ns%slot(j, ic) = k
        end if
        ns%gc(k, ic) = ns%gc(k, ic) + grad(j)
      end do
    end do
    if (.not. ns%refactor) return
    ns%refactor = .false.
    select case (ns%path)
    case (PATH_BORDERED)
      call saddle_factor(lm%sd, ns%gc, ns%ngnz, ns%gnz, status)
    case (PATH_BAND_SADDLE)
      call saddle_take_band(lm%sd, lm%ab, sys%kl)
      call saddle_factor(lm%sd, ns%gc, ns%ngnz, ns%gnz, status)
    case default
      if (ns%nc > 0) call schur_matrix(sys, lm, ns, status)
    end select
  end subroutine ns_rows

  !> X = S^-1 G (all rows as one block) and the multipliers' matrix G' X, LU-factorized.
  subroutine schur_matrix(sys, lm, ns, status)
    type(coupled_system), intent(in) :: sys
    type(link_mats), intent(inout) :: lm
    type(newton_solver), intent(inout) :: ns
    integer, intent(out) :: status
    integer :: ic, j, info
    ns%x(:, 1:ns%nc) = 0.0_dp
    do j = 1, ns%nc
      ns%x(ns%gnz(1:ns%ngnz(j), j), j) = ns%gc(1:ns%ngnz(j), j)
    end do
    if (ns%path == PATH_CONDENSED) then
      call lm_solve(sys, lm, ns%nc, ns%x, ns%nf, status)
      if (status /= STATUS_OK) return
    else
      call dgbtrs('N', ns%nf, sys%kl, sys%ku, ns%nc, lm%ab, size(lm%ab, 1), ns%ipiv, ns%x, ns%nf, info)
    end if
    do j = 1, ns%nc
      do ic = 1, ns%nc
        ns%amat(ic, j) = ns_gdot(ns, ic, ns%x(:, j))
      end do
    end do
    call dgetrf(ns%nc, ns%nc, ns%amat, size(ns%amat, 1), ns%ipc, info)
    status = lapack_status(info)
  end subroutine schur_matrix

  !> One Newton correction at the assembled residual res (all DOFs, with G^T lam): solve
  !> S da + G dlam = -R, G' da = -shift (shift (nc): the rows' residual in the units of G' a), update
  !> a (all DOFs, free entries) and lam; da_norm = |da|, a_norm = |a|, newton(1:3) = [|R|, |da|, |a|].
  subroutine ns_correction(sys, lm, ns, res, shift, a, lam, da_norm, a_norm, newton, status)
    type(coupled_system), intent(in) :: sys
    type(link_mats), intent(inout) :: lm
    type(newton_solver), intent(inout) :: ns
    real(dp), intent(in) :: res(:), shift(:)
    real(dp), intent(inout) :: a(:), lam(:), newton(:)
    real(dp), intent(out) :: da_norm, a_norm
    integer, intent(out) :: status
    integer :: i, nc
    nc = ns%nc
    do i = 1, ns%nf
      ns%rf(i) = -res(ns%freeidx(i))
    end do
    newton(1) = norm2(ns%rf)
    da_norm = 0.0_dp; a_norm = 0.0_dp
    if (ns%path == PATH_BORDERED .or. ns%path == PATH_BAND_SADDLE) then
      ns%dlam(1:nc) = -shift(1:nc)
      call saddle_solve(lm%sd, ns%rf, ns%dlam(1:nc), status)
      if (status == STATUS_OK .and. .not. ieee_is_finite(sum(abs(ns%rf)) + sum(abs(ns%dlam(1:nc))))) &
        status = STATUS_NONFINITE
    else
      call schur_correction(sys, lm, ns, shift, status)
    end if
    if (status /= STATUS_OK) return
    lam(1:nc) = lam(1:nc) + ns%dlam(1:nc)
    do i = 1, ns%nf         ! a loop: a(freeidx) = a(freeidx) + rf would copy through the heap
      a(ns%freeidx(i)) = a(ns%freeidx(i)) + ns%rf(i)
      a_norm = a_norm + a(ns%freeidx(i))**2
    end do
    da_norm = sqrt(sum(ns%rf**2)); a_norm = sqrt(a_norm)
    newton(2:3) = [da_norm, a_norm]
  end subroutine ns_correction

  !> rf = -R on entry, da on return, dlam: da = S^-1 (-R) - X dlam with (G' X) dlam = G' S^-1 (-R) + shift.
  subroutine schur_correction(sys, lm, ns, shift, status)
    type(coupled_system), intent(in) :: sys
    type(link_mats), intent(inout) :: lm
    type(newton_solver), intent(inout) :: ns
    real(dp), intent(in) :: shift(:)
    integer, intent(out) :: status
    integer :: i, info
    status = STATUS_OK
    if (ns%path == PATH_CONDENSED) then
      call lm_solve(sys, lm, 1, ns%rf, ns%nf, status)
    else
      call dgbtrs('N', ns%nf, sys%kl, sys%ku, 1, lm%ab, size(lm%ab, 1), ns%ipiv, ns%rf, ns%nf, info)
    end if
    if (status == STATUS_OK .and. .not. ieee_is_finite(sum(abs(ns%rf)))) status = STATUS_NONFINITE
    if (status /= STATUS_OK .or. ns%nc == 0) return
    do i = 1, ns%nc
      ns%dlam(i) = ns_gdot(ns, i, ns%rf) + shift(i)
    end do
    call dgetrs('N', ns%nc, 1, ns%amat, size(ns%amat, 1), ns%ipc, ns%dlam, size(ns%dlam), info)
    if (.not. ieee_is_finite(sum(abs(ns%dlam(1:ns%nc))))) then
      status = STATUS_NONFINITE
      return
    end if
    do i = 1, ns%nc
      ns%rf = ns%rf - ns%x(:, i)*ns%dlam(i)
    end do
  end subroutine schur_correction

  !> G(:, ic)^T y (y over the free DOFs) on the gradient's nonzero pattern.
  pure real(dp) function ns_gdot(ns, ic, y)
    type(newton_solver), intent(in) :: ns
    integer, intent(in) :: ic
    real(dp), intent(in) :: y(:)
    integer :: k
    ns_gdot = 0.0_dp
    do k = 1, ns%ngnz(ic)
      ns_gdot = ns_gdot + ns%gc(k, ic)*y(ns%gnz(k, ic))
    end do
  end function ns_gdot

  !> The slot k of free DOF f in row ic's gradient pattern (gnz(k, ic) = f; 0: not on it).
  pure integer function pattern_slot(ns, ic, f) result(k)
    type(newton_solver), intent(in) :: ns
    integer, intent(in) :: ic, f
    do k = 1, ns%ngnz(ic)
      if (ns%gnz(k, ic) == f) return
    end do
    k = 0
  end function pattern_slot

  !> The path and its size: [path (PATH_*), unknowns in the band, the band's half width, unknowns
  !> eliminated densely (border, or the rows of a Schur complement), floating-point operations of one
  !> factorization and of one solve] (machine-independent: the tests read their growth with the mesh;
  !> the operation counts of saddle_work, and for the Schur paths the band LU 4 n kl^2, nc solves of
  !> 6 n kl, G' X and the dense LU; the condensed segments as bench.flops_condensed).
  function ns_structure(sys, lm, ns) result(info)
    type(coupled_system), intent(in) :: sys
    type(link_mats), intent(in) :: lm
    type(newton_solver), intent(in) :: ns
    real(dp) :: info(6)
    real(dp) :: n, k, c, fsolve, fl(2), m, kb
    c = real(ns%nc, dp)
    select case (ns%path)
    case (PATH_BORDERED, PATH_BAND_SADDLE)
      fl = saddle_work(lm%sd)
      info = [real(ns%path, dp), real(lm%sd%ni, dp), real(lm%sd%ka, dp), real(lm%sd%nb, dp), fl(1), fl(2)]
    case (PATH_CONDENSED)
      m = real(lm%ni, dp); k = real(lm%kbi, dp); n = real(lm%nb, dp); kb = real(lm%kbb, dp)
      fsolve = m*(6.0_dp*k + 16.0_dp) + 6.0_dp*n*kb
      info = [real(ns%path, dp), m, k, n + c, m*(4.0_dp*k*k + 24.0_dp*k + 32.0_dp) + 4.0_dp*n*kb*kb + &
              c*fsolve + 12.0_dp*c*c + 2.0_dp*c**3/3.0_dp, fsolve + 2.0_dp*c*c + 2.0_dp*real(ns%nf, dp)*c]
    case default
      n = real(ns%nf, dp); k = real(sys%kl, dp)
      fsolve = 6.0_dp*n*k
      info = [real(ns%path, dp), n, k, c, 4.0_dp*n*k*k + c*fsolve + 12.0_dp*c*c + 2.0_dp*c**3/3.0_dp, &
              fsolve + 2.0_dp*c*c + 2.0_dp*n*c]
    end select
  end function ns_structure

end module flexmech_coupled_solve
