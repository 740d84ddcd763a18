!> One-element segments of the coupled and nonlinear models (the nonlinear model's co-rotational
!> elements; the coupled model at one element per link) in one pass: residual, energies and the
!> segment's 6 x 6 block of the iteration matrix S = M + ccv C_v + ckt K_t from the chord frame,
!> the element's Gram matrix and its constants, without the general path's segment-block storage
!> (flexmech_coupled_element: link_eval, which calls here for these segments; its Gauss-point path
!> is the check of this one).  docs/theory.md sections 12.1, 12.3 and 12.4.
!>
!> Local DOFs of the segment: [xs, ys, xe, ye, th_0, th_1]: end positions [m], then the end angles
!> [rad]: absolute node angles psi_k when sys%absang(l) = 1 (evaluated in the chord-relative angles
!> th_k = psi_k - phi and carried back, see one_element_eval), else already chord-relative.
!> The element's field along e2 is w = N_0 th_0 + N_1 th_1 (Hermite shapes); inertia over
!> phi = [1 - xi, xi, N_0, N_1] and the Gram matrix G = int phi phi^T dm (sys%gram).
module flexmech_coupled_corot
  use flexmech_kinds, only: dp
  use flexmech_coupled_system, only: coupled_system, wrap
  implicit none
  private
  public :: stretch_damping_k, one_element_residual, one_element_eval, one_element_elastic, absolute_block, chord

  !> The chord frame of a segment and its chord-relative end angles: c = re - rs [m] and its rates,
  !> l2 = |c|^2, ell = |c|, e1 = c/ell, e2 = Omega e1, g = Omega c/l2 (d phi/d re), omega = g.c',
  !> alpha0 = -2 (c.c') omega/l2 (the velocity part of alpha = phi''), th, th', th'' [rad, rad/s, rad/s^2].
  type :: chord_frame
    real(dp) :: c(2), cd(2), cdd(2), l2, ell, e1(2), e2(2), g(2), om, al0, al, th(2), thd(2), thdd(2)
  end type chord_frame

contains

  !> Residual r (6) [N, N m] of one-element segment l at its local q, v, a (no energies, no matrix):
  !> the Newton iterations that keep the factorized matrix.
  pure subroutine one_element_residual(sys, l, q, v, a, r)
    type(coupled_system), intent(in) :: sys
    integer, intent(in) :: l
    real(dp), intent(in) :: q(:), v(:), a(:)
    real(dp), intent(out) :: r(:)
    type(chord_frame) :: fr
    real(dp) :: f, ath(2)
    fr = frame_of(q, v, a, sys%absang(l) == 1)
    call residual_terms(sys, l, fr, a, r, f, ath)
    if (sys%absang(l) == 1) call absolute_rows(fr, r)
  end subroutine one_element_residual

  !> Residual r (6) and either the energies [J] (kinetic; strain + gravity; want = .false., the
  !> frames) or the segment's block s6 (6 x 6) of S = M + ccv C_v + ckt K_t (want; ekin = epot = 0:
  !> the Newton iterations do not read them).  With absolute node angles the block of the chord-relative
  !> angles is carried back by T = d th / d(rs, re, psi) (docs/theory.md 12.1):
  !>   S = T^T S_rel T + (the chord terms of th', th'') - ckt (R_th0 + R_th1) d2phi/d(rs, re)2.
  pure subroutine one_element_eval(sys, l, q, v, a, want, ccv, ckt, r, s6, ekin, epot)
    type(coupled_system), intent(in) :: sys
    integer, intent(in) :: l
    real(dp), intent(in) :: q(:), v(:), a(:), ccv, ckt
    logical, intent(in) :: want
    real(dp), intent(out) :: r(:), s6(6, 6), ekin, epot
    type(chord_frame) :: fr
    real(dp) :: f, ath(2), msum(6), csum(6), sr
    fr = frame_of(q, v, a, sys%absang(l) == 1)
    call residual_terms(sys, l, fr, a, r, f, ath)
    sr = r(5) + r(6)
    if (sys%absang(l) == 1) call absolute_rows(fr, r)
    ekin = 0.0_dp; epot = 0.0_dp
    if (.not. want) then
      call energies(sys, l, fr, q, v, f, ekin, epot)
      return
    end if
    msum = 0.0_dp; csum = 0.0_dp
    call inertia_block(sys, l, fr, ccv, ckt, s6, msum, csum)
    call rotary_block(sys, l, fr, ccv, s6, msum)
    call axial_block(sys, l, fr, ccv, ckt, f, ath, s6)
    call bending_block(sys, l, ccv, ckt, s6, csum)
    if (sys%absang(l) == 1) call absolute_block(s6, fr%c, fr%cd, fr%cdd, sr, ccv, ckt, msum, csum)
  end subroutine one_element_eval

  !> The terms of a one-element segment besides its translational inertia, at local q, v, a with
  !> chord-relative angles (the general path's Gauss-point check, flexmech_coupled_element: link_eval):
  !> r (6) += rotary inertias, axial force (and the shallow arch's), bending and damping; ekin +=
  !> the rotary inertias', epot += the strain energy; if want, s6 (6 x 6) gets their part of S and
  !> msum, csum their angle-column sums of M and C_v (absolute node angles only, as one_element_eval).
  pure subroutine one_element_elastic(sys, l, q, v, a, want, ccv, ckt, r, s6, msum, csum, ekin, epot)
    type(coupled_system), intent(in) :: sys
    integer, intent(in) :: l
    real(dp), intent(in) :: q(:), v(:), a(:), ccv, ckt
    logical, intent(in) :: want
    real(dp), intent(inout) :: r(:), msum(6), csum(6), ekin, epot
    real(dp), intent(out) :: s6(6, 6)
    type(chord_frame) :: fr
    real(dp) :: f, ath(2), ek, ep
    fr = frame_of(q, v, a, .false.)
    call rotary_residual(sys, l, fr, r)
    call axial_residual(sys, l, fr, r, f, ath)
    call bending_residual(sys, l, fr, r)
    call elastic_energies(sys, l, fr, f, ek, ep)
    ekin = ekin + ek; epot = epot + ep
    s6 = 0.0_dp
    if (.not. want) return
    call rotary_block(sys, l, fr, ccv, s6, msum)
    call axial_block(sys, l, fr, ccv, ckt, f, ath, s6)
    call bending_block(sys, l, ccv, ckt, s6, csum)
  end subroutine one_element_elastic

  !> A one-element segment's block s6 of S in chord-relative angles carried to absolute node angles
  !> (docs/theory.md 12.1): the chord terms of th', th'' (angle_rate_terms), T^T S T (angle_transform)
  !> and the geometric stiffness - ckt sr d2phi/d(rs, re)2 of the end moments turning with the chord;
  !> c, cd, cdd the chord and its rates [m, m/s, m/s^2], sr = R_th0 + R_th1 the relative angles'
  !> residual [N m], msum, csum the sums of the angle columns of M and C_v.
  pure subroutine absolute_block(s6, c, cd, cdd, sr, ccv, ckt, msum, csum)
    real(dp), intent(inout) :: s6(6, 6)
    real(dp), intent(in) :: c(2), cd(2), cdd(2), sr, ccv, ckt, msum(6), csum(6)
    real(dp) :: l2, g(2), h(2, 2)
    l2 = c(1)**2 + c(2)**2
    g = [-c(2), c(1)]/l2
    h(1, 1) = 2.0_dp*c(1)*c(2)/l2**2; h(1, 2) = (c(2)**2 - c(1)**2)/l2**2    ! d2 phi / dc2
    h(2, 1) = h(1, 2); h(2, 2) = -h(1, 1)
    call angle_rate_terms(s6, c, cd, cdd, g, g(1)*cd(1) + g(2)*cd(2), h, ccv, ckt, msum, csum)
    call angle_transform(s6, [5, 6], [g(1), g(2), -g(1), -g(2)])
    h = ckt*sr*h
    s6(1:2, 1:2) = s6(1:2, 1:2) - h; s6(3:4, 3:4) = s6(3:4, 3:4) - h
    s6(1:2, 3:4) = s6(1:2, 3:4) + h; s6(3:4, 1:2) = s6(3:4, 1:2) + h
  end subroutine absolute_block

  !> The residual in chord-relative angles: inertia and gravity, rotary inertias, axial force f [N]
  !> (ath = d eps/d th of a shallow arch), bending and damping.
  pure subroutine residual_terms(sys, l, fr, a, r, f, ath)
    type(coupled_system), intent(in) :: sys
    integer, intent(in) :: l
    type(chord_frame), intent(in) :: fr
    real(dp), intent(in) :: a(:)
    real(dp), intent(out) :: r(:), f, ath(2)
    call inertia_residual(sys, l, fr, a, r)
    call rotary_residual(sys, l, fr, r)
    call axial_residual(sys, l, fr, r, f, ath)
    call bending_residual(sys, l, fr, r)
  end subroutine residual_terms

  !> The chord frame of a one-element segment and its chord-relative end angles at the local q, v, a
  !> (absolute: q(5:6) are absolute node angles psi_k, carried to th_k = psi_k - phi).
  pure function frame_of(q, v, a, absolute) result(fr)
    real(dp), intent(in) :: q(:), v(:), a(:)
    logical, intent(in) :: absolute
    type(chord_frame) :: fr
    real(dp) :: phi
    fr%c = q(3:4) - q(1:2); fr%cd = v(3:4) - v(1:2); fr%cdd = a(3:4) - a(1:2)
    fr%l2 = fr%c(1)**2 + fr%c(2)**2; fr%ell = sqrt(fr%l2)
    fr%e1 = fr%c/fr%ell; fr%e2 = [-fr%e1(2), fr%e1(1)]
    fr%g = [-fr%c(2), fr%c(1)]/fr%l2
    fr%om = fr%g(1)*fr%cd(1) + fr%g(2)*fr%cd(2)
    fr%al0 = -2.0_dp*(fr%c(1)*fr%cd(1) + fr%c(2)*fr%cd(2))*fr%om/fr%l2
    fr%al = fr%al0 + fr%g(1)*fr%cdd(1) + fr%g(2)*fr%cdd(2)
    fr%th = q(5:6); fr%thd = v(5:6); fr%thdd = a(5:6)
    if (absolute) then
      phi = atan2(fr%e1(2), fr%e1(1))
      fr%th = [wrap(fr%th(1) - phi), wrap(fr%th(2) - phi)]
      fr%thd = fr%thd - fr%om; fr%thdd = fr%thdd - fr%al
    end if
  end function frame_of

  !> The chord of a segment (frame_of's, for the general path's segments of several elements, whose
  !> q(5:6) are not end angles): direction (cs, sn), length ell [m], g = d phi/d re [1/m], omega [rad/s],
  !> alpha0 (alpha's velocity part) and alpha [rad/s^2].
  pure subroutine chord(q, v, a, cs, sn, ell, g, om, al0, al)
    real(dp), intent(in) :: q(:), v(:), a(:)
    real(dp), intent(out) :: cs, sn, ell, g(2), om, al0, al
    type(chord_frame) :: fr
    fr = frame_of(q, v, a, .false.)
    cs = fr%e1(1); sn = fr%e1(2); ell = fr%ell; g = fr%g; om = fr%om; al0 = fr%al0; al = fr%al
  end subroutine chord

  !> w0 = d alpha0 / d c' [1/m s]: the chord velocity's part in alpha0 = -2 (c.c') omega/|c|^2.
  pure function alpha0_rate(fr) result(w0)
    type(chord_frame), intent(in) :: fr
    real(dp) :: w0(2)
    w0 = -(2.0_dp/fr%l2)*(fr%om*fr%c + (fr%c(1)*fr%cd(1) + fr%c(2)*fr%cd(2))*fr%g)
  end function alpha0_rate

  !> Inertia and gravity: R_j = sum_a J_a,j . (G (r'' - grav))_a with r'' = sum_a phi_a A_a,
  !> A = [rs'', re'', -(alpha th_k + 2 omega th_k') e1 + (th_k'' - omega^2 th_k) e2].
  pure subroutine inertia_residual(sys, l, fr, a, r)
    type(coupled_system), intent(in) :: sys
    integer, intent(in) :: l
    type(chord_frame), intent(in) :: fr
    real(dp), intent(in) :: a(:)
    real(dp), intent(out) :: r(:)
    real(dp) :: acc(2, 4), gm(4, 4)
    integer :: b
    gm = sys%gram(:, :, l)         ! fixed shapes: matmul inline, no temporary
    acc(:, 1) = a(1:2) - sys%grav; acc(:, 2) = a(3:4) - sys%grav      ! gravity: 1 = phi_1 + phi_2
    do b = 1, 2
      acc(:, 2 + b) = -(fr%al*fr%th(b) + 2.0_dp*fr%om*fr%thd(b))*fr%e1 + (fr%thdd(b) - fr%om**2*fr%th(b))*fr%e2
    end do
    r(1:6) = jt_times(matmul(acc, gm), fr)
  end subroutine inertia_residual

  !> Rotary inertias J [kg m^2] at the segment's nodes, turning with psi = phi + th_k: J psi'' d psi/dq.
  pure subroutine rotary_residual(sys, l, fr, r)
    type(coupled_system), intent(in) :: sys
    integer, intent(in) :: l
    type(chord_frame), intent(in) :: fr
    real(dp), intent(inout) :: r(:)
    real(dp) :: m
    integer :: i, k
    do i = 1, sys%nri
      if (sys%ri_seg(i) /= l) cycle
      k = sys%ri_node(i)
      m = sys%ri_j(i)*(fr%al + fr%thdd(k + 1))
      r(1:2) = r(1:2) - m*fr%g; r(3:4) = r(3:4) + m*fr%g; r(5 + k) = r(5 + k) + m
    end do
  end subroutine rotary_residual

  !> Axial force f = EA eps [N], eps = (ell - L)/L (+ th^T A th/60 for a shallow arch, A = [4 -1; -1 4],
  !> ath = d eps/d th): -f' e1 at the start, +f' e1 at the end, f L ath on the angles (arch), where
  !> f' = f + a_K EA (e1 . c')/L adds the stiffness-proportional Rayleigh damping of the chord's stretch.
  pure subroutine axial_residual(sys, l, fr, r, f, ath)
    type(coupled_system), intent(in) :: sys
    integer, intent(in) :: l
    type(chord_frame), intent(in) :: fr
    real(dp), intent(inout) :: r(:)
    real(dp), intent(out) :: f, ath(2)
    real(dp) :: len, eps, epsd, ft
    len = sys%prop(1, l)
    eps = (fr%ell - len)/len
    epsd = dot_product(fr%e1, fr%cd)/len         ! the chord's stretch rate [1/s]
    ath = 0.0_dp
    if (sys%arch(l) == 1) then
      ath = [4.0_dp*fr%th(1) - fr%th(2), 4.0_dp*fr%th(2) - fr%th(1)]/30.0_dp
      eps = eps + 0.5_dp*dot_product(fr%th, ath)
    end if
    f = sys%prop(3, l)*eps
    ft = f + sys%ray(2)*sys%prop(3, l)*epsd      ! with the stiffness-proportional damping a_K EA of the stretch
    r(1:2) = r(1:2) - ft*fr%e1; r(3:4) = r(3:4) + ft*fr%e1
    if (sys%arch(l) == 1) r(5:6) = r(5:6) + f*len*ath
  end subroutine axial_residual

  !> Bending K_th th and Rayleigh damping C_th th' over the angle part of the element matrices.
  pure subroutine bending_residual(sys, l, fr, r)
    type(coupled_system), intent(in) :: sys
    integer, intent(in) :: l
    type(chord_frame), intent(in) :: fr
    real(dp), intent(inout) :: r(:)
    real(dp) :: kth(2, 2)
    integer :: el
    el = sys%el_off(l) + 1
    kth = angle_part(sys, el, .true.)
    r(5:6) = r(5:6) + matmul(kth, fr%th)
    if (.not. damped(sys)) return
    kth = damping_th(sys, el)      ! (a local: matmul of a function result copies through the heap)
    r(5:6) = r(5:6) + matmul(kth, fr%thd)
  end subroutine bending_residual

  pure logical function damped(sys)
    type(coupled_system), intent(in) :: sys
    damped = sys%ray(1) /= 0.0_dp .or. sys%ray(2) /= 0.0_dp
  end function damped

  !> The angle part of the element's Rayleigh damping a0 M + a1 K.
  pure function damping_th(sys, el) result(cth)
    type(coupled_system), intent(in) :: sys
    integer, intent(in) :: el
    real(dp) :: cth(2, 2)
    cth = sys%ray(1)*angle_part(sys, el, .false.) + sys%ray(2)*angle_part(sys, el, .true.)
  end function damping_th

  !> The angle part (rows and columns 3 and 6: th_0, th_1) of element el's 6 x 6 stiffness or mass
  !> matrix (element by element: a vector-subscripted section would copy through the heap).
  pure function angle_part(sys, el, stiffness) result(m2)
    type(coupled_system), intent(in) :: sys
    integer, intent(in) :: el
    logical, intent(in) :: stiffness       !< sys%ke, else sys%me
    real(dp) :: m2(2, 2)
    integer :: i, j
    integer, parameter :: th(2) = [3, 6]
    do j = 1, 2
      do i = 1, 2
        if (stiffness) then
          m2(i, j) = sys%ke(th(i), th(j), el)
        else
          m2(i, j) = sys%me(th(i), th(j), el)
        end if
      end do
    end do
  end function angle_part

  !> Absolute node angles: th_k = psi_k - phi(rs, re), so the ends' rows gain (R_th0 + R_th1) d th/d(rs, re).
  pure subroutine absolute_rows(fr, r)
    type(chord_frame), intent(in) :: fr
    real(dp), intent(inout) :: r(:)
    real(dp) :: sr
    sr = r(5) + r(6)
    r(1:2) = r(1:2) + sr*fr%g; r(3:4) = r(3:4) - sr*fr%g
  end subroutine absolute_rows

  !> Kinetic energy 1/2 int |r'|^2 dm + rotary, potential: strain (axial force f, bending) - int grav.r dm.
  pure subroutine energies(sys, l, fr, q, v, f, ekin, epot)
    type(coupled_system), intent(in) :: sys
    integer, intent(in) :: l
    type(chord_frame), intent(in) :: fr
    real(dp), intent(in) :: q(:), v(:), f
    real(dp), intent(out) :: ekin, epot
    real(dp) :: vel(2, 4), gm(4, 4), gs, ek, ep
    integer :: b
    gm = sys%gram(:, :, l)
    vel(:, 1) = v(1:2); vel(:, 2) = v(3:4)
    do b = 1, 2
      vel(:, 2 + b) = -fr%om*fr%th(b)*fr%e1 + fr%thd(b)*fr%e2
    end do
    ekin = 0.5_dp*sum(matmul(vel, gm)*vel)
    gs = dot_product(sys%grav, fr%e2)
    epot = -sum((gm(1, :) + gm(2, :))*[dot_product(sys%grav, q(1:2)), dot_product(sys%grav, q(3:4)), &
                                       fr%th(1)*gs, fr%th(2)*gs])
    call elastic_energies(sys, l, fr, f, ek, ep)
    ekin = ekin + ek; epot = epot + ep
  end subroutine energies

  !> The rotary inertias' kinetic energy 1/2 J (omega + th_k')^2 and the strain energy (axial force f
  !> [N], bending).
  pure subroutine elastic_energies(sys, l, fr, f, ekin, epot)
    type(coupled_system), intent(in) :: sys
    integer, intent(in) :: l
    type(chord_frame), intent(in) :: fr
    real(dp), intent(in) :: f
    real(dp), intent(out) :: ekin, epot
    real(dp) :: kth(2, 2)
    integer :: i, k
    ekin = 0.0_dp
    do i = 1, sys%nri
      if (sys%ri_seg(i) /= l) cycle
      k = sys%ri_node(i)
      ekin = ekin + 0.5_dp*sys%ri_j(i)*(fr%om + fr%thd(k + 1))**2
    end do
    kth = angle_part(sys, sys%el_off(l) + 1, .true.)
    epot = 0.5_dp*f**2*sys%prop(1, l)/sys%prop(3, l) + 0.5_dp*dot_product(fr%th, matmul(kth, fr%th))
  end subroutine elastic_energies

  !> Inertia part of S: S_ij = sum_a J_a,i . (G B_j)_a with J = dr'/dq' and B = J + cc dr''/dv +
  !> ck dr''/dq (at fixed chord), column by column from B_j's phi coefficients (2, 4) (jt_times);
  !> msum, csum get the sums of the angle columns of M and C_v (the chord terms of absolute angles).
  pure subroutine inertia_block(sys, l, fr, cc, ck, s6, msum, csum)
    type(coupled_system), intent(in) :: sys
    integer, intent(in) :: l
    type(chord_frame), intent(in) :: fr
    real(dp), intent(in) :: cc, ck
    real(dp), intent(out) :: s6(6, 6)
    real(dp), intent(inout) :: msum(6), csum(6)
    real(dp) :: gm(4, 4), w0(2), jc(2, 2), ac(2, 2), rot(2)
    integer :: j, b
    gm = sys%gram(:, :, l)
    w0 = alpha0_rate(fr)
    do j = 1, 2           ! the end-position columns rs_j, re_j
      do b = 1, 2         ! J's and dr''/dc'_j's coefficients of N_b (b = 1, 2: th_0, th_1)
        jc(:, b) = fr%th(b)*fr%g(j)*fr%e1
        ac(:, b) = -fr%th(b)*w0(j)*fr%e1 + (-2.0_dp*fr%om*fr%th(b)*fr%e2 - 2.0_dp*fr%thd(b)*fr%e1)*fr%g(j)
      end do
      s6(:, j) = jt_times(x_gram(j, 1, jc(:, 1) - cc*ac(:, 1), jc(:, 2) - cc*ac(:, 2), gm), fr)
      s6(:, 2 + j) = jt_times(x_gram(j, 2, cc*ac(:, 1) - jc(:, 1), cc*ac(:, 2) - jc(:, 2), gm), fr)
    end do
    rot = fr%e2 - (2.0_dp*cc*fr%om + ck*fr%al)*fr%e1 - (ck*fr%om**2)*fr%e2   ! the angle columns' one coefficient
    s6(:, 5) = jt_times(x_gram(0, 0, rot, [0.0_dp, 0.0_dp], gm), fr)
    s6(:, 6) = jt_times(x_gram(0, 0, [0.0_dp, 0.0_dp], rot, gm), fr)
    if (sys%absang(l) == 0) return
    msum = msum + jt_times(x_gram(0, 0, fr%e2, fr%e2, gm), fr)          ! J's angle columns summed
    csum = csum + jt_times(x_gram(0, 0, -2.0_dp*fr%om*fr%e1, -2.0_dp*fr%om*fr%e1, gm), fr)   ! dr''/dv's
  end subroutine inertia_block

  !> X G for the phi coefficients X (2, 4) of a column: e_j at phi_ub (ub = 1, 2; 0: none), x3 and x4
  !> at N_0 and N_1 (G symmetric; the zero coefficients skipped).
  pure function x_gram(j, ub, x3, x4, gm) result(y)
    integer, intent(in) :: j, ub
    real(dp), intent(in) :: x3(2), x4(2), gm(4, 4)
    real(dp) :: y(2, 4)
    integer :: k
    do k = 1, 4
      y(:, k) = x3*gm(3, k) + x4*gm(4, k)
    end do
    if (ub > 0) y(j, :) = y(j, :) + gm(ub, :)
  end function x_gram

  !> J^T applied to a field's phi coefficients x (2, 4): (J^T x)_i = sum_a J_a,i . x_a over the local
  !> DOFs, J = dr'/dq' (J_1 = I, J_2 = 0 on rs and the reverse on re, plus th_k g_j e1 on N_k;
  !> e2 N_k on th_k).
  pure function jt_times(x, fr) result(col)
    real(dp), intent(in) :: x(2, 4)
    type(chord_frame), intent(in) :: fr
    real(dp) :: col(6), s
    s = fr%th(1)*dot_product(fr%e1, x(:, 3)) + fr%th(2)*dot_product(fr%e1, x(:, 4))
    col(1:2) = x(:, 1) + s*fr%g
    col(3:4) = x(:, 2) - s*fr%g
    col(5) = dot_product(fr%e2, x(:, 3)); col(6) = dot_product(fr%e2, x(:, 4))
  end function jt_times

  !> Rotary inertias' part of S: J d d^T with d = d psi/dq = [-g, g, 1 at th_k], and the velocity
  !> dependence of psi'' through alpha0 (ccv J d w0^T on the end columns); msum gets J d.
  pure subroutine rotary_block(sys, l, fr, ccv, s6, msum)
    type(coupled_system), intent(in) :: sys
    integer, intent(in) :: l
    type(chord_frame), intent(in) :: fr
    real(dp), intent(in) :: ccv
    real(dp), intent(inout) :: s6(6, 6), msum(6)
    real(dp) :: d(6), w0(2)
    integer :: i, j
    do i = 1, sys%nri
      if (sys%ri_seg(i) /= l) cycle
      w0 = alpha0_rate(fr)
      d = [-fr%g(1), -fr%g(2), fr%g(1), fr%g(2), 0.0_dp, 0.0_dp]
      d(5 + sys%ri_node(i)) = 1.0_dp
      do j = 1, 6
        s6(:, j) = s6(:, j) + sys%ri_j(i)*d(j)*d
      end do
      do j = 1, 2
        s6(:, j) = s6(:, j) - ccv*sys%ri_j(i)*w0(j)*d
        s6(:, 2 + j) = s6(:, 2 + j) + ccv*sys%ri_j(i)*w0(j)*d
      end do
      if (sys%absang(l) == 1) msum = msum + sys%ri_j(i)*d
    end do
  end subroutine rotary_block

  !> Axial stiffness ckt d2U/dq2: (EA/L) u u^T + (f/ell)(I - u u^T) between the ends (u = e1) and,
  !> for a shallow arch, EA u ath^T between the ends and the angles and EA L ath ath^T + f L A/30; and
  !> the chord stretch's damping ccv a_K (EA/L) u u^T between the ends.
  pure subroutine axial_block(sys, l, fr, ccv, ckt, f, ath, s6)
    type(coupled_system), intent(in) :: sys
    integer, intent(in) :: l
    type(chord_frame), intent(in) :: fr
    real(dp), intent(in) :: ccv, ckt, f, ath(2)
    real(dp), intent(inout) :: s6(6, 6)
    real(dp) :: len, ea, cc(2, 2), ua(2, 2)
    integer :: j
    len = sys%prop(1, l); ea = sys%prop(3, l)
    do j = 1, 2
      cc(:, j) = fr%e1*fr%e1(j)
    end do
    cc = (ckt*(ea/len - f/fr%ell) + ccv*sys%ray(2)*ea/len)*cc    ! + the stretch damping's C_v
    cc(1, 1) = cc(1, 1) + ckt*f/fr%ell; cc(2, 2) = cc(2, 2) + ckt*f/fr%ell
    if (sys%ray(2) /= 0.0_dp) cc = cc + ckt*stretch_damping_k(sys%ray(2)*ea/len, fr%e1, fr%cd, fr%ell)
    s6(1:2, 1:2) = s6(1:2, 1:2) + cc; s6(3:4, 3:4) = s6(3:4, 3:4) + cc
    s6(1:2, 3:4) = s6(1:2, 3:4) - cc; s6(3:4, 1:2) = s6(3:4, 1:2) - cc
    if (sys%arch(l) == 0) return
    do j = 1, 2
      ua(:, j) = ckt*ea*fr%e1*ath(j)
    end do
    s6(3:4, 5:6) = s6(3:4, 5:6) + ua; s6(5:6, 3:4) = s6(5:6, 3:4) + transpose(ua)
    s6(1:2, 5:6) = s6(1:2, 5:6) - ua; s6(5:6, 1:2) = s6(5:6, 1:2) - transpose(ua)
    do j = 1, 2
      s6(5:6, 4 + j) = s6(5:6, 4 + j) + ckt*(ea*len*ath*ath(j) + f*len*merge([4.0_dp, -1.0_dp], [-1.0_dp, 4.0_dp], j == 1)/30.0_dp)
    end do
  end subroutine axial_block

  !> d(fd e1)/dc [N/m] of the stretch damping force fd = ck (e1 . c') along e1 = c/ell (ck = a_K EA/L
  !> [N s/m]): ck/ell (e1 c'^T + (e1 . c') I)(I - e1 e1^T), the part of K_t between the chord's ends.
  pure function stretch_damping_k(ck, e1, cd, ell) result(d)
    real(dp), intent(in) :: ck, e1(2), cd(2), ell
    real(dp) :: d(2, 2), p(2, 2)
    integer :: j
    do j = 1, 2
      p(:, j) = -e1*e1(j)
      p(j, j) = p(j, j) + 1.0_dp
      d(:, j) = e1*cd(j)
      d(j, j) = d(j, j) + dot_product(e1, cd)
    end do
    d = ck/ell*matmul(d, p)
  end function stretch_damping_k

  !> Bending and damping: ckt K_th + ccv C_th on the angles; csum gets C_th's angle-column sums.
  pure subroutine bending_block(sys, l, ccv, ckt, s6, csum)
    type(coupled_system), intent(in) :: sys
    integer, intent(in) :: l
    real(dp), intent(in) :: ccv, ckt
    real(dp), intent(inout) :: s6(6, 6), csum(6)
    real(dp) :: cth(2, 2)
    integer :: el
    el = sys%el_off(l) + 1
    s6(5:6, 5:6) = s6(5:6, 5:6) + ckt*angle_part(sys, el, .true.)
    if (.not. damped(sys)) return
    cth = damping_th(sys, el)
    s6(5:6, 5:6) = s6(5:6, 5:6) + ccv*cth
    if (sys%absang(l) == 1) csum(5:6) = csum(5:6) + cth(:, 1) + cth(:, 2)
  end subroutine bending_block

  !> The parts of S from the chord terms of the relative angle rates th' = psi' - omega(c, c') and
  !> th'' = psi'' - alpha(c, c', c''), as columns of the end positions (before angle_transform):
  !> S(:, rs) += msum (ccv w0 + ckt da) + csum ckt H c', S(:, re) -= the same, with w0 = d alpha0/dc',
  !> da = d alpha/dc = H c'' + d alpha0/dc, H = d2phi/dc2 and msum, csum the sums of the angle columns
  !> of M and C_v (alpha0 = -2 (c.c') omega / |c|^2, the velocity part of alpha).
  pure subroutine angle_rate_terms(s6, c, cd, cdd, g, om, h, ccv, ckt, msum, csum)
    real(dp), intent(inout) :: s6(6, 6)
    real(dp), intent(in) :: c(2), cd(2), cdd(2), g(2), om, h(2, 2), ccv, ckt, msum(:), csum(:)
    real(dp) :: l2, sc, hc(2), w0(2), da(2), col(6)
    integer :: j
    l2 = c(1)**2 + c(2)**2
    sc = c(1)*cd(1) + c(2)*cd(2)
    hc = matmul(h, cd)
    w0 = -(2.0_dp/l2)*(om*c + sc*g)
    da = matmul(h, cdd) - 2.0_dp*(cd*om/l2 + sc*hc/l2 - 2.0_dp*sc*om*c/l2**2)
    do j = 1, 2
      col = msum(1:6)*(ccv*w0(j) + ckt*da(j)) + csum(1:6)*ckt*hc(j)
      s6(:, j) = s6(:, j) + col
      s6(:, 2 + j) = s6(:, 2 + j) - col
    end do
  end subroutine angle_rate_terms

  !> S <- (I + E)^T S (I + E) on a one-element segment's block s6, E(th_k, 1:4) = e for its angle
  !> DOFs th(:): the change from chord-relative to absolute node angles (see one_element_eval).
  pure subroutine angle_transform(s6, th, e)
    real(dp), intent(inout) :: s6(6, 6)
    integer, intent(in) :: th(:)
    real(dp), intent(in) :: e(4)
    real(dp) :: sum_th(6)
    integer :: j, k
    sum_th = 0.0_dp
    do k = 1, size(th)          ! S (I + E): columns 1:4 gain the angle columns times e
      sum_th = sum_th + s6(:, th(k))
    end do
    do j = 1, 4
      s6(:, j) = s6(:, j) + sum_th*e(j)
    end do
    sum_th = 0.0_dp
    do k = 1, size(th)          ! (I + E)^T: rows 1:4 gain the angle rows times e
      sum_th = sum_th + s6(th(k), :)
    end do
    do j = 1, 4
      s6(j, :) = s6(j, :) + e(j)*sum_th
    end do
  end subroutine angle_transform

end module flexmech_coupled_corot
