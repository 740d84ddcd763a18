!> Markers, constraint rows and force drives evaluated on the coupled system (flexmech_coupled_system):
!> a marker's state from the all-DOF state, a row's value, rate, velocity part of its acceleration
!> and gradient (the kinds of flexmech_markers), a force drive's generalized force (flexmech_drivelaw).
module flexmech_coupled_rows
  use flexmech_kinds, only: dp
  use flexmech_drivelaw, only: force_law
  use flexmech_control, only: ctl_output, ctl_slopes
  use flexmech_markers, only: marker_state, segment_marker, body_marker, ground_marker, constraint_row, &
                              CON_POINT, CON_ANGLE, CON_PROJECTION, MAXCOL
  use flexmech_coupled_system, only: coupled_system, MK_GROUND, MK_NODE, MK_BODY, NPAR
  implicit none
  private
  public :: get_marker, eval_row, drive_load, coupled_rows, row_patterns, control_measure, control_gains

contains

  !> State of marker m at the all-DOF state (q, v) (flexmech_markers).
  pure subroutine get_marker(sys, m, q, v, ms)
    type(coupled_system), intent(in) :: sys
    integer, intent(in) :: m
    real(dp), intent(in) :: q(:), v(:)
    type(marker_state), intent(out) :: ms
    integer :: s, n, b, i
    real(dp) :: z(3), zd(3)
    select case (sys%mk_kind(m))
    case (MK_NODE)
      s = sys%mk_idx(m); n = sys%n_el(s)
      call segment_marker(q, v, sys%ld(1:3*n + 3, s), n, sys%mk_node(m), sys%wn(sys%mk_node(m) + 1, s), &
                          sys%absang(s) /= 0, ms)
    case (MK_BODY)
      b = sys%mk_idx(m)
      do i = 1, 3           ! a loop: vector subscripts would copy through the heap
        z(i) = q(sys%rb_dof(i, b)); zd(i) = v(sys%rb_dof(i, b))
      end do
      call body_marker(z, zd, sys%rb_dof(:, b), sys%mk_pos(:, m), ms)
    case default
      call ground_marker(sys%mk_pos(:, m), ms)
    end select
  end subroutine get_marker

  !> A row of kind `kind` (aux, direction d) between markers mka and mkb at (q, v): value g, rate gd,
  !> velocity part acc0 of its second derivative, gradient grad over the all-DOF columns cols(1:nc)
  !> (marker a's columns first: ma%n of them); the marker states ma, mb.
  pure subroutine eval_row(sys, kind, aux, d, mka, mkb, q, v, g, gd, acc0, nc, cols, grad, ma, mb)
    type(coupled_system), intent(in) :: sys
    integer, intent(in) :: kind, aux, mka, mkb
    real(dp), intent(in) :: d(2), q(:), v(:)
    real(dp), intent(out) :: g, gd, acc0, grad(2*MAXCOL)
    integer, intent(out) :: nc, cols(2*MAXCOL)
    type(marker_state), intent(out) :: ma, mb
    call get_marker(sys, mka, q, v, ma)
    call get_marker(sys, mkb, q, v, mb)
    call constraint_row(kind, aux, d, ma, mb, g, gd, acc0, nc, cols, grad)
  end subroutine eval_row

  !> Coordinate theta of force drive i at (q, v) (its gradient over cols(1:nc), marker states) and the
  !> law's generalized force tau(theta, t) [N m or N], plus the output of the controllers acting
  !> through it (flexmech_control: ctl_effort, at theta and its rate).
  pure subroutine drive_load(sys, i, q, v, t, tau, theta, nc, cols, grad, ma, mb)
    type(coupled_system), intent(in) :: sys
    integer, intent(in) :: i
    real(dp), intent(in) :: q(:), v(:), t
    real(dp), intent(out) :: tau, theta, grad(2*MAXCOL)
    integer, intent(out) :: nc, cols(2*MAXCOL)
    type(marker_state), intent(out) :: ma, mb
    real(dp) :: gd, acc0
    integer :: k, nk
    call eval_row(sys, sys%dv(1, i), 0, sys%dv_dir(:, i), sys%dv(2, i), sys%dv(3, i), q, v, theta, gd, acc0, nc, &
                  cols, grad, ma, mb)
    k = sys%dv(4, i); nk = sys%dv(5, i)
    if (nk > 0) then
      tau = force_law(sys%dv_par(:, i), sys%dv_harm(:, i), sys%dv_th(:, :, i), sys%tab_t(k:k + nk - 1), &
                      sys%tab_c(:, k:k + nk - 1), theta, t)
    else
      tau = force_law(sys%dv_par(:, i), sys%dv_harm(:, i), sys%dv_th(:, :, i), sys%tab_t(1:0), sys%tab_c(:, 1:0), &
                      theta, t)
    end if
    if (sys%ctl%n > 0) tau = tau + control_effort(sys, i, q, v, t, theta, gd)
  end subroutine drive_load

  !> Sum of the outputs [N m or N] of the controllers acting through force drive i at (q, v, t); theta,
  !> gd: the drive's coordinate and rate (the collocated measurement).
  pure real(dp) function control_effort(sys, i, q, v, t, theta, gd) result(u)
    type(coupled_system), intent(in) :: sys
    integer, intent(in) :: i
    real(dp), intent(in) :: q(:), v(:), t, theta, gd
    integer :: j
    real(dp) :: y, yd
    u = 0.0_dp
    do j = 1, sys%ctl%n
      if (sys%ctl%ci(1, j) /= i) cycle
      if (sys%ctl%ci(10, j) == 0) then
        y = theta; yd = gd
      else
        call control_measure(sys, j, q, v, y, yd)
      end if
      u = u + ctl_output(sys%ctl, j, y, yd, t)
    end do
  end function control_effort

  !> The collocated controllers' gains on force drive i at (t, its coordinate theta and rate gd):
  !> kq = -sum du/dtheta, kv = -sum du/dtheta' (ctl_slopes), the drive's force tau(theta, theta')
  !> linearized as -kq dtheta - kv dtheta'.  A non-collocated controller (its force on this drive, its
  !> measurement elsewhere: an unsymmetric coupling) adds nothing.
  pure subroutine control_gains(sys, i, t, theta, gd, kq, kv)
    type(coupled_system), intent(in) :: sys
    integer, intent(in) :: i
    real(dp), intent(in) :: t, theta, gd
    real(dp), intent(out) :: kq, kv
    integer :: j
    real(dp) :: dy, dyd
    kq = 0.0_dp; kv = 0.0_dp
    do j = 1, sys%ctl%n
      if (sys%ctl%ci(1, j) /= i .or. sys%ctl%ci(10, j) /= 0) cycle
      call ctl_slopes(sys%ctl, j, theta, gd, t, dy, dyd)
      kq = kq - dy; kv = kv - dyd
    end do
  end subroutine control_gains

  !> The signal y and rate yd controller j measures at (q, v): its drive's coordinate (collocated) or
  !> its own row between two markers (non-collocated, e.g. a tip position).
  pure subroutine control_measure(sys, j, q, v, y, yd)
    type(coupled_system), intent(in) :: sys
    integer, intent(in) :: j
    real(dp), intent(in) :: q(:), v(:)
    real(dp), intent(out) :: y, yd
    integer :: i, ncl, cols(2*MAXCOL)
    real(dp) :: acc0, grad(2*MAXCOL)
    type(marker_state) :: ma, mb
    associate (c => sys%ctl%ci(:, j))
      if (c(10) == 0) then
        i = c(1)
        call eval_row(sys, sys%dv(1, i), 0, sys%dv_dir(:, i), sys%dv(2, i), sys%dv(3, i), q, v, y, yd, acc0, ncl, &
                      cols, grad, ma, mb)
      else
        call eval_row(sys, c(10), 0, sys%ctl%cp(16:17, j), c(11), c(12), q, v, y, yd, acc0, ncl, cols, grad, ma, mb)
      end if
    end associate
  end subroutine control_measure

  !> The free DOFs on which every row's gradient can be nonzero (the columns of its two markers),
  !> without repetitions: gnz(1:ngnz(ic), ic), ic = 1..nc (gnz: (2 MAXCOL, >= nc)); at any (q, v).
  pure subroutine row_patterns(sys, q, v, ngnz, gnz)
    type(coupled_system), intent(in) :: sys
    real(dp), intent(in) :: q(:), v(:)
    integer, intent(out) :: ngnz(:), gnz(:, :)
    integer :: ic, k, f, ncl, cols(2*MAXCOL)
    real(dp) :: gv, gd, ac, grad(2*MAXCOL)
    type(marker_state) :: ma, mb
    ngnz = 0
    gnz = 0
    do ic = 1, sys%nc
      call eval_row(sys, sys%con(1, ic), sys%con(4, ic), sys%con_dir(:, ic), sys%con(2, ic), sys%con(3, ic), &
                    q, v, gv, gd, ac, ncl, cols, grad, ma, mb)
      do k = 1, ncl
        f = sys%free_of(cols(k))
        if (f == 0) cycle
        if (any(gnz(1:ngnz(ic), ic) == f)) cycle
        ngnz(ic) = ngnz(ic) + 1
        gnz(ngnz(ic), ic) = f
      end do
    end do
  end subroutine row_patterns

  !> Values g (nc, ns) of the constraint rows (not wrapped) and their gradients gq (nc, ndof, ns) over
  !> all DOFs at each of ns configurations q(:, s) (velocities v enter the rates only, not returned).
  subroutine coupled_rows(sys, q, v, g, gq)
    type(coupled_system), intent(in) :: sys
    real(dp), intent(in) :: q(:, :), v(:)
    real(dp), intent(out) :: g(:, :), gq(:, :, :)
    integer :: s, ic, j, ncl, cols(2*MAXCOL)
    real(dp) :: gd, acc0, grad(2*MAXCOL)
    type(marker_state) :: ma, mb
    gq = 0.0_dp
    do s = 1, size(q, 2)
      do ic = 1, sys%nc
        call eval_row(sys, sys%con(1, ic), sys%con(4, ic), sys%con_dir(:, ic), sys%con(2, ic), sys%con(3, ic), &
                      q(:, s), v, g(ic, s), gd, acc0, ncl, cols, grad, ma, mb)
        do j = 1, ncl
          gq(ic, cols(j), s) = gq(ic, cols(j), s) + grad(j)
        end do
      end do
    end do
  end subroutine coupled_rows

end module flexmech_coupled_rows
