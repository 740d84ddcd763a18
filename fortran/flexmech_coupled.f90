!> One-pass model with mutual rigid-elastic coupling (seed Section 3, Gibbs-Appell),
!> in the chord-frame form derived in docs/theory.md (section "Coupled model").
!>
!> Generalized coordinates of a link l of length L with n elements (local vector, nld = 3n+3):
!>   [xs, ys, xe, ye, th_0, p_1, v_1, th_1, ..., p_{n-1}, v_{n-1}, th_{n-1}, th_n]
!>   xs..ye   absolute positions [m] of the link's start and end ("rigid" DOFs; shared at joints)
!>   p_k, v_k elastic axial / transverse displacement [m] of interior node k in the chord frame
!>   th_k     elastic rotation [rad] of node k relative to the chord
!> The chord c = r_e - r_s defines the link frame: phi = atan2(c), omega = g.c', g = Omega c/|c|^2.
!> A material point at zeta (0..L along the link, w = zeta/L) is at
!>   r = (1-w) r_s + w r_e + R(phi) N(xi) delta_e ,
!> with delta_e the element's local elastic DOFs (end-node translations are zero by definition).
!> Gibbs-Appell: dG/da + dU/dq = Q with G = 1/2 int |r''|^2 dm, i.e. int J^T r'' dm + dU/dq = Q,
!> J = dr'/dq' = dr''/dq''.  Strain energy: 1/2 (EA/L)(|c| - L)^2 + 1/2 delta^T k delta.
!> Integration: generalized-alpha (Arnold & Bruls 2007; Newmark (beta, gamma) for am = af = 0) in
!> acceleration form with Newton iterations on the true acceleration a_{n+1}, the equations and the
!> constraints holding exactly at t_{n+1} (see flexmech_newmark and docs/theory.md section 15); the
!> iteration matrix S = M + gamma' dt C_v + beta' dt^2 K_t is built once per step (modified Newton):
!> M and C_v exact, K_t = elastic + chord + elastic inertial terms (the configuration
!> dependence of the inertia through the chord is left out of S; it is in the residual).
module flexmech_coupled
  use, intrinsic :: ieee_arithmetic, only: ieee_is_finite
  use flexmech_kinds, only: dp
  use flexmech_lapack, only: dgbtrf, dgbtrs, dgetrf, dgetrs, lapack_status, STATUS_OK, STATUS_NONFINITE, &
                             STATUS_BAD_INPUT, STATUS_NEWTON, STATUS_DIVERGED
  use flexmech_beam, only: beam_mass, beam_stiffness
  use flexmech_assembly, only: band_rows, band_to_dense
  implicit none
  private
  public :: coupled_system, coupled_build, coupled_run, coupled_dense, coupled_elastic_measure, STATUS_NEWTON
  public :: coupled_set_solver, SOLVER_AUTO, SOLVER_BAND, SOLVER_CONDENSED

  !> Linear solver of the iteration matrix in coupled_run (docs/theory.md section 11, "The solve"):
  !> SOLVER_CONDENSED eliminates every segment's elastic DOFs (a band of half width <= 5) onto the
  !> shared end-position DOFs and solves the condensed band system; SOLVER_BAND factorizes the whole
  !> free-DOF band matrix (half bandwidth 3 x elements per segment + 2); SOLVER_AUTO (default) takes
  !> the condensed solve when the whole band is wider than the interior band + 4, i.e. when the
  !> segments' arrowheads widen it (2 or more elements per segment); with one element per segment
  !> (the nonlinear model) the whole band is narrow and its one LAPACK call beats one per segment.
  integer, parameter :: SOLVER_AUTO = -1, SOLVER_BAND = 0, SOLVER_CONDENSED = 1
  integer :: solver_mode = SOLVER_AUTO

  real(dp), parameter :: gx(4) = [ &
    0.5_dp - 0.5_dp*0.8611363115940526_dp, 0.5_dp - 0.5_dp*0.3399810435848563_dp, &
    0.5_dp + 0.5_dp*0.3399810435848563_dp, 0.5_dp + 0.5_dp*0.8611363115940526_dp]
  real(dp), parameter :: gw(4) = 0.5_dp*[0.3478548451374538_dp, 0.6521451548625461_dp, &
                                          0.6521451548625461_dp, 0.3478548451374538_dp]

  type :: coupled_system
    integer :: nlinks = 0, ndof = 0, nfree = 0, maxld = 0, kl = 0, ku = 0, npm = 0, nri = 0, ntq = 0, nh = 0
    integer, allocatable :: n_el(:), ld(:, :), free_of(:)
    real(dp), allocatable :: prop(:, :)          !< (4, nlinks) [L, rho*A, E*A, E*I]
    real(dp), allocatable :: me(:, :, :), ke(:, :, :)  !< (6, 6, nlinks) local element mass, stiffness
    integer, allocatable :: pm_link(:), ri_link(:), ri_node(:)
    real(dp), allocatable :: pm_prop(:, :), ri_j(:)
    integer, allocatable :: tq_link(:, :), tq_end(:, :)   !< (2, ntq): [b, a] links (a = 0: ground), ends 0/1
    real(dp), allocatable :: tq_coef(:, :)                !< (1 + 2 nh, ntq)
    integer :: ncon = 0
    integer, allocatable :: con_link(:, :), con_end(:, :)   !< (2, ncon) like the torques
    real(dp) :: grav(2) = 0.0_dp, ray(2) = 0.0_dp
  end type coupled_system

  !> Iteration matrix S = M + cc C_v + ck K_t stored by segment blocks.  Local DOFs of segment l:
  !> 1..4 the end positions ("boundary", B), 5..nl the elastic DOFs ("interior", I; ni_l = nl - 4),
  !> numbered off(l)+1..off(l)+ni_l in the interior arrays.
  !>   bb(4, 4, l)   S_BB block of the segment            bi(4, ni)  S_BI (rows: local 1..4)
  !>   ib(ni, 4)     S_IB (columns: local 1..4)           ai(ldi, ni) S_II, LAPACK band storage with
  !>                 kl = ku = kbi (row 2 kbi + 1 + i - j), factorized in place (ipi) by the condensed solve
  !> Condensed solve (cond = .true.: every interior DOF free and local to one segment):
  !>   z = S_II^-1 S_IB per segment, Schur complement sb = S_BB - S_BI z over the nb free boundary DOFs
  !>   (band kbb, LAPACK storage, ipb), workspaces yi(ni, nrhs), yb(nb, nrhs).
  type :: link_mats
    integer :: ni = 0, kbi = 0, ldi = 0, nb = 0, kbb = 0, ldb = 0, nrhs = 0
    logical :: cond = .false.
    integer, allocatable :: off(:), ifree(:), bfree(:, :), bglob(:), ipi(:), ipb(:)
    real(dp), allocatable :: bb(:, :, :), bi(:, :), ib(:, :), ai(:, :), z(:, :), sb(:, :), yi(:, :), yb(:, :)
  end type link_mats

