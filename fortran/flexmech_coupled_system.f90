!> The system of the coupled and nonlinear models (one-pass model with mutual rigid-elastic coupling,
!> seed Section 3, Gibbs-Appell)
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
!> This module holds the system (coupled_build: from the flat description Python packs), the
!> elements' Gram matrices and the index helpers of a segment's local vector; the element kernels are
!> in flexmech_coupled_element, the iteration matrix's storage in flexmech_coupled_storage, the
!> assembly in flexmech_coupled_assembly, the time loop in flexmech_coupled_run (docs/theory.md 11-12).
module flexmech_coupled_system
  use flexmech_kinds, only: dp
  use flexmech_lapack, only: STATUS_OK, STATUS_BAD_INPUT
  use flexmech_beam, only: beam_mass, beam_stiffness
  use flexmech_markers, only: CON_POINT, con_valid
  use flexmech_assembly, only: half_bandwidth
  use flexmech_control, only: control_bank
  implicit none
  private
  public :: coupled_system, coupled_build, set_mode, wrap, elem_index, shape_fn, th_index
  public :: MK_GROUND, MK_NODE, MK_BODY, COUPLED_NSPEC_HEADER, NPAR, gx, gw

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
    integer :: npm = 0, nri = 0, nmk = 0, nc = 0, nd = 0, nh = 0, nth = 0, ntab = 0
    integer, allocatable :: n_el(:), ld(:, :), free_of(:), el_off(:), rb_dof(:, :)
    !> (nseg) 1: the segment's th DOFs are absolute node angles psi_k, shared with the neighbouring
    !> segments of its link (the nonlinear model, docs/theory.md section 12.1), 0: angles from the chord
    integer, allocatable :: absang(:)
    !> (nseg) 1: the segment is one co-rotational element whose axial strain holds its mean w'^2/2
    !> (shallow arch, the nonlinear model, docs/theory.md section 12.4), 0: the chord stretch alone
    integer, allocatable :: arch(:)
    !> the nonlinear model's bordered saddle band (flexmech_saddle_band, docs/theory.md section 12.6):
    !> nbd >= 0 the last nbd free DOFs are border DOFs, row_border(nc) /= 0 marks the border rows;
    !> nbd = -1: no such layout (the coupled model: its own solves, flexmech_coupled_storage)
    integer :: nbd = -1
    integer, allocatable :: row_border(:)
    !> (6, 6, total elements) per element: G = int psi psi^T dm over psi = [1 - xi, xi, H_v0, H_th0,
    !> H_v1, H_th1] (the shapes of shape_fn; distributed mass and point masses; long_element_inertia)
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
    type(control_bank) :: ctl                    !< feedback controllers adding to the force drives (none: n = 0)
  end type coupled_system

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

  !> Build the system from its flat description; status STATUS_BAD_INPUT on bad sizes or indices.
  !> ispec (integers, 1-based indices):
  !>   [nseg, nrb, ndof, maxn, npm, nri, nmk, nc, nd, nh, nth, ntab,
  !>    n_el(nseg), ld(3 maxn + 3, nseg), rb_dof(3, nrb), free_of(ndof), pm_seg(npm), pm_el(npm),
  !>    ri_seg(nri), ri_node(nri), mk_kind(nmk), mk_idx(nmk), mk_node(nmk), con(4, nc), dv(5, nd),
  !>    absang(nseg), arch(nseg), nbd, row_border(nc)]
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
    status = STATUS_BAD_INPUT
    if (.not. sizes_read(ispec, rspec, sys)) return
    call unpack_integers(ispec, sys)
    call unpack_reals(rspec, sys)
    if (.not. indices_valid(sys)) return
    call element_matrices(sys)
    sys%kl = band_half_width(sys)
    sys%ku = sys%kl
    status = STATUS_OK
  end subroutine coupled_build

  !> The header counts of ispec into sys; .false. when they are negative or do not match the lengths
  !> of ispec and rspec.
  logical function sizes_read(ispec, rspec, sys)
    integer, intent(in) :: ispec(:)
    real(dp), intent(in) :: rspec(:)
    type(coupled_system), intent(inout) :: sys
    integer :: ns, ml, ntab
    sizes_read = .false.
    if (size(ispec) < COUPLED_NSPEC_HEADER) return
    if (any(ispec(1:COUPLED_NSPEC_HEADER) < 0)) return
    sys%nseg = ispec(1); sys%nrb = ispec(2); sys%ndof = ispec(3); sys%maxn = ispec(4); sys%npm = ispec(5)
    sys%nri = ispec(6); sys%nmk = ispec(7); sys%nc = ispec(8); sys%nd = ispec(9); sys%nh = ispec(10)
    sys%nth = ispec(11); sys%ntab = ispec(12); ntab = sys%ntab
    ns = sys%nseg; ml = 3*sys%maxn + 3; sys%maxld = ml
    if (ns < 1 .or. sys%maxn < 1 .or. sys%ndof < 1) return
    if (size(ispec) /= COUPLED_NSPEC_HEADER + ns*(1 + ml) + 3*sys%nrb + sys%ndof + 2*sys%npm + 2*sys%nri &
        + 3*sys%nmk + 5*sys%nc + 5*sys%nd + 2*ns + 1) return
    if (size(rspec) /= ns*(4 + sys%maxn + 1) + 3*sys%nrb + 2*sys%npm + sys%nri + 2*sys%nmk + 2*sys%nc &
        + (2 + NPAR + 2*sys%nh + 3*sys%nth)*sys%nd + 5*ntab + 4) return
    sizes_read = .true.
  end function sizes_read

  !> The integer blocks of ispec (layout: coupled_build) into sys, whose counts sizes_read has set.
  subroutine unpack_integers(ispec, sys)
    integer, intent(in) :: ispec(:)
    type(coupled_system), intent(inout) :: sys
    integer :: o, ns, ml
    ns = sys%nseg; ml = sys%maxld
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
    sys%arch = ispec(o + 1:o + ns); o = o + ns
    sys%nbd = ispec(o + 1); o = o + 1
    sys%row_border = ispec(o + 1:o + sys%nc)
  end subroutine unpack_integers

  !> The real blocks of rspec (layout: coupled_build) into sys.
  subroutine unpack_reals(rspec, sys)
    real(dp), intent(in) :: rspec(:)
    type(coupled_system), intent(inout) :: sys
    integer :: o, ns, ntab
    ns = sys%nseg; ntab = sys%ntab
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
  end subroutine unpack_reals

  !> Every index in range (segments, elements, DOFs, bodies, markers, rows, drives, table knots) and
  !> the values that must be positive; sets sys%nfree.
  logical function indices_valid(sys)
    type(coupled_system), intent(inout) :: sys
    integer :: s, e, i, nl, ns, ntab
    indices_valid = .false.
    ns = sys%nseg; ntab = sys%ntab
    if (any(sys%n_el < 1) .or. any(sys%n_el > sys%maxn) .or. any(sys%free_of < 0)) return
    if (any(sys%absang < 0) .or. any(sys%absang > 1)) return
    if (any(sys%absang == 1 .and. sys%n_el /= 1)) return
    if (any(sys%arch < 0) .or. any(sys%arch > 1) .or. any(sys%arch == 1 .and. sys%n_el /= 1)) return
    sys%nfree = maxval([0, sys%free_of])
    if (sys%nfree < 1 .or. any(sys%prop <= 0.0_dp)) return
    if (sys%nbd < -1 .or. sys%nbd > sys%nfree .or. any(sys%row_border < 0) .or. any(sys%row_border > 1)) return
    if (sys%nbd >= 0 .and. sys%maxn /= 1) return      ! the bordered band holds one-element segments
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
      if (.not. con_valid(sys%con(1, i), sys%con(4, i))) return
      if (any(sys%con(2:3, i) < 1) .or. any(sys%con(2:3, i) > sys%nmk)) return
    end do
    do i = 1, sys%nd
      if (sys%dv(1, i) == CON_POINT .or. .not. con_valid(sys%dv(1, i), 0)) return   ! a coordinate row
      if (any(sys%dv(2:3, i) < 1) .or. any(sys%dv(2:3, i) > sys%nmk)) return
      if (sys%dv(5, i) > 0) then
        if (sys%dv(4, i) < 1 .or. sys%dv(4, i) + sys%dv(5, i) - 1 > ntab .or. sys%dv(5, i) < 2) return
      end if
    end do
    indices_valid = .true.
  end function indices_valid

  !> Per element: its offset, local mass and stiffness matrices and Gram matrix.
  subroutine element_matrices(sys)
    type(coupled_system), intent(inout) :: sys
    integer :: s, e, k, ns
    real(dp) :: le
    ns = sys%nseg
    ! element by element (segments may have elements of different lengths)
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
  end subroutine element_matrices

  !> Half bandwidth of the free-DOF matrix: the widest span of free-DOF numbers within one segment
  !> (flexmech_assembly: half_bandwidth over the segments' local vectors).
  integer function band_half_width(sys)
    type(coupled_system), intent(in) :: sys
    integer :: idx(sys%maxld, sys%nseg), s, nl
    idx = 0
    do s = 1, sys%nseg
      nl = 3*sys%n_el(s) + 3
      idx(1:nl, s) = sys%free_of(sys%ld(1:nl, s))
    end do
    band_half_width = half_bandwidth(idx)
  end function band_half_width

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

  !> Position of th_k (node k = 0..n) in the link vector.
  pure integer function th_index(n, k)
    integer, intent(in) :: n, k
    if (k >= n) then
      th_index = 3*n + 3
    else
      th_index = 3*k + 5
    end if
  end function th_index

end module flexmech_coupled_system
