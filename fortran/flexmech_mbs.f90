!> Rigid-body mechanics of a planar mechanism described as bodies, markers, typed joints and drives
!> (docs/theory.md section 17).  The same description serves every model: it is built in Python
!> (flexmech_py/mechanism) and packed into two flat arrays (mbs_build documents their layout).
!>
!> Coordinates: z = [x_1, y_1, phi_1, ..., x_nb, y_nb, phi_nb], per moving body the position of its
!> centre of mass [m] and the angle of its frame [rad]; mass matrix M = diag(m, m, J_C) (constant).
!> A marker k is a point fixed on body b (b = 0: the ground) at s_k in the body frame, relative to the
!> centre of mass: r_k = c_b + R(phi_b) s_k (ground: r_k = s_k).
!>
!> Joint kinds (each a set of constraint rows Phi(z) = 0 on two markers P on body a, Q on body b):
!>   JOINT_REVOLUTE   r_P - r_Q = 0                                   2 rows; coordinate phi_b - phi_a [rad]
!>   JOINT_PRISMATIC  n . (r_Q - r_P) = 0,  phi_b - phi_a - ref = 0   2 rows; coordinate u . (r_Q - r_P) [m]
!>                    u = R(phi_a) axis, n = R(phi_a) Omega axis, the guide fixed to body a through P
!>   JOINT_WELD       r_P - r_Q = 0,  phi_b - phi_a - ref = 0         3 rows; coordinate phi_b - phi_a [rad]
!> A kinematic drive adds one row g_j(z) - f(t) = 0 on the coordinate g_j of its joint; a force drive
!> adds the generalized force tau dg_j/dz (flexmech_drivelaw).  Rows are ordered joint by joint, then
!> drive by drive; the multipliers lambda of M z'' + Phi_z^T lambda = Q are the constraint forces
!> (the force body a exerts on body b at a revolute is +lambda; a kinematic drive applies -lambda).
!> Acceleration equations Phi_z z'' = gamma, velocity equations Phi_z z' = nu (nu = f' on drive rows).
module flexmech_mbs
  use, intrinsic :: ieee_arithmetic, only: ieee_is_finite
  use flexmech_kinds, only: dp
  use flexmech_lapack, only: STATUS_OK, STATUS_BAD_INPUT, STATUS_SINGULAR, STATUS_NONFINITE, &
                             STATUS_SINGULAR_POSITION, STATUS_ASSEMBLY
  use flexmech_dense, only: lu_factor, lu_solve, pivot_ratio, det_sign
  use flexmech_drivelaw, only: kinematic_law, force_law, LAW_FORCE
  use flexmech_ode, only: ode_problem
  implicit none
  private
  public :: mbs_system, mbs_build, mbs_constraints, mbs_forces, mbs_accelerations, mbs_project, &
            mbs_solve_positions, mbs_joint_coordinates, mbs_kinematic_sample, mbs_gram_rcond, mbs_nspec_header, &
            mbs_drive_values, mbs_drive_change
  public :: JOINT_REVOLUTE, JOINT_PRISMATIC, JOINT_WELD

  integer, parameter :: JOINT_REVOLUTE = 1, JOINT_PRISMATIC = 2, JOINT_WELD = 3
  integer, parameter :: NPAR = 4                   !< parameters per drive law (flexmech_drivelaw)
  integer, parameter :: mbs_nspec_header = 7       !< integers before the first block of ispec

  type, extends(ode_problem) :: mbs_system
    integer :: nb = 0, n = 0, nmk = 0, nj = 0, nd = 0, nrow = 0, nh = 0, nth = 0
    real(dp), allocatable :: mass(:), inertia(:)   !< (nb) [kg], [kg m^2] about the centre of mass
    integer, allocatable :: mk_body(:)             !< (nmk) body of each marker, 0 = ground
    real(dp), allocatable :: mk_pos(:, :)          !< (2, nmk) position in its body frame from the COM [m]
    integer, allocatable :: jt_kind(:), jt_mk(:, :), jt_row(:)   !< (nj), (2, nj) [P, Q], first row
    real(dp), allocatable :: jt_axis(:, :), jt_ref(:)            !< (2, nj) guide direction in a's frame; ref angle
    integer, allocatable :: dv_joint(:), dv_kind(:), dv_tab(:, :), dv_row(:)   !< dv_row 0: force drive
    real(dp), allocatable :: dv_par(:, :), dv_harm(:, :), dv_th(:, :, :)
    real(dp), allocatable :: tab_t(:), tab_c(:, :)
    real(dp) :: grav(2) = 0.0_dp, lref = 1.0_dp    !< gravity [m/s^2]; length scale of the mechanism [m]
    real(dp), allocatable :: rscale(:)             !< (nrow) length per unit of each row: 1 [m] or lref [rad]
    ! workspace of the last evaluation
    real(dp), allocatable :: phi(:), jac(:, :), gam(:), nu(:), q(:), aug(:, :), sol(:)
    integer, allocatable :: ipiv(:)
  contains
    procedure :: rhs => dynamics_rhs
  end type mbs_system

