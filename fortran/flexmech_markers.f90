!> Markers and constraint kinds of the coupled and nonlinear models (docs/theory.md section 11.6).
!>
!> A marker is a point of a body with a frame angle: a node of a beam segment, a point of a rigid
!> body, or a ground point.  marker_state holds, at one state (q, v), its position r [m], frame
!> angle psi [rad], their rates, the velocity parts of their second derivatives (r'' = dr . q'' + ra0,
!> psi'' = dpsi . q'' + psia0) and their gradients over the marker's DOFs:
!>   segment node k (local fraction w, chord c = r_e - r_s, phi = atan2(c), g = Omega c / |c|^2,
!>   omega = g . c', alpha0 = -2 (c . c') omega / |c|^2, elastic translation u = [p_k, v_k] in the
!>   chord frame, zero at the segment ends):
!>     r = (1 - w) r_s + w r_e + R(phi) u,   psi = phi + th_k
!>     DOFs [xs, ys, xe, ye, (p_k, v_k,) th_k]
!>   rigid-body point s (body frame, from the centre of mass):  r = r_C + R(phi) s,  psi = phi
!>     DOFs [x_C, y_C, phi]
!>   ground point: r fixed, psi = 0, no DOF.
!> A constraint row (or a joint coordinate) is a scalar function of two markers a, b, returned as its
!> value g, rate g', the velocity part acc0 of g'' and its gradient over the columns of a (first ma%n
!> entries) then of b (next mb%n entries; a column may repeat when the two markers share a DOF:
!> gradients add).  Every model (the rigid-body solver flexmech_mbs, the coupled and nonlinear models
!> through flexmech_coupled_rows) evaluates its rows here, by the index of the row kind: this table is
!> the one constraint vocabulary (its Python mirror: flexmech_py/mechanism/rows.py).
!>   index  name            routine          value unit  g; parameters (aux integer, d(2) real)
!>   1      CON_POINT       row_point        m           (r_a - r_b)_i, i = aux (1: x, 2: y)
!>   2      CON_ANGLE       row_angle        rad         psi_b - psi_a
!>   3      CON_PROJECTION  row_projection   m           e . (r_b - r_a), e = R(psi_a) d, d fixed in a's frame
!>   4      CON_GEAR        row_gear         m           d1 psi_a + d2 psi_b - (d1 + d2) theta, theta the angle
!>                                                       of r_b - r_a (aux: its branch, 0..3; d = (r_a, s r_b))
!> A joint kind is a list of rows of these kinds on its two markers (revolute: two CON_POINT rows;
!> weld: two CON_POINT and a CON_ANGLE; prismatic: CON_PROJECTION on the guide normal and a CON_ANGLE)
!> and a coordinate row (CON_ANGLE, or CON_PROJECTION on the guide direction) that drives act on.
!> A new row kind is one pure routine here with the signature of row_angle (plus aux, d when it
!> needs them), one index NCON + 1, one case in constraint_row and its unit in con_in_radians
!> (docs/architecture.md, "Fortran: the constraint vocabulary").  Builders reject any index outside
!> 1..NCON (con_valid): an unknown kind is an input error, never a fallback.
module flexmech_markers
  use, intrinsic :: ieee_arithmetic, only: ieee_value, ieee_quiet_nan
  use flexmech_kinds, only: dp
  implicit none
  private
  public :: marker_state, segment_marker, body_marker, ground_marker, constraint_row
  public :: row_point, row_angle, row_projection, row_gear, con_valid, con_residual, con_in_radians
  public :: CON_POINT, CON_ANGLE, CON_PROJECTION, CON_GEAR, NCON, MAXCOL

  integer, parameter :: CON_POINT = 1, CON_ANGLE = 2, CON_PROJECTION = 3, CON_GEAR = 4
  integer, parameter :: NCON = 4          !< row kinds: the valid indices are 1..NCON
  integer, parameter :: MAXCOL = 7        !< columns of one marker (an interior segment node)

  !> Set by segment_marker, body_marker or ground_marker; the column arrays hold n valid entries (no
  !> default initialization: the markers are made in the innermost loops of every model).
  type :: marker_state
    real(dp) :: r(2), psi            !< position [m], frame angle [rad]
    real(dp) :: rd(2), psid          !< their rates
    real(dp) :: ra0(2), psia0        !< velocity parts of their second derivatives
    integer :: n                     !< number of columns
    integer :: col(MAXCOL)           !< all-DOF numbers of the columns (1:n)
    integer :: loc(MAXCOL)           !< positions in the owner's local vector (1:n)
    real(dp) :: dr(2, MAXCOL), dpsi(MAXCOL)   !< gradients (columns 1:n)
  end type marker_state

