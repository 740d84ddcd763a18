!> One-pass model with mutual rigid-elastic coupling (seed Section 3, Gibbs-Appell),
!> in the chord-frame form derived in docs/theory.md (section "Coupled model"), on any planar
!> mechanism: beam segments, rigid bodies, and constraint rows on markers (flexmech_markers).
!>
!> Bodies and their generalized coordinates (all-DOF vector; ground DOFs fixed):
!> - a beam segment of length L with n elements (local vector, nld = 3n+3):
!>     [xs, ys, xe, ye, th_0, p_1, v_1, th_1, ..., p_{n-1}, v_{n-1}, th_{n-1}, th_n]
!>   xs..ye   absolute positions [m] of the segment's start and end (shared by segments that meet
!>            there: consecutive segments of a link, links joined end to end by a revolute or weld)
!>   p_k, v_k elastic axial / transverse displacement [m] of interior node k in the chord frame
!>   th_k     elastic rotation [rad] of node k relative to the chord
!>   The chord c = r_e - r_s defines the segment frame: phi = atan2(c), omega = g.c', g = Omega c/|c|^2.
!>   A material point at fraction w of the segment (element e at xi) is at
!>     r = (1-w) r_s + w r_e + R(phi) N(xi) delta_e ,
!>   with delta_e the element's local elastic DOFs (end-node translations are zero by definition).
!>   The coupled model has one segment per link, the nonlinear model one per element.
!> - a rigid body: [x_C, y_C, phi], mass diag(m, m, J_C) (rigid links and the case's rigid bodies).
!> Gibbs-Appell: dG/da + dU/dq = Q with G = 1/2 int |r''|^2 dm, i.e. int J^T r'' dm + dU/dq = Q,
!> J = dr'/dq' = dr''/dq''.  Strain energy: 1/2 (EA/L)(|c| - L)^2 + 1/2 delta^T k delta.
!> Joints and kinematic drives are constraint rows on markers with Lagrange multipliers (the
!> constraint forces; rows of kinds CON_POINT, CON_ANGLE, CON_PROJECTION of flexmech_markers);
!> force drives are generalized forces tau(theta, t) d theta/dq on a joint coordinate theta (a row
!> evaluated but not enforced; law: flexmech_drivelaw's force_law).
!> Integration: generalized-alpha (Arnold & Bruls 2007; Newmark (beta, gamma) for am = af = 0) in
!> acceleration form with Newton iterations on the true acceleration a_{n+1}, the equations and the
!> constraints holding exactly at t_{n+1} (see flexmech_newmark and docs/theory.md section 15); the
!> iteration matrix S = M + gamma' dt C_v + beta' dt^2 K_t is built once per step (modified Newton):
!> M and C_v exact, K_t = elastic + chord + elastic inertial terms (the configuration
!> dependence of the inertia through the chord, the constraint curvature and the force laws'
!> dependence on the configuration are left out of S; they are in the residual).
module flexmech_coupled
  use, intrinsic :: ieee_arithmetic, only: ieee_is_finite
  use flexmech_kinds, only: dp
  use flexmech_lapack, only: dgbtrf, dgbtrs, dgetrf, dgetrs, lapack_status, STATUS_OK, STATUS_NONFINITE, &
                             STATUS_BAD_INPUT, STATUS_NEWTON, STATUS_DIVERGED
  use flexmech_beam, only: beam_mass, beam_stiffness
  use flexmech_assembly, only: band_rows, band_to_dense
  use flexmech_drivelaw, only: force_law
  use flexmech_markers, only: marker_state, segment_marker, body_marker, ground_marker, constraint_row, &
                              CON_POINT, CON_ANGLE, CON_PROJECTION, MAXCOL
  implicit none
  private
  public :: coupled_system, coupled_build, coupled_run, coupled_dense, coupled_post, coupled_elastic_measure
  public :: coupled_residual, coupled_rows
  public :: coupled_set_newton, NEWTON_MODIFIED, NEWTON_FULL, NEWTON_AUTO
  public :: coupled_set_start, START_ACCELERATION, START_VELOCITY, coupled_set_inertia
  public :: coupled_set_solver, SOLVER_AUTO, SOLVER_BAND, SOLVER_CONDENSED, STATUS_NEWTON, COUPLED_NSPEC_HEADER
  public :: MK_GROUND, MK_NODE, MK_BODY

  !> Linear solver of the iteration matrix in coupled_run (docs/theory.md section 11, "The solve"):
  !> SOLVER_CONDENSED eliminates every segment's elastic DOFs (a band of half width <= 5) onto the
  !> shared end-position DOFs and solves the condensed band system; SOLVER_BAND factorizes the whole
  !> free-DOF band matrix (half bandwidth 3 x elements per segment + 2); SOLVER_AUTO (default) takes
  !> the condensed solve when the whole band is wider than the interior band + 4, i.e. when the
  !> segments' arrowheads widen it (2 or more elements per segment); with one element per segment
  !> (the nonlinear model) the whole band is narrow and its one LAPACK call beats one per segment.
  integer, parameter :: SOLVER_AUTO = -1, SOLVER_BAND = 0, SOLVER_CONDENSED = 1
  integer :: solver_mode = SOLVER_AUTO
  !> When coupled_run rebuilds and factorizes the iteration matrix within a step (docs/theory.md
  !> section 12.2): NEWTON_MODIFIED once per step (at the predictor), NEWTON_FULL at every iteration,
  !> NEWTON_AUTO (default) once per step and again whenever an iteration contracts the correction by
  !> less than NEWTON_RATE (the matrix of the predictor no longer describes the step).
  integer, parameter :: NEWTON_MODIFIED = 0, NEWTON_FULL = 1, NEWTON_AUTO = 2
  real(dp), parameter :: NEWTON_RATE = 0.1_dp
  integer :: newton_mode = NEWTON_AUTO
  !> Where the Newton iteration of a step starts (docs/theory.md section 12.2): START_ACCELERATION at
  !> the last step's acceleration (q = q* + beta' dt^2 a_n, which for Newmark is q_n + dt v_n +
  !> dt^2/2 a_n), START_VELOCITY (default) at the position q_n + dt v_n (an unresolved stiff mode's
  !> acceleration swings by its whole size from step to step: starting from a_n puts the first
  !> iterate beta' dt^2 |a_n| away, radians at fine meshes).
  integer, parameter :: START_ACCELERATION = 0, START_VELOCITY = 1, START_POSITION = 2
  integer :: start_mode = START_VELOCITY
  !> START_VELOCITY starts again at q_n when the first correction moves the configuration by more
  !> than this fraction of the mechanism's size
  real(dp), parameter :: RESTART_MOVE = 0.05_dp
  !> Inertia in closed form over the elements' Gram matrices: INERTIA_CLOSED (default; one-element
  !> segments element_inertia, the residual of longer ones element_inertia_residual) or INERTIA_GAUSS
  !> (mass_point at the Gauss points throughout; the check of the closed form)
  integer, parameter :: INERTIA_CLOSED = 0, INERTIA_GAUSS = 1
  integer :: inertia_mode = INERTIA_CLOSED
  !> Marker kinds: a ground point, a node of a segment, a point of a rigid body.
  integer, parameter :: MK_GROUND = 0, MK_NODE = 1, MK_BODY = 2
  integer, parameter :: COUPLED_NSPEC_HEADER = 12   !< integers before the first block of ispec
  integer, parameter :: NPAR = 4                    !< parameters per force law (flexmech_drivelaw)

  real(dp), parameter :: gx(4) = [ &
    0.5_dp - 0.5_dp*0.8611363115940526_dp, 0.5_dp - 0.5_dp*0.3399810435848563_dp, &
    0.5_dp + 0.5_dp*0.3399810435848563_dp, 0.5_dp + 0.5_dp*0.8611363115940526_dp]
  real(dp), parameter :: gw(4) = 0.5_dp*[0.3478548451374538_dp, 0.6521451548625461_dp, &
                                          0.6521451548625461_dp, 0.3478548451374538_dp]

  !> The system (layout of its flat description: coupled_build).
  type :: coupled_system
    integer :: nseg = 0, nrb = 0, ndof = 0, nfree = 0, maxn = 0, maxld = 0, kl = 0, ku = 0
    integer :: npm = 0, nri = 0, nmk = 0, nc = 0, nd = 0, nh = 0, nth = 0
    integer, allocatable :: n_el(:), ld(:, :), free_of(:), el_off(:), rb_dof(:, :)
    !> (nseg) 1: the segment's th DOFs are absolute node angles psi_k, shared with the neighbouring
    !> segments of its link (the nonlinear model, docs/theory.md section 12.1), 0: angles from the chord
    integer, allocatable :: absang(:)
    !> (nseg) 1: the segment is one co-rotational element whose axial strain holds its mean w'^2/2
    !> (shallow arch, the nonlinear model, docs/theory.md section 12.4), 0: the chord stretch alone
    integer, allocatable :: arch(:)
    !> (6, 6, total elements) per element: G = int psi psi^T dm over psi = [1 - xi, xi, H_v0, H_th0,
    !> H_v1, H_th1] (the shapes of shape_fn; distributed mass and point masses; element_inertia_residual)
    real(dp), allocatable :: gram6(:, :, :)
    !> (4, 4, nseg) its phi = [1 - xi, xi, H_th0, H_th1] part for one-element segments, copied once
    !> (element_inertia reads it in the hot path), zero for the others
    real(dp), allocatable :: gram(:, :, :)
    real(dp), allocatable :: prop(:, :)          !< (4, nseg) [L, rho*A, E*A, E*I]
    real(dp), allocatable :: wn(:, :)            !< (maxn+1, nseg) node fractions of each segment (0 .. 1)
    real(dp), allocatable :: me(:, :, :), ke(:, :, :)  !< (6, 6, elements) local element mass, stiffness
    real(dp), allocatable :: rb_m(:, :)          !< (3, nrb) [m, J_C, J_C in the iteration matrix]
    integer, allocatable :: pm_seg(:), pm_el(:), ri_seg(:), ri_node(:)
    real(dp), allocatable :: pm_prop(:, :), ri_j(:)   !< (2, npm) [xi in its element, mass]; (nri) J
    integer, allocatable :: mk_kind(:), mk_idx(:), mk_node(:)   !< (nmk) MK_*, segment or body, node
    real(dp), allocatable :: mk_pos(:, :)        !< (2, nmk) ground position, or body-frame point from the COM
    integer, allocatable :: con(:, :)            !< (4, nc) [kind CON_*, marker a, marker b, aux]
    real(dp), allocatable :: con_dir(:, :)       !< (2, nc) direction of CON_PROJECTION in a's frame
    integer, allocatable :: dv(:, :)             !< (5, nd) force drives [kind, marker a, marker b, table first, knots]
    real(dp), allocatable :: dv_dir(:, :), dv_par(:, :), dv_harm(:, :), dv_th(:, :, :), tab_t(:), tab_c(:, :)
    real(dp) :: grav(2) = 0.0_dp, ray(2) = 0.0_dp
  end type coupled_system

  !> Iteration matrix S = M + cc C_v + ck K_t stored by segment blocks.  Local DOFs of segment l:
  !> 1..4 the end positions ("boundary", B), 5..nl the elastic DOFs ("interior", I; ni_l = nl - 4),
  !> numbered off(l)+1..off(l)+ni_l in the interior arrays.
  !>   bb(4, 4, l)   S_BB block of the segment            bi(4, ni)  S_BI (rows: local 1..4)
  !>   ib(ni, 4)     S_IB (columns: local 1..4)           ai(ldi, ni) S_II, LAPACK band storage with
  !>                 kl = ku = kbi (row 2 kbi + 1 + i - j), factorized in place (ipi) by the condensed solve
  !>   dg(nfree)     diagonal of the rigid bodies (their DOFs are boundary DOFs coupled to nothing else)
  !> Condensed solve (cond = .true.: every interior DOF free and local to one segment):
  !>   z = S_II^-1 S_IB per segment, Schur complement sb = S_BB - S_BI z over the nb free boundary DOFs
  !>   (band kbb, LAPACK storage, ipb), workspaces yi(ni, nrhs), yb(nb, nrhs).
  type :: link_mats
    integer :: ni = 0, kbi = 0, ldi = 0, nb = 0, kbb = 0, ldb = 0, nrhs = 0
    logical :: cond = .false.
    integer, allocatable :: off(:), ifree(:), bfree(:, :), bglob(:), ipi(:), ipb(:)
    real(dp), allocatable :: bb(:, :, :), bi(:, :), ib(:, :), ai(:, :), z(:, :), sb(:, :), yi(:, :), yb(:, :), dg(:)
    !> assemble's work: a segment's all-DOF numbers and its local [R, q, v, a] (maxld; allocated once
    !> by lm_setup, so that no evaluation allocates; never referenced through lm by link_eval)
    integer, allocatable :: widx(:)
    real(dp), allocatable :: wl(:, :)
  end type link_mats

contains

  !> var = mode when lo <= mode <= hi (status STATUS_OK), else var unchanged and STATUS_BAD_INPUT:
  !> the setters of the module's modes.
  pure subroutine set_mode(mode, lo, hi, var, status)
    integer, intent(in) :: mode, lo, hi
    integer, intent(inout) :: var
    integer, intent(out) :: status
    status = STATUS_BAD_INPUT
    if (mode < lo .or. mode > hi) return
    var = mode
    status = STATUS_OK
  end subroutine set_mode

  !> Matrix refresh policy of every later coupled_run (NEWTON_*); status STATUS_BAD_INPUT otherwise.
  subroutine coupled_set_newton(mode, status)
    integer, intent(in) :: mode
    integer, intent(out) :: status
    call set_mode(mode, NEWTON_MODIFIED, NEWTON_AUTO, newton_mode, status)
  end subroutine coupled_set_newton

  !> Start of every later coupled_run's Newton iterations (START_*); status STATUS_BAD_INPUT otherwise.
  subroutine coupled_set_start(mode, status)
    integer, intent(in) :: mode
    integer, intent(out) :: status
    call set_mode(mode, START_ACCELERATION, START_POSITION, start_mode, status)
  end subroutine coupled_set_start

  !> Inertia of one-element segments in every later call (INERTIA_*); status STATUS_BAD_INPUT otherwise.
  subroutine coupled_set_inertia(mode, status)
    integer, intent(in) :: mode
    integer, intent(out) :: status
    call set_mode(mode, INERTIA_CLOSED, INERTIA_GAUSS, inertia_mode, status)
  end subroutine coupled_set_inertia

  !> Build the system from its flat description; status STATUS_BAD_INPUT on bad sizes or indices.
  !> ispec (integers, 1-based indices):
  !>   [nseg, nrb, ndof, maxn, npm, nri, nmk, nc, nd, nh, nth, ntab,
  !>    n_el(nseg), ld(3 maxn + 3, nseg), rb_dof(3, nrb), free_of(ndof), pm_seg(npm), pm_el(npm),
  !>    ri_seg(nri), ri_node(nri), mk_kind(nmk), mk_idx(nmk), mk_node(nmk), con(4, nc), dv(5, nd),
  !>    absang(nseg), arch(nseg)]
  !> rspec (reals):
  !>   [prop(4, nseg), wn(maxn + 1, nseg), rb_m(3, nrb), pm_prop(2, npm), ri_j(nri), mk_pos(2, nmk),
  !>    con_dir(2, nc), dv_dir(2, nd), dv_par(4, nd), dv_harm(2 nh, nd), dv_th(3, nth, nd),
  !>    tab_t(ntab), tab_c(4, ntab), grav(2), ray(2)]
  !> free_of: free-DOF number of each DOF (0 = fixed); ld: all-DOF numbers of each segment's local
  !> vector (entries past 3 n + 3 unused); ri_node: node 0..n of the segment the inertia turns with;
  !> mk_idx: the segment (MK_NODE) or body (MK_BODY) of a marker, mk_node its node (MK_NODE);
  !> con aux: the component 1/2 of a CON_POINT row; 1 for a row whose value moves (a kinematic drive:
  !> its work is counted), else 0; dv kind: CON_ANGLE (torque on a revolute) or CON_PROJECTION (force
  !> along a prismatic guide), table first knot and number of knots (0: none); dv_par, dv_harm,
  !> dv_th, tab_*: the force law (flexmech_drivelaw: force_law); grav [m/s^2]; ray Rayleigh [1/s, s].
  subroutine coupled_build(ispec, rspec, sys, status)
    integer, intent(in) :: ispec(:)
    real(dp), intent(in) :: rspec(:)
    type(coupled_system), intent(out) :: sys
    integer, intent(out) :: status
    integer :: o, s, e, i, nl, f, lo, hi, ntab, ns, ml, k
    real(dp) :: le
    status = STATUS_BAD_INPUT
    if (size(ispec) < COUPLED_NSPEC_HEADER) return
    if (any(ispec(1:COUPLED_NSPEC_HEADER) < 0)) return
    sys%nseg = ispec(1); sys%nrb = ispec(2); sys%ndof = ispec(3); sys%maxn = ispec(4); sys%npm = ispec(5)
    sys%nri = ispec(6); sys%nmk = ispec(7); sys%nc = ispec(8); sys%nd = ispec(9); sys%nh = ispec(10)
    sys%nth = ispec(11); ntab = ispec(12)
    ns = sys%nseg; ml = 3*sys%maxn + 3; sys%maxld = ml
    if (ns < 1 .or. sys%maxn < 1 .or. sys%ndof < 1) return
    if (size(ispec) /= COUPLED_NSPEC_HEADER + ns*(1 + ml) + 3*sys%nrb + sys%ndof + 2*sys%npm + 2*sys%nri &
        + 3*sys%nmk + 4*sys%nc + 5*sys%nd + 2*ns) return
    if (size(rspec) /= ns*(4 + sys%maxn + 1) + 3*sys%nrb + 2*sys%npm + sys%nri + 2*sys%nmk + 2*sys%nc &
        + (2 + NPAR + 2*sys%nh + 3*sys%nth)*sys%nd + 5*ntab + 4) return
    o = COUPLED_NSPEC_HEADER
    sys%n_el = ispec(o + 1:o + ns); o = o + ns
    sys%ld = reshape(ispec(o + 1:o + ml*ns), [ml, ns]); o = o + ml*ns
    sys%rb_dof = reshape(ispec(o + 1:o + 3*sys%nrb), [3, sys%nrb]); o = o + 3*sys%nrb
    sys%free_of = ispec(o + 1:o + sys%ndof); o = o + sys%ndof
    sys%pm_seg = ispec(o + 1:o + sys%npm); o = o + sys%npm
    sys%pm_el = ispec(o + 1:o + sys%npm); o = o + sys%npm
    sys%ri_seg = ispec(o + 1:o + sys%nri); o = o + sys%nri
    sys%ri_node = ispec(o + 1:o + sys%nri); o = o + sys%nri
    sys%mk_kind = ispec(o + 1:o + sys%nmk); o = o + sys%nmk
    sys%mk_idx = ispec(o + 1:o + sys%nmk); o = o + sys%nmk
    sys%mk_node = ispec(o + 1:o + sys%nmk); o = o + sys%nmk
    sys%con = reshape(ispec(o + 1:o + 4*sys%nc), [4, sys%nc]); o = o + 4*sys%nc
    sys%dv = reshape(ispec(o + 1:o + 5*sys%nd), [5, sys%nd]); o = o + 5*sys%nd
    sys%absang = ispec(o + 1:o + ns); o = o + ns
    sys%arch = ispec(o + 1:o + ns)
    o = 0
    sys%prop = reshape(rspec(o + 1:o + 4*ns), [4, ns]); o = o + 4*ns
    sys%wn = reshape(rspec(o + 1:o + (sys%maxn + 1)*ns), [sys%maxn + 1, ns]); o = o + (sys%maxn + 1)*ns
    sys%rb_m = reshape(rspec(o + 1:o + 3*sys%nrb), [3, sys%nrb]); o = o + 3*sys%nrb
    sys%pm_prop = reshape(rspec(o + 1:o + 2*sys%npm), [2, sys%npm]); o = o + 2*sys%npm
    sys%ri_j = rspec(o + 1:o + sys%nri); o = o + sys%nri
    sys%mk_pos = reshape(rspec(o + 1:o + 2*sys%nmk), [2, sys%nmk]); o = o + 2*sys%nmk
    sys%con_dir = reshape(rspec(o + 1:o + 2*sys%nc), [2, sys%nc]); o = o + 2*sys%nc
    sys%dv_dir = reshape(rspec(o + 1:o + 2*sys%nd), [2, sys%nd]); o = o + 2*sys%nd
    sys%dv_par = reshape(rspec(o + 1:o + NPAR*sys%nd), [NPAR, sys%nd]); o = o + NPAR*sys%nd
    sys%dv_harm = reshape(rspec(o + 1:o + 2*sys%nh*sys%nd), [2*sys%nh, sys%nd]); o = o + 2*sys%nh*sys%nd
    sys%dv_th = reshape(rspec(o + 1:o + 3*sys%nth*sys%nd), [3, sys%nth, sys%nd]); o = o + 3*sys%nth*sys%nd
    sys%tab_t = rspec(o + 1:o + ntab); o = o + ntab
    sys%tab_c = reshape(rspec(o + 1:o + 4*ntab), [4, ntab]); o = o + 4*ntab
    sys%grav = rspec(o + 1:o + 2); sys%ray = rspec(o + 3:o + 4)
    ! checks of indices and values
    if (any(sys%n_el < 1) .or. any(sys%n_el > sys%maxn) .or. any(sys%free_of < 0)) return
    if (any(sys%absang < 0) .or. any(sys%absang > 1)) return
    if (any(sys%absang == 1 .and. sys%n_el /= 1)) return
    if (any(sys%arch < 0) .or. any(sys%arch > 1) .or. any(sys%arch == 1 .and. sys%n_el /= 1)) return
    sys%nfree = maxval([0, sys%free_of])
    if (sys%nfree < 1 .or. any(sys%prop <= 0.0_dp)) return
    do s = 1, ns
      nl = 3*sys%n_el(s) + 3
      if (any(sys%ld(1:nl, s) < 1) .or. any(sys%ld(1:nl, s) > sys%ndof)) return
      do e = 1, sys%n_el(s)
        if (.not. sys%wn(e + 1, s) > sys%wn(e, s)) return
      end do
    end do
    if (any(sys%rb_dof < 1) .or. any(sys%rb_dof > sys%ndof)) return
    if (sys%nrb > 0) then
      if (any(sys%rb_m(1, :) <= 0.0_dp) .or. any(sys%rb_m(2, :) < 0.0_dp) .or. any(sys%rb_m(3, :) <= 0.0_dp)) return
    end if
    do i = 1, sys%npm
      if (sys%pm_seg(i) < 1 .or. sys%pm_seg(i) > ns) return
      if (sys%pm_el(i) < 1 .or. sys%pm_el(i) > sys%n_el(max(1, sys%pm_seg(i)))) return
    end do
    do i = 1, sys%nri
      if (sys%ri_seg(i) < 1 .or. sys%ri_seg(i) > ns) return
      if (sys%ri_node(i) < 0 .or. sys%ri_node(i) > sys%n_el(sys%ri_seg(i))) return
    end do
    do i = 1, sys%nmk
      select case (sys%mk_kind(i))
      case (MK_NODE)
        if (sys%mk_idx(i) < 1 .or. sys%mk_idx(i) > ns) return
        if (sys%mk_node(i) < 0 .or. sys%mk_node(i) > sys%n_el(sys%mk_idx(i))) return
      case (MK_BODY)
        if (sys%mk_idx(i) < 1 .or. sys%mk_idx(i) > sys%nrb) return
      case (MK_GROUND)
      case default
        return
      end select
    end do
    do i = 1, sys%nc
      if (sys%con(1, i) < CON_POINT .or. sys%con(1, i) > CON_PROJECTION) return
      if (any(sys%con(2:3, i) < 1) .or. any(sys%con(2:3, i) > sys%nmk)) return
      if (sys%con(1, i) == CON_POINT .and. (sys%con(4, i) < 1 .or. sys%con(4, i) > 2)) return
    end do
    do i = 1, sys%nd
      if (sys%dv(1, i) /= CON_ANGLE .and. sys%dv(1, i) /= CON_PROJECTION) return
      if (any(sys%dv(2:3, i) < 1) .or. any(sys%dv(2:3, i) > sys%nmk)) return
      if (sys%dv(5, i) > 0) then
        if (sys%dv(4, i) < 1 .or. sys%dv(4, i) + sys%dv(5, i) - 1 > ntab .or. sys%dv(5, i) < 2) return
      end if
    end do
    ! element matrices, element by element (segments may have elements of different lengths)
    allocate (sys%el_off(ns))
    sys%el_off(1) = 0
    do s = 2, ns
      sys%el_off(s) = sys%el_off(s - 1) + sys%n_el(s - 1)
    end do
    allocate (sys%me(6, 6, sum(sys%n_el)), sys%ke(6, 6, sum(sys%n_el)))
    call gram_matrices(sys)
    do s = 1, ns
      do e = 1, sys%n_el(s)
        le = sys%prop(1, s)*(sys%wn(e + 1, s) - sys%wn(e, s))
        k = sys%el_off(s) + e
        sys%me(:, :, k) = beam_mass(sys%prop(2, s), le)
        sys%ke(:, :, k) = beam_stiffness(sys%prop(3, s), sys%prop(4, s), le)
      end do
    end do
    sys%kl = 0
    do s = 1, ns
      nl = 3*sys%n_el(s) + 3
      lo = huge(1); hi = 0
      do i = 1, nl
        f = sys%free_of(sys%ld(i, s))
        if (f > 0) then
          lo = min(lo, f); hi = max(hi, f)
        end if
      end do
      if (hi > 0) sys%kl = max(sys%kl, hi - lo)
    end do
    sys%ku = sys%kl
    status = STATUS_OK
  end subroutine coupled_build

  !> The Gram matrix G = int psi psi^T dm of every element (see sys%gram6): the distributed mass by
  !> the 4-point Gauss rule (exact: degree 6) and the point masses; its phi part (sys%gram).
  subroutine gram_matrices(sys)
    type(coupled_system), intent(inout) :: sys
    integer :: s, k, i, e
    allocate (sys%gram6(6, 6, sum(sys%n_el)))
    sys%gram6 = 0.0_dp
    do s = 1, sys%nseg
      do e = 1, sys%n_el(s)
        do k = 1, 4
          call add_point(s, e, gx(k), gw(k)*sys%prop(2, s)*element_length(s, e))
        end do
      end do
    end do
    do i = 1, sys%npm
      call add_point(sys%pm_seg(i), sys%pm_el(i), sys%pm_prop(1, i), sys%pm_prop(2, i))
    end do
    allocate (sys%gram(4, 4, sys%nseg))
    sys%gram = 0.0_dp
    do s = 1, sys%nseg
      if (sys%n_el(s) == 1) sys%gram(:, :, s) = sys%gram6([1, 2, 4, 6], [1, 2, 4, 6], sys%el_off(s) + 1)
    end do
  contains
    pure real(dp) function element_length(s, e)
      integer, intent(in) :: s, e
      element_length = sys%prop(1, s)*(sys%wn(e + 1, s) - sys%wn(e, s))
    end function element_length

    subroutine add_point(s, e, xi, dm)
      integer, intent(in) :: s, e
      real(dp), intent(in) :: xi, dm
      real(dp) :: nm(2, 6), ps(6)
      integer :: j
      nm = shape_fn(xi, element_length(s, e))
      ps = [nm(1, 1), nm(1, 4), nm(2, 2), nm(2, 3), nm(2, 5), nm(2, 6)]
      do j = 1, 6
        sys%gram6(:, j, sys%el_off(s) + e) = sys%gram6(:, j, sys%el_off(s) + e) + dm*ps*ps(j)
      end do
    end subroutine add_point
  end subroutine gram_matrices

  !> Inertia and gravity of a one-element segment in closed form (docs/theory.md section 12.3),
  !> local DOFs [xs, ys, xe, ye, th_0, th_1].  Its velocity r', acceleration r'' and the columns of
  !> J = dr'/dq' (and of dr''/dv, dr''/dq) are fields X(xi) = sum_a phi_a(xi) X_a over phi = [1 - xi,
  !> xi, N_0, N_1] (N_0, N_1 the transverse Hermite shapes of th_0, th_1; the elastic field is
  !> w = N_0 th_0 + N_1 th_1 along e2), so every integral of mass_point is a form in the segment's
  !> Gram matrix G (sys%gram, the phi part of gram6): the same residual, energies, S blocks and angle-column
  !> sums as mass_point summed over the Gauss points and point masses, without a loop over points.
  subroutine element_inertia(sys, l, q, v, a, want, cc, ck, r, lm, ekin, epot, msum, csum)
    type(coupled_system), intent(in) :: sys
    integer, intent(in) :: l
    real(dp), intent(in) :: q(:), v(:), a(:), cc, ck
    logical, intent(in) :: want
    real(dp), intent(inout) :: r(:), ekin, epot
    real(dp), intent(inout), optional :: msum(:), csum(:)
    type(link_mats), intent(inout) :: lm
    real(dp) :: cs, sn, ell, g(2), om, al0, al, e1(2), e2(2), w(4), wd(4), wdd(4), c(2), cdot(2), w0(2)
    real(dp) :: gm(4, 4), acc(2, 4), vel(2, 4), jf(2, 4, 6), gj(2, 4, 6), bv(2, 4, 6), bf(2, 4, 6), blk(6, 6)
    real(dp) :: acj(2, 4), ga(2, 4), gv(2, 4), s1, s6(6, 6)
    integer :: i, j, b
    gm = sys%gram(:, :, l)
    call chord(q, v, a, cs, sn, ell, g, om, al0, al)
    e1 = [cs, sn]; e2 = [-sn, cs]
    w = [0.0_dp, 0.0_dp, q(5), q(6)]; wd = [0.0_dp, 0.0_dp, v(5), v(6)]; wdd = [0.0_dp, 0.0_dp, a(5), a(6)]
    vel(:, 1) = v(1:2); vel(:, 2) = v(3:4)
    acc(:, 1) = a(1:2) - sys%grav; acc(:, 2) = a(3:4) - sys%grav        ! gravity: 1 = phi_1 + phi_2
    do b = 3, 4
      vel(:, b) = -om*w(b)*e1 + wd(b)*e2
      acc(:, b) = -(al*w(b) + 2.0_dp*om*wd(b))*e1 + (wdd(b) - om*om*w(b))*e2
    end do
    ga = matmul(acc, gm); gv = matmul(vel, gm)     ! (G r'')_a and (G r')_a, 2 x 4
    ekin = ekin + 0.5_dp*sum(gv*vel)
    epot = epot - sum((gm(1, :) + gm(2, :))*[dot_product(sys%grav, q(1:2)), dot_product(sys%grav, q(3:4)), &
                                             w(3)*dot_product(sys%grav, e2), w(4)*dot_product(sys%grav, e2)])
    ! R_j = sum_a J_a,j . (G r'')_a over the nonzero columns of J (see jf below)
    s1 = w(3)*dot_product(e1, ga(:, 3)) + w(4)*dot_product(e1, ga(:, 4))
    r(1:2) = r(1:2) + ga(:, 1) + s1*g
    r(3:4) = r(3:4) + ga(:, 2) - s1*g
    r(5) = r(5) + dot_product(e2, ga(:, 3))
    r(6) = r(6) + dot_product(e2, ga(:, 4))
    if (.not. want) return
    jf = 0.0_dp                               ! J = dr'/dq' by columns
    do j = 1, 2
      jf(j, 1, j) = 1.0_dp; jf(j, 2, 2 + j) = 1.0_dp
      do b = 3, 4
        jf(:, b, j) = w(b)*g(j)*e1
        jf(:, b, 2 + j) = -w(b)*g(j)*e1
      end do
    end do
    jf(:, 3, 5) = e2; jf(:, 4, 6) = e2
    do j = 1, 6                               ! gj = G J (G symmetric)
      do b = 1, 4
        gj(:, b, j) = matmul(jf(:, :, j), gm(:, b))
      end do
    end do
    c = q(3:4) - q(1:2); cdot = v(3:4) - v(1:2)
    w0 = -(2.0_dp/ell**2)*(om*c + (c(1)*cdot(1) + c(2)*cdot(2))*g)
    bv = 0.0_dp                               ! dr''/dv by columns
    do j = 1, 2
      acj = 0.0_dp
      do b = 3, 4
        acj(:, b) = -w(b)*w0(j)*e1 + (-2.0_dp*om*w(b)*e2 - 2.0_dp*wd(b)*e1)*g(j)
      end do
      bv(:, :, j) = -acj; bv(:, :, 2 + j) = acj
    end do
    bv(:, 3, 5) = -2.0_dp*om*e1; bv(:, 4, 6) = -2.0_dp*om*e1
    bf = jf + cc*bv                           ! + ck dr''/dq at fixed chord (the angle columns only)
    bf(:, 3, 5) = bf(:, 3, 5) + ck*(-al*e1 - om*om*e2)
    bf(:, 4, 6) = bf(:, 4, 6) + ck*(-al*e1 - om*om*e2)
    do j = 1, 6
      do i = 1, 6
        blk(i, j) = sum(gj(:, :, i)*bf(:, :, j))
      end do
    end do
    call lm_block_get(lm, l, s6)
    call lm_block_put(lm, l, s6 + blk)
    if (.not. present(msum)) return
    do i = 1, 6
      msum(i) = msum(i) + sum(gj(:, :, i)*(jf(:, :, 5) + jf(:, :, 6)))
      csum(i) = csum(i) + sum(gj(:, :, i)*(bv(:, :, 5) + bv(:, :, 6)))
    end do
  end subroutine element_inertia

  !> State of marker m at the all-DOF state (q, v) (flexmech_markers).
  pure subroutine get_marker(sys, m, q, v, ms)
    type(coupled_system), intent(in) :: sys
    integer, intent(in) :: m
    real(dp), intent(in) :: q(:), v(:)
    type(marker_state), intent(out) :: ms
    integer :: s, n, b
    select case (sys%mk_kind(m))
    case (MK_NODE)
      s = sys%mk_idx(m); n = sys%n_el(s)
      call segment_marker(q, v, sys%ld(1:3*n + 3, s), n, sys%mk_node(m), sys%wn(sys%mk_node(m) + 1, s), &
                          sys%absang(s) /= 0, ms)
    case (MK_BODY)
      b = sys%mk_idx(m)
      call body_marker(q(sys%rb_dof(:, b)), v(sys%rb_dof(:, b)), sys%rb_dof(:, b), sys%mk_pos(:, m), ms)
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
  !> law's generalized force tau(theta, t) [N m or N].
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
  end subroutine drive_load

  pure real(dp) function wrap(x)
    real(dp), intent(in) :: x
    real(dp), parameter :: twopi = 6.283185307179586_dp
    wrap = x - twopi*anint(x/twopi)     ! the principal value (-pi, pi], up to the end point
  end function wrap

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

  !> Residual, kinetic and gravity energy of the inertia of element e of a longer segment l in
  !> closed form (what mass_point gives summed over the element's Gauss points and point masses):
  !> over psi = [1 - xi, xi, H_v0, H_th0, H_v1, H_th1] every field of mass_point is sum_a psi_a X_a,
  !> with (1 - w) = (1 - w_0) psi_1 + (1 - w_1) psi_2, w = w_0 psi_1 + w_1 psi_2 (w_0, w_1 the element's
  !> node fractions) and R u = sum_a psi_a U_a (U_1 = p_0 e1, U_2 = p_1 e1, U_3 = v_0 e2, U_4 = th_0 e2,
  !> U_5 = v_1 e2, U_6 = th_1 e2), so R_j = sum_a J_a,j . (G r'')_a with G = sys%gram6 (docs/theory.md
  !> section 12.3).  Local DOFs of the segment as in link_eval_rel.
  subroutine element_inertia_residual(sys, l, e, q, v, a, r, ekin, epot)
    type(coupled_system), intent(in) :: sys
    integer, intent(in) :: l, e
    real(dp), intent(in) :: q(:), v(:), a(:)
    real(dp), intent(inout) :: r(:), ekin, epot
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
  end subroutine element_inertia_residual

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
    real(dp) :: jth(2), bth(2)
    real(dp) :: cs, sn, ell, g(2), om, al0, al, nm(2, 6), de(6), dv(6), da(6)
    real(dp) :: ul(2), uld(2), uldd(2), rot(2, 2), ru(2), rou(2), roud(2), rd(2), rdd(2)
    real(dp) :: jac(2, 10), bv(2, 10), bq(2, 10), ac(2, 2), w0(2), cdot(2), c(2), rn(2), bc(2), blk(10, 10)
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
  end subroutine mass_point

  !> Residual (local vector of length nld), energies and, if want, the blocks of segment l of the
  !> iteration matrix S = M + ccv C_v + ckt K_t (added to lm, which the caller has zeroed).
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
    real(dp) :: cs, sn, ell, g(2), om, al0, al, phi, sr, c(2), l2, h(2, 2), s6(6, 6)
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
    c = q(3:4) - q(1:2)
    l2 = c(1)**2 + c(2)**2
    h(1, 1) = 2.0_dp*c(1)*c(2)/l2**2; h(1, 2) = (c(2)**2 - c(1)**2)/l2**2    ! d2 phi / dc2
    h(2, 1) = h(1, 2); h(2, 2) = -h(1, 1)
    call lm_block_get(lm, l, s6)
    call angle_rate_terms(s6, c, v(3:4) - v(1:2), a(3:4) - a(1:2), g, om, h, ccv, ckt, msum, csum)
    call angle_transform(s6, it(1:n + 1), [g(1), g(2), -g(1), -g(2)])
    h = ckt*sr*h
    s6(1:2, 1:2) = s6(1:2, 1:2) - h; s6(3:4, 3:4) = s6(3:4, 3:4) - h
    s6(1:2, 3:4) = s6(1:2, 3:4) + h; s6(3:4, 1:2) = s6(3:4, 1:2) + h
    call lm_block_put(lm, l, s6)
  end subroutine link_eval

  !> The parts of S from the chord terms of the relative angle rates th' = psi' - omega(c, c') and
  !> th'' = psi'' - alpha(c, c', c''), as columns of the end positions (before angle_transform):
  !> S(:, rs) += msum (ccv w0 + ckt da) + csum ckt H c', S(:, re) -= the same, with w0 = d alpha0/dc',
  !> da = d alpha/dc = H c'' + d alpha0/dc, H = d2 phi/dc2 and msum, csum the sums of the angle columns
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
  !> DOFs th(:): the change from chord-relative to absolute node angles (see link_eval).
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

  !> The 6 x 6 block of one-element segment l (local DOFs [xs ys xe ye th_0 th_1]) out of its
  !> storage in lm, and back (lm_block_put), for dense work on it.
  pure subroutine lm_block_get(lm, l, s6)
    type(link_mats), intent(in) :: lm
    integer, intent(in) :: l
    real(dp), intent(out) :: s6(6, 6)
    integer :: o, d, i, j
    o = lm%off(l); d = 2*lm%kbi + 1
    s6(1:4, 1:4) = lm%bb(:, :, l)
    s6(1:4, 5:6) = lm%bi(1:4, o + 1:o + 2)
    s6(5:6, 1:4) = lm%ib(o + 1:o + 2, 1:4)
    do j = 5, 6
      do i = 5, 6
        s6(i, j) = lm%ai(d + i - j, o + j - 4)
      end do
    end do
  end subroutine lm_block_get

  pure subroutine lm_block_put(lm, l, s6)
    type(link_mats), intent(inout) :: lm
    integer, intent(in) :: l
    real(dp), intent(in) :: s6(6, 6)
    integer :: o, d, i, j
    o = lm%off(l); d = 2*lm%kbi + 1
    lm%bb(:, :, l) = s6(1:4, 1:4)
    lm%bi(1:4, o + 1:o + 2) = s6(1:4, 5:6)
    lm%ib(o + 1:o + 2, 1:4) = s6(5:6, 1:4)
    do j = 5, 6
      do i = 5, 6
        lm%ai(d + i - j, o + j - 4) = s6(i, j)
      end do
    end do
  end subroutine lm_block_put

  !> link_eval in chord-relative angles (the coupled model's segments).
  subroutine link_eval_rel(sys, l, q, v, a, want, ccv, ckt, r, lm, ekin, epot, msum, csum)
    type(coupled_system), intent(in) :: sys
    integer, intent(in) :: l
    real(dp), intent(in) :: q(:), v(:), a(:), ccv, ckt
    logical, intent(in) :: want
    real(dp), intent(out) :: r(:), ekin, epot
    real(dp), intent(out), optional :: msum(:), csum(:)   !< (nl) sums of the angle columns of M and C_v (if want)
    type(link_mats), intent(inout) :: lm
    integer :: n, nl, e
    real(dp) :: cs, sn, ell, g(2), om, al0, al
    n = sys%n_el(l); nl = 3*n + 3
    r(1:nl) = 0.0_dp; ekin = 0.0_dp; epot = 0.0_dp
    if (present(msum)) then
      msum(1:nl) = 0.0_dp; csum(1:nl) = 0.0_dp
    end if
    if (n == 1 .and. inertia_mode == INERTIA_CLOSED) then      ! one element: closed form
      call element_inertia(sys, l, q, v, a, want, ccv, ckt, r, lm, ekin, epot, msum, csum)
    else if (.not. want .and. inertia_mode == INERTIA_CLOSED) then   ! the residual alone
      do e = 1, n
        call element_inertia_residual(sys, l, e, q, v, a, r, ekin, epot)
      end do
    else
      call gauss_inertia(sys, l, q, v, a, want, ccv, ckt, r, lm, ekin, epot, msum, csum)
    end if
    call chord(q, v, a, cs, sn, ell, g, om, al0, al)
    call rotary_inertias(sys, l, q, v, a, want, ccv, ell, g, om, al, r, lm, ekin, msum)
    call axial_strain(sys, l, q, ell, want, ckt, r, lm, epot)
    call bending_forces(sys, l, q, v, want, ccv, ckt, r, lm, epot, csum)
  end subroutine link_eval_rel

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

  !> Axial strain energy of segment l, U = 1/2 EA L eps^2 [J], its residual and (if want) ckt times its
  !> stiffness. eps = (|c| - L)/L, c = re - rs the chord [m], L the segment's length; for a shallow-arch
  !> segment (sys%arch, one element) eps also holds the element's mean w'^2/2 from its chord-relative
  !> end angles th = (th_0, th_1) [rad]: eps += th^T A th / 60, A = [4 -1; -1 4] (docs/theory.md 12.4).
  !> Local DOFs: 1:4 = (xs, ys, xe, ye) [m], 5:6 = (th_0, th_1) for a one-element segment.
  subroutine axial_strain(sys, l, q, ell, want, ckt, r, lm, epot)
    type(coupled_system), intent(in) :: sys
    integer, intent(in) :: l
    real(dp), intent(in) :: q(:), ell, ckt
    logical, intent(in) :: want
    real(dp), intent(inout) :: r(:), epot
    type(link_mats), intent(inout) :: lm
    real(dp) :: len, ea, c(2), u(2), eps, f, cc(2, 2), th(2), ath(2)
    integer :: i, j
    len = sys%prop(1, l); ea = sys%prop(3, l)
    c = q(3:4) - q(1:2); u = c/ell
    eps = (ell - len)/len
    ath = 0.0_dp
    if (sys%arch(l) == 1) then
      th = q(5:6)
      ath = [4.0_dp*th(1) - th(2), 4.0_dp*th(2) - th(1)]/30.0_dp     ! d eps / d th
      eps = eps + 0.5_dp*dot_product(th, ath)
    end if
    f = ea*eps                               ! axial force [N]
    r(1:2) = r(1:2) - f*u
    r(3:4) = r(3:4) + f*u
    if (sys%arch(l) == 1) r(5:6) = r(5:6) + f*len*ath
    epot = epot + 0.5_dp*ea*len*eps**2
    if (.not. want) return
    cc(:, 1) = u*u(1); cc(:, 2) = u*u(2)
    cc = ckt*(ea/len*cc - f/ell*cc)
    cc(1, 1) = cc(1, 1) + ckt*f/ell; cc(2, 2) = cc(2, 2) + ckt*f/ell
    lm%bb(1:2, 1:2, l) = lm%bb(1:2, 1:2, l) + cc; lm%bb(3:4, 3:4, l) = lm%bb(3:4, 3:4, l) + cc
    lm%bb(1:2, 3:4, l) = lm%bb(1:2, 3:4, l) - cc; lm%bb(3:4, 1:2, l) = lm%bb(3:4, 1:2, l) - cc
    if (sys%arch(l) == 0) return
    do j = 1, 2
      do i = 1, 2        ! d2U/d(re) d(th) = EA u ath^T, the start with the opposite sign
        call lm_add(lm, l, 2 + i, 4 + j, ckt*ea*u(i)*ath(j))
        call lm_add(lm, l, 4 + j, 2 + i, ckt*ea*u(i)*ath(j))
        call lm_add(lm, l, i, 4 + j, -ckt*ea*u(i)*ath(j))
        call lm_add(lm, l, 4 + j, i, -ckt*ea*u(i)*ath(j))
      end do
    end do
    do j = 1, 2          ! d2U/dth2 = EA L ath ath^T + f L A / 30
      do i = 1, 2
        call lm_add(lm, l, 4 + i, 4 + j, ckt*(ea*len*ath(i)*ath(j) + f*len*merge(4.0_dp, -1.0_dp, i == j)/30.0_dp))
      end do
    end do
  end subroutine axial_strain

  !> Position of th_k (node k = 0..n) in the link vector.
  pure integer function th_index(n, k)
    integer, intent(in) :: n, k
    if (k >= n) then
      th_index = 3*n + 3
    else
      th_index = 3*k + 5
    end if
  end function th_index

  !> Assemble the global residual R (all DOFs) at time t and, if want, the iteration matrix
  !> S = M + cc*C_v + ck*K_t over the free DOFs (segment blocks and the rigid bodies' diagonal, in lm).
  !> R holds the inertia, elastic, damping, gravity and force-drive terms (not the constraint forces).
  !> Returns energies [kinetic, potential (strain + gravity)].
  subroutine assemble(sys, q, v, a, t, want, cc, ck, res, lm, energy)
    type(coupled_system), intent(in) :: sys
    real(dp), intent(in) :: q(:), v(:), a(:), t, cc, ck
    logical, intent(in) :: want
    real(dp), intent(out) :: res(:), energy(2)
    type(link_mats), intent(inout) :: lm
    integer :: l, nl, i, j
    real(dp) :: ek, ep
    res = 0.0_dp
    energy = 0.0_dp
    if (want) then
      lm%bb = 0.0_dp; lm%bi = 0.0_dp; lm%ib = 0.0_dp; lm%ai = 0.0_dp; lm%dg = 0.0_dp
    end if
    do l = 1, sys%nseg
      nl = 3*sys%n_el(l) + 3
      do i = 1, nl          ! explicit loops: vector-subscripted sections copy through the heap
        j = sys%ld(i, l)
        lm%widx(i) = j
        lm%wl(i, 2) = q(j); lm%wl(i, 3) = v(j); lm%wl(i, 4) = a(j)
      end do
      call link_eval(sys, l, lm%wl(1:nl, 2), lm%wl(1:nl, 3), lm%wl(1:nl, 4), want, cc, ck, lm%wl(:, 1), lm, ek, ep)
      do i = 1, nl
        j = lm%widx(i)
        res(j) = res(j) + lm%wl(i, 1)
      end do
      energy = energy + [ek, ep]
    end do
    call bodies_eval(sys, q, v, a, want, res, lm, energy)
    call drive_loads(sys, q, v, t, res)
  end subroutine assemble

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

  !> Dense residual (all DOFs, without constraint forces), iteration-matrix parts over the free DOFs and
  !> energies at one state and time t (for tests and analysis): mm = M, cm = C_v, km = K_t,
  !> energy = [kinetic, potential].  A rigid body's diagonal in mm is [m, m, J_S].
  subroutine coupled_dense(sys, q, v, a, t, res, mm, cm, km, energy)
    type(coupled_system), intent(in) :: sys
    real(dp), intent(in) :: q(:), v(:), a(:), t
    real(dp), intent(out) :: res(:), mm(:, :), cm(:, :), km(:, :), energy(2)
    real(dp), allocatable :: ab(:, :)
    type(link_mats) :: lm
    call lm_setup(sys, 1, lm)
    allocate (ab(band_rows(sys%kl, sys%ku), sys%nfree))
    call assemble(sys, q, v, a, t, .true., 0.0_dp, 0.0_dp, res, lm, energy)
    call lm_to_band(sys, lm, ab)
    mm = band_to_dense(ab, sys%kl, sys%ku, sys%nfree)
    call assemble(sys, q, v, a, t, .true., 1.0_dp, 0.0_dp, res, lm, energy)
    call lm_to_band(sys, lm, ab)
    cm = band_to_dense(ab, sys%kl, sys%ku, sys%nfree) - mm
    call assemble(sys, q, v, a, t, .true., 0.0_dp, 1.0_dp, res, lm, energy)
    call lm_to_band(sys, lm, ab)
    km = band_to_dense(ab, sys%kl, sys%ku, sys%nfree) - mm
  end subroutine coupled_dense

  !> Residual res (all DOFs: inertia, elastic, damping, gravity and force drives, no constraint forces)
  !> at each of ns states (q(:, s), v, a) at time t [s] (modal analysis: its derivatives by differences).
  subroutine coupled_residual(sys, q, v, a, t, res)
    type(coupled_system), intent(in) :: sys
    real(dp), intent(in) :: q(:, :), v(:), a(:), t
    real(dp), intent(out) :: res(:, :)
    type(link_mats) :: lm
    real(dp) :: energy(2)
    integer :: s
    call lm_setup(sys, 1, lm)
    do s = 1, size(q, 2)
      call assemble(sys, q(:, s), v, a, t, .false., 0.0_dp, 0.0_dp, res(:, s), lm, energy)
    end do
  end subroutine coupled_residual

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

  !> Select the linear solver of coupled_run (SOLVER_AUTO, SOLVER_BAND or SOLVER_CONDENSED;
  !> module-wide, for tests and benchmarks).  status = STATUS_BAD_INPUT for another value.
  subroutine coupled_set_solver(mode, status)
    integer, intent(in) :: mode
    integer, intent(out) :: status
    call set_mode(mode, SOLVER_AUTO, SOLVER_CONDENSED, solver_mode, status)
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
    allocate (lm%off(sys%nseg), lm%bfree(4, sys%nseg), lm%widx(sys%maxld), lm%wl(sys%maxld, 4))
    lm%ni = 0; lm%kbi = 0
    do l = 1, sys%nseg
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
    allocate (lm%bb(4, 4, sys%nseg), lm%bi(4, lm%ni), lm%ib(lm%ni, 4), lm%ai(lm%ldi, lm%ni), lm%ifree(lm%ni))
    allocate (cnt(sys%nfree), isb(sys%nfree), bnum(sys%nfree))
    cnt = 0; isb = .false.
    lm%cond = .true.
    do l = 1, sys%nseg
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
    do l = 1, sys%nrb        ! rigid-body DOFs: boundary DOFs with a diagonal block
      do k = 1, 3
        f = sys%free_of(sys%rb_dof(k, l))
        if (f > 0) isb(f) = .true.
      end do
    end do
    allocate (lm%dg(sys%nfree))
    lm%dg = 0.0_dp
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
    do l = 1, sys%nseg
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
  !> free DOFs (and the rigid bodies' diagonal): the reference solve and coupled_dense.
  subroutine lm_to_band(sys, lm, ab)
    type(coupled_system), intent(in) :: sys
    type(link_mats), intent(in) :: lm
    real(dp), intent(out) :: ab(:, :)
    integer :: l, nl, m, o, i, j, ii, jj, fi, fj, d
    ab = 0.0_dp
    d = sys%kl + sys%ku + 1
    do l = 1, sys%nseg
      nl = 3*sys%n_el(l) + 3; m = nl - 4; o = lm%off(l)
      do j = 1, 4
        fj = sys%free_of(sys%ld(j, l))
        if (fj == 0) cycle
        do i = 1, 4
          fi = sys%free_of(sys%ld(i, l))
          if (fi > 0) ab(d + fi - fj, fj) = ab(d + fi - fj, fj) + lm%bb(i, j, l)
        end do
        do ii = 1, m
          fi = sys%free_of(sys%ld(4 + ii, l))
          if (fi > 0) ab(d + fi - fj, fj) = ab(d + fi - fj, fj) + lm%ib(o + ii, j)
        end do
      end do
      do jj = 1, m
        fj = sys%free_of(sys%ld(4 + jj, l))
        if (fj == 0) cycle
        do i = 1, 4
          fi = sys%free_of(sys%ld(i, l))
          if (fi > 0) ab(d + fi - fj, fj) = ab(d + fi - fj, fj) + lm%bi(i, o + jj)
        end do
        do ii = max(1, jj - lm%kbi), min(m, jj + lm%kbi)
          fi = sys%free_of(sys%ld(4 + ii, l))
          if (fi > 0) ab(d + fi - fj, fj) = ab(d + fi - fj, fj) + lm%ai(2*lm%kbi + 1 + ii - jj, o + jj)
        end do
      end do
    end do
    do fi = 1, sys%nfree
      ab(d, fi) = ab(d, fi) + lm%dg(fi)
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
    do l = 1, sys%nseg
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
    do bi = 1, lm%nb
      lm%sb(d, bi) = lm%sb(d, bi) + lm%dg(lm%bglob(bi))
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
    do l = 1, sys%nseg
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
    do l = 1, sys%nseg
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
    do while (s0 <= sys%nseg)
      l = seg_link(s0)
      s1 = s0
      do while (s1 < sys%nseg)
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
  !> q, v, a: (ndof) all-DOF state, fixed entries hold their values.  Constraint rows (sys%nc):
  !> g_i(q) = cval(1, i, k) at step k (angles wrapped to the principal value), enforced at the position
  !> level with Lagrange multipliers lam (the constraint forces: the residual holds G^T lam).
  !> t0: time of the first step [s] (the force laws depend on time); nsteps = size(cval, 3) - 1.
  !> start selects how the run begins:
  !>   1  a fresh run: a (true acceleration) and the multipliers made consistent with the equations and
  !>      constraints at t0, p (pseudo-acceleration) = a, no work done yet;
  !>   0  as 1 but p as given;
  !>   2  the continuation of a run (docs/theory.md section 11.7): q, v, a, p and carry as a run left
  !>      them, so the steps are the ones an uninterrupted run takes.
  !> carry(nc1 + 2) = [multipliers (nc1), Newton length scale lref [m], work of the inputs [J]]: read
  !> when start = 2, on return the state reached (like q, v, a, p).
  !> Frames at steps 0, out_every, ...: qf, vf, af (ndof, nframes), lf (nc, nframes) multipliers,
  !> ef(4, nframes) = [kinetic, potential (strain + gravity), work of the inputs (force drives and
  !> moving constraint rows), max Newton iterations since the last frame]; nvalid frames are valid.
  !> Divergence guard: coupled_elastic_measure > div_limit [m] after a step stops the run with
  !> STATUS_DIVERGED (fail_step = that step).  newton(4) on return: [norm of the residual (free DOFs,
  !> with the constraint forces) before the last iteration, norm of its acceleration correction, norm
  !> of the accelerations, number of factorizations of the iteration matrix].
  subroutine coupled_run(sys, cval, t0, dt, alpha_m, alpha_f, beta, gamma, out_every, tol, maxit, &
                         start, div_limit, seg_link, q, v, a, p, carry, qf, vf, af, lf, ef, status, fail_step, &
                         iters, nvalid, newton)
    type(coupled_system), intent(in) :: sys
    real(dp), intent(in) :: cval(:, :, :)        !< (3, >= nc, nsteps+1) [value, rate, acceleration] of the rows
    real(dp), intent(in) :: t0, dt, tol
    real(dp), intent(in) :: alpha_m, alpha_f, beta, gamma   !< generalized-alpha parameters
    integer, intent(in) :: out_every, maxit, start
    real(dp), intent(in) :: div_limit              !< divergence limit [m]
    integer, intent(in) :: seg_link(:)             !< (nseg) link of each segment
    real(dp), intent(inout) :: q(:), v(:), a(:), p(:)
    real(dp), intent(inout) :: carry(:)            !< (nc1 + 2) [multipliers, lref [m], work [J]]
    real(dp), intent(out) :: qf(:, :), vf(:, :), af(:, :), lf(:, :), ef(:, :)
    integer, intent(out) :: status, fail_step, iters, nvalid
    real(dp), intent(out) :: newton(4)
    real(dp), allocatable :: ab(:, :), res(:), qs(:), vs(:), rf(:), w(:), gt(:, :), x(:, :), amat(:, :)
    real(dp), allocatable :: qn(:), lamn(:), lam(:), dlam(:), gval(:), acc0(:), g0(:), lam0(:), th0(:), tau0(:), gsh(:)
    integer, allocatable :: ipiv(:), freeidx(:), ipc(:), gnz(:, :), ngnz(:)
    integer :: nsteps, n, it, frame, info, itmax_frame, nf, nc, kat
    real(dp) :: energy(2), work, da_norm, a_norm, da_prev, c1, betap, gammap, lref, t
    logical :: converged, refactor, use_cond, refresh, second
    type(link_mats) :: lm
    status = STATUS_OK; fail_step = 0; iters = 0; nvalid = 0; newton = 0.0_dp
    nsteps = size(cval, 3) - 1
    nf = sys%nfree
    nc = sys%nc
    refactor = .false.
    if (out_every < 1 .or. dt <= 0.0_dp .or. nsteps < 0 .or. size(qf, 2) /= nsteps/out_every + 1 .or. &
        size(cval, 2) < nc .or. size(lf, 1) < nc .or. beta <= 0.0_dp .or. gamma < 0.5_dp .or. &
        alpha_m >= 1.0_dp .or. alpha_f >= 1.0_dp .or. .not. div_limit > 0.0_dp .or. &
        size(seg_link) /= sys%nseg .or. size(p) /= sys%ndof .or. size(carry) < max(1, nc) + 2 .or. &
        start < 0 .or. start > 2) then
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
    if (start == 2) lref = carry(size(carry) - 1)
    gammap = gamma*(1.0_dp - alpha_f)*c1
    call setup_work()
    if (start == 2) then
      lam = 0.0_dp
      lam(1:nc) = carry(1:nc)
      work = carry(size(carry))
      call assemble(sys, q, v, a, t0, .false., 0.0_dp, 0.0_dp, res, lm, energy)
    else
      call initial_acceleration()
      if (status /= STATUS_OK) return
      if (start == 1) p = a
      work = 0.0_dp
    end if
    call drive_state(t0, th0, tau0)
    call row_values(g0)
    lam0 = lam
    frame = 1
    qf(:, 1) = q; vf(:, 1) = v; af(:, 1) = a; lf(1:nc, 1) = lam(1:nc)
    ef(:, 1) = [energy(1), energy(2), work, 0.0_dp]
    nvalid = 1
    call save_carry()
    itmax_frame = 0
    do n = 1, nsteps
      t = t0 + n*dt
      w(freeidx) = alpha_f*a(freeidx) - alpha_m*p(freeidx)     ! zero for Newmark
      qs = q + dt*v + (dt*dt*(0.5_dp - beta))*p + (dt*dt*beta*c1)*w
      vs = v + (dt*(1.0_dp - gamma))*p + (dt*gamma*c1)*w
      call newton_iterations(n)
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
      call step_work(t)
      if (mod(n, out_every) == 0) then
        call assemble(sys, q, v, a, t, .false., 0.0_dp, 0.0_dp, res, lm, energy)
        frame = frame + 1
        qf(:, frame) = q; vf(:, frame) = v; af(:, frame) = a; lf(1:nc, frame) = lam(1:nc)
        ef(:, frame) = [energy(1), energy(2), work, real(itmax_frame, dp)]
        nvalid = frame
        itmax_frame = 0
      end if
    end do
    call save_carry()

  contains

    !> The band or condensed storage of S, the work arrays, the free-DOF index and the constraint
    !> gradients' nonzero pattern.
    subroutine setup_work()
      integer :: i
      call lm_setup(sys, nc, lm)
      use_cond = lm%cond .and. (solver_mode == SOLVER_CONDENSED .or. &
                                (solver_mode == SOLVER_AUTO .and. sys%kl > lm%kbi + 4))
      if (use_cond) then
        allocate (ab(1, 1))
      else
        allocate (ab(band_rows(sys%kl, sys%ku), nf))
      end if
      allocate (res(sys%ndof), qs(sys%ndof), vs(sys%ndof), rf(nf), ipiv(nf), w(sys%ndof), freeidx(nf), qn(sys%ndof))
      w = 0.0_dp
      allocate (gt(nf, max(1, nc)), x(nf, max(1, nc)), amat(max(1, nc), max(1, nc)), lam(max(1, nc)), &
                dlam(max(1, nc)), lamn(max(1, nc)), gval(max(1, nc)), acc0(max(1, nc)), g0(max(1, nc)), ipc(max(1, nc)), &
                lam0(max(1, nc)), gsh(max(1, nc)), gnz(2*MAXCOL, max(1, nc)), ngnz(max(1, nc)), th0(max(1, sys%nd)), &
                tau0(max(1, sys%nd)))
      gt = 0.0_dp
      do i = 1, sys%ndof
        if (sys%free_of(i) > 0) freeidx(sys%free_of(i)) = i
      end do
      call gradient_pattern()
    end subroutine setup_work

    !> The Newton iterations of step n (predictor qs, vs set): converged, it and the state at the
    !> accepted iterate; status on a failed factorization or solve.
    subroutine newton_iterations(n)
      integer, intent(in) :: n
      converged = .false.
      da_prev = huge(1.0_dp)
      refresh = .true.
      qn = q; lamn = lam
      second = .false.
      kat = 0
      if (start_mode == START_VELOCITY) a(freeidx) = (q(freeidx) + dt*v(freeidx) - qs(freeidx))/(betap*dt*dt)
      if (start_mode == START_POSITION) call restart_at_qn()
      do it = 1, merge(2*maxit, maxit, start_mode /= START_ACCELERATION)
        q(freeidx) = qs(freeidx) + (betap*dt*dt)*a(freeidx)
        v(freeidx) = vs(freeidx) + (gammap*dt)*a(freeidx)
        call assemble(sys, q, v, a, t, refresh, gammap*dt, betap*dt*dt, res, lm, energy)
        if (refresh) then
          call factor()
          if (status /= STATUS_OK) exit
        end if
        call constraints(n + 1)      ! gradients (matrix part only after a factorization), values, G^T lam in res
        if (status /= STATUS_OK) exit
        gsh(1:nc) = gval(1:nc)/(betap*dt*dt)
        call correction(gsh(1:nc))
        if (status /= STATUS_OK) exit
        iters = iters + 1
        kat = kat + 1                ! iterations of this attempt
        refresh = newton_mode == NEWTON_FULL .or. &
                  (newton_mode == NEWTON_AUTO .and. kat > 1 .and. da_norm > NEWTON_RATE*da_prev)
        if (it == 1 .and. start_mode == START_VELOCITY .and. betap*dt*dt*da_norm > RESTART_MOVE*lref) then
          ! the start q_n + dt v_n was far (an unresolved stiff mode's velocity): start again at q_n
          call restart_at_qn()
          refresh = .true.
          cycle
        end if
        if (accepted()) then
          converged = .true.
          exit
        end if
        da_prev = da_norm
        if (it == maxit .and. start_mode /= START_ACCELERATION) then
          ! not converged from the start: a second attempt of maxit iterations from q_n, the
          ! matrix rebuilt at every iteration
          call restart_at_qn()
          second = .true.
        end if
        refresh = refresh .or. second
      end do
    end subroutine newton_iterations

    !> One Newton correction at the assembled residual: solve S da = -R with the multipliers' Schur
    !> complement, whose right-hand side is G S^-1 (-R) + shift (shift (nc): the rows' residual in the
    !> units of G a), update a and lam; newton(1:3) = [|R|, |da|, |a|].
    subroutine correction(shift)
      real(dp), intent(in) :: shift(:)
      integer :: i
      rf = -res(freeidx)
      newton(1) = norm2(rf)
      call band_solve_rhs(rf)
      if (status /= STATUS_OK) return
      if (nc > 0) then   ! Schur complement on the multipliers
        do i = 1, nc
          dlam(i) = gdot(i, rf) + shift(i)
        end do
        call small_solve(dlam)
        if (status /= STATUS_OK) return
        do i = 1, nc
          rf = rf - x(:, i)*dlam(i)
        end do
        lam(1:nc) = lam(1:nc) + dlam(1:nc)
      end if
      a_norm = 0.0_dp
      do i = 1, nf         ! a loop: a(freeidx) = a(freeidx) + rf would copy through the heap
        a(freeidx(i)) = a(freeidx(i)) + rf(i)
        a_norm = a_norm + a(freeidx(i))**2
      end do
      da_norm = sqrt(sum(rf**2)); a_norm = sqrt(a_norm)
      newton(2:3) = [da_norm, a_norm]
    end subroutine correction

    !> Accept the iterate: the correction within tol of the accelerations (or the position correction
    !> below 1e-2 tol of the mechanism size), or stagnated at the round-off level of the residual (no
    !> further contraction while already within sqrt(tol): the stiff chord terms limit the attainable
    !> precision), or the error left after it, estimated from the contraction rate rho of the last two
    !> corrections (|a - a*| ~ rho/(1 - rho) |da|), within tol.
    logical function accepted()
      real(dp) :: rho
      rho = da_norm/da_prev
      accepted = da_norm <= tol*(a_norm + 1.0e-30) .or. betap*dt*dt*da_norm <= 1.0e-2_dp*tol*lref .or. &
                 (kat > 1 .and. rho < 0.5_dp .and. rho/(1.0_dp - rho)*da_norm <= tol*(a_norm + 1.0e-30)) .or. &
                 (kat > 1 .and. da_norm >= 0.5_dp*da_prev .and. da_norm <= sqrt(tol)*(a_norm + 1.0e-30))
    end function accepted

    !> Start the step's iteration (again) at the last step's position q_n and multipliers: the
    !> acceleration that puts q at qn, a fresh contraction history.
    subroutine restart_at_qn()
      lam = lamn
      a(freeidx) = (qn(freeidx) - qs(freeidx))/(betap*dt*dt)
      da_prev = huge(1.0_dp)
      kat = 0
    end subroutine restart_at_qn

    !> The state a continuation needs besides (q, v, a, p): multipliers, lref, work.
    subroutine save_carry()
      carry = 0.0_dp
      carry(1:nc) = lam(1:nc)
      carry(size(carry) - 1) = lref
      carry(size(carry)) = work
    end subroutine save_carry

    !> Free DOFs on which row ic's gradient can be nonzero (the columns of its two markers), without
    !> repetitions: gnz(1:ngnz(ic), ic).
    subroutine gradient_pattern()
      integer :: ic, k, f, ncl, cols(2*MAXCOL)
      real(dp) :: gv, gd, ac, grad(2*MAXCOL)
      type(marker_state) :: ma, mb
      ngnz = 0
      do ic = 1, nc
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
    end subroutine gradient_pattern

    !> Consistent initial acceleration and multipliers at t0: [M G; G^T 0] [a; lam] = [-R(q, v, 0);
    !> cval'' - acc0], by iterative refinement with S = M (a rigid body's J_S stands for a zero inertia
    !> in S; the refinement removes its effect).
    subroutine initial_acceleration()
      integer :: k, j
      real(dp) :: dn, an, dn_prev, shift(max(1, nc))
      dn_prev = huge(1.0_dp)
      a(freeidx) = 0.0_dp
      lam = 0.0_dp
      do k = 1, max(1, maxit)
        call assemble(sys, q, v, a, t0, k == 1, 0.0_dp, 0.0_dp, res, lm, energy)
        if (k == 1) then
          call factor()
          if (status /= STATUS_OK) return
        end if
        call constraints(1)
        if (status /= STATUS_OK) return
        do j = 1, nc        ! the rows' acceleration residual G a - (cval'' - acc0)
          shift(j) = gdot(j, a(freeidx)) - (cval(3, j, 1) - acc0(j))
        end do
        call correction(shift(1:nc))
        if (status /= STATUS_OK) return
        dn = da_norm; an = a_norm
        if (dn <= 1.0e-3_dp*tol*(an + 1.0e-30) .or. dn > 0.5_dp*dn_prev) exit   ! converged, or round-off
        dn_prev = dn
      end do
      call assemble(sys, q, v, a, t0, .false., 0.0_dp, 0.0_dp, res, lm, energy)
    end subroutine initial_acceleration

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

    !> Values of the rows (the constraint functions, not their errors).
    subroutine row_values(gv)
      real(dp), intent(out) :: gv(:)
      integer :: ic, ncl, cols(2*MAXCOL)
      real(dp) :: gd, ac, grad(2*MAXCOL)
      type(marker_state) :: ma, mb
      do ic = 1, nc
        if (sys%con(1, ic) == CON_POINT .or. sys%con(4, ic) /= 1) cycle   ! only moving rows do work
        call eval_row(sys, sys%con(1, ic), sys%con(4, ic), sys%con_dir(:, ic), sys%con(2, ic), sys%con(3, ic), &
                      q, v, gv(ic), gd, ac, ncl, cols, grad, ma, mb)
      end do
    end subroutine row_values

    !> Coordinates and generalized forces of the force drives at time tt.
    subroutine drive_state(tt, th, tau)
      real(dp), intent(in) :: tt
      real(dp), intent(out) :: th(:), tau(:)
      integer :: i2, ncl, cols(2*MAXCOL)
      real(dp) :: grad(2*MAXCOL)
      type(marker_state) :: ma, mb
      do i2 = 1, sys%nd
        call drive_load(sys, i2, q, v, tt, tau(i2), th(i2), ncl, cols, grad, ma, mb)
      end do
    end subroutine drive_state

    !> Work of the inputs over the step just taken, trapezoidal: force drives tau d theta, moving rows
    !> (kinematic drives, whose generalized force is -lam) -lam d g.
    subroutine step_work(tt)
      real(dp), intent(in) :: tt
      real(dp) :: th1(max(1, sys%nd)), tau1(max(1, sys%nd)), g1(max(1, nc)), dth
      integer :: i2
      call drive_state(tt, th1, tau1)
      do i2 = 1, sys%nd
        dth = th1(i2) - th0(i2)
        if (sys%dv(1, i2) == CON_ANGLE) dth = wrap(dth)
        work = work + 0.5_dp*(tau0(i2) + tau1(i2))*dth
      end do
      th0 = th1; tau0 = tau1
      call row_values(g1)
      do i2 = 1, nc
        if (sys%con(1, i2) == CON_POINT .or. sys%con(4, i2) /= 1) cycle
        dth = g1(i2) - g0(i2)
        if (sys%con(1, i2) == CON_ANGLE) dth = wrap(dth)
        work = work - 0.5_dp*(lam0(i2) + lam(i2))*dth
      end do
      g0 = g1
      lam0 = lam
    end subroutine step_work

    !> Constraint gradients (X = S^-1 G and the Schur matrix when S was just factorized), errors
    !> gval = g - cval (angles: principal value), velocity parts acc0 of g'', and G^T lam in res.
    subroutine constraints(k)
      integer, intent(in) :: k
      integer :: ic, j, f, ncl, cols(2*MAXCOL)
      real(dp) :: gv, gd, grad(2*MAXCOL)
      type(marker_state) :: ma, mb
      do ic = 1, nc
        call eval_row(sys, sys%con(1, ic), sys%con(4, ic), sys%con_dir(:, ic), sys%con(2, ic), sys%con(3, ic), &
                      q, v, gv, gd, acc0(ic), ncl, cols, grad, ma, mb)
        gval(ic) = gv - cval(1, ic, k)
        if (sys%con(1, ic) == CON_ANGLE) gval(ic) = wrap(gval(ic))
        do j = 1, ngnz(ic)
          gt(gnz(j, ic), ic) = 0.0_dp
        end do
        do j = 1, ncl
          res(cols(j)) = res(cols(j)) + lam(ic)*grad(j)
          f = sys%free_of(cols(j))
          if (f > 0) gt(f, ic) = gt(f, ic) + grad(j)
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
      newton(4) = newton(4) + 1.0_dp
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

end module flexmech_coupled
