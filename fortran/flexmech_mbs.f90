!> Rigid-body mechanics of a planar mechanism described as bodies, markers, joints and drives
!> (docs/theory.md section 17).  The same description serves every model: it is built in Python
!> (flexmech_py/mechanism) and packed into two flat arrays (mbs_build documents their layout); the
!> position-level solvers on it are in flexmech_mbs_solve.
!>
!> Coordinates: z = [x_1, y_1, phi_1, ..., x_nb, y_nb, phi_nb], per moving body the position of its
!> centre of mass [m] and the angle of its frame [rad]; mass matrix M = diag(m, m, J_C) (constant).
!> A marker k is a point fixed on body b (b = 0: the ground) at s_k in the body frame, relative to the
!> centre of mass: r_k = c_b + R(phi_b) s_k (ground: r_k = s_k), frame angle phi_b (flexmech_markers:
!> body_marker, ground_marker).
!>
!> A joint is a list of constraint rows g(z) - ref = 0 on its two markers P (on body a) and Q (on
!> body b), each of a row kind of flexmech_markers (the one constraint vocabulary of every model,
!> evaluated by its constraint_row), and one coordinate row g_j(z) (its joint coordinate, which drives
!> act on and the outputs report).  Python writes them per joint kind (flexmech_py/mechanism/joints.py);
!> this module never asks which kind a joint is.  The kinds of today:
!>   revolute   CON_POINT (x), CON_POINT (y)                        coordinate CON_ANGLE phi_b - phi_a [rad]
!>   prismatic  CON_PROJECTION (d = guide normal), CON_ANGLE - ref  coordinate CON_PROJECTION (d = guide) [m]
!>   weld       CON_POINT (x), CON_POINT (y), CON_ANGLE - ref       coordinate CON_ANGLE [rad]
!> (the guide fixed to body a through P; d in a's frame).  A kinematic drive adds one row
!> g_j(z) - f(t) = 0 on the coordinate of its joint; a force drive adds the generalized force
!> tau dg_j/dz (flexmech_drivelaw).  Rows are ordered joint by joint, then drive by drive; the
!> multipliers lambda of M z'' + Phi_z^T lambda = Q are the constraint forces (the force body a exerts
!> on body b at a revolute is +lambda; a kinematic drive applies -lambda).  Acceleration equations
!> Phi_z z'' = gamma (gamma = -acc0 of the rows), velocity equations Phi_z z' = nu (nu = f' on drive rows).
module flexmech_mbs
  use, intrinsic :: ieee_arithmetic, only: ieee_is_finite
  use flexmech_kinds, only: dp
  use flexmech_lapack, only: STATUS_OK, STATUS_BAD_INPUT, STATUS_SINGULAR, STATUS_NONFINITE
  use flexmech_dense, only: lu_factor, lu_solve, chol_factor, chol_solve
  use flexmech_drivelaw, only: kinematic_law, force_law, LAW_FORCE
  use flexmech_markers, only: marker_state, body_marker, ground_marker, constraint_row, con_valid, &
                              con_in_radians, CON_POINT, MAXCOL
  use flexmech_ode, only: ode_problem
  implicit none
  private
  public :: mbs_system, mbs_build, mbs_constraints, mbs_forces, mbs_accelerations, mbs_joint_coordinates, &
            mbs_nspec_header, mbs_drive_values, mbs_drive_change, factor_augmented, solve_augmented, solve_dynamics, &
            joint_coordinate

  integer, parameter :: NPAR = 4                   !< parameters per drive law (flexmech_drivelaw)
  integer, parameter :: mbs_nspec_header = 8       !< integers before the first block of ispec

  type, extends(ode_problem) :: mbs_system
    integer :: nb = 0, n = 0, nmk = 0, nj = 0, nd = 0, ncr = 0, nrow = 0, nh = 0, nth = 0, ntab = 0
    real(dp), allocatable :: mass(:), inertia(:)   !< (nb) [kg], [kg m^2] about the centre of mass
    integer, allocatable :: mk_body(:)             !< (nmk) body of each marker, 0 = ground
    real(dp), allocatable :: mk_pos(:, :)          !< (2, nmk) position in its body frame from the COM [m]
    integer, allocatable :: jt_mk(:, :)            !< (2, nj) markers [P, Q] of each joint
    integer, allocatable :: jt_coord(:, :)         !< (2, nj) coordinate row [kind, aux]
    real(dp), allocatable :: jt_dir(:, :)          !< (2, nj) its direction d (a's frame)
    integer, allocatable :: jt_row(:)              !< (nj + 1) joint j's rows: jt_row(j) .. jt_row(j + 1) - 1
    integer, allocatable :: cr(:, :)               !< (3, ncr) the joints' rows [joint, kind, aux]
    real(dp), allocatable :: cr_dir(:, :), cr_ref(:)   !< (2, ncr) direction d; (ncr) value held [m or rad]
    integer, allocatable :: dv_joint(:), dv_kind(:), dv_tab(:, :), dv_row(:)   !< dv_row 0: force drive
    real(dp), allocatable :: dv_par(:, :), dv_harm(:, :), dv_th(:, :, :)
    real(dp), allocatable :: tab_t(:), tab_c(:, :)
    real(dp) :: grav(2) = 0.0_dp, lref = 1.0_dp    !< gravity [m/s^2]; length scale of the mechanism [m]
    real(dp), allocatable :: rscale(:)             !< (nrow) length per unit of each row: 1 [m] or lref [rad]
    ! workspace of the last evaluation
    real(dp), allocatable :: phi(:), jac(:, :), gam(:), nu(:), q(:), aug(:, :), sol(:)
    integer, allocatable :: ipiv(:)
    type(marker_state), allocatable :: mk(:)       !< (nmk) every marker at the state of the last evaluation
    real(dp), allocatable :: minv(:)               !< (n) the inverse of the diagonal mass matrix (0: singular M)
    logical :: schur = .false.                     !< the last factor_augmented is the Gram matrix's (below)
  contains
    procedure :: rhs => dynamics_rhs
  end type mbs_system

contains

  !> Unpack and check the flat description.  ispec (integers):
  !>   [nb, nmk, nj, nd, ntab, nh, nth, ncr,  mk_body(nmk),  jt_mk(2, nj),  jt_coord(2, nj) = [kind, aux],
  !>    cr(3, ncr) = [joint, kind, aux] (rows ordered by joint),
  !>    dv_joint(nd), dv_kind(nd), dv_tab(2, nd) = [first knot, knots] (0 knots: no table)]
  !> rspec (reals):
  !>   [mass(nb), inertia(nb), grav(2), lref,  mk_pos(2, nmk),  jt_dir(2, nj),  cr_dir(2, ncr), cr_ref(ncr),
  !>    dv_par(4, nd), dv_harm(2 nh, nd), dv_th(3, nth, nd),  tab_t(ntab), tab_c(4, ntab)]
  !> Row kinds and their parameters (aux, d): flexmech_markers; an unknown kind is STATUS_BAD_INPUT.
  subroutine mbs_build(ispec, rspec, sys, status)
    integer, intent(in) :: ispec(:)
    real(dp), intent(in) :: rspec(:)
    type(mbs_system), intent(out) :: sys
    integer, intent(out) :: status
    integer :: r
    status = STATUS_BAD_INPUT
    if (size(ispec) < mbs_nspec_header) return
    if (any(ispec(1:mbs_nspec_header) < 0) .or. ispec(1) < 1) return
    sys%nb = ispec(1); sys%nmk = ispec(2); sys%nj = ispec(3); sys%nd = ispec(4); sys%ntab = ispec(5)
    sys%nh = ispec(6); sys%nth = ispec(7); sys%ncr = ispec(8)
    sys%n = 3*sys%nb
    if (size(ispec) /= mbs_nspec_header + sys%nmk + 4*sys%nj + 3*sys%ncr + 4*sys%nd) return
    if (size(rspec) /= 2*sys%nb + 3 + 2*sys%nmk + 2*sys%nj + 3*sys%ncr + (NPAR + 2*sys%nh + 3*sys%nth)*sys%nd &
        + 5*sys%ntab) return
    call unpack_ints(ispec, sys)
    call unpack_reals(rspec, sys)
    if (.not. valid(sys)) return
    call number_rows(sys)
    r = sys%nrow
    allocate (sys%phi(r), sys%jac(max(r, 1), sys%n), sys%gam(r), sys%nu(r), sys%q(sys%n))
    allocate (sys%aug(sys%n + r, sys%n + r), sys%sol(sys%n + r), sys%ipiv(sys%n + r), sys%mk(sys%nmk))
    allocate (sys%minv(sys%n))
    sys%minv = 0.0_dp
    if (all(sys%inertia > 0.0_dp)) then
      sys%minv(1:sys%n:3) = 1.0_dp/sys%mass; sys%minv(2:sys%n:3) = 1.0_dp/sys%mass
      sys%minv(3:sys%n:3) = 1.0_dp/sys%inertia
    end if
    do r = 1, sys%nmk          ! the ground's markers never change
      if (sys%mk_body(r) == 0) call ground_marker(sys%mk_pos(:, r), sys%mk(r))
    end do
    status = STATUS_OK
  end subroutine mbs_build

  !> The integer blocks of ispec (layout: mbs_build).
  subroutine unpack_ints(ispec, sys)
    integer, intent(in) :: ispec(:)
    type(mbs_system), intent(inout) :: sys
    integer :: o
    o = mbs_nspec_header
    sys%mk_body = ispec(o + 1:o + sys%nmk); o = o + sys%nmk
    sys%jt_mk = reshape(ispec(o + 1:o + 2*sys%nj), [2, sys%nj]); o = o + 2*sys%nj
    sys%jt_coord = reshape(ispec(o + 1:o + 2*sys%nj), [2, sys%nj]); o = o + 2*sys%nj
    sys%cr = reshape(ispec(o + 1:o + 3*sys%ncr), [3, sys%ncr]); o = o + 3*sys%ncr
    sys%dv_joint = ispec(o + 1:o + sys%nd); o = o + sys%nd
    sys%dv_kind = ispec(o + 1:o + sys%nd); o = o + sys%nd
    sys%dv_tab = reshape(ispec(o + 1:o + 2*sys%nd), [2, sys%nd])
  end subroutine unpack_ints

  !> The real blocks of rspec (layout: mbs_build).
  subroutine unpack_reals(rspec, sys)
    real(dp), intent(in) :: rspec(:)
    type(mbs_system), intent(inout) :: sys
    integer :: o, nd
    nd = sys%nd
    o = 0
    sys%mass = rspec(o + 1:o + sys%nb); o = o + sys%nb
    sys%inertia = rspec(o + 1:o + sys%nb); o = o + sys%nb
    sys%grav = rspec(o + 1:o + 2); sys%lref = rspec(o + 3); o = o + 3
    sys%mk_pos = reshape(rspec(o + 1:o + 2*sys%nmk), [2, sys%nmk]); o = o + 2*sys%nmk
    sys%jt_dir = reshape(rspec(o + 1:o + 2*sys%nj), [2, sys%nj]); o = o + 2*sys%nj
    sys%cr_dir = reshape(rspec(o + 1:o + 2*sys%ncr), [2, sys%ncr]); o = o + 2*sys%ncr
    sys%cr_ref = rspec(o + 1:o + sys%ncr); o = o + sys%ncr
    sys%dv_par = reshape(rspec(o + 1:o + NPAR*nd), [NPAR, nd]); o = o + NPAR*nd
    sys%dv_harm = reshape(rspec(o + 1:o + 2*sys%nh*nd), [2*sys%nh, nd]); o = o + 2*sys%nh*nd
    sys%dv_th = reshape(rspec(o + 1:o + 3*sys%nth*nd), [3, sys%nth, nd]); o = o + 3*sys%nth*nd
    sys%tab_t = rspec(o + 1:o + sys%ntab); o = o + sys%ntab
    sys%tab_c = reshape(rspec(o + 1:o + 4*sys%ntab), [4, sys%ntab])
  end subroutine unpack_reals

  !> Indices and values of an unpacked description are in range; every row kind is one of
  !> flexmech_markers' (a joint coordinate: not a point component); the joints' rows in joint order.
  logical function valid(sys)
    type(mbs_system), intent(in) :: sys
    integer :: i
    valid = .false.
    if (any(sys%mass <= 0.0_dp) .or. any(sys%inertia < 0.0_dp) .or. .not. sys%lref > 0.0_dp) return
    if (any(sys%mk_body < 0) .or. any(sys%mk_body > sys%nb)) return
    if (any(sys%jt_mk < 1) .or. any(sys%jt_mk > sys%nmk)) return
    do i = 1, sys%nj
      if (sys%jt_coord(1, i) == CON_POINT .or. .not. con_valid(sys%jt_coord(1, i), sys%jt_coord(2, i))) return
    end do
    do i = 1, sys%ncr
      if (.not. con_valid(sys%cr(2, i), sys%cr(3, i))) return
      if (sys%cr(1, i) < 1 .or. sys%cr(1, i) > sys%nj) return
      if (i > 1) then
        if (sys%cr(1, i) < sys%cr(1, i - 1)) return
      end if
    end do
    if (any(sys%dv_joint < 1) .or. any(sys%dv_joint > sys%nj)) return
    do i = 1, sys%nd
      if (sys%dv_tab(2, i) > 0) then
        if (sys%dv_tab(1, i) < 1 .or. sys%dv_tab(1, i) + sys%dv_tab(2, i) - 1 > sys%ntab .or. sys%dv_tab(2, i) < 2) &
          return
      end if
    end do
    valid = .true.
  end function valid

  !> Row numbers: each joint's first row (jt_row), each kinematic drive's (dv_row), and every row's
  !> length per unit (rscale: lref for rows in radians).
  subroutine number_rows(sys)
    type(mbs_system), intent(inout) :: sys
    integer :: i, j, r
    allocate (sys%jt_row(sys%nj + 1), sys%dv_row(sys%nd))
    r = 1
    do j = 1, sys%nj
      sys%jt_row(j) = r
      do while (r <= sys%ncr)
        if (sys%cr(1, r) /= j) exit
        r = r + 1
      end do
    end do
    sys%jt_row(sys%nj + 1) = r
    r = sys%ncr
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
    do r = 1, sys%ncr
      if (con_in_radians(sys%cr(2, r))) sys%rscale(r) = sys%lref
    end do
    do i = 1, sys%nd
      if (sys%dv_row(i) > 0 .and. con_in_radians(sys%jt_coord(1, sys%dv_joint(i)))) sys%rscale(sys%dv_row(i)) = sys%lref
    end do
  end subroutine number_rows

  !> Every moving marker's state at (z, zd) into sys%mk (flexmech_markers: body_marker; the ground's
  !> are set once by mbs_build).  Each marker is evaluated once per state: the joints' rows, the drives'
  !> rows and forces, and the joint coordinates all read these.
  subroutine eval_markers(sys, z, zd)
    type(mbs_system), intent(inout) :: sys
    real(dp), intent(in) :: z(:), zd(:)
    integer :: k, b
    do k = 1, sys%nmk
      b = sys%mk_body(k)
      if (b > 0) call body_marker(z(3*b - 2:3*b), zd(3*b - 2:3*b), [3*b - 2, 3*b - 1, 3*b], sys%mk_pos(:, k), sys%mk(k))
    end do
  end subroutine eval_markers

  !> Coordinate g of joint j (its coordinate row) at the markers of the last evaluation, its rate gd,
  !> the velocity part acc0 of its second derivative (g'' = grad . z'' + acc0) and its gradient grad
  !> over the coordinates cols(1:nc).
  pure subroutine joint_coordinate(sys, j, g, gd, acc0, nc, cols, grad)
    type(mbs_system), intent(in) :: sys
    integer, intent(in) :: j
    real(dp), intent(out) :: g, gd, acc0, grad(2*MAXCOL)
    integer, intent(out) :: nc, cols(2*MAXCOL)
    call constraint_row(sys%jt_coord(1, j), sys%jt_coord(2, j), sys%jt_dir(:, j), sys%mk(sys%jt_mk(1, j)), &
                        sys%mk(sys%jt_mk(2, j)), g, gd, acc0, nc, cols, grad)
  end subroutine joint_coordinate

  !> Constraint values phi, Jacobian jac (nrow x n, dense), acceleration right-hand side gam and velocity
  !> right-hand side nu at (z, zd, t), into sys's workspace (the markers' states too: mbs_forces,
  !> mbs_joint_coordinates and mbs_drive_values read them).
  subroutine mbs_constraints(sys, z, zd, t)
    type(mbs_system), intent(inout) :: sys
    real(dp), intent(in) :: z(:), zd(:), t
    integer :: j, r, i, nc, cols(2*MAXCOL)
    real(dp) :: g, gd, acc0, grad(2*MAXCOL), f(3)
    call eval_markers(sys, z, zd)
    sys%jac = 0.0_dp; sys%nu = 0.0_dp
    do j = 1, sys%nj
      associate (ma => sys%mk(sys%jt_mk(1, j)), mb => sys%mk(sys%jt_mk(2, j)))
        do r = sys%jt_row(j), sys%jt_row(j + 1) - 1
          call constraint_row(sys%cr(2, r), sys%cr(3, r), sys%cr_dir(:, r), ma, mb, g, gd, acc0, nc, cols, grad)
          call put_row(sys, r, g - sys%cr_ref(r), -acc0, nc, cols, grad)
        end do
      end associate
    end do
    do i = 1, sys%nd
      r = sys%dv_row(i)
      if (r == 0) cycle
      call joint_coordinate(sys, sys%dv_joint(i), g, gd, acc0, nc, cols, grad)
      f = drive_law(sys, i, t)
      call put_row(sys, r, g - f(1), f(3) - acc0, nc, cols, grad)
      sys%nu(r) = f(2)
    end do
  end subroutine mbs_constraints

  !> Row r of the workspace: value, acceleration right-hand side and gradient (added over cols(1:nc)).
  pure subroutine put_row(sys, r, val, gamma, nc, cols, grad)
    type(mbs_system), intent(inout) :: sys
    integer, intent(in) :: r, nc, cols(:)
    real(dp), intent(in) :: val, gamma, grad(:)
    integer :: c
    sys%phi(r) = val
    sys%gam(r) = gamma
    do c = 1, nc
      sys%jac(r, cols(c)) = sys%jac(r, cols(c)) + grad(c)
    end do
  end subroutine put_row

  !> Generalized applied forces q (n) at time t and the state of the last mbs_constraints: gravity and
  !> the force drives.
  pure subroutine mbs_forces(sys, t, q)
    type(mbs_system), intent(in) :: sys
    real(dp), intent(in) :: t
    real(dp), intent(out) :: q(:)
    integer :: i, b, c, nc, cols(2*MAXCOL)
    real(dp) :: g, gd, acc0, grad(2*MAXCOL), tau
    q = 0.0_dp
    do b = 1, sys%nb
      q(3*b - 2:3*b - 1) = sys%mass(b)*sys%grav
    end do
    do i = 1, sys%nd
      if (sys%dv_kind(i) /= LAW_FORCE) cycle
      call joint_coordinate(sys, sys%dv_joint(i), g, gd, acc0, nc, cols, grad)
      tau = force_value(sys, i, g, t)
      do c = 1, nc
        q(cols(c)) = q(cols(c)) + tau*grad(c)
      end do
    end do
  end subroutine mbs_forces

  !> Generalized force [N m or N] of force drive i's law at its coordinate g and time t [s].
  pure real(dp) function force_value(sys, i, g, t) result(tau)
    type(mbs_system), intent(in) :: sys
    integer, intent(in) :: i
    real(dp), intent(in) :: g, t
    integer :: k, nk
    k = sys%dv_tab(1, i); nk = sys%dv_tab(2, i)
    if (nk > 0) then
      tau = force_law(sys%dv_par(:, i), sys%dv_harm(:, i), sys%dv_th(:, :, i), sys%tab_t(k:k + nk - 1), &
                      sys%tab_c(:, k:k + nk - 1), g, t)
    else
      tau = force_law(sys%dv_par(:, i), sys%dv_harm(:, i), sys%dv_th(:, :, i), sys%tab_t(1:0), &
                      sys%tab_c(:, 1:0), g, t)
    end if
  end function force_value

  !> Accelerations zdd and multipliers lam at (z, zd, t) from [M Phi_z^T; Phi_z 0][zdd; lam] = [Q; gamma]
  !> (the augmented matrix stays factorized in sys%aug for mbs_project).
  subroutine mbs_accelerations(sys, z, zd, t, zdd, lam, status)
    type(mbs_system), intent(inout) :: sys
    real(dp), intent(in) :: z(:), zd(:), t
    real(dp), intent(out) :: zdd(:), lam(:)
    integer, intent(out) :: status
    call mbs_constraints(sys, z, zd, t)
    call mbs_forces(sys, t, sys%q)
    call solve_dynamics(sys, zdd, lam, status)
  end subroutine mbs_accelerations

  !> Accelerations zdd and multipliers lam from [M Phi_z^T; Phi_z 0][zdd; lam] = [sys%q; sys%gam] at the
  !> last mbs_constraints (the applied forces in sys%q as the caller left them).
  subroutine solve_dynamics(sys, zdd, lam, status)
    type(mbs_system), intent(inout) :: sys
    real(dp), intent(out) :: zdd(:), lam(:)
    integer, intent(out) :: status
    call factor_augmented(sys, status)
    if (status /= STATUS_OK) return
    sys%sol(1:sys%n) = sys%q
    sys%sol(sys%n + 1:) = sys%gam
    call solve_augmented(sys, status)
    zdd = sys%sol(1:sys%n)
    lam = sys%sol(sys%n + 1:)
  end subroutine solve_dynamics

  !> Factor the augmented matrix [M Phi_z^T; Phi_z 0] of the last mbs_constraints for solve_augmented.
  !> M is diagonal: when it is regular (every body has a rotary inertia), through the Gram matrix
  !> G = Phi_z M^-1 Phi_z^T (nrow x nrow, Cholesky in sys%aug(1:nrow, 1:nrow); (nrow^3/6 + nrow^2 n/2
  !> flops against (n + nrow)^3/3 for the whole matrix).  When G is not positive definite to 1e-10 of
  !> its diagonal (rows dependent or nearly so) or M is singular: LU of the whole augmented matrix.
  subroutine factor_augmented(sys, status)
    type(mbs_system), intent(inout) :: sys
    integer, intent(out) :: status
    integer :: info
    status = STATUS_OK
    sys%schur = sys%minv(1) > 0.0_dp
    if (sys%schur .and. sys%nrow > 0) then
      call gram_lower(sys)
      call chol_factor(sys%aug, sys%nrow, 1e-10_dp, info)
      sys%schur = info == 0
    end if
    if (sys%schur) return
    call augmented_lu(sys, info)
    status = merge(STATUS_SINGULAR, STATUS_OK, info > 0)
  end subroutine factor_augmented

  !> Lower triangle of G = Phi_z M^-1 Phi_z^T into sys%aug(1:nrow, 1:nrow), column by column of
  !> Phi_z (a row touches at most two bodies: most products are skipped).
  subroutine gram_lower(sys)
    type(mbs_system), intent(inout) :: sys
    integer :: i, j, c, m
    real(dp) :: t
    m = sys%nrow
    sys%aug(1:m, 1:m) = 0.0_dp
    do c = 1, sys%n
      do j = 1, m
        t = sys%jac(j, c)*sys%minv(c)
        if (t == 0.0_dp) cycle
        do i = j, m
          sys%aug(i, j) = sys%aug(i, j) + sys%jac(i, c)*t
        end do
      end do
    end do
  end subroutine gram_lower

  !> LU of the whole augmented matrix in sys%aug (info > 0: an exactly zero pivot).
  subroutine augmented_lu(sys, info)
    type(mbs_system), intent(inout) :: sys
    integer, intent(out) :: info
    integer :: b, n
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
  end subroutine augmented_lu

  !> Solve [M Phi_z^T; Phi_z 0] [x; lam] = [f; g] with factor_augmented's factors: sys%sol = [f; g]
  !> (n + nrow) overwritten by [x; lam].  Through the Gram matrix: G lam = Phi_z M^-1 f - g,
  !> x = M^-1 (f - Phi_z^T lam).
  subroutine solve_augmented(sys, status)
    type(mbs_system), intent(inout) :: sys
    integer, intent(out) :: status
    integer :: n, m
    n = sys%n; m = sys%nrow
    if (sys%schur) then
      sys%sol(1:n) = sys%minv*sys%sol(1:n)
      sys%sol(n + 1:) = matmul(sys%jac(1:m, :), sys%sol(1:n)) - sys%sol(n + 1:)
      call chol_solve(sys%aug, m, sys%sol(n + 1:))
      sys%sol(1:n) = sys%sol(1:n) - sys%minv*matmul(sys%sol(n + 1:), sys%jac(1:m, :))
    else
      call lu_solve(sys%aug, n + m, sys%ipiv, sys%sol, .false.)
    end if
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

  !> The generalized force every drive applies on its joint coordinate [N m or N] at time t and the
  !> state of the last mbs_constraints, with multipliers lam: a force drive's law, a kinematic drive's
  !> -lambda (its constraint force).
  pure subroutine mbs_drive_values(sys, t, lam, dv)
    type(mbs_system), intent(in) :: sys
    real(dp), intent(in) :: t, lam(:)
    real(dp), intent(out) :: dv(:)
    integer :: i, nc, cols(2*MAXCOL)
    real(dp) :: g, gd, acc0, grad(2*MAXCOL)
    do i = 1, sys%nd
      if (sys%dv_row(i) > 0) then
        dv(i) = -lam(sys%dv_row(i))
        cycle
      end if
      call joint_coordinate(sys, sys%dv_joint(i), g, gd, acc0, nc, cols, grad)
      dv(i) = force_value(sys, i, g, t)
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

  !> Coordinates of every joint [value, rate, acceleration] (3, nj) at the state of the last
  !> mbs_constraints, accelerations zdd and time t [s].  A
  !> kinematically driven joint's are its law's [f, f', f''] at t: the position solve meets the law only
  !> to its tolerance (1e-12 of the mechanism's size, drifting between Newton corrections), and the
  !> coupled models prescribe these values in their drive rows, where an error of 1e-13 m is a
  !> multiplier kick of m 1e-13 / (beta h^2) (docs/theory.md section 15.4).
  pure subroutine mbs_joint_coordinates(sys, zdd, t, jq)
    type(mbs_system), intent(in) :: sys
    real(dp), intent(in) :: zdd(:), t
    real(dp), intent(out) :: jq(:, :)
    integer :: i, j, c, nc, cols(2*MAXCOL)
    real(dp) :: g, gd, acc0, grad(2*MAXCOL), acc
    do j = 1, sys%nj
      call joint_coordinate(sys, j, g, gd, acc0, nc, cols, grad)
      acc = acc0
      do c = 1, nc
        acc = acc + grad(c)*zdd(cols(c))
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