contains

  !> Marker at node k (0..n) of a segment of n elements, at fraction w of its length; q, v the
  !> all-DOF vectors, cols(3n+3) the all-DOF numbers of the segment's local vector
  !> [xs ys xe ye th_0 (p_j v_j th_j)_{j=1..n-1} th_n]; absang: the th_k are the nodes' absolute
  !> angles psi_k [rad] (the nonlinear model's shared node angles) instead of angles from the chord.
  pure subroutine segment_marker(q, v, cols, n, k, w, absang, ms)
    real(dp), intent(in) :: q(:), v(:), w
    integer, intent(in) :: cols(:), n, k
    logical, intent(in) :: absang
    type(marker_state), intent(out) :: ms
    real(dp) :: c(2), cd(2), l2, cs, sn, g(2), om, al0, u(2), ud(2), ru(2), rou(2), roud(2), rs(2), re(2)
    integer :: kt, j
    rs = q(cols(1:2)); re = q(cols(3:4))
    c = re - rs; cd = v(cols(3:4)) - v(cols(1:2))
    l2 = c(1)**2 + c(2)**2
    cs = c(1)/sqrt(l2); sn = c(2)/sqrt(l2)
    g = [-c(2), c(1)]/l2
    om = g(1)*cd(1) + g(2)*cd(2)
    al0 = -2.0_dp*(c(1)*cd(1) + c(2)*cd(2))*om/l2
    kt = merge(3*n + 3, 3*k + 5, k >= n)
    u = 0.0_dp; ud = 0.0_dp
    if (k > 0 .and. k < n) then
      u = q(cols(3*k + 3:3*k + 4)); ud = v(cols(3*k + 3:3*k + 4))
    end if
    ru = [cs*u(1) - sn*u(2), sn*u(1) + cs*u(2)]          ! R u
    rou = [-ru(2), ru(1)]                                  ! Omega R u
    roud = [-(sn*ud(1) + cs*ud(2)), cs*ud(1) - sn*ud(2)]   ! Omega R u'
    ms%r = (1.0_dp - w)*rs + w*re + ru
    ms%rd = (1.0_dp - w)*v(cols(1:2)) + w*v(cols(3:4)) + om*rou + [cs*ud(1) - sn*ud(2), sn*ud(1) + cs*ud(2)]
    ms%ra0 = al0*rou - om*om*ru + 2.0_dp*om*roud
    ms%psi = atan2(c(2), c(1)) + q(cols(kt))
    ms%psid = om + v(cols(kt))
    ms%psia0 = al0
    ms%n = 5
    ms%loc(1:4) = [1, 2, 3, 4]
    ms%dr = 0.0_dp; ms%dpsi = 0.0_dp
    ms%dr(1, 1) = 1.0_dp - w; ms%dr(2, 2) = 1.0_dp - w; ms%dr(1, 3) = w; ms%dr(2, 4) = w
    do j = 1, 2
      ms%dr(:, j) = ms%dr(:, j) - rou*g(j)
      ms%dr(:, 2 + j) = ms%dr(:, 2 + j) + rou*g(j)
    end do
    ms%dpsi(1:2) = -g; ms%dpsi(3:4) = g
    if (k > 0 .and. k < n) then
      ms%n = 7
      ms%loc(5:6) = [3*k + 3, 3*k + 4]
      ms%dr(:, 5) = [cs, sn]; ms%dr(:, 6) = [-sn, cs]
    end if
    ms%loc(ms%n) = kt
    ms%dpsi(ms%n) = 1.0_dp
    if (absang) then          ! psi = psi_k itself: no chord part
      ms%psi = q(cols(kt)); ms%psid = v(cols(kt)); ms%psia0 = 0.0_dp
      ms%dpsi(1:4) = 0.0_dp
    end if
    do j = 1, ms%n          ! a loop: a vector subscript would copy through the heap
      ms%col(j) = cols(ms%loc(j))
    end do
  end subroutine segment_marker

  !> Marker at s (body frame, from the centre of mass) of a rigid body with coordinates z = [x_C, y_C,
  !> phi], rates zd and all-DOF numbers cols(3).
  pure subroutine body_marker(z, zd, cols, s, ms)
    real(dp), intent(in) :: z(3), zd(3), s(2)
    integer, intent(in) :: cols(3)
    type(marker_state), intent(out) :: ms
    real(dp) :: rs(2), c, sn
    c = cos(z(3)); sn = sin(z(3))
    rs = [c*s(1) - sn*s(2), sn*s(1) + c*s(2)]
    ms%r = z(1:2) + rs
    ms%rd = zd(1:2) + zd(3)*[-rs(2), rs(1)]
    ms%ra0 = -zd(3)**2*rs
    ms%psi = z(3); ms%psid = zd(3); ms%psia0 = 0.0_dp
    ms%n = 3
    ms%loc(1:3) = [1, 2, 3]
    ms%col(1:3) = cols
    ms%dr(:, 1) = [1.0_dp, 0.0_dp]; ms%dr(:, 2) = [0.0_dp, 1.0_dp]; ms%dr(:, 3) = [-rs(2), rs(1)]
    ms%dpsi(1:3) = [0.0_dp, 0.0_dp, 1.0_dp]
  end subroutine body_marker

  !> A ground point at pos [m] (frame angle 0, no DOF).
  pure subroutine ground_marker(pos, ms)
    real(dp), intent(in) :: pos(2)
    type(marker_state), intent(out) :: ms
    ms%r = pos
    ms%rd = 0.0_dp; ms%ra0 = 0.0_dp
    ms%psi = 0.0_dp; ms%psid = 0.0_dp; ms%psia0 = 0.0_dp
    ms%n = 0
  end subroutine ground_marker

  !> The row kind index is one of the table's (1..NCON) and its integer parameter aux fits it (the
  !> component 1 or 2 of CON_POINT, the branch 0..3 of CON_GEAR; the other kinds take any aux).
  pure logical function con_valid(kind, aux)
    integer, intent(in) :: kind, aux
    con_valid = kind >= 1 .and. kind <= NCON
    if (kind == CON_POINT) con_valid = aux == 1 .or. aux == 2
    if (kind == CON_GEAR) con_valid = aux >= 0 .and. aux <= 3
  end function con_valid

  !> The row's value is an angle [rad] (else a length [m]): scaled by the mechanism's length where
  !> rows are compared or conditioned.
  pure logical function con_in_radians(kind)
    integer, intent(in) :: kind
    con_in_radians = kind == CON_ANGLE
  end function con_in_radians

  !> The residual r = g - value of a row reduced to the representative the solvers drive to zero:
  !> CON_ANGLE wrapped to (-pi, pi]; CON_GEAR less the nearest of 2 pi (n_a d1 + n_b d2), n in
  !> {-1, 0, 1} (a frame angle psi taken on the other side of its +-pi cut than the value's: a segment
  !> node's angle is the chord's atan2 plus the node's rotation); other kinds unchanged.
  pure real(dp) function con_residual(kind, d, r)
    integer, intent(in) :: kind
    real(dp), intent(in) :: d(2), r
    real(dp), parameter :: TWO_PI = 6.283185307179586_dp
    real(dp) :: x
    integer :: na, nb
    con_residual = r
    if (kind == CON_ANGLE) then
      con_residual = r - TWO_PI*anint(r/TWO_PI)
    else if (kind == CON_GEAR) then
      do na = -1, 1
        do nb = -1, 1
          x = r - TWO_PI*(na*d(1) + nb*d(2))
          if (abs(x) < abs(con_residual)) con_residual = x
        end do
      end do
    end if
  end function con_residual

  !> Row of kind CON_* between markers a and b (aux: the component of CON_POINT; d: the direction of
  !> CON_PROJECTION in a's frame).  Columns: a's then b's (nc = ma%n + mb%n).  An index outside the
  !> table (which every builder rejects first) gives NaN values.
  pure subroutine constraint_row(kind, aux, d, ma, mb, g, gd, acc0, nc, cols, grad)
    integer, intent(in) :: kind, aux
    real(dp), intent(in) :: d(2)
    type(marker_state), intent(in) :: ma, mb
    real(dp), intent(out) :: g, gd, acc0, grad(2*MAXCOL)
    integer, intent(out) :: nc, cols(2*MAXCOL)
    nc = ma%n + mb%n
    cols(1:ma%n) = ma%col(1:ma%n)
    cols(ma%n + 1:nc) = mb%col(1:mb%n)
    select case (kind)
    case (CON_POINT)
      call row_point(aux, ma, mb, g, gd, acc0, grad)
    case (CON_ANGLE)
      call row_angle(ma, mb, g, gd, acc0, grad)
    case (CON_PROJECTION)
      call row_projection(d, ma, mb, g, gd, acc0, grad)
    case (CON_GEAR)
      call row_gear(aux, d, ma, mb, g, gd, acc0, grad)
    case default
      g = ieee_value(g, ieee_quiet_nan); gd = g; acc0 = g; grad = g
    end select
  end subroutine constraint_row

  !> Point coincidence, component i: g = (r_a - r_b)_i.
  pure subroutine row_point(i, ma, mb, g, gd, acc0, grad)
    integer, intent(in) :: i
    type(marker_state), intent(in) :: ma, mb
    real(dp), intent(out) :: g, gd, acc0, grad(:)
    g = ma%r(i) - mb%r(i)
    gd = ma%rd(i) - mb%rd(i)
    acc0 = ma%ra0(i) - mb%ra0(i)
    grad(1:ma%n) = ma%dr(i, 1:ma%n)
    grad(ma%n + 1:ma%n + mb%n) = -mb%dr(i, 1:mb%n)
  end subroutine row_point

  !> Relative frame angle g = psi_b - psi_a [rad] (not wrapped).
  pure subroutine row_angle(ma, mb, g, gd, acc0, grad)
    type(marker_state), intent(in) :: ma, mb
    real(dp), intent(out) :: g, gd, acc0, grad(:)
    g = mb%psi - ma%psi
    gd = mb%psid - ma%psid
    acc0 = mb%psia0 - ma%psia0
    grad(1:ma%n) = -ma%dpsi(1:ma%n)
    grad(ma%n + 1:ma%n + mb%n) = mb%dpsi(1:mb%n)
  end subroutine row_angle

  !> Projection g = e . (r_b - r_a) on the direction e = R(psi_a) d turning with marker a:
  !>   g' = psi_a' (Omega e) . dr + e . dr',  dr = r_b - r_a
  !>   g'' = e . dr'' + 2 psi_a' (Omega e) . dr' - psi_a'^2 e . dr + psi_a'' (Omega e) . dr
  pure subroutine row_projection(d, ma, mb, g, gd, acc0, grad)
    real(dp), intent(in) :: d(2)
    type(marker_state), intent(in) :: ma, mb
    real(dp), intent(out) :: g, gd, acc0, grad(:)
    real(dp) :: e(2), oe(2), dr(2), drd(2), c, s, oed
    integer :: j
    c = cos(ma%psi); s = sin(ma%psi)
    e = [c*d(1) - s*d(2), s*d(1) + c*d(2)]
    oe = [-e(2), e(1)]
    dr = mb%r - ma%r; drd = mb%rd - ma%rd
    oed = dot_product(oe, dr)
    g = dot_product(e, dr)
    gd = ma%psid*oed + dot_product(e, drd)
    acc0 = dot_product(e, mb%ra0 - ma%ra0) + 2.0_dp*ma%psid*dot_product(oe, drd) - ma%psid**2*g + ma%psia0*oed
    do j = 1, ma%n
      grad(j) = -dot_product(e, ma%dr(:, j)) + oed*ma%dpsi(j)
    end do
    do j = 1, mb%n
      grad(ma%n + j) = dot_product(e, mb%dr(:, j))
    end do
  end subroutine row_projection

  !> Gear mesh (rolling of two pitch circles without slip) between the centres a and b of two gears
  !> of pitch radii r_a, r_b, d = (r_a, s r_b), s = +1 for an external mesh, -1 for an internal one:
  !>   g = r_a psi_a + s r_b psi_b - (r_a + s r_b) theta,   theta = angle of c = r_b - r_a [m]
  !> (the arc rolled on each pitch circle relative to the line of centres; with fixed centres
  !> r_a psi_a' = -s r_b psi_b', the gear ratio).  theta is taken on the branch around aux pi/2
  !> (aux 0..3, the quadrant of the assembled line of centres: no jump while it turns less than
  !> 3 pi/4 from there).  With k = r_a + s r_b, h = Omega c / |c|^2 (d theta / d c):
  !>   g' = r_a psi_a' + s r_b psi_b' - k h . c',   acc0 = r_a psi_a0'' + s r_b psi_b0'' - k (h . c0''
  !>        - 2 (c . c') (h . c') / |c|^2)
  !> Its multiplier is the tangential tooth force [N]: a force of magnitude |lambda| (k/|c| = 1 at the
  !> nominal centre distance) along the common tangent at the pitch point.
  pure subroutine row_gear(aux, d, ma, mb, g, gd, acc0, grad)
    integer, intent(in) :: aux
    real(dp), intent(in) :: d(2)
    type(marker_state), intent(in) :: ma, mb
    real(dp), intent(out) :: g, gd, acc0, grad(:)
    real(dp), parameter :: HALF_PI = 1.5707963267948966_dp
    real(dp) :: c(2), cd(2), cr(2), h(2), l2, k, th, thd
    integer :: j
    c = mb%r - ma%r; cd = mb%rd - ma%rd
    select case (aux)          ! c turned back by aux quarter turns: its angle near 0
    case (1); cr = [c(2), -c(1)]
    case (2); cr = -c
    case (3); cr = [-c(2), c(1)]
    case default; cr = c
    end select
    th = atan2(cr(2), cr(1)) + aux*HALF_PI
    l2 = dot_product(c, c)
    h = [-c(2), c(1)] / l2
    thd = dot_product(h, cd)
    k = d(1) + d(2)
    g = d(1)*ma%psi + d(2)*mb%psi - k*th
    gd = d(1)*ma%psid + d(2)*mb%psid - k*thd
    acc0 = d(1)*ma%psia0 + d(2)*mb%psia0 - k*(dot_product(h, mb%ra0 - ma%ra0) - 2.0_dp*dot_product(c, cd)*thd/l2)
    do j = 1, ma%n
      grad(j) = d(1)*ma%dpsi(j) + k*dot_product(h, ma%dr(:, j))
    end do
    do j = 1, mb%n
      grad(ma%n + j) = d(2)*mb%dpsi(j) - k*dot_product(h, mb%dr(:, j))
    end do
  end subroutine row_gear

end module flexmech_markers
