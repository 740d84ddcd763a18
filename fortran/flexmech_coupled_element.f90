!> The segments of the coupled and nonlinear models: residual, energies and blocks of the iteration
!> matrix of one segment (link_eval) from its local vector [xs, ys, xe, ye, th_0, p_1, v_1, th_1, ...,
!> th_n] (flexmech_coupled_system): inertia in closed form over the elements' Gram matrices or at the
!> Gauss points, rotary inertias, the axial strain of the chord (and of the shallow arch), bending and
!> Rayleigh damping; absolute node angles carried to the chord-relative ones (docs/theory.md 11-12).
module flexmech_coupled_element
  use flexmech_kinds, only: dp
  use flexmech_lapack, only: STATUS_OK
  use flexmech_coupled_system, only: coupled_system, set_mode, wrap, elem_index, shape_fn, th_index, gx, gw
  use flexmech_coupled_storage, only: link_mats, lm_add, lm_add_block, lm_block_get, lm_block_put, lm_put_one
  use flexmech_coupled_corot, only: one_element_residual, one_element_eval, one_element_elastic, absolute_block, &
                                    chord, stretch_damping_k
  implicit none
  private
  public :: link_eval, segment_residual, coupled_set_inertia, INERTIA_CLOSED, INERTIA_GAUSS

  !> Inertia in closed form over the elements' Gram matrices: INERTIA_CLOSED (default; one-element
  !> segments in one pass by flexmech_coupled_corot, the elements of longer ones long_element_inertia) or INERTIA_GAUSS
  !> (mass_point at the Gauss points throughout; the check of the closed form)
  integer, parameter :: INERTIA_CLOSED = 0, INERTIA_GAUSS = 1
  integer :: inertia_mode = INERTIA_CLOSED