contains

  !> Build the system from flat arrays (see flexmech_api); status STATUS_BAD_INPUT on bad indices.
  subroutine coupled_build(sys, free_of, n_el, ld, prop, pm_link, pm_prop, ri_link, ri_node, ri_j, &
                           tq_link, tq_end, tq_coef, ncon, con_link, con_end, grav, ray, status)
    type(coupled_system), intent(out) :: sys
    integer, intent(in) :: free_of(:), n_el(:), ld(:, :), pm_link(:), ri_link(:), ri_node(:), tq_link(:, :), tq_end(:, :)
    integer, intent(in) :: ncon, con_link(:, :), con_end(:, :)   !< rotation constraints: the first ncon columns
    real(dp), intent(in) :: prop(:, :), pm_prop(:, :), ri_j(:), tq_coef(:, :), grav(2), ray(2)
    integer, intent(out) :: status
    integer :: l, nl, lo, hi, i, f
    status = STATUS_BAD_INPUT
    sys%nlinks = size(n_el); sys%ndof = size(free_of); sys%maxld = size(ld, 1)
    sys%nfree = maxval([0, free_of])
    if (sys%nfree < 1 .or. any(n_el < 1) .or. any(3*n_el + 3 > sys%maxld)) return
    if (any(prop(1:4, :) <= 0.0_dp)) return
    do l = 1, sys%nlinks
      nl = 3*n_el(l) + 3
      if (any(ld(1:nl, l) < 1) .or. any(ld(1:nl, l) > sys%ndof)) return
    end do
    if (any(pm_link < 1) .or. any(pm_link > sys%nlinks) .or. any(ri_link < 1) .or. any(ri_link > sys%nlinks)) return
    if (any(tq_link < 0) .or. any(tq_link > sys%nlinks) .or. any(tq_link(1, :) < 1)) return
    if (mod(size(tq_coef, 1), 2) /= 1) return
    if (ncon < 0 .or. ncon > size(con_link, 2)) return
    if (ncon > 0) then
      if (any(con_link(:, 1:ncon) < 0) .or. any(con_link(:, 1:ncon) > size(n_el)) .or. any(con_link(1, 1:ncon) < 1)) return
    end if
    sys%ncon = ncon
    sys%con_link = con_link(:, 1:max(ncon, 0)); sys%con_end = con_end(:, 1:max(ncon, 0))
    sys%n_el = n_el; sys%ld = ld; sys%prop = prop; sys%free_of = free_of
    sys%npm = size(pm_link); sys%pm_link = pm_link; sys%pm_prop = pm_prop
    sys%nri = size(ri_link); sys%ri_link = ri_link; sys%ri_node = ri_node; sys%ri_j = ri_j
    sys%ntq = size(tq_link, 2); sys%tq_link = tq_link; sys%tq_end = tq_end; sys%tq_coef = tq_coef
    sys%nh = (size(tq_coef, 1) - 1)/2
    sys%grav = grav; sys%ray = ray
    allocate (sys%me(6, 6, sys%nlinks), sys%ke(6, 6, sys%nlinks))
    do l = 1, sys%nlinks
      sys%me(:, :, l) = beam_mass(prop(2, l), prop(1, l)/n_el(l))
      sys%ke(:, :, l) = beam_stiffness(prop(3, l), prop(4, l), prop(1, l)/n_el(l))
    end do
    sys%kl = 0
    do l = 1, sys%nlinks
      nl = 3*n_el(l) + 3
      lo = huge(1); hi = 0
      do i = 1, nl
        f = free_of(ld(i, l))
        if (f > 0) then
          lo = min(lo, f); hi = max(hi, f)
        end if
      end do
      if (hi > 0) sys%kl = max(sys%kl, hi - lo)
    end do
    sys%ku = sys%kl
    status = STATUS_OK
  end subroutine coupled_build

  !> Dense residual (all DOFs), iteration-matrix parts over the free DOFs and energies at one state
  !> (for tests and analysis): mm = M, cm = C_v, km = K_t, energy = [kinetic, potential].
  subroutine coupled_dense(sys, q, v, a, res, mm, cm, km, energy)
    type(coupled_system), intent(in) :: sys
    real(dp), intent(in) :: q(:), v(:), a(:)
    real(dp), intent(out) :: res(:), mm(:, :), cm(:, :), km(:, :), energy(2)
    real(dp), allocatable :: ab(:, :)
    type(link_mats) :: lm
    call lm_setup(sys, 1, lm)
    allocate (ab(band_rows(sys%kl, sys%ku), sys%nfree))
    call assemble(sys, q, v, a, .true., 0.0_dp, 0.0_dp, res, lm, energy)
    call lm_to_band(sys, lm, ab)
    mm = band_to_dense(ab, sys%kl, sys%ku, sys%nfree)
    call assemble(sys, q, v, a, .true., 1.0_dp, 0.0_dp, res, lm, energy)
    call lm_to_band(sys, lm, ab)
    cm = band_to_dense(ab, sys%kl, sys%ku, sys%nfree) - mm
    call assemble(sys, q, v, a, .true., 0.0_dp, 1.0_dp, res, lm, energy)
    call lm_to_band(sys, lm, ab)
    km = band_to_dense(ab, sys%kl, sys%ku, sys%nfree) - mm
  end subroutine coupled_dense

  !> Position in the link vector of the elastic DOFs of element e (1..n): [p, v, th, p, v, th], 0 = none.
  pure function elem_index(n, e) result(idx)
    integer, intent(in) :: n, e
    integer :: idx(6), k
    k = e - 1
    idx = 0
    idx(3) = 3*k + 5
    if (k > 0) then
      idx(1) = 3*k + 3; idx(2) = 3*k + 4
    end if
    if (k + 1 < n) then
      idx(4) = 3*(k + 1) + 3; idx(5) = 3*(k + 1) + 4; idx(6) = 3*(k + 1) + 5
    else
      idx(6) = 3*n + 3
    end if
  end function elem_index

  !> Hermite/linear shape functions N (2 x 6) at xi for element length le.
  pure function shape_fn(xi, le) result(n)
    real(dp), intent(in) :: xi, le
    real(dp) :: n(2, 6)
    n = 0.0_dp
    n(1, 1) = 1.0_dp - xi; n(1, 4) = xi
    n(2, 2) = 1.0_dp - 3.0_dp*xi**2 + 2.0_dp*xi**3
    n(2, 3) = le*(xi - 2.0_dp*xi**2 + xi**3)
    n(2, 5) = 3.0_dp*xi**2 - 2.0_dp*xi**3
    n(2, 6) = le*(-xi**2 + xi**3)
  end function shape_fn

  !> Chord quantities of a link from its local q, v, a.
  pure subroutine chord(q, v, a, cs, sn, ell, g, om, al0, al)
    real(dp), intent(in) :: q(:), v(:), a(:)
    real(dp), intent(out) :: cs, sn, ell, g(2), om, al0, al
    real(dp) :: c(2), cd(2), cdd(2), l2
    c = q(3:4) - q(1:2); cd = v(3:4) - v(1:2); cdd = a(3:4) - a(1:2)
    l2 = c(1)**2 + c(2)**2
    ell = sqrt(l2)
    cs = c(1)/ell; sn = c(2)/ell
    g = [-c(2), c(1)]/l2
    om = g(1)*cd(1) + g(2)*cd(2)
    al0 = -2.0_dp*(c(1)*cd(1) + c(2)*cd(2))*om/l2   ! part of alpha independent of the accelerations
    al = al0 + g(1)*cdd(1) + g(2)*cdd(2)
  end subroutine chord

  !> Contribution of one mass point (weight dm at link fraction w, element e at xi) to the link
  !> residual and iteration matrix.  Adds dm * J^T (r'' - grav) to r and, if want, to segment l's
  !> blocks of S (lm) dm J^T (J + cc dr''/dv + ck dr''/d(elastic q)) (the point's parts of M, C_v,
  !> K_t); returns the kinetic energy 1/2 dm |r'|^2.
  subroutine mass_point(sys, l, q, v, a, e, xi, w, dm, want, cc, ck, r, lm, ekin, epot)
    type(coupled_system), intent(in) :: sys
    integer, intent(in) :: l, e
    real(dp), intent(in) :: q(:), v(:), a(:), xi, w, dm, cc, ck
    logical, intent(in) :: want
    real(dp), intent(inout) :: r(:), ekin, epot
    type(link_mats), intent(inout) :: lm
    integer :: n, idx(6), i, j, nl, ncl, cl(10)
    real(dp) :: cs, sn, ell, g(2), om, al0, al, le, nm(2, 6), de(6), dv(6), da(6)
    real(dp) :: ul(2), uld(2), uldd(2), rot(2, 2), ru(2), rou(2), roud(2), rd(2), rdd(2)
    real(dp) :: jac(2, 10), bv(2, 10), bq(2, 10), ac(2, 2), w0(2), cdot(2), c(2), rn(2), bc(2), blk(10, 10)
    n = sys%n_el(l); nl = 3*n + 3
    le = sys%prop(1, l)/n
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
    rot = reshape([cs, sn, -sn, cs], [2, 2])
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
    r(cl(1:ncl)) = r(cl(1:ncl)) + dm*matmul(rdd, jac(:, 1:ncl))
    if (.not. want) return
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
  end subroutine mass_point

  !> Residual (local vector of length nld), energies and, if want, the blocks of segment l of the
  !> iteration matrix S = M + ccv C_v + ckt K_t (added to lm, which the caller has zeroed).
  subroutine link_eval(sys, l, q, v, a, want, ccv, ckt, r, lm, ekin, epot)
    type(coupled_system), intent(in) :: sys
    integer, intent(in) :: l
    real(dp), intent(in) :: q(:), v(:), a(:), ccv, ckt
    logical, intent(in) :: want
    real(dp), intent(out) :: r(:), ekin, epot
    type(link_mats), intent(inout) :: lm
    integer :: n, nl, e, k, i, j, idx(6), cl5(5)
    real(dp) :: len, le, rho_a, ea, c(2), ell, f, cc(2, 2), de(6), dv(6), fe(6), ce(6, 6), xi, psi_dd
    real(dp) :: cs, sn, g(2), om, al0, al, dpsi(sys%maxld), w0(2), d5(5), blk(5, 5)
    n = sys%n_el(l); nl = 3*n + 3
    len = sys%prop(1, l); rho_a = sys%prop(2, l); ea = sys%prop(3, l); le = len/n
    r(1:nl) = 0.0_dp; ekin = 0.0_dp; epot = 0.0_dp
    do e = 1, n          ! distributed mass
      do k = 1, 4
        call mass_point(sys, l, q, v, a, e, gx(k), ((e - 1) + gx(k))/n, gw(k)*rho_a*le, want, ccv, ckt, r, lm, &
                        ekin, epot)
      end do
    end do
    do i = 1, sys%npm    ! point masses on this link
      if (sys%pm_link(i) /= l) cycle
      xi = sys%pm_prop(2, i)/le
      e = min(n, max(1, int(xi) + 1))
      call mass_point(sys, l, q, v, a, e, xi - (e - 1), sys%pm_prop(2, i)/len, sys%pm_prop(1, i), want, &
                      ccv, ckt, r, lm, ekin, epot)
    end do
    call chord(q, v, a, cs, sn, ell, g, om, al0, al)
    do i = 1, sys%nri    ! rotary inertias turning with this link: psi = phi + th_k
      if (sys%ri_link(i) /= l) cycle
      k = th_index(n, sys%ri_node(i))
      dpsi(1:nl) = 0.0_dp
      dpsi(1:2) = -g; dpsi(3:4) = g; dpsi(k) = 1.0_dp
      psi_dd = al + a(k)
      r(1:nl) = r(1:nl) + sys%ri_j(i)*psi_dd*dpsi(1:nl)
      ekin = ekin + 0.5_dp*sys%ri_j(i)*(om + v(k))**2
      if (want) then     ! dpsi is nonzero on the local DOFs cl5 = [1..4, k] only
        cl5 = [1, 2, 3, 4, k]
        d5 = dpsi(cl5)
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
      end if
    end do
    ! chord stretch: U = 1/2 EA/L (|c| - L)^2
    c = q(3:4) - q(1:2)
    f = ea/len*(ell - len)
    r(1:2) = r(1:2) - f*c/ell
    r(3:4) = r(3:4) + f*c/ell
    epot = epot + 0.5_dp*ea/len*(ell - len)**2
    if (want) then
      cc(:, 1) = c*c(1)/ell**2; cc(:, 2) = c*c(2)/ell**2
      cc = ckt*(ea/len*cc + f/ell*(reshape([1.0_dp, 0.0_dp, 0.0_dp, 1.0_dp], [2, 2]) - cc))
      lm%bb(1:2, 1:2, l) = lm%bb(1:2, 1:2, l) + cc; lm%bb(3:4, 3:4, l) = lm%bb(3:4, 3:4, l) + cc
      lm%bb(1:2, 3:4, l) = lm%bb(1:2, 3:4, l) - cc; lm%bb(3:4, 1:2, l) = lm%bb(3:4, 1:2, l) - cc
    end if
    ! elastic strain energy and Rayleigh damping, element by element (local DOFs)
    do e = 1, n
      idx = elem_index(n, e)
      do i = 1, 6
        if (idx(i) > 0) then
          de(i) = q(idx(i)); dv(i) = v(idx(i))
        else
          de(i) = 0.0_dp; dv(i) = 0.0_dp
        end if
      end do
      fe = matmul(sys%ke(:, :, l), de)
      epot = epot + 0.5_dp*dot_product(de, fe)
      ce = sys%ray(1)*sys%me(:, :, l) + sys%ray(2)*sys%ke(:, :, l)
      if (sys%ray(1) /= 0.0_dp .or. sys%ray(2) /= 0.0_dp) fe = fe + matmul(ce, dv)
      do i = 1, 6
        if (idx(i) > 0) r(idx(i)) = r(idx(i)) + fe(i)
      end do
      if (want) then
        do j = 1, 6
          if (idx(j) == 0) cycle
          do i = 1, 6
            if (idx(i) == 0) cycle
            call lm_add(lm, l, idx(i), idx(j), ckt*sys%ke(i, j, l) + ccv*ce(i, j))
          end do
        end do
      end if
    end do
  end subroutine link_eval

  !> Position of th_k (node k = 0..n) in the link vector.
  pure integer function th_index(n, k)
    integer, intent(in) :: n, k
    if (k >= n) then
      th_index = 3*n + 3
    else
      th_index = 3*k + 5
    end if
  end function th_index

  !> Tangent angle psi = phi + th(end) of link l at end (0 start, 1 end), and d psi / d q_local.
  subroutine tangent_angle(sys, l, iend, q, psi, dpsi)
    type(coupled_system), intent(in) :: sys
    integer, intent(in) :: l, iend
    real(dp), intent(in) :: q(:)
    real(dp), intent(out) :: psi, dpsi(:)
    real(dp) :: c(2), l2
    integer :: k
    c = q(3:4) - q(1:2); l2 = c(1)**2 + c(2)**2
    k = th_index(sys%n_el(l), iend*sys%n_el(l))
    psi = atan2(c(2), c(1)) + q(k)
    dpsi = 0.0_dp
    dpsi(1:2) = -[-c(2), c(1)]/l2; dpsi(3:4) = [-c(2), c(1)]/l2; dpsi(k) = 1.0_dp
  end subroutine tangent_angle

  !> Torque of law i at joint angle theta [N m].
  pure real(dp) function torque(sys, i, theta)
    type(coupled_system), intent(in) :: sys
    integer, intent(in) :: i
    real(dp), intent(in) :: theta
    integer :: h
    torque = sys%tq_coef(1, i)
    do h = 1, sys%nh
      torque = torque + sys%tq_coef(1 + h, i)*sin(h*theta) + sys%tq_coef(1 + sys%nh + h, i)*cos(h*theta)
    end do
  end function torque

  !> Joint angles of every torque joint (psi_b - psi_a) for the global state q.
  subroutine joint_angles(sys, q, theta)
    type(coupled_system), intent(in) :: sys
    real(dp), intent(in) :: q(:)
    real(dp), intent(out) :: theta(:)
    integer :: i, s, l
    real(dp) :: psi, dpsi(sys%maxld)
    do i = 1, sys%ntq
      theta(i) = 0.0_dp
      do s = 1, 2
        l = sys%tq_link(s, i)
        if (l == 0) cycle
        call tangent_angle(sys, l, sys%tq_end(s, i), q(sys%ld(1:3*sys%n_el(l) + 3, l)), psi, dpsi)
        theta(i) = theta(i) + merge(1.0_dp, -1.0_dp, s == 1)*psi
      end do
    end do
  end subroutine joint_angles

  !> Assemble the global residual R (all DOFs) and, if want, the band iteration matrix
  !> S = M + cc*C_v + ck*K_t over the free DOFs.  Returns energies [kinetic, strain].
  subroutine assemble(sys, q, v, a, want, cc, ck, res, lm, energy)
    type(coupled_system), intent(in) :: sys
    real(dp), intent(in) :: q(:), v(:), a(:), cc, ck
    logical, intent(in) :: want
    real(dp), intent(out) :: res(:), energy(2)
    type(link_mats), intent(inout) :: lm
    integer :: l, nl, i, s, idx(sys%maxld)
    real(dp) :: rl(sys%maxld), ql(sys%maxld), vl(sys%maxld), al(sys%maxld)
    real(dp) :: ek, ep, psi, dpsi(sys%maxld), theta(max(1, sys%ntq)), tau
    res = 0.0_dp
    energy = 0.0_dp
    if (want) then
      lm%bb = 0.0_dp; lm%bi = 0.0_dp; lm%ib = 0.0_dp; lm%ai = 0.0_dp
    end if
    do l = 1, sys%nlinks
      nl = 3*sys%n_el(l) + 3
      idx(1:nl) = sys%ld(1:nl, l)
      ql(1:nl) = q(idx(1:nl)); vl(1:nl) = v(idx(1:nl)); al(1:nl) = a(idx(1:nl))
      call link_eval(sys, l, ql(1:nl), vl(1:nl), al(1:nl), want, cc, ck, rl, lm, ek, ep)
      res(idx(1:nl)) = res(idx(1:nl)) + rl(1:nl)
      energy = energy + [ek, ep]
    end do
    call joint_angles(sys, q, theta)
    do i = 1, sys%ntq      ! applied torques: generalized forces tau (d psi_b - d psi_a)
      tau = torque(sys, i, theta(i))
      do s = 1, 2
        l = sys%tq_link(s, i)
        if (l == 0) cycle
        nl = 3*sys%n_el(l) + 3
        call tangent_angle(sys, l, sys%tq_end(s, i), q(sys%ld(1:nl, l)), psi, dpsi(1:nl))
        res(sys%ld(1:nl, l)) = res(sys%ld(1:nl, l)) - merge(1.0_dp, -1.0_dp, s == 1)*tau*dpsi(1:nl)
      end do
    end do
  end subroutine assemble

  !> Select the linear solver of coupled_run (SOLVER_AUTO, SOLVER_BAND or SOLVER_CONDENSED;
  !> module-wide, for tests and benchmarks).  status = STATUS_BAD_INPUT for another value.
  subroutine coupled_set_solver(mode, status)
    integer, intent(in) :: mode
    integer, intent(out) :: status
    status = STATUS_BAD_INPUT
    if (mode < SOLVER_AUTO .or. mode > SOLVER_CONDENSED) return
    solver_mode = mode
    status = STATUS_OK
  end subroutine coupled_set_solver

  !> Allocate the segment-block storage of S (see link_mats) and, when every segment's elastic DOFs
  !> are free and its own, the condensed solve's arrays for up to nrhs right-hand sides.
  subroutine lm_setup(sys, nrhs, lm)
    type(coupled_system), intent(in) :: sys
    integer, intent(in) :: nrhs
    type(link_mats), intent(out) :: lm
    integer :: l, n, nl, e, k, f, idx(6), lo, hi
    integer, allocatable :: cnt(:), bnum(:)
    logical, allocatable :: isb(:)
    allocate (lm%off(sys%nlinks), lm%bfree(4, sys%nlinks))
    lm%ni = 0; lm%kbi = 0
    do l = 1, sys%nlinks
      n = sys%n_el(l); nl = 3*n + 3
      lm%off(l) = lm%ni
      lm%ni = lm%ni + nl - 4
      do e = 1, n           ! interior coupling is element by element: half band of the element DOFs
        idx = elem_index(n, e)
        lm%kbi = max(lm%kbi, maxval(idx) - minval(idx, mask=idx > 0))
      end do
    end do
    lm%ldi = 3*lm%kbi + 1
    lm%nrhs = max(1, nrhs)
    allocate (lm%bb(4, 4, sys%nlinks), lm%bi(4, lm%ni), lm%ib(lm%ni, 4), lm%ai(lm%ldi, lm%ni), lm%ifree(lm%ni))
    allocate (cnt(sys%nfree), isb(sys%nfree), bnum(sys%nfree))
    cnt = 0; isb = .false.
    lm%cond = .true.
    do l = 1, sys%nlinks
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
    ! condensation needs: interior DOFs free, in one segment only, never an end position; every free
    ! DOF interior or boundary
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
    lm%kbb = 0
    do l = 1, sys%nlinks
      lo = huge(1); hi = 0
      do k = 1, 4
        f = sys%free_of(sys%ld(k, l))
        lm%bfree(k, l) = 0
        if (f > 0) then
          lm%bfree(k, l) = bnum(f)
          lo = min(lo, bnum(f)); hi = max(hi, bnum(f))
        end if
      end do
      if (hi > 0) lm%kbb = max(lm%kbb, hi - lo)
    end do
    lm%ldb = 3*lm%kbb + 1
    if (lm%cond) then
      allocate (lm%z(lm%ni, 4), lm%sb(lm%ldb, lm%nb), lm%ipi(lm%ni), lm%ipb(lm%nb), lm%yi(lm%ni, lm%nrhs), &
                lm%yb(lm%nb, lm%nrhs))
    end if
  end subroutine lm_setup

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

  !> S(cl(i), cl(j)) += blk(i, j), i, j = 1..ncl, local DOFs of segment l.
  pure subroutine lm_add_block(lm, l, ncl, cl, blk)
    type(link_mats), intent(inout) :: lm
    integer, intent(in) :: l, ncl, cl(:)
    real(dp), intent(in) :: blk(:, :)
    integer :: i, j
    do j = 1, ncl
      do i = 1, ncl
        call lm_add(lm, l, cl(i), cl(j), blk(i, j))
      end do
    end do
  end subroutine lm_add_block

  !> Scatter the segment blocks into the band matrix ab (LAPACK storage, kl = ku = sys%kl) over the
  !> free DOFs: the reference solve and coupled_dense.
  subroutine lm_to_band(sys, lm, ab)
    type(coupled_system), intent(in) :: sys
    type(link_mats), intent(in) :: lm
    real(dp), intent(out) :: ab(:, :)
    integer :: l, nl, m, o, i, j, ii, jj, fi, fj, d, fidx(sys%maxld)
    ab = 0.0_dp
    d = sys%kl + sys%ku + 1
    do l = 1, sys%nlinks
      nl = 3*sys%n_el(l) + 3; m = nl - 4; o = lm%off(l)
      fidx(1:nl) = sys%free_of(sys%ld(1:nl, l))
      do j = 1, 4
        fj = fidx(j)
        if (fj == 0) cycle
        do i = 1, 4
          fi = fidx(i)
          if (fi > 0) ab(d + fi - fj, fj) = ab(d + fi - fj, fj) + lm%bb(i, j, l)
        end do
        do ii = 1, m
          fi = fidx(4 + ii)
          if (fi > 0) ab(d + fi - fj, fj) = ab(d + fi - fj, fj) + lm%ib(o + ii, j)
        end do
      end do
      do jj = 1, m
        fj = fidx(4 + jj)
        if (fj == 0) cycle
        do i = 1, 4
          fi = fidx(i)
          if (fi > 0) ab(d + fi - fj, fj) = ab(d + fi - fj, fj) + lm%bi(i, o + jj)
        end do
        do ii = max(1, jj - lm%kbi), min(m, jj + lm%kbi)
          fi = fidx(4 + ii)
          if (fi > 0) ab(d + fi - fj, fj) = ab(d + fi - fj, fj) + lm%ai(2*lm%kbi + 1 + ii - jj, o + jj)
        end do
      end do
    end do
  end subroutine lm_to_band

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
    do l = 1, sys%nlinks
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
    do l = 1, sys%nlinks
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
    do l = 1, sys%nlinks
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

  !> Angle sum of constraint ic, sum_s sign_s psi_s (psi = phi + th_end, ground = 0), its gradient
  !> over the free DOFs, and the velocity part of its second time derivative.
  subroutine constraint_eval(sys, ic, q, v, angle, grad, acc0)
    type(coupled_system), intent(in) :: sys
    integer, intent(in) :: ic
    real(dp), intent(in) :: q(:), v(:)
    real(dp), intent(out) :: angle, grad(:), acc0
    integer :: s, l, nl, k
    real(dp) :: psi, dpsi(sys%maxld), sg, cs, sn, ell, g(2), om, al0, al, zero(sys%maxld)
    angle = 0.0_dp; grad = 0.0_dp; acc0 = 0.0_dp; zero = 0.0_dp
    do s = 1, 2
      l = sys%con_link(s, ic)
      if (l == 0) cycle
      sg = merge(1.0_dp, -1.0_dp, s == 1)
      nl = 3*sys%n_el(l) + 3
      call tangent_angle(sys, l, sys%con_end(s, ic), q(sys%ld(1:nl, l)), psi, dpsi(1:nl))
      angle = angle + sg*psi
      do k = 1, nl
        if (sys%free_of(sys%ld(k, l)) > 0) grad(sys%free_of(sys%ld(k, l))) = grad(sys%free_of(sys%ld(k, l))) &
                                                                             + sg*dpsi(k)
      end do
      call chord(q(sys%ld(1:nl, l)), v(sys%ld(1:nl, l)), zero(1:nl), cs, sn, ell, g, om, al0, al)
      acc0 = acc0 + sg*al0
    end do
  end subroutine constraint_eval

  !> Elastic deformation measure of the divergence guard [m]: over the links (seg_link(s) = link of
  !> segment s; a link's segments listed consecutively from its start), the largest of
  !>   | |c| - L |                         change of the length of the link chord c (first segment's
  !>                                       start node to last segment's end node), L = sum of the
  !>                                       segment lengths;
  !>   |r_k - (r_start + w_k c)|           offset of every segment-end node from its place on the
  !>                                       straight chord (w_k = fraction of L up to node k);
  !>   sqrt(p_k^2 + v_k^2)                 interior elastic chord-frame translations of each segment.
  !> Elastic rotations (radians) are not included.  For the coupled model (one segment per link)
  !> this is the largest elastic chord-frame translation or chord stretch; for the nonlinear model
  !> (one segment per element) the largest node offset from the link's chord.
  function coupled_elastic_measure(sys, seg_link, q) result(dmax)
    type(coupled_system), intent(in) :: sys
    integer, intent(in) :: seg_link(:)   !< (number of segments) link of each segment, 1-based
    real(dp), intent(in) :: q(:)         !< (ndof) all-DOF positions
    real(dp) :: dmax
    integer :: l, s, s0, s1, k, n
    real(dp) :: r0(2), c(2), ltot, acc, w0
    dmax = 0.0_dp
    s0 = 1
    do while (s0 <= sys%nlinks)
      l = seg_link(s0)
      s1 = s0
      do while (s1 < sys%nlinks)
        if (seg_link(s1 + 1) /= l) exit
        s1 = s1 + 1
      end do
      ltot = sum(sys%prop(1, s0:s1))
      r0 = q(sys%ld(1:2, s0))
      c = q(sys%ld(3:4, s1)) - r0
      dmax = max(dmax, abs(norm2(c) - ltot))
      acc = 0.0_dp
      do s = s0, s1
        n = sys%n_el(s)
        w0 = acc/ltot
        acc = acc + sys%prop(1, s)
        dmax = max(dmax, norm2(q(sys%ld(1:2, s)) - (r0 + w0*c)), norm2(q(sys%ld(3:4, s)) - (r0 + (acc/ltot)*c)))
        do k = 1, n - 1
          dmax = max(dmax, hypot(q(sys%ld(3*k + 3, s)), q(sys%ld(3*k + 4, s))))
        end do
      end do
      s0 = s1 + 1
    end do
  end function coupled_elastic_measure

  !> Generalized-alpha-Newton integration of the coupled model (Newmark for alpha_m = alpha_f = 0).
  !> q, v, a: (ndof) all-DOF state, constrained entries hold their values (prescribed ones are
  !> overwritten from presc each step).  Rotation constraints (sys%ncon): sum_s sign psi_s = cval(1,i,k),
  !> enforced at the position level with Lagrange multipliers lam (the constraint torques).
  !> a is the true acceleration (made consistent with the equations and constraints at the start),
  !> p the pseudo-acceleration (init_pseudo /= 0: p = a at the start, a fresh run; else p as given,
  !> continuing a run).  On return (q, v, a, p) is the last state reached.
  !> Frames at steps 0, out_every, ...: qf, vf, af (ndof, nframes), lf (ncon, nframes) multipliers,
  !> ef(4, nframes) = [kinetic, potential (strain + gravity), work of the inputs (torques and
  !> prescribed rotations), max Newton iterations since the last frame]; nvalid frames are valid.
  !> Divergence guard: coupled_elastic_measure > div_limit [m] after a step stops the run with
  !> STATUS_DIVERGED (fail_step = that step).
  subroutine coupled_run(sys, presc_dof, presc, cval, dt, alpha_m, alpha_f, beta, gamma, out_every, tol, maxit, &
                         init_pseudo, div_limit, seg_link, q, v, a, p, qf, vf, af, lf, ef, status, fail_step, &
                         iters, nvalid)
    type(coupled_system), intent(in) :: sys
    integer, intent(in) :: presc_dof(:)          !< (np) prescribed DOFs (all-DOF numbers)
    real(dp), intent(in) :: presc(:, :, :)       !< (3, np, nsteps+1) [q, v, a] of prescribed DOFs
    real(dp), intent(in) :: cval(:, :, :)        !< (3, ncon, nsteps+1) [angle, rate, acceleration] of constraints
    real(dp), intent(in) :: dt, tol
    real(dp), intent(in) :: alpha_m, alpha_f, beta, gamma   !< generalized-alpha parameters
    integer, intent(in) :: out_every, maxit, init_pseudo
    real(dp), intent(in) :: div_limit              !< divergence limit [m]
    integer, intent(in) :: seg_link(:)             !< (number of segments) link of each segment
    real(dp), intent(inout) :: q(:), v(:), a(:), p(:)
    real(dp), intent(out) :: qf(:, :), vf(:, :), af(:, :), lf(:, :), ef(:, :)
    integer, intent(out) :: status, fail_step, iters, nvalid
    real(dp), allocatable :: ab(:, :), res(:), qs(:), vs(:), rf(:), theta0(:), theta1(:), w(:)
    real(dp), allocatable :: gt(:, :), x(:, :), amat(:, :), lam(:), dlam(:), gval(:), acc0(:), ang0(:), ang1(:), lam0(:)
    integer, allocatable :: ipiv(:), freeidx(:), ipc(:), gnz(:, :), ngnz(:)
    integer :: nsteps, n, it, i, frame, info, itmax_frame, nf, nc
    real(dp) :: energy(2), work, da_norm, a_norm, da_prev, c1, betap, gammap, lref
    logical :: converged, refactor, use_cond
    type(link_mats) :: lm
    status = STATUS_OK; fail_step = 0; iters = 0; nvalid = 0
    nsteps = size(presc, 3) - 1
    nf = sys%nfree
    nc = sys%ncon
    refactor = .false.
    if (out_every < 1 .or. dt <= 0.0_dp .or. size(qf, 2) /= nsteps/out_every + 1 .or. &
        (nc > 0 .and. size(cval, 3) /= nsteps + 1) .or. beta <= 0.0_dp .or. gamma < 0.5_dp .or. &
        alpha_m >= 1.0_dp .or. alpha_f >= 1.0_dp .or. .not. div_limit > 0.0_dp .or. &
        size(seg_link) /= sys%nlinks .or. size(p) /= sys%ndof) then
      status = STATUS_BAD_INPUT
      return
    end if
    if (any(seg_link < 1)) then
      status = STATUS_BAD_INPUT
      return
    end if
    c1 = 1.0_dp/(1.0_dp - alpha_m)
    betap = beta*(1.0_dp - alpha_f)*c1
    ! length scale of the mechanism [m] (largest nodal coordinate at the start): the absolute floor of
    ! the Newton test, for steps where the accelerations themselves vanish (a smooth start from rest)
    lref = max(maxval(abs(q)), tiny(1.0_dp))
    gammap = gamma*(1.0_dp - alpha_f)*c1
    call lm_setup(sys, nc, lm)
    use_cond = lm%cond .and. (solver_mode == SOLVER_CONDENSED .or. &
                              (solver_mode == SOLVER_AUTO .and. sys%kl > lm%kbi + 4))
    if (use_cond) then
      allocate (ab(1, 1))
    else
      allocate (ab(band_rows(sys%kl, sys%ku), nf))
    end if
    allocate (res(sys%ndof), qs(sys%ndof), vs(sys%ndof), rf(nf), ipiv(nf))
    allocate (w(sys%ndof))
    w = 0.0_dp
    allocate (theta0(max(1, sys%ntq)), theta1(max(1, sys%ntq)), freeidx(nf))
    allocate (gt(nf, max(1, nc)), x(nf, max(1, nc)), amat(max(1, nc), max(1, nc)), lam(max(1, nc)), &
              dlam(max(1, nc)), gval(max(1, nc)), acc0(max(1, nc)), ang0(max(1, nc)), ang1(max(1, nc)), ipc(max(1, nc)), &
              lam0(max(1, nc)))
    allocate (gnz(10, max(1, nc)), ngnz(max(1, nc)))
    do i = 1, sys%ndof
      if (sys%free_of(i) > 0) freeidx(sys%free_of(i)) = i
    end do
    call gradient_pattern()
    lam = 0.0_dp
    call set_prescribed(1)
    ! consistent initial acceleration: [M G; G^T 0] [a; lam] = [-R(q0, v0, 0); cval'' - acc0]
    a(freeidx) = 0.0_dp
    call assemble(sys, q, v, a, .true., 0.0_dp, 0.0_dp, res, lm, energy)
    rf = -res(freeidx)
    call factor()
    if (status /= STATUS_OK) return
    call constraints(1)
    if (status /= STATUS_OK) return
    call band_solve_rhs(rf)
    if (nc > 0) then
      do i = 1, nc
        dlam(i) = gdot(i, rf) - (cval(3, i, 1) - acc0(i))
      end do
      call small_solve(dlam)
      do i = 1, nc
        rf = rf - x(:, i)*dlam(i)
      end do
      lam(1:nc) = dlam(1:nc)
    end if
    if (status /= STATUS_OK) return
    a(freeidx) = rf
    if (init_pseudo /= 0) p = a
    work = 0.0_dp
    call joint_angles(sys, q, theta0)
    call con_angles(ang0)
    lam0 = lam
    frame = 1
    qf(:, 1) = q; vf(:, 1) = v; af(:, 1) = a; lf(:, 1) = lam(1:size(lf, 1))
    ef(:, 1) = [energy(1), energy(2), 0.0_dp, 0.0_dp]
    nvalid = 1
    itmax_frame = 0
    do n = 1, nsteps
      w(freeidx) = alpha_f*a(freeidx) - alpha_m*p(freeidx)     ! zero for Newmark
      qs = q + dt*v + (dt*dt*(0.5_dp - beta))*p + (dt*dt*beta*c1)*w
      vs = v + (dt*(1.0_dp - gamma))*p + (dt*gamma*c1)*w
      call set_prescribed(n + 1)
      converged = .false.
      da_prev = huge(1.0_dp)
      do it = 1, maxit
        q(freeidx) = qs(freeidx) + (betap*dt*dt)*a(freeidx)
        v(freeidx) = vs(freeidx) + (gammap*dt)*a(freeidx)
        call assemble(sys, q, v, a, it == 1, gammap*dt, betap*dt*dt, res, lm, energy)
        if (it == 1) then
          call factor()
          if (status /= STATUS_OK) exit
        end if
        call constraints(n + 1)      ! gradients (matrix part only at it == 1), values, G^T lam in res
        if (status /= STATUS_OK) exit
        rf = -res(freeidx)
        call band_solve_rhs(rf)
        if (status /= STATUS_OK) exit
        if (nc > 0) then   ! Schur complement on the multipliers
          do i = 1, nc
            dlam(i) = gdot(i, rf) + gval(i)/(betap*dt*dt)
          end do
          call small_solve(dlam)
          if (status /= STATUS_OK) exit
          do i = 1, nc
            rf = rf - x(:, i)*dlam(i)
          end do
          lam(1:nc) = lam(1:nc) + dlam(1:nc)
        end if
        a(freeidx) = a(freeidx) + rf
        da_norm = sqrt(sum(rf**2)); a_norm = sqrt(sum(a(freeidx)**2))
        iters = iters + 1
        ! converged (relative to the accelerations, or the position correction below 1e-2 tol of the
        ! mechanism size), or stagnated at the round-off level of the residual (no further contraction
        ! while already within sqrt(tol): the stiff chord terms limit the attainable precision)
        if (da_norm <= tol*(a_norm + 1.0e-30) .or. betap*dt*dt*da_norm <= 1.0e-2_dp*tol*lref .or. &
            (it > 1 .and. da_norm >= 0.5_dp*da_prev .and. da_norm <= sqrt(tol)*(a_norm + 1.0e-30))) then
          converged = .true.
          exit
        end if
        da_prev = da_norm
      end do
      if (status == STATUS_OK .and. .not. converged) status = STATUS_NEWTON
      if (status /= STATUS_OK) then
        fail_step = n
        return
      end if
      q(freeidx) = qs(freeidx) + (betap*dt*dt)*a(freeidx)
      v(freeidx) = vs(freeidx) + (gammap*dt)*a(freeidx)
      p(freeidx) = c1*((1.0_dp - alpha_f)*a(freeidx) + w(freeidx))
      itmax_frame = max(itmax_frame, it)
      if (coupled_elastic_measure(sys, seg_link, q) > div_limit) then
        status = STATUS_DIVERGED
        fail_step = n
        return
      end if
      call joint_angles(sys, q, theta1)
      do i = 1, sys%ntq    ! work of the torques, trapezoidal in the joint angle
        work = work + 0.5_dp*(torque(sys, i, theta0(i)) + torque(sys, i, theta1(i)))*wrap(theta1(i) - theta0(i))
      end do
      theta0 = theta1
      call con_angles(ang1)
      do i = 1, nc         ! work of the prescribed rotations (the constraint torque is -lam), trapezoidal
        work = work - 0.5_dp*(lam0(i) + lam(i))*wrap(ang1(i) - ang0(i))
      end do
      ang0 = ang1
      lam0 = lam
      if (mod(n, out_every) == 0) then
        call assemble(sys, q, v, a, .false., 0.0_dp, 0.0_dp, res, lm, energy)
        frame = frame + 1
        qf(:, frame) = q; vf(:, frame) = v; af(:, frame) = a; lf(:, frame) = lam(1:size(lf, 1))
        ef(:, frame) = [energy(1), energy(2), work, real(itmax_frame, dp)]
        nvalid = frame
        itmax_frame = 0
      end if
    end do

  contains

    !> Free DOFs on which constraint ic's gradient can be nonzero (the end positions and the
    !> end rotation of its one or two segments), without repetitions: gnz(1:ngnz(ic), ic).
    subroutine gradient_pattern()
      integer :: ic, s, l, k, f, loc(5)
      ngnz = 0
      do ic = 1, nc
        do s = 1, 2
          l = sys%con_link(s, ic)
          if (l == 0) cycle
          loc = [1, 2, 3, 4, th_index(sys%n_el(l), sys%con_end(s, ic)*sys%n_el(l))]
          do k = 1, 5
            f = sys%free_of(sys%ld(loc(k), l))
            if (f == 0) cycle
            if (any(gnz(1:ngnz(ic), ic) == f)) cycle
            ngnz(ic) = ngnz(ic) + 1
            gnz(ngnz(ic), ic) = f
          end do
        end do
      end do
    end subroutine gradient_pattern

    !> G(:, ic)^T y over the gradient's nonzero pattern.
    pure real(dp) function gdot(ic, y)
      integer, intent(in) :: ic
      real(dp), intent(in) :: y(:)
      integer :: k
      gdot = 0.0_dp
      do k = 1, ngnz(ic)
        gdot = gdot + gt(gnz(k, ic), ic)*y(gnz(k, ic))
      end do
    end function gdot

    pure real(dp) function wrap(x)
      real(dp), intent(in) :: x
      wrap = atan2(sin(x), cos(x))
    end function wrap

    subroutine set_prescribed(k)
      integer, intent(in) :: k
      integer :: j
      do j = 1, size(presc_dof)
        q(presc_dof(j)) = presc(1, j, k); v(presc_dof(j)) = presc(2, j, k); a(presc_dof(j)) = presc(3, j, k)
      end do
    end subroutine set_prescribed

    subroutine con_angles(ang)
      real(dp), intent(out) :: ang(:)
      integer :: ic
      real(dp) :: a1
      do ic = 1, nc
        call constraint_eval(sys, ic, q, v, ang(ic), gt(:, ic), a1)
      end do
    end subroutine con_angles

    !> Constraint gradients (X = S^-1 G and the Schur matrix when S was just factorized), values
    !> g = angle - cval (principal value), velocity part of the angle acceleration, and G^T lam in res.
    subroutine constraints(k)
      integer, intent(in) :: k
      integer :: ic, s, l, nl, j
      real(dp) :: ang, psi, dpsi(sys%maxld), sg
      do ic = 1, nc
        call constraint_eval(sys, ic, q, v, ang, gt(:, ic), acc0(ic))
        gval(ic) = wrap(ang - cval(1, ic, k))
        do s = 1, 2            ! residual += G^T lam (over all DOFs)
          l = sys%con_link(s, ic)
          if (l == 0) cycle
          sg = merge(1.0_dp, -1.0_dp, s == 1)
          nl = 3*sys%n_el(l) + 3
          call tangent_angle(sys, l, sys%con_end(s, ic), q(sys%ld(1:nl, l)), psi, dpsi(1:nl))
          do j = 1, nl
            res(sys%ld(j, l)) = res(sys%ld(j, l)) + sg*lam(ic)*dpsi(j)
          end do
        end do
      end do
      if (nc > 0 .and. refactor) then
        x(:, 1:nc) = gt(:, 1:nc)
        if (use_cond) then
          call lm_solve(sys, lm, nc, x, nf, status)
          if (status /= STATUS_OK) return
        else
          call dgbtrs('N', nf, sys%kl, sys%ku, nc, ab, size(ab, 1), ipiv, x, nf, info)
        end if
        do j = 1, nc
          do ic = 1, nc
            amat(ic, j) = gdot(ic, x(:, j))
          end do
        end do
        call dgetrf(nc, nc, amat, size(amat, 1), ipc, info)
        status = lapack_status(info)
        refactor = .false.
      end if
    end subroutine constraints

    !> Factorize S (assembled in lm): condensed, or the whole band (reference).
    subroutine factor()
      if (use_cond) then
        call lm_factor(sys, lm, status)
      else
        call lm_to_band(sys, lm, ab)
        call dgbtrf(nf, nf, sys%kl, sys%ku, ab, size(ab, 1), ipiv, info)
        status = lapack_status(info)
      end if
      refactor = .true.
    end subroutine factor

    subroutine band_solve_rhs(xx)
      real(dp), intent(inout) :: xx(:)
      if (use_cond) then
        call lm_solve(sys, lm, 1, xx, nf, status)
      else
        call dgbtrs('N', nf, sys%kl, sys%ku, 1, ab, size(ab, 1), ipiv, xx, nf, info)
      end if
      if (.not. ieee_is_finite(sum(abs(xx)))) status = STATUS_NONFINITE
    end subroutine band_solve_rhs

    subroutine small_solve(xx)
      real(dp), intent(inout) :: xx(:)
      call dgetrs('N', nc, 1, amat, size(amat, 1), ipc, xx, size(xx), info)
      if (.not. ieee_is_finite(sum(abs(xx(1:nc))))) status = STATUS_NONFINITE
    end subroutine small_solve

  end subroutine coupled_run

end module flexmech_coupled
