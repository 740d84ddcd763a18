!> Post-processing of the coupled and nonlinear models' frames: marker states, measure rows, the force
!> drives' generalized forces and the forces at every segment's ends.
module flexmech_coupled_post
  use flexmech_kinds, only: dp
  use flexmech_markers, only: marker_state, MAXCOL
  use flexmech_coupled_system, only: coupled_system, MK_NODE
  use flexmech_coupled_rows, only: get_marker, eval_row, drive_load
  use flexmech_coupled_storage, only: link_mats, lm_setup
  use flexmech_coupled_element, only: link_eval
  implicit none
  private
  public :: coupled_post

contains

  !> Post-processing of frames (qf, vf, af (ndof, nf), multipliers lf (>= nc, nf), times tf (nf)):
  !>   mks(9, nmk, nf)   every marker's [x, y, psi, x', y', psi', x'', y'', psi'']
  !>   mv(3, nm, nf)     [value, rate, acceleration] of the measure rows meas(4, nm) = [kind, marker a,
  !>                     marker b, aux], directions meas_dir(2, nm) (same kinds as the constraints)
  !>   dvals(nd, nf)     the force drives' generalized forces tau(theta, t)
  !>   rend(4, nseg, nf) per segment, the residual at its end positions of everything acting on the
  !>                     segment (inertia, elastic forces, gravity, the force drives' and the constraint
  !>                     rows' generalized forces on its DOFs, split by marker owner): the force the
  !>                     rest of the mechanism exerts on the segment there through shared DOFs
  subroutine coupled_post(sys, qf, vf, af, lf, tf, meas, meas_dir, mks, mv, dvals, rend)
    type(coupled_system), intent(in) :: sys
    real(dp), intent(in) :: qf(:, :), vf(:, :), af(:, :), lf(:, :), tf(:), meas_dir(:, :)
    integer, intent(in) :: meas(:, :)
    real(dp), intent(out) :: mks(:, :, :), mv(:, :, :), dvals(:, :), rend(:, :, :)
    integer :: k, m, i, l, nl, ncl, cols(2*MAXCOL)
    real(dp) :: g, gd, acc0, grad(2*MAXCOL), tau, rl(sys%maxld), ek, ep
    type(marker_state) :: ma, mb
    type(link_mats) :: lm
    call lm_setup(sys, 1, lm)
    mks = 0.0_dp; mv = 0.0_dp; dvals = 0.0_dp; rend = 0.0_dp
    do k = 1, size(qf, 2)
      do m = 1, sys%nmk
        call get_marker(sys, m, qf(:, k), vf(:, k), ma)
        mks(1:6, m, k) = [ma%r, ma%psi, ma%rd, ma%psid]
        mks(7:8, m, k) = ma%ra0 + matmul(ma%dr(:, 1:ma%n), af(ma%col(1:ma%n), k))
        mks(9, m, k) = ma%psia0 + dot_product(ma%dpsi(1:ma%n), af(ma%col(1:ma%n), k))
      end do
      do i = 1, size(meas, 2)
        call eval_row(sys, meas(1, i), meas(4, i), meas_dir(:, i), meas(2, i), meas(3, i), qf(:, k), vf(:, k), &
                      g, gd, acc0, ncl, cols, grad, ma, mb)
        mv(:, i, k) = [g, gd, acc0 + dot_product(grad(1:ncl), af(cols(1:ncl), k))]
      end do
      do l = 1, sys%nseg
        nl = 3*sys%n_el(l) + 3
        call link_eval(sys, l, qf(sys%ld(1:nl, l), k), vf(sys%ld(1:nl, l), k), af(sys%ld(1:nl, l), k), .false., &
                       0.0_dp, 0.0_dp, rl, lm, ek, ep)
        rend(:, l, k) = rl(1:4)
      end do
      do i = 1, sys%nd
        call drive_load(sys, i, qf(:, k), vf(:, k), tf(k), tau, g, ncl, cols, grad, ma, mb)
        dvals(i, k) = tau
        call add_ends(-tau*grad, sys%dv(2, i), sys%dv(3, i), ma, mb, rend(:, :, k))
      end do
      do i = 1, sys%nc
        call eval_row(sys, sys%con(1, i), sys%con(4, i), sys%con_dir(:, i), sys%con(2, i), sys%con(3, i), &
                      qf(:, k), vf(:, k), g, gd, acc0, ncl, cols, grad, ma, mb)
        call add_ends(lf(i, k)*grad, sys%con(2, i), sys%con(3, i), ma, mb, rend(:, :, k))
      end do
    end do

  contains

    !> Add generalized forces f (columns: marker a's, then b's) to the end positions of the segments
    !> that own them.
    subroutine add_ends(f, mka, mkb, ma, mb, re)
      real(dp), intent(in) :: f(:)
      integer, intent(in) :: mka, mkb
      type(marker_state), intent(in) :: ma, mb
      real(dp), intent(inout) :: re(:, :)
      integer :: j
      if (sys%mk_kind(mka) == MK_NODE) then
        do j = 1, ma%n
          if (ma%loc(j) <= 4) re(ma%loc(j), sys%mk_idx(mka)) = re(ma%loc(j), sys%mk_idx(mka)) + f(j)
        end do
      end if
      if (sys%mk_kind(mkb) == MK_NODE) then
        do j = 1, mb%n
          if (mb%loc(j) <= 4) re(mb%loc(j), sys%mk_idx(mkb)) = re(mb%loc(j), sys%mk_idx(mkb)) + f(ma%n + j)
        end do
      end if
    end subroutine add_ends

  end subroutine coupled_post

end module flexmech_coupled_post