contains

  !> Unpack the flat description.  ispec (integers):
  !>   [nb, nmk, nj, nd, ntab, nh, nth,  mk_body(nmk),  jt_kind(nj),  jt_mk(2, nj),
  !>    dv_joint(nd), dv_kind(nd), dv_tab(2, nd) = [first knot, knots] (0 knots: no table)]
  !> rspec (reals):
  !>   [mass(nb), inertia(nb), grav(2), lref,  mk_pos(2, nmk),  jt_axis(2, nj), jt_ref(nj),
  !>    dv_par(4, nd), dv_harm(2 nh, nd), dv_th(3, nth, nd),  tab_t(ntab), tab_c(4, ntab)]
  subroutine mbs_build(ispec, rspec, sys, status)
    integer, intent(in) :: ispec(:)
    real(dp), intent(in) :: rspec(:)
    type(mbs_system), intent(out) :: sys
    integer, intent(out) :: status
    integer :: i, o, r, ntab, j
    status = STATUS_BAD_INPUT
    if (size(ispec) < mbs_nspec_header) return
    sys%nb = ispec(1); sys%nmk = ispec(2); sys%nj = ispec(3); sys%nd = ispec(4); ntab = ispec(5)
    sys%nh = ispec(6); sys%nth = ispec(7)
    sys%n = 3*sys%nb
    if (sys%nb < 1 .or. sys%nmk < 0 .or. sys%nj < 0 .or. sys%nd < 0 .or. ntab < 0 .or. sys%nh < 0 .or. sys%nth < 0) return
    if (size(ispec) /= mbs_nspec_header + sys%nmk + 3*sys%nj + 4*sys%nd) return
    if (size(rspec) /= 2*sys%nb + 3 + 2*sys%nmk + 3*sys%nj + (NPAR + 2*sys%nh + 3*sys%nth)*sys%nd + 5*ntab) return
    o = mbs_nspec_header
    sys%mk_body = ispec(o + 1:o + sys%nmk); o = o + sys%nmk
    sys%jt_kind = ispec(o + 1:o + sys%nj); o = o + sys%nj
    sys%jt_mk = reshape(ispec(o + 1:o + 2*sys%nj), [2, sys%nj]); o = o + 2*sys%nj
    sys%dv_joint = ispec(o + 1:o + sys%nd); o = o + sys%nd
    sys%dv_kind = ispec(o + 1:o + sys%nd); o = o + sys%nd
    sys%dv_tab = reshape(ispec(o + 1:o + 2*sys%nd), [2, sys%nd])
    o = 0
    sys%mass = rspec(o + 1:o + sys%nb); o = o + sys%nb
    sys%inertia = rspec(o + 1:o + sys%nb); o = o + sys%nb
    sys%grav = rspec(o + 1:o + 2); sys%lref = rspec(o + 3); o = o + 3
    sys%mk_pos = reshape(rspec(o + 1:o + 2*sys%nmk), [2, sys%nmk]); o = o + 2*sys%nmk
    sys%jt_axis = reshape(rspec(o + 1:o + 2*sys%nj), [2, sys%nj]); o = o + 2*sys%nj
    sys%jt_ref = rspec(o + 1:o + sys%nj); o = o + sys%nj
    sys%dv_par = reshape(rspec(o + 1:o + NPAR*sys%nd), [NPAR, sys%nd]); o = o + NPAR*sys%nd
    sys%dv_harm = reshape(rspec(o + 1:o + 2*sys%nh*sys%nd), [2*sys%nh, sys%nd]); o = o + 2*sys%nh*sys%nd
    sys%dv_th = reshape(rspec(o + 1:o + 3*sys%nth*sys%nd), [3, sys%nth, sys%nd]); o = o + 3*sys%nth*sys%nd
    sys%tab_t = rspec(o + 1:o + ntab); o = o + ntab
    sys%tab_c = reshape(rspec(o + 1:o + 4*ntab), [4, ntab])
    ! checks of indices and values
    if (any(sys%mass <= 0.0_dp) .or. any(sys%inertia < 0.0_dp) .or. .not. sys%lref > 0.0_dp) return
    if (any(sys%mk_body < 0) .or. any(sys%mk_body > sys%nb)) return
    if (any(sys%jt_kind < JOINT_REVOLUTE) .or. any(sys%jt_kind > JOINT_WELD)) return
    if (any(sys%jt_mk < 1) .or. any(sys%jt_mk > sys%nmk)) return
    if (any(sys%dv_joint < 1) .or. any(sys%dv_joint > sys%nj)) return
    do i = 1, sys%nd
      if (sys%dv_tab(2, i) > 0) then
        if (sys%dv_tab(1, i) < 1 .or. sys%dv_tab(1, i) + sys%dv_tab(2, i) - 1 > ntab .or. sys%dv_tab(2, i) < 2) return
      end if
    end do
    allocate (sys%jt_row(sys%nj), sys%dv_row(sys%nd))
    r = 0
    do j = 1, sys%nj
      sys%jt_row(j) = r + 1
      r = r + merge(3, 2, sys%jt_kind(j) == JOINT_WELD)
    end do
    do i = 1, sys%nd
      sys%dv_row(i) = 0
      if (sys%dv_kind(i) /= LAW_FORCE) then
        r = r + 1
        sys%dv_row(i) = r
      end if
    end do
    sys%nrow = r
    allocate (sys%rscale(r))
    sys%rscale = 1.0_dp
    do j = 1, sys%nj
      if (sys%jt_kind(j) == JOINT_PRISMATIC) sys%rscale(sys%jt_row(j) + 1) = sys%lref
      if (sys%jt_kind(j) == JOINT_WELD) sys%rscale(sys%jt_row(j) + 2) = sys%lref
    end do
    do i = 1, sys%nd
      if (sys%dv_row(i) > 0 .and. sys%jt_kind(sys%dv_joint(i)) /= JOINT_PRISMATIC) sys%rscale(sys%dv_row(i)) = sys%lref
    end do
    allocate (sys%phi(r), sys%jac(max(r, 1), sys%n), sys%gam(r), sys%nu(r), sys%q(sys%n))
    allocate (sys%aug(sys%n + r, sys%n + r), sys%sol(sys%n + r), sys%ipiv(sys%n + r))
    status = STATUS_OK
  end subroutine mbs_build

  !> Position r, dr/dphi = Omega R s (w), velocity v and velocity part of the acceleration
  !> (-phi'^2 R s, aq) of marker k; body 0 (ground): r = s, the rest zero.  ib: its body.
  pure subroutine marker(sys, k, z, zd, r, w, v, aq, ib)
    type(mbs_system), intent(in) :: sys
    integer, intent(in) :: k
    real(dp), intent(in) :: z(:), zd(:)
    real(dp), intent(out) :: r(2), w(2), v(2), aq(2)
    integer, intent(out) :: ib
    real(dp) :: c, s, rs(2)
    ib = sys%mk_body(k)
    if (ib == 0) then
      r = sys%mk_pos(:, k); w = 0.0_dp; v = 0.0_dp; aq = 0.0_dp
      return
    end if
    c = cos(z(3*ib)); s = sin(z(3*ib))
    rs = [c*sys%mk_pos(1, k) - s*sys%mk_pos(2, k), s*sys%mk_pos(1, k) + c*sys%mk_pos(2, k)]
    r = z(3*ib - 2:3*ib - 1) + rs
    w = [-rs(2), rs(1)]
    v = zd(3*ib - 2:3*ib - 1) + zd(3*ib)*w
    aq = -zd(3*ib)**2*rs
  end subroutine marker

  !> Coordinate g of joint j, its gradient (nonzero on the columns cols(1:6) of the two bodies' 3
  !> coordinates, 0 = ground), its rate and the velocity part gq of its second derivative
  !> (g'' = grad . z'' + gq).  kind_dir: the guide direction of a prismatic joint (axis) or its normal
  !> (Omega axis); angle for revolute and weld joints.
  pure subroutine joint_coordinate(sys, j, z, zd, normal, g, cols, grad, gd, gq)
    type(mbs_system), intent(in) :: sys
    integer, intent(in) :: j
    real(dp), intent(in) :: z(:), zd(:)
    logical, intent(in) :: normal           !< prismatic: the normal component instead of the coordinate
    real(dp), intent(out) :: g, grad(6), gd, gq
    integer, intent(out) :: cols(6)
    integer :: ia, ib, kp, kq
    real(dp) :: rp(2), wp(2), vp(2), ap(2), rq(2), wq(2), vq(2), aq(2), u(2), ou(2), d(2), dd(2), ca, sa, om
    kp = sys%jt_mk(1, j); kq = sys%jt_mk(2, j)
    ia = sys%mk_body(kp); ib = sys%mk_body(kq)
    cols = 0; grad = 0.0_dp
    if (ia > 0) cols(1:3) = [3*ia - 2, 3*ia - 1, 3*ia]
    if (ib > 0) cols(4:6) = [3*ib - 2, 3*ib - 1, 3*ib]
    if (sys%jt_kind(j) /= JOINT_PRISMATIC) then     ! relative angle phi_b - phi_a
      g = 0.0_dp; gd = 0.0_dp
      if (ib > 0) then
        g = z(3*ib); gd = zd(3*ib); grad(6) = 1.0_dp
      end if
      if (ia > 0) then
        g = g - z(3*ia); gd = gd - zd(3*ia); grad(3) = -1.0_dp
      end if
      gq = 0.0_dp
      return
    end if
    call marker(sys, kp, z, zd, rp, wp, vp, ap, ia)
    call marker(sys, kq, z, zd, rq, wq, vq, aq, ib)
    u = sys%jt_axis(:, j)
    if (normal) u = [-u(2), u(1)]
    om = 0.0_dp
    if (ia > 0) then
      ca = cos(z(3*ia)); sa = sin(z(3*ia))
      u = [ca*u(1) - sa*u(2), sa*u(1) + ca*u(2)]
      om = zd(3*ia)
    end if
    ou = [-u(2), u(1)]
    d = rq - rp; dd = vq - vp
    g = dot_product(u, d)
    gd = om*dot_product(ou, d) + dot_product(u, dd)
    gq = -om*om*dot_product(u, d) + 2.0_dp*om*dot_product(ou, dd) + dot_product(u, aq - ap)
    if (ia > 0) then
      grad(1:2) = -u
      grad(3) = dot_product(ou, rq - z(3*ia - 2:3*ia - 1))
    end if
    if (ib > 0) then
      grad(4:5) = u
      grad(6) = dot_product(u, wq)
    end if
  end subroutine joint_coordinate

  !> Constraint values phi, Jacobian jac (nrow x n, dense), acceleration right-hand side gam and velocity
  !> right-hand side nu at (z, zd, t), into sys's workspace.
  subroutine mbs_constraints(sys, z, zd, t)
    type(mbs_system), intent(inout) :: sys
    real(dp), intent(in) :: z(:), zd(:), t
    integer :: j, r, i, ia, ib, cols(6)
    real(dp) :: rp(2), wp(2), vp(2), ap(2), rq(2), wq(2), vq(2), aq(2), g, grad(6), gd, gq, f(3)
    sys%jac = 0.0_dp; sys%nu = 0.0_dp
    do j = 1, sys%nj
      r = sys%jt_row(j)
      if (sys%jt_kind(j) /= JOINT_PRISMATIC) then          ! point rows r_P - r_Q
        call marker(sys, sys%jt_mk(1, j), z, zd, rp, wp, vp, ap, ia)
        call marker(sys, sys%jt_mk(2, j), z, zd, rq, wq, vq, aq, ib)
        sys%phi(r:r + 1) = rp - rq
        sys%gam(r:r + 1) = aq - ap
        if (ia > 0) then
          sys%jac(r, 3*ia - 2) = 1.0_dp; sys%jac(r + 1, 3*ia - 1) = 1.0_dp
          sys%jac(r:r + 1, 3*ia) = wp
        end if
        if (ib > 0) then
          sys%jac(r, 3*ib - 2) = sys%jac(r, 3*ib - 2) - 1.0_dp
          sys%jac(r + 1, 3*ib - 1) = sys%jac(r + 1, 3*ib - 1) - 1.0_dp
          sys%jac(r:r + 1, 3*ib) = sys%jac(r:r + 1, 3*ib) - wq
        end if
        if (sys%jt_kind(j) == JOINT_REVOLUTE) cycle
        r = r + 2                                            ! weld: the angle row
        call joint_coordinate(sys, j, z, zd, .false., g, cols, grad, gd, gq)
      else
        call joint_coordinate(sys, j, z, zd, .true., g, cols, grad, gd, gq)   ! normal row
        call put_row(r, g, -gq)
        r = r + 1
        call angle_of(j, g, cols, grad)                      ! the angle row
        gq = 0.0_dp
      end if
      call put_row(r, g - sys%jt_ref(j), -gq)
    end do
    do i = 1, sys%nd
      r = sys%dv_row(i)
      if (r == 0) cycle
      j = sys%dv_joint(i)
      call joint_coordinate(sys, j, z, zd, .false., g, cols, grad, gd, gq)
      f = drive_law(sys, i, t)
      call put_row(r, g - f(1), f(3) - gq)
      sys%nu(r) = f(2)
    end do

  contains

    subroutine put_row(row, val, gamma)
      integer, intent(in) :: row
      real(dp), intent(in) :: val, gamma
      integer :: c
      sys%phi(row) = val
      sys%gam(row) = gamma
      do c = 1, 6
        if (cols(c) > 0) sys%jac(row, cols(c)) = sys%jac(row, cols(c)) + grad(c)
      end do
    end subroutine put_row

    !> phi_b - phi_a of joint jj as a coordinate row (whatever the joint's kind).
    subroutine angle_of(jj, gval, c6, g6)
      integer, intent(in) :: jj
      real(dp), intent(out) :: gval, g6(6)
      integer, intent(out) :: c6(6)
      integer :: a, b
      a = sys%mk_body(sys%jt_mk(1, jj)); b = sys%mk_body(sys%jt_mk(2, jj))
      c6 = 0; g6 = 0.0_dp; gval = 0.0_dp
      if (a > 0) then
        c6(3) = 3*a; g6(3) = -1.0_dp; gval = -z(3*a)
      end if
      if (b > 0) then
        c6(6) = 3*b; g6(6) = 1.0_dp; gval = gval + z(3*b)
      end if
    end subroutine angle_of

  end subroutine mbs_constraints

  !> Generalized applied forces q (n) at (z, zd, t): gravity and the force drives.
  pure subroutine mbs_forces(sys, z, zd, t, q)
    type(mbs_system), intent(in) :: sys
    real(dp), intent(in) :: z(:), zd(:), t
    real(dp), intent(out) :: q(:)
    integer :: i, b, k, c, cols(6), nk
    real(dp) :: g, grad(6), gd, gq, tau
    q = 0.0_dp
    do b = 1, sys%nb
      q(3*b - 2:3*b - 1) = sys%mass(b)*sys%grav
    end do
    do i = 1, sys%nd
      if (sys%dv_kind(i) /= LAW_FORCE) cycle
      call joint_coordinate(sys, sys%dv_joint(i), z, zd, .false., g, cols, grad, gd, gq)
      k = sys%dv_tab(1, i); nk = sys%dv_tab(2, i)
      if (nk > 0) then
        tau = force_law(sys%dv_par(:, i), sys%dv_harm(:, i), sys%dv_th(:, :, i), sys%tab_t(k:k + nk - 1), &
                        sys%tab_c(:, k:k + nk - 1), g, t)
      else
        tau = force_law(sys%dv_par(:, i), sys%dv_harm(:, i), sys%dv_th(:, :, i), sys%tab_t(1:0), &
                        sys%tab_c(:, 1:0), g, t)
      end if
      do c = 1, 6
        if (cols(c) > 0) q(cols(c)) = q(cols(c)) + tau*grad(c)
      end do
    end do
  end subroutine mbs_forces

  !> Accelerations zdd and multipliers lam at (z, zd, t) from [M Phi_z^T; Phi_z 0][zdd; lam] = [Q; gamma]
  !> (the augmented matrix stays factorized in sys%aug for mbs_project).
  subroutine mbs_accelerations(sys, z, zd, t, zdd, lam, status)
    type(mbs_system), intent(inout) :: sys
    real(dp), intent(in) :: z(:), zd(:), t
    real(dp), intent(out) :: zdd(:), lam(:)
    integer, intent(out) :: status
    call mbs_constraints(sys, z, zd, t)
    call mbs_forces(sys, z, zd, t, sys%q)
    call factor_augmented(sys, status)
    if (status /= STATUS_OK) return
    sys%sol(1:sys%n) = sys%q
    sys%sol(sys%n + 1:) = sys%gam
    call solve_augmented(sys, status)
    zdd = sys%sol(1:sys%n)
    lam = sys%sol(sys%n + 1:)
  end subroutine mbs_accelerations

  subroutine factor_augmented(sys, status)
    type(mbs_system), intent(inout) :: sys
    integer, intent(out) :: status
    integer :: b, n, info
    n = sys%n
    sys%aug = 0.0_dp
    do b = 1, sys%nb
      sys%aug(3*b - 2, 3*b - 2) = sys%mass(b)
      sys%aug(3*b - 1, 3*b - 1) = sys%mass(b)
      sys%aug(3*b, 3*b) = sys%inertia(b)
    end do
    if (sys%nrow > 0) then
      sys%aug(n + 1:, 1:n) = sys%jac(1:sys%nrow, :)
      sys%aug(1:n, n + 1:) = transpose(sys%jac(1:sys%nrow, :))
    end if
    call lu_factor(sys%aug, n + sys%nrow, sys%ipiv, info)
    status = merge(STATUS_SINGULAR, STATUS_OK, info > 0)
  end subroutine factor_augmented

  subroutine solve_augmented(sys, status)
    type(mbs_system), intent(inout) :: sys
    integer, intent(out) :: status
    call lu_solve(sys%aug, sys%n + sys%nrow, sys%ipiv, sys%sol, .false.)
    status = STATUS_OK
    if (.not. ieee_is_finite(sum(abs(sys%sol)))) status = STATUS_NONFINITE
  end subroutine solve_augmented

  !> Right-hand side of the index-1 dynamics for flexmech_ode: y = [z; zd], f = [zd; zdd].
  subroutine dynamics_rhs(self, t, y, f, status)
    class(mbs_system), intent(inout) :: self
    real(dp), intent(in) :: t, y(:)
    real(dp), intent(out) :: f(:)
    integer, intent(out) :: status
    real(dp) :: lam(self%nrow)
    associate (n => self%n)
      f(1:n) = y(n + 1:2*n)
      call mbs_accelerations(self, y(1:n), y(n + 1:2*n), t, f(n + 1:2*n), lam, status)
    end associate
  end subroutine dynamics_rhs

  !> Project (z, zd) onto the position and velocity constraints at t (M-orthogonally, with the
  !> augmented matrix): Newton on Phi(z) = 0 until max |phi| <= tol (lengths; angle rows times lref),
  !> then zd onto Phi_z zd = nu.  STATUS_ASSEMBLY when the positions do not converge in maxit.
  subroutine mbs_project(sys, z, zd, t, tol, maxit, status)
    type(mbs_system), intent(inout) :: sys
    real(dp), intent(inout) :: z(:), zd(:)
    real(dp), intent(in) :: t, tol
    integer, intent(in) :: maxit
    integer, intent(out) :: status
    integer :: it
    status = STATUS_OK
    if (sys%nrow == 0) return
    do it = 1, maxit + 1
      call mbs_constraints(sys, z, zd, t)
      if (residual(sys) <= tol) exit
      if (it > maxit) then
        status = STATUS_ASSEMBLY
        return
      end if
      call factor_augmented(sys, status)
      if (status /= STATUS_OK) return
      sys%sol(1:sys%n) = 0.0_dp
      sys%sol(sys%n + 1:) = -sys%phi
      call solve_augmented(sys, status)
      if (status /= STATUS_OK) return
      z = z + sys%sol(1:sys%n)
    end do
    call factor_augmented(sys, status)
    if (status /= STATUS_OK) return
    sys%sol(1:sys%n) = 0.0_dp
    sys%sol(sys%n + 1:) = sys%nu - matmul(sys%jac(1:sys%nrow, :), zd)
    call solve_augmented(sys, status)
    if (status /= STATUS_OK) return
    zd = zd + sys%sol(1:sys%n)
  end subroutine mbs_project

  !> Largest constraint violation [m] (angle rows scaled by lref) of the last mbs_constraints.
  pure real(dp) function residual(sys)
    type(mbs_system), intent(in) :: sys
    residual = 0.0_dp
    if (sys%nrow > 0) residual = maxval(abs(sys%phi)*sys%rscale)
  end function residual

  !> Kinematic positions: Newton on the square system Phi(z, t) = 0 (joints and kinematic drives,
  !> nrow = n) from the guess z; then zd, zdd from the Jacobian and lam from Phi_z^T lam = Q - M zdd.
  !> rcond: the pivot ratio of the scaled Jacobian (rotation columns times lref, angle rows times
  !> lref); dsign: the sign of its determinant (a change between neighbouring samples means the motion
  !> crossed a singular position).  STATUS_ASSEMBLY when Newton does not converge,
  !> STATUS_SINGULAR_POSITION when rcond < rcond_min.
  subroutine mbs_kinematic_sample(sys, z, t, tol, maxit, rcond_min, zd, zdd, lam, rcond, dsign, status)
    type(mbs_system), intent(inout) :: sys
    real(dp), intent(inout) :: z(:)
    real(dp), intent(in) :: t, tol, rcond_min
    integer, intent(in) :: maxit
    real(dp), intent(out) :: zd(:), zdd(:), lam(:), rcond
    integer, intent(out) :: dsign, status
    rcond = 0.0_dp
    dsign = 0
    call mbs_solve_positions(sys, z, t, tol, maxit, status)     ! leaves the constraints evaluated at z
    if (status /= STATUS_OK) return
    call square_factor(sys, rcond, status)
    if (status /= STATUS_OK .or. rcond < rcond_min) then
      status = STATUS_SINGULAR_POSITION
      return
    end if
    dsign = det_sign(sys%aug, sys%n, sys%ipiv)
    zd = sys%nu
    call square_solve(sys, zd, 'N', status)
    call mbs_constraints(sys, z, zd, t)                          ! gamma with the velocities (same Jacobian)
    zdd = sys%gam
    call square_solve(sys, zdd, 'N', status)
    call mbs_forces(sys, z, zd, t, sys%q)
    lam = sys%q
    lam(1:sys%n:3) = lam(1:sys%n:3) - sys%mass*zdd(1:sys%n:3)
    lam(2:sys%n:3) = lam(2:sys%n:3) - sys%mass*zdd(2:sys%n:3)
    lam(3:sys%n:3) = lam(3:sys%n:3) - sys%inertia*zdd(3:sys%n:3)
    call square_solve(sys, lam, 'T', status)
  end subroutine mbs_kinematic_sample

  !> Newton on the square position equations (nrow = n) from z; max |phi| <= tol on return, with the
  !> constraints evaluated at the returned z (zd = 0).
  subroutine mbs_solve_positions(sys, z, t, tol, maxit, status)
    type(mbs_system), intent(inout) :: sys
    real(dp), intent(inout) :: z(:)
    real(dp), intent(in) :: t, tol
    integer, intent(in) :: maxit
    integer, intent(out) :: status
    real(dp) :: zd0(sys%n), dz(sys%n), rc
    integer :: it
    zd0 = 0.0_dp
    status = STATUS_OK
    do it = 1, maxit + 1
      call mbs_constraints(sys, z, zd0, t)
      if (residual(sys) <= tol) return
      if (it > maxit .or. .not. ieee_is_finite(sum(abs(sys%phi)))) exit
      call square_factor(sys, rc, status)
      if (status /= STATUS_OK) then     ! the Jacobian lost rank on the way: a singular position
        status = STATUS_SINGULAR_POSITION
        return
      end if
      dz = -sys%phi
      call square_solve(sys, dz, 'N', status)
      if (status /= STATUS_OK) exit
      z = z + dz
    end do
    status = STATUS_ASSEMBLY
  end subroutine mbs_solve_positions

  !> LU of the scaled square Jacobian S J D of the last mbs_constraints in sys%aug(1:n, 1:n) (S: angle
  !> rows times lref, D: rotation columns times lref, both in length units); rcond: its pivot ratio
  !> (flexmech_dense), 0 when singular (then STATUS_SINGULAR).
  subroutine square_factor(sys, rcond, status)
    type(mbs_system), intent(inout) :: sys
    real(dp), intent(out) :: rcond
    integer, intent(out) :: status
    integer :: info, n, r
    n = sys%n
    do r = 1, n
      sys%aug(r, 1:n) = sys%rscale(r)*sys%jac(r, :)
    end do
    sys%aug(1:n, 3:n:3) = sys%aug(1:n, 3:n:3)*sys%lref
    call lu_factor(sys%aug, n, sys%ipiv, info)
    rcond = pivot_ratio(sys%aug, n)
    status = STATUS_OK
    if (info > 0) then
      rcond = 0.0_dp
      status = STATUS_SINGULAR
    end if
  end subroutine square_factor

  !> Solve J x = b (trans 'N') or J^T x = b ('T') with square_factor's scaled factors, x overwritten.
  subroutine square_solve(sys, x, trans, status)
    type(mbs_system), intent(inout) :: sys
    real(dp), intent(inout) :: x(:)
    character, intent(in) :: trans
    integer, intent(out) :: status
    integer :: n
    n = sys%n
    if (trans == 'N') then
      x = x*sys%rscale
      call lu_solve(sys%aug, n, sys%ipiv, x, .false.)
      x(3:n:3) = x(3:n:3)*sys%lref
    else
      x(3:n:3) = x(3:n:3)*sys%lref
      call lu_solve(sys%aug, n, sys%ipiv, x, .true.)
      x = x*sys%rscale
    end if
    status = STATUS_OK
    if (.not. ieee_is_finite(sum(abs(x)))) status = STATUS_NONFINITE
  end subroutine square_solve

  !> Pivot ratio of the scaled Gram matrix G = S Phi_z D^2 Phi_z^T S of the last mbs_constraints (S, D as
  !> in square_factor): about (sigma_min / sigma_max)^2 of the scaled constraint Jacobian; 0 when G is
  !> singular.
  function mbs_gram_rcond(sys) result(rcond)
    type(mbs_system), intent(inout) :: sys
    real(dp) :: rcond
    real(dp) :: a(sys%nrow, sys%n), g(sys%nrow, sys%nrow)
    integer :: ipiv(sys%nrow), info, r, m
    m = sys%nrow
    rcond = 1.0_dp
    if (m == 0) return
    do r = 1, m
      a(r, :) = sys%rscale(r)*sys%jac(r, :)
    end do
    a(:, 3:sys%n:3) = a(:, 3:sys%n:3)*sys%lref
    g = matmul(a, transpose(a))
    call lu_factor(g, m, ipiv, info)
    rcond = 0.0_dp
    if (info == 0) rcond = pivot_ratio(g, m)
  end function mbs_gram_rcond

  !> The generalized force every drive applies on its joint coordinate [N m or N] at (z, zd, t) with
  !> multipliers lam: a force drive's law, a kinematic drive's -lambda (its constraint force).
  pure subroutine mbs_drive_values(sys, z, zd, t, lam, dv)
    type(mbs_system), intent(in) :: sys
    real(dp), intent(in) :: z(:), zd(:), t, lam(:)
    real(dp), intent(out) :: dv(:)
    integer :: i, k, nk, cols(6)
    real(dp) :: g, grad(6), gd, gq
    do i = 1, sys%nd
      if (sys%dv_row(i) > 0) then
        dv(i) = -lam(sys%dv_row(i))
        cycle
      end if
      call joint_coordinate(sys, sys%dv_joint(i), z, zd, .false., g, cols, grad, gd, gq)
      k = sys%dv_tab(1, i); nk = sys%dv_tab(2, i)
      if (nk > 0) then
        dv(i) = force_law(sys%dv_par(:, i), sys%dv_harm(:, i), sys%dv_th(:, :, i), sys%tab_t(k:k + nk - 1), &
                          sys%tab_c(:, k:k + nk - 1), g, t)
      else
        dv(i) = force_law(sys%dv_par(:, i), sys%dv_harm(:, i), sys%dv_th(:, :, i), sys%tab_t(1:0), &
                          sys%tab_c(:, 1:0), g, t)
      end if
    end do
  end subroutine mbs_drive_values

  !> How far the kinematic drives move their coordinates from t0 to t1: max |f(t1) - f(t0)| over the
  !> kinematic drives, in units of the mechanism's length lref (angles in rad, slides / lref); 0
  !> without kinematic drives.  It sees the prescribed motion before any position is solved (a start
  !> from rest, whose rates and accelerations at t0 predict no motion).
  pure function mbs_drive_change(sys, t0, t1) result(change)
    type(mbs_system), intent(in) :: sys
    real(dp), intent(in) :: t0, t1
    real(dp) :: change, f0(3), f1(3)
    integer :: i
    change = 0.0_dp
    do i = 1, sys%nd
      if (sys%dv_row(i) == 0) cycle
      f0 = drive_law(sys, i, t0)
      f1 = drive_law(sys, i, t1)
      change = max(change, abs(f1(1) - f0(1))*sys%rscale(sys%dv_row(i))/sys%lref)
    end do
  end function mbs_drive_change

  !> Coordinates of every joint [value, rate, acceleration] (3, nj) at (z, zd, zdd) and time t [s].  A
  !> kinematically driven joint's are its law's [f, f', f''] at t: the position solve meets the law only
  !> to its tolerance (1e-12 of the mechanism's size, drifting between Newton corrections), and the
  !> coupled models prescribe these values in their drive rows, where an error of 1e-13 m is a
  !> multiplier kick of m 1e-13 / (beta h^2) (docs/theory.md section 15.4).
  pure subroutine mbs_joint_coordinates(sys, z, zd, zdd, t, jq)
    type(mbs_system), intent(in) :: sys
    real(dp), intent(in) :: z(:), zd(:), zdd(:), t
    real(dp), intent(out) :: jq(:, :)
    integer :: i, j, c, cols(6)
    real(dp) :: g, grad(6), gd, gq, acc
    do j = 1, sys%nj
      call joint_coordinate(sys, j, z, zd, .false., g, cols, grad, gd, gq)
      acc = gq
      do c = 1, 6
        if (cols(c) > 0) acc = acc + grad(c)*zdd(cols(c))
      end do
      jq(:, j) = [g, gd, acc]
    end do
    do i = 1, sys%nd
      if (sys%dv_row(i) > 0) jq(:, sys%dv_joint(i)) = drive_law(sys, i, t)
    end do
  end subroutine mbs_joint_coordinates

  !> [f, f', f''] of kinematic drive i's law at time t [s].
  pure function drive_law(sys, i, t) result(f)
    type(mbs_system), intent(in) :: sys
    integer, intent(in) :: i
    real(dp), intent(in) :: t
    real(dp) :: f(3)
    integer :: k
    k = sys%dv_tab(1, i)
    f = kinematic_law(sys%dv_kind(i), sys%dv_par(:, i), sys%tab_t(k:k + max(sys%dv_tab(2, i), 1) - 1), &
                      sys%tab_c(:, k:k + max(sys%dv_tab(2, i), 1) - 1), t)
  end function drive_law

end module flexmech_mbs
