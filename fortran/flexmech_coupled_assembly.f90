!> The coupled and nonlinear models' global residual and iteration matrix: every segment (link_eval),
!> the rigid bodies and the force drives, at one state; the dense parts and batches of residuals for
!> tests and the modal analysis.
module flexmech_coupled_assembly
  use flexmech_kinds, only: dp
  use flexmech_markers, only: marker_state, MAXCOL
  use flexmech_coupled_system, only: coupled_system
  use flexmech_coupled_rows, only: drive_load, row_patterns, control_gains, eval_row
  use flexmech_coupled_storage, only: link_mats, lm_setup, lm_zero, lm_band_setup, lm_bordered_setup, lm_band_finish, &
                                      lm_dense, lm_add_pair
  use flexmech_coupled_element, only: link_eval, segment_residual
  implicit none
  private
  public :: assemble, assemble_residual, coupled_dense, coupled_residual

contains

  !> Assemble the global residual R (all DOFs) at time t and, if want, the iteration matrix
  !> S = M + cc*C_v + ck*K_t over the free DOFs (segment blocks and the rigid bodies' diagonal, in lm).
  !> R holds the inertia, elastic, damping, gravity and force-drive terms (not the constraint forces).
  !> Returns energies [kinetic, potential (strain + gravity)] when not want (with want the
  !> one-element segments leave theirs out: the Newton iterations do not read them).
  subroutine assemble(sys, q, v, a, t, want, cc, ck, res, lm, energy)
    type(coupled_system), intent(in) :: sys
    real(dp), intent(in) :: q(:), v(:), a(:), t, cc, ck
    logical, intent(in) :: want
    real(dp), intent(out) :: res(:), energy(2)
    type(link_mats), intent(inout) :: lm
    integer :: l, nl
    real(dp) :: ek, ep
    res = 0.0_dp
    energy = 0.0_dp
    if (want) call lm_zero(lm)
    do l = 1, sys%nseg
      nl = 3*sys%n_el(l) + 3
      call gather(sys, l, nl, q, v, a, lm)
      call link_eval(sys, l, lm%wl(1:nl, 2), lm%wl(1:nl, 3), lm%wl(1:nl, 4), want, cc, ck, lm%wl(:, 1), lm, ek, ep)
      call scatter(nl, lm, res)
      energy = energy + [ek, ep]
    end do
    call bodies_eval(sys, q, v, a, want, res, lm, energy)
    call drive_loads(sys, q, v, t, res)
    if (want .and. sys%ctl%n > 0) call control_matrix(sys, q, v, t, cc, ck, lm)
  end subroutine assemble

  !> The global residual R alone (assemble's, without energies or matrix): the Newton iterations
  !> that keep the factorized matrix, and coupled_residual.
  subroutine assemble_residual(sys, q, v, a, t, res, lm)
    type(coupled_system), intent(in) :: sys
    real(dp), intent(in) :: q(:), v(:), a(:), t
    real(dp), intent(out) :: res(:)
    type(link_mats), intent(inout) :: lm
    integer :: l, nl
    real(dp) :: energy(2)
    res = 0.0_dp
    energy = 0.0_dp
    do l = 1, sys%nseg
      nl = 3*sys%n_el(l) + 3
      call gather(sys, l, nl, q, v, a, lm)
      call segment_residual(sys, l, lm%wl(1:nl, 2), lm%wl(1:nl, 3), lm%wl(1:nl, 4), lm%wl(:, 1), lm)
      call scatter(nl, lm, res)
    end do
    call bodies_eval(sys, q, v, a, .false., res, lm, energy)
    call drive_loads(sys, q, v, t, res)
  end subroutine assemble_residual

  !> Segment l's local q, v, a (lm%wl(:, 2:4)) and all-DOF numbers (lm%widx) out of the all-DOF
  !> vectors.
  pure subroutine gather(sys, l, nl, q, v, a, lm)
    type(coupled_system), intent(in) :: sys
    integer, intent(in) :: l, nl
    real(dp), intent(in) :: q(:), v(:), a(:)
    type(link_mats), intent(inout) :: lm
    call gather_into(nl, sys%ld(1, l), q, v, a, lm%widx, size(lm%wl, 1), lm%wl)
  end subroutine gather

  !> gather's loop over plain arrays (explicit loops: vector-subscripted sections copy through the
  !> heap; explicit shapes: no descriptor reads per element).
  pure subroutine gather_into(nl, ld, q, v, a, widx, ldw, wl)
    integer, intent(in) :: nl, ldw, ld(nl)
    real(dp), intent(in) :: q(:), v(:), a(:)
    integer, intent(out) :: widx(nl)
    real(dp), intent(inout) :: wl(ldw, 4)
    integer :: i, j
    do i = 1, nl
      j = ld(i)
      widx(i) = j
      wl(i, 2) = q(j); wl(i, 3) = v(j); wl(i, 4) = a(j)
    end do
  end subroutine gather_into

  !> res += the segment's local residual lm%wl(1:nl, 1) at its all-DOF numbers.
  pure subroutine scatter(nl, lm, res)
    integer, intent(in) :: nl
    type(link_mats), intent(in) :: lm
    real(dp), intent(inout) :: res(:)
    call scatter_from(nl, lm%widx, lm%wl(1, 1), res)
  end subroutine scatter

  !> scatter's loop over plain arrays: res(widx(i)) += r(i).
  pure subroutine scatter_from(nl, widx, r, res)
    integer, intent(in) :: nl, widx(nl)
    real(dp), intent(in) :: r(nl)
    real(dp), intent(inout) :: res(:)
    integer :: i
    do i = 1, nl
      res(widx(i)) = res(widx(i)) + r(i)
    end do
  end subroutine scatter_from

  !> Rigid bodies: residual m (a_C - grav), J alpha; S gets diag(m, m, J_S) (J_S > 0 also for a body
  !> of zero inertia whose angle a constraint holds); energies 1/2 m |v_C|^2 + 1/2 J omega^2, -m grav.r_C.
  subroutine bodies_eval(sys, q, v, a, want, res, lm, energy)
    type(coupled_system), intent(in) :: sys
    real(dp), intent(in) :: q(:), v(:), a(:)
    logical, intent(in) :: want
    real(dp), intent(inout) :: res(:), energy(2)
    type(link_mats), intent(inout) :: lm
    integer :: b, k, d(3), f
    real(dp) :: m, jc
    do b = 1, sys%nrb
      d = sys%rb_dof(:, b)
      m = sys%rb_m(1, b); jc = sys%rb_m(2, b)
      res(d(1:2)) = res(d(1:2)) + m*(a(d(1:2)) - sys%grav)
      res(d(3)) = res(d(3)) + jc*a(d(3))
      energy(1) = energy(1) + 0.5_dp*(m*(v(d(1))**2 + v(d(2))**2) + jc*v(d(3))**2)
      energy(2) = energy(2) - m*dot_product(sys%grav, q(d(1:2)))
      if (.not. want) cycle
      do k = 1, 3
        f = sys%free_of(d(k))
        if (f > 0) lm%dg(f) = lm%dg(f) + merge(m, sys%rb_m(3, b), k < 3)
      end do
    end do
  end subroutine bodies_eval

  !> Force drives: res -= tau(theta, t) d theta/dq on the drives' joint coordinates.
  subroutine drive_loads(sys, q, v, t, res)
    type(coupled_system), intent(in) :: sys
    real(dp), intent(in) :: q(:), v(:), t
    real(dp), intent(inout) :: res(:)
    integer :: i, j, nc, cols(2*MAXCOL)
    real(dp) :: tau, theta, grad(2*MAXCOL)
    type(marker_state) :: ma, mb
    do i = 1, sys%nd
      call drive_load(sys, i, q, v, t, tau, theta, nc, cols, grad, ma, mb)
      do j = 1, nc
        res(cols(j)) = res(cols(j)) - tau*grad(j)
      end do
    end do
  end subroutine drive_loads

  !> The collocated controllers' part of S (docs/theory.md 23.2): force drive i's force -kq dth - kv dth'
  !> (control_gains) adds (ck kq + cc kv) g g^T over its coordinate's gradient g (free DOFs); the
  !> geometric part (tau dg/dq) is left out.  A drive whose g g^T does not fit S's storage (a coordinate
  !> across two segments in the condensed or bordered storage) adds nothing: its force stays in the
  !> residual only.
  subroutine control_matrix(sys, q, v, t, cc, ck, lm)
    type(coupled_system), intent(in) :: sys
    real(dp), intent(in) :: q(:), v(:), t, cc, ck
    type(link_mats), intent(inout) :: lm
    integer :: i, a, b, nc, nf, cols(2*MAXCOL), f(2*MAXCOL), pass
    real(dp) :: tau, theta, gd, acc0, kq, kv, grad(2*MAXCOL), g(2*MAXCOL)
    logical :: stored, fits
    type(marker_state) :: ma, mb
    do i = 1, sys%nd
      call eval_row(sys, sys%dv(1, i), 0, sys%dv_dir(:, i), sys%dv(2, i), sys%dv(3, i), q, v, theta, gd, acc0, nc, &
                    cols, grad, ma, mb)
      call control_gains(sys, i, t, theta, gd, kq, kv)
      if (ck*kq + cc*kv == 0.0_dp) cycle
      nf = 0                                   ! the gradient over free DOFs, repeated columns merged
      do a = 1, nc
        if (sys%free_of(cols(a)) == 0) cycle
        b = findloc(f(1:nf), sys%free_of(cols(a)), 1)
        if (b == 0) then
          nf = nf + 1; b = nf; f(b) = sys%free_of(cols(a)); g(b) = 0.0_dp
        end if
        g(b) = g(b) + grad(a)
      end do
      fits = .true.
      do pass = 1, 2                           ! 1: whether every pair fits; 2: add them
        do b = 1, nf
          do a = 1, nf
            call lm_add_pair(sys, lm, f(a), f(b), (ck*kq + cc*kv)*g(a)*g(b), pass == 2, stored)
            fits = fits .and. stored
          end do
        end do
        if (.not. fits) exit
      end do
    end do
  end subroutine control_matrix

  !> Dense residual (all DOFs, without constraint forces), iteration-matrix parts over the free DOFs and
  !> energies at one state and time t (for tests and analysis): mm = M, cm = C_v, km = K_t,
  !> energy = [kinetic, potential].  A rigid body's diagonal in mm is [m, m, J_S].  S is stored as a
  !> run stores it (one-element segments straight into the band or the bordered saddle band).
  subroutine coupled_dense(sys, q, v, a, t, res, mm, cm, km, energy)
    type(coupled_system), intent(in) :: sys
    real(dp), intent(in) :: q(:), v(:), a(:), t
    real(dp), intent(out) :: res(:), mm(:, :), cm(:, :), km(:, :), energy(2)
    type(link_mats) :: lm
    integer :: ngnz(max(1, sys%nc)), gnz(2*MAXCOL, max(1, sys%nc))
    call lm_setup(sys, 1, lm)
    if (sys%nbd >= 0) then
      call row_patterns(sys, q, v, ngnz, gnz)
      call lm_bordered_setup(sys, lm, ngnz, gnz)
    else
      call lm_band_setup(sys, lm)
    end if
    call assemble(sys, q, v, a, t, .true., 0.0_dp, 0.0_dp, res, lm, energy)
    call lm_band_finish(sys, lm)
    call lm_dense(sys, lm, mm)
    call assemble(sys, q, v, a, t, .true., 1.0_dp, 0.0_dp, res, lm, energy)
    call lm_band_finish(sys, lm)
    call lm_dense(sys, lm, cm)
    cm = cm - mm
    call assemble(sys, q, v, a, t, .true., 0.0_dp, 1.0_dp, res, lm, energy)
    call lm_band_finish(sys, lm)
    call lm_dense(sys, lm, km)
    km = km - mm
    call assemble(sys, q, v, a, t, .false., 0.0_dp, 0.0_dp, res, lm, energy)   ! the energies (and res)
  end subroutine coupled_dense

  !> Residual res (all DOFs: inertia, elastic, damping, gravity and force drives, no constraint forces)
  !> at each of ns states (q(:, s), v, a) at time t [s] (modal analysis: its derivatives by differences).
  subroutine coupled_residual(sys, q, v, a, t, res)
    type(coupled_system), intent(in) :: sys
    real(dp), intent(in) :: q(:, :), v(:), a(:), t
    real(dp), intent(out) :: res(:, :)
    type(link_mats) :: lm
    integer :: s
    call lm_setup(sys, 1, lm)
    do s = 1, size(q, 2)
      call assemble_residual(sys, q(:, s), v, a, t, res(:, s), lm)
    end do
  end subroutine coupled_residual

end module flexmech_coupled_assembly