contains

  !> Inertia of one-element segments in every later call (INERTIA_*); status STATUS_BAD_INPUT otherwise.
  subroutine coupled_set_inertia(mode, status)
    integer, intent(in) :: mode
    integer, intent(out) :: status
    call set_mode(mode, INERTIA_CLOSED, INERTIA_GAUSS, inertia_mode, status)
  end subroutine coupled_set_inertia

  !> Residual (local vector of length nld), energies and, if want, the blocks of segment l of the
  !> iteration matrix S = M + ccv C_v + ckt K_t (added to lm, which the caller has zeroed); a
  !> one-element segment's energies only when not want (one_element_eval).
  !> A segment with absolute node angles (sys%absang(l) = 1, the nonlinear model) is evaluated in the
  !> chord-relative angles th_k = psi_k - phi, th_k' = psi_k' - omega, th_k'' = psi_k'' - alpha, and
  !> its residual and matrix carried back by T = d th / d(xs, ys, xe, ye, psi) (docs/theory.md 12.1):
  !>   R = T^T R_rel,   S = T^T S_rel T - ckt (sum_k R_rel,th_k) d2phi/d(rs, re)2,
  !> the last term the geometric stiffness of the end moments turning with the chord.
  subroutine link_eval(sys, l, q, v, a, want, ccv, ckt, r, lm, ekin, epot)
    type(coupled_system), intent(in) :: sys
    integer, intent(in) :: l
    real(dp), intent(in) :: q(:), v(:), a(:), ccv, ckt
    logical, intent(in) :: want
    real(dp), intent(out) :: r(:), ekin, epot
    type(link_mats), intent(inout) :: lm
    integer :: n, nl, k, it(2)
    real(dp) :: qr(6), vr(6), ar(6), msum(6), csum(6)
    real(dp) :: cs, sn, ell, g(2), om, al0, al, phi, sr, s6(6, 6)
    if (sys%n_el(l) == 1 .and. inertia_mode == INERTIA_CLOSED) then   ! one element: one pass
      call one_element_eval(sys, l, q, v, a, want, ccv, ckt, r, s6, ekin, epot)
      if (want) call lm_put_one(sys, lm, l, s6)
      return
    end if
    if (sys%absang(l) == 0) then
      call link_eval_rel(sys, l, q, v, a, want, ccv, ckt, r, lm, ekin, epot)
      return
    end if
    n = 1; nl = 6                  ! absolute angles: one element per segment (coupled_build)
    call chord(q, v, a, cs, sn, ell, g, om, al0, al)
    phi = atan2(sn, cs)
    qr = q(1:6); vr = v(1:6); ar = a(1:6)
    do k = 0, n
      it(k + 1) = th_index(n, k)
      qr(it(k + 1)) = wrap(q(it(k + 1)) - phi)
      vr(it(k + 1)) = v(it(k + 1)) - om
      ar(it(k + 1)) = a(it(k + 1)) - al
    end do
    call link_eval_rel(sys, l, qr, vr, ar, want, ccv, ckt, r, lm, ekin, epot, msum, csum)
    sr = sum(r(it(1:n + 1)))
    r(1:2) = r(1:2) + sr*g
    r(3:4) = r(3:4) - sr*g
    if (.not. want) return
    call lm_block_get(lm, l, s6)
    call absolute_block(s6, q(3:4) - q(1:2), v(3:4) - v(1:2), a(3:4) - a(1:2), sr, ccv, ckt, msum, csum)
    call lm_block_put(lm, l, s6)
  end subroutine link_eval

  !> The residual alone of segment l (local vector r of length 3 n_el + 3; link_eval's, without
  !> energies or matrix): the Newton iterations that keep the factorized matrix.  A one-element
  !> segment with closed-form inertia goes through one_element_residual, the others through link_eval.
  subroutine segment_residual(sys, l, q, v, a, r, lm)
    type(coupled_system), intent(in) :: sys
    integer, intent(in) :: l
    real(dp), intent(in) :: q(:), v(:), a(:)
    real(dp), intent(out) :: r(:)
    type(link_mats), intent(inout) :: lm
    real(dp) :: ekin, epot
    if (sys%n_el(l) == 1 .and. inertia_mode == INERTIA_CLOSED) then
      call one_element_residual(sys, l, q, v, a, r)
    else
      call link_eval(sys, l, q, v, a, .false., 0.0_dp, 0.0_dp, r, lm, ekin, epot)
    end if
  end subroutine segment_residual

  !> link_eval in chord-relative angles (the coupled model's segments; one-element segments here only
  !> on the Gauss-point check path, their other terms from flexmech_coupled_corot).
  subroutine link_eval_rel(sys, l, q, v, a, want, ccv, ckt, r, lm, ekin, epot, msum, csum)
    type(coupled_system), intent(in) :: sys
    integer, intent(in) :: l
    real(dp), intent(in) :: q(:), v(:), a(:), ccv, ckt
    logical, intent(in) :: want
    real(dp), intent(out) :: r(:), ekin, epot
    real(dp), intent(out), optional :: msum(:), csum(:)   !< (nl) sums of the angle columns of M and C_v (if want)
    type(link_mats), intent(inout) :: lm
    integer :: n, nl, e
    real(dp) :: cs, sn, ell, g(2), om, al0, al, s6(6, 6), m6(6), c6(6)
    n = sys%n_el(l); nl = 3*n + 3
    r(1:nl) = 0.0_dp; ekin = 0.0_dp; epot = 0.0_dp
    m6 = 0.0_dp; c6 = 0.0_dp
    if (present(msum)) then
      msum(1:nl) = 0.0_dp; csum(1:nl) = 0.0_dp
    end if
    if (inertia_mode == INERTIA_CLOSED .and. .not. present(msum)) then   ! element by element
      do e = 1, n
        call long_element_inertia(sys, l, e, q, v, a, want, ccv, ckt, r, lm, ekin, epot)
      end do
    else
      call gauss_inertia(sys, l, q, v, a, want, ccv, ckt, r, lm, ekin, epot, msum, csum)
    end if
    if (n == 1) then      ! the one-pass kernel's own rotary, axial (arch) and bending terms
      call one_element_elastic(sys, l, q, v, a, want, ccv, ckt, r, s6, m6, c6, ekin, epot)
      if (want) call lm_add_block(lm, l, 6, [1, 2, 3, 4, 5, 6], s6)
      if (present(msum)) then
        msum(1:6) = msum(1:6) + m6; csum(1:6) = csum(1:6) + c6
      end if
      return
    end if
    call chord(q, v, a, cs, sn, ell, g, om, al0, al)
    call rotary_inertias(sys, l, q, v, a, want, ccv, ell, g, om, al, r, lm, ekin, msum)
    call axial_strain(sys, l, q, v, ell, want, ccv, ckt, r, lm, epot)
    call bending_forces(sys, l, q, v, want, ccv, ckt, r, lm, epot, csum)
  end subroutine link_eval_rel

  !> Inertia of element e of a longer segment l in closed form (what mass_point gives summed over the
  !> element's Gauss points and point masses): residual, kinetic and gravity energy and, if want, the
  !> element's block of S = M + cc C_v + ck K_t.  Over psi = [1 - xi, xi, H_v0, H_th0, H_v1, H_th1]
  !> every field of mass_point is sum_a psi_a X_a, with (1 - w) = (1 - w_0) psi_1 + (1 - w_1) psi_2,
  !> w = w_0 psi_1 + w_1 psi_2 (w_0, w_1 the element's node fractions) and R u = sum_a psi_a U_a
  !> (U_1 = p_0 e1, U_2 = p_1 e1, U_3 = v_0 e2, U_4 = th_0 e2, U_5 = v_1 e2, U_6 = th_1 e2), so
  !> R_j = sum_a J_a,j . (G r'')_a and S_ij = sum_a J_a,i . (G B_j)_a with G = sys%gram6 (docs/theory.md
  !> section 12.3).  Local DOFs of the segment as in link_eval_rel.
  subroutine long_element_inertia(sys, l, e, q, v, a, want, cc, ck, r, lm, ekin, epot)
    type(coupled_system), intent(in) :: sys
    integer, intent(in) :: l, e
    real(dp), intent(in) :: q(:), v(:), a(:), cc, ck
    logical, intent(in) :: want
    real(dp), intent(inout) :: r(:), ekin, epot
    type(link_mats), intent(inout) :: lm
    integer, parameter :: basis(6) = [1, 3, 4, 2, 5, 6]      ! psi of the element DOFs [p, v, th, p, v, th]
    integer :: idx(6), i, b
    real(dp) :: cs, sn, ell, g(2), om, al0, al, e1(2), e2(2), gm(6, 6), cst(6), cen(6), dir(2, 6)
    real(dp) :: u(2, 6), ud(2, 6), udd(2, 6), rd(2, 6), rdd(2, 6), ga(2, 6), gv(2, 6), s1, w0, w1
    gm = sys%gram6(:, :, sys%el_off(l) + e)
    call chord(q, v, a, cs, sn, ell, g, om, al0, al)
    e1 = [cs, sn]; e2 = [-sn, cs]
    w0 = sys%wn(e, l); w1 = sys%wn(e + 1, l)
    cst = [1.0_dp - w0, 1.0_dp - w1, 0.0_dp, 0.0_dp, 0.0_dp, 0.0_dp]
    cen = [w0, w1, 0.0_dp, 0.0_dp, 0.0_dp, 0.0_dp]
    idx = elem_index(sys%n_el(l), e)
    u = 0.0_dp; ud = 0.0_dp; udd = 0.0_dp
    do i = 1, 6
      dir(:, i) = merge(e1, e2, i == 1 .or. i == 4)
      if (idx(i) == 0) cycle
      b = basis(i)
      u(:, b) = q(idx(i))*dir(:, i); ud(:, b) = v(idx(i))*dir(:, i); udd(:, b) = a(idx(i))*dir(:, i)
    end do
    do b = 1, 6           ! r' and r'' - g by basis function (Omega x = (-x_2, x_1))
      rd(:, b) = cst(b)*v(1:2) + cen(b)*v(3:4) + om*[-u(2, b), u(1, b)] + ud(:, b)
      rdd(:, b) = cst(b)*(a(1:2) - sys%grav) + cen(b)*(a(3:4) - sys%grav) + al*[-u(2, b), u(1, b)] &
                  - om*om*u(:, b) + 2.0_dp*om*[-ud(2, b), ud(1, b)] + udd(:, b)
    end do
    ga = matmul(rdd, gm); gv = matmul(rd, gm)
    ekin = ekin + 0.5_dp*sum(gv*rd)
    do b = 1, 6           ! int r dm = sum_b r_b (G_b1 + G_b2): psi_1 + psi_2 = 1
      epot = epot - (gm(b, 1) + gm(b, 2))*dot_product(sys%grav, cst(b)*q(1:2) + cen(b)*q(3:4) + u(:, b))
    end do
    s1 = sum(-u(2, :)*ga(1, :) + u(1, :)*ga(2, :))           ! sum_b (Omega U_b) . (G r'')_b
    r(1:2) = r(1:2) + cst(1)*ga(:, 1) + cst(2)*ga(:, 2) - s1*g      ! cst, cen vanish past psi_2
    r(3:4) = r(3:4) + cen(1)*ga(:, 1) + cen(2)*ga(:, 2) + s1*g
    do i = 1, 6
      if (idx(i) > 0) r(idx(i)) = r(idx(i)) + dot_product(dir(:, i), ga(:, basis(i)))
    end do
    if (want) call long_element_block(l, q, v, cc, ck, gm, idx, basis, dir, cst, cen, u, ud, &
                                      ell, g, om, al, lm)
  end subroutine long_element_inertia

  !> The block of S of element e of a longer segment (long_element_inertia, whose fields it takes):
  !> over the columns the element touches (the segment's end positions, then its DOFs idx > 0),
  !> J = dr'/dq' and B = J + cc dr''/dv + ck dr''/dq (at fixed chord, as mass_point) by psi
  !> coefficients X(2, 6, column), Z(2, 6, column); S_ij = sum_a X_a,i . (G Z_j)_a.  An elastic DOF's
  !> columns have one psi coefficient (its own shape), which the sums skip to.
  subroutine long_element_block(l, q, v, cc, ck, gm, idx, basis, dir, cst, cen, u, ud, ell, g, om, al, lm)
    integer, intent(in) :: l, idx(6), basis(6)
    real(dp), intent(in) :: q(:), v(:), cc, ck, gm(6, 6), dir(2, 6), cst(6), cen(6), u(2, 6), ud(2, 6)
    real(dp), intent(in) :: ell, g(2), om, al
    type(link_mats), intent(inout) :: lm
    integer :: i, j, b, ncl, cl(10), bc(10), pos(10)
    real(dp) :: x(2, 6, 4), z(2, 6, 4), zc(2, 10), gz(2, 6, 10), blk(10, 10), c(2), cd(2), w0v(2), ej(2), ou(2), yv(2), od(2)
    c = q(3:4) - q(1:2); cd = v(3:4) - v(1:2)
    w0v = -(2.0_dp/ell**2)*(om*c + (c(1)*cd(1) + c(2)*cd(2))*g)      ! d alpha0 / d c'
    do j = 1, 2           ! the end-position columns: rs (j), re (2 + j)
      ej = 0.0_dp; ej(j) = 1.0_dp
      do b = 1, 6
        ou = [-u(2, b), u(1, b)]
        yv = ou*w0v(j) + (-2.0_dp*om*u(:, b) + 2.0_dp*[-ud(2, b), ud(1, b)])*g(j)
        x(:, b, j) = cst(b)*ej - g(j)*ou
        x(:, b, 2 + j) = cen(b)*ej + g(j)*ou
        z(:, b, j) = x(:, b, j) - cc*yv
        z(:, b, 2 + j) = x(:, b, 2 + j) + cc*yv
      end do
    end do
    ncl = 4
    cl(1:4) = [1, 2, 3, 4]
    do i = 1, 6           ! the element's DOFs: J = R N_i, B adds 2 omega R Omega N_i and alpha R Omega N_i - omega^2 R N_i
      if (idx(i) == 0) cycle
      ncl = ncl + 1
      cl(ncl) = idx(i); bc(ncl) = basis(i); pos(ncl) = i
      od = [-dir(2, i), dir(1, i)]
      zc(:, ncl) = dir(:, i) + (2.0_dp*cc*om + ck*al)*od - (ck*om*om)*dir(:, i)    ! its one coefficient
    end do
    do j = 1, 4
      gz(:, :, j) = matmul(z(:, :, j), gm)
    end do
    do j = 5, ncl
      do b = 1, 6
        gz(:, b, j) = zc(:, j)*gm(bc(j), b)
      end do
    end do
    do j = 1, ncl
      do i = 1, 4
        blk(i, j) = sum(x(:, :, i)*gz(:, :, j))
      end do
      do i = 5, ncl
        blk(i, j) = dot_product(dir(:, pos(i)), gz(:, bc(i), j))
      end do
    end do
    call lm_add_block(lm, l, ncl, cl, blk)
  end subroutine long_element_block

  !> Inertia and gravity of segment l by mass_point at each element's Gauss points and at the
  !> point masses on the segment (local DOFs as link_eval_rel).
  subroutine gauss_inertia(sys, l, q, v, a, want, ccv, ckt, r, lm, ekin, epot, msum, csum)
    type(coupled_system), intent(in) :: sys
    integer, intent(in) :: l
    real(dp), intent(in) :: q(:), v(:), a(:), ccv, ckt
    logical, intent(in) :: want
    real(dp), intent(inout) :: r(:), ekin, epot
    real(dp), intent(inout), optional :: msum(:), csum(:)
    type(link_mats), intent(inout) :: lm
    integer :: n, e, k, i
    real(dp) :: len, rho_a, dw, le, xi
    n = sys%n_el(l)
    len = sys%prop(1, l); rho_a = sys%prop(2, l)
    do e = 1, n          ! distributed mass
      dw = sys%wn(e + 1, l) - sys%wn(e, l)
      le = len*dw
      do k = 1, 4
        call mass_point(sys, l, q, v, a, e, gx(k), sys%wn(e, l) + gx(k)*dw, le, gw(k)*rho_a*le, want, ccv, ckt, r, &
                        lm, ekin, epot, msum, csum)
      end do
    end do
    do i = 1, sys%npm    ! point masses on this segment
      if (sys%pm_seg(i) /= l) cycle
      e = sys%pm_el(i)
      xi = sys%pm_prop(1, i)
      dw = sys%wn(e + 1, l) - sys%wn(e, l)
      call mass_point(sys, l, q, v, a, e, xi, sys%wn(e, l) + xi*dw, len*dw, sys%pm_prop(2, i), want, &
                      ccv, ckt, r, lm, ekin, epot, msum, csum)
    end do
  end subroutine gauss_inertia

  !> Contribution of one mass point (weight dm at segment fraction w, element e of length le at xi) to the segment
  !> residual and iteration matrix.  Adds dm * J^T (r'' - grav) to r and, if want, to segment l's
  !> blocks of S (lm) dm J^T (J + cc dr''/dv + ck dr''/d(elastic q)) (the point's parts of M, C_v,
  !> K_t); returns the kinetic energy 1/2 dm |r'|^2.  If want, msum and csum (local DOFs) get the
  !> point's part of the sums over the element's angle columns th of M and of C_v (link_eval).
  subroutine mass_point(sys, l, q, v, a, e, xi, w, le, dm, want, cc, ck, r, lm, ekin, epot, msum, csum)
    type(coupled_system), intent(in) :: sys
    integer, intent(in) :: l, e
    real(dp), intent(in) :: q(:), v(:), a(:), xi, w, le, dm, cc, ck
    logical, intent(in) :: want
    real(dp), intent(inout) :: r(:), ekin, epot
    real(dp), intent(inout), optional :: msum(:), csum(:)
    type(link_mats), intent(inout) :: lm
    integer :: n, idx(6), i, j, nl, ncl, cl(10)
    real(dp) :: cs, sn, ell, g(2), om, al0, al, nm(2, 6), de(6), dv(6), da(6)
    real(dp) :: ul(2), uld(2), uldd(2), rot(2, 2), ru(2), rou(2), roud(2), rd(2), rdd(2), jac(2, 10)
    n = sys%n_el(l); nl = 3*n + 3
    idx = elem_index(n, e)
    call chord(q, v, a, cs, sn, ell, g, om, al0, al)
    nm = shape_fn(xi, le)
    do i = 1, 6
      if (idx(i) > 0) then
        de(i) = q(idx(i)); dv(i) = v(idx(i)); da(i) = a(idx(i))
      else
        de(i) = 0.0_dp; dv(i) = 0.0_dp; da(i) = 0.0_dp
      end if
    end do
    ul = matmul(nm, de); uld = matmul(nm, dv); uldd = matmul(nm, da)
    rot(1, 1) = cs; rot(2, 1) = sn; rot(1, 2) = -sn; rot(2, 2) = cs
    ru = matmul(rot, ul)                     ! R u
    rou = [-ru(2), ru(1)]                    ! R Omega u = Omega R u
    roud = matmul(rot, [-uld(2), uld(1)])    ! R Omega u'
    rd = (1.0_dp - w)*v(1:2) + w*v(3:4) + om*rou + matmul(rot, uld)
    rdd = (1.0_dp - w)*a(1:2) + w*a(3:4) + al*rou - om*om*ru + 2.0_dp*om*roud + matmul(rot, uldd)
    ekin = ekin + 0.5_dp*dm*(rd(1)**2 + rd(2)**2)
    epot = epot - dm*dot_product(sys%grav, (1.0_dp - w)*q(1:2) + w*q(3:4) + ru)
    ! J = dr'/dq', on the (at most 10) columns this point touches: the link ends and the element's DOFs
    ncl = 4
    cl(1:4) = [1, 2, 3, 4]
    jac(:, 1:4) = 0.0_dp
    jac(1, 1) = 1.0_dp - w; jac(2, 2) = 1.0_dp - w; jac(1, 3) = w; jac(2, 4) = w
    do j = 1, 2
      jac(:, j) = jac(:, j) - rou*g(j)
      jac(:, 2 + j) = jac(:, 2 + j) + rou*g(j)
    end do
    do i = 1, 6
      if (idx(i) == 0) cycle
      ncl = ncl + 1
      cl(ncl) = idx(i)
      jac(:, ncl) = matmul(rot, nm(:, i))
    end do
    rdd = rdd - sys%grav
    do j = 1, ncl
      r(cl(j)) = r(cl(j)) + dm*(rdd(1)*jac(1, j) + rdd(2)*jac(2, j))
    end do
    if (.not. want) return
    call mass_point_block(l, q, v, idx, ncl, cl, jac, ell, g, om, al, ru, rou, roud, dm, cc, ck, lm, msum, csum)
  end subroutine mass_point

  !> mass_point's blocks of S (and, with msum, its angle-column sums) for a mass dm on the columns
  !> cl(1:ncl) of segment l with J = dr/dq' (jac) there: dm J^T (J + cc dr''/dv + ck dr''/dq) with
  !> dr''/dq at fixed chord; ell, g, om, al the chord quantities, ru = R u, rou = Omega R u,
  !> roud = R Omega u' of the point.
  subroutine mass_point_block(l, q, v, idx, ncl, cl, jac, ell, g, om, al, ru, rou, roud, dm, cc, ck, lm, msum, csum)
    integer, intent(in) :: l, idx(6), ncl, cl(10)
    real(dp), intent(in) :: q(:), v(:), jac(2, 10), ell, g(2), om, al, ru(2), rou(2), roud(2), dm, cc, ck
    type(link_mats), intent(inout) :: lm
    real(dp), intent(inout), optional :: msum(:), csum(:)
    integer :: i, j
    real(dp) :: jth(2), bth(2), bv(2, 10), bq(2, 10), ac(2, 2), w0(2), cdot(2), c(2), rn(2), bc(2), blk(10, 10)
    ! dr''/dv: chord velocity through omega and alpha0, elastic velocities through 2 omega R Omega N
    c = q(3:4) - q(1:2); cdot = v(3:4) - v(1:2)
    w0 = -(2.0_dp/ell**2)*(om*c + (c(1)*cdot(1) + c(2)*cdot(2))*g)
    do j = 1, 2
      ac(:, j) = rou*w0(j) + (-2.0_dp*om*ru + 2.0_dp*roud)*g(j)
    end do
    bv(:, 1:2) = -ac; bv(:, 3:4) = ac
    bq(:, 1:4) = 0.0_dp
    do j = 5, ncl
      rn = jac(:, j)                                   ! R N_i
      bv(:, j) = 2.0_dp*om*[-rn(2), rn(1)]             ! 2 omega R Omega N_i
      bq(:, j) = al*[-rn(2), rn(1)] - om*om*rn         ! at fixed chord
    end do
    do j = 1, ncl
      bc = jac(:, j) + cc*bv(:, j) + ck*bq(:, j)
      do i = 1, ncl
        blk(i, j) = dm*(jac(1, i)*bc(1) + jac(2, i)*bc(2))
      end do
    end do
    call lm_add_block(lm, l, ncl, cl, blk)
    if (.not. present(msum)) return
    jth = 0.0_dp; bth = 0.0_dp          ! the element's angle columns: idx(3) and idx(6)
    j = 4
    do i = 1, 6
      if (idx(i) == 0) cycle
      j = j + 1
      if (i == 3 .or. i == 6) then
        jth = jth + jac(:, j); bth = bth + bv(:, j)
      end if
    end do
    do i = 1, ncl
      msum(cl(i)) = msum(cl(i)) + dm*dot_product(jac(:, i), jth)
      csum(cl(i)) = csum(cl(i)) + dm*dot_product(jac(:, i), bth)
    end do
  end subroutine mass_point_block

  !> Rotary inertias turning with segment l (psi = phi + th_k at their node): residual, kinetic energy
  !> and (if want) their blocks of S and angle-column sums; ell, g, om, al the chord quantities.
  subroutine rotary_inertias(sys, l, q, v, a, want, ccv, ell, g, om, al, r, lm, ekin, msum)
    type(coupled_system), intent(in) :: sys
    integer, intent(in) :: l
    real(dp), intent(in) :: q(:), v(:), a(:), ccv, ell, g(2), om, al
    logical, intent(in) :: want
    real(dp), intent(inout) :: r(:), ekin
    real(dp), intent(inout), optional :: msum(:)
    type(link_mats), intent(inout) :: lm
    integer :: i, j, k, cl5(5)
    real(dp) :: c(2), w0(2), d5(5), blk(5, 5), psi_dd
    do i = 1, sys%nri    ! rotary inertias turning with this link: psi = phi + th_k
      if (sys%ri_seg(i) /= l) cycle
      k = th_index(sys%n_el(l), sys%ri_node(i))
      cl5 = [1, 2, 3, 4, k]                 ! d psi / d q is nonzero on these local DOFs only
      d5 = [-g(1), -g(2), g(1), g(2), 1.0_dp]
      psi_dd = al + a(k)
      r(cl5) = r(cl5) + sys%ri_j(i)*psi_dd*d5
      ekin = ekin + 0.5_dp*sys%ri_j(i)*(om + v(k))**2
      if (want) then
        do j = 1, 5
          blk(:, j) = sys%ri_j(i)*d5(j)*d5
        end do
        ! velocity dependence of psi'' through alpha0: d alpha0 / d c' = w0
        c = q(3:4) - q(1:2)
        w0 = -(2.0_dp/ell**2)*(om*c + (c(1)*(v(3) - v(1)) + c(2)*(v(4) - v(2)))*g)
        do j = 1, 2
          blk(:, j) = blk(:, j) - ccv*sys%ri_j(i)*w0(j)*d5
          blk(:, 2 + j) = blk(:, 2 + j) + ccv*sys%ri_j(i)*w0(j)*d5
        end do
        call lm_add_block(lm, l, 5, cl5, blk)
        if (present(msum)) msum(cl5) = msum(cl5) + sys%ri_j(i)*d5
      end if
    end do
  end subroutine rotary_inertias

  !> Axial strain energy of a segment l of several elements, U = 1/2 EA L eps^2 [J], its residual with
  !> the stiffness-proportional damping a_K EA eps' of the stretch and (if want) ckt times its stiffness
  !> plus ccv times that damping. eps = (|c| - L)/L, c = re - rs the chord [m], L the segment's length
  !> (one-element segments, whose strain may hold the shallow arch's term: flexmech_coupled_corot).
  subroutine axial_strain(sys, l, q, v, ell, want, ccv, ckt, r, lm, epot)
    type(coupled_system), intent(in) :: sys
    integer, intent(in) :: l
    real(dp), intent(in) :: q(:), v(:), ell, ccv, ckt
    logical, intent(in) :: want
    real(dp), intent(inout) :: r(:), epot
    type(link_mats), intent(inout) :: lm
    real(dp) :: len, ea, u(2), eps, f, ft, cc(2, 2)
    len = sys%prop(1, l); ea = sys%prop(3, l)
    u = (q(3:4) - q(1:2))/ell
    eps = (ell - len)/len
    f = ea*eps                               ! axial force [N]
    ft = f + sys%ray(2)*ea*dot_product(u, v(3:4) - v(1:2))/len     ! with the damping of the stretch
    r(1:2) = r(1:2) - ft*u
    r(3:4) = r(3:4) + ft*u
    epot = epot + 0.5_dp*ea*len*eps**2
    if (.not. want) return
    cc(:, 1) = u*u(1); cc(:, 2) = u*u(2)
    cc = (ckt*(ea/len - f/ell) + ccv*sys%ray(2)*ea/len)*cc
    if (sys%ray(2) /= 0.0_dp) cc = cc + ckt*stretch_damping_k(sys%ray(2)*ea/len, u, v(3:4) - v(1:2), ell)
    cc(1, 1) = cc(1, 1) + ckt*f/ell; cc(2, 2) = cc(2, 2) + ckt*f/ell
    lm%bb(1:2, 1:2, l) = lm%bb(1:2, 1:2, l) + cc; lm%bb(3:4, 3:4, l) = lm%bb(3:4, 3:4, l) + cc
    lm%bb(1:2, 3:4, l) = lm%bb(1:2, 3:4, l) - cc; lm%bb(3:4, 1:2, l) = lm%bb(3:4, 1:2, l) - cc
  end subroutine axial_strain

  !> Bending (the elements' local stiffness K) and Rayleigh damping of segment l, element by element
  !> over its local DOFs: residual, strain energy and (if want) ckt K + ccv C in S, C's angle-column
  !> sums in csum.
  subroutine bending_forces(sys, l, q, v, want, ccv, ckt, r, lm, epot, csum)
    type(coupled_system), intent(in) :: sys
    integer, intent(in) :: l
    real(dp), intent(in) :: q(:), v(:), ccv, ckt
    logical, intent(in) :: want
    real(dp), intent(inout) :: r(:), epot
    real(dp), intent(inout), optional :: csum(:)
    type(link_mats), intent(inout) :: lm
    integer :: n, e, i, j, idx(6)
    real(dp) :: de(6), dv(6), fe(6), ce(6, 6), val
    logical :: damped
    n = sys%n_el(l)
    damped = sys%ray(1) /= 0.0_dp .or. sys%ray(2) /= 0.0_dp
    do e = 1, n
      idx = elem_index(n, e)
      do i = 1, 6
        if (idx(i) > 0) then
          de(i) = q(idx(i)); dv(i) = v(idx(i))
        else
          de(i) = 0.0_dp; dv(i) = 0.0_dp
        end if
      end do
      fe = 0.0_dp
      do j = 1, 6              ! K de over the element's DOFs present here (th only in a one-element segment)
        if (idx(j) > 0) fe = fe + sys%ke(:, j, sys%el_off(l) + e)*de(j)
      end do
      epot = epot + 0.5_dp*dot_product(de, fe)
      if (damped) then
        ce = sys%ray(1)*sys%me(:, :, sys%el_off(l) + e) + sys%ray(2)*sys%ke(:, :, sys%el_off(l) + e)
        fe = fe + matmul(ce, dv)
      end if
      do i = 1, 6
        if (idx(i) > 0) r(idx(i)) = r(idx(i)) + fe(i)
      end do
      if (want) then
        do j = 1, 6
          if (idx(j) == 0) cycle
          do i = 1, 6
            if (idx(i) == 0) cycle
            val = ckt*sys%ke(i, j, sys%el_off(l) + e)
            if (damped) val = val + ccv*ce(i, j)
            call lm_add(lm, l, idx(i), idx(j), val)
          end do
        end do
        if (present(csum) .and. damped) then
          do i = 1, 6
            if (idx(i) > 0) csum(idx(i)) = csum(idx(i)) + ce(i, 3) + ce(i, 6)
          end do
        end if
      end if
    end do
  end subroutine bending_forces


end module flexmech_coupled_element
