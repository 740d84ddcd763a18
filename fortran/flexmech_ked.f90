!> Superposition kineto-elastodynamic (KED) system: elastic equations of a
!> mechanism about a prescribed rigid-body motion (seed Section 2),
!>
!>   M(t) x'' + (C(t) + Cg(t)) x' + (K(t) + Kc(t)) x = Q(t) - F_rigid(t)
!>
!> Rigid-motion sample layout, per link j (columns of rig(5, nlinks)):
!>   rig(1,j) phi [rad], rig(2,j) omega [rad/s], rig(3,j) alpha [rad/s^2],
!>   rig(4:5,j) acceleration of the link's reference point O minus gravity [m/s^2].
!> A material point at distance zeta from O along the link has the rigid
!> acceleration a_O + alpha*Omega*e*zeta - omega^2*e*zeta, e = (cos phi, sin phi).
!>
!> Rigid-inertia load models (F_rigid, per element, built in the element frame):
!>   LOAD_HAC      case I, seed Eq. 15-16: m0 [a_p1, a_v1, a_p2, a_v2]
!>   LOAD_CLASSIC  case II, seed Eq. 14: m [a_p1, a_v1, alpha, a_p2, a_v2, alpha]
!>   LOAD_CLASSIC_TRANSLATIONAL  Eq. 14 with the rotational entries set to 0
!> Lumped point masses carry m*a_rigid(node) in every model; rotary inertias
!> J*alpha(link they turn with), except in LOAD_CLASSIC_TRANSLATIONAL.
!> Rigid bodies enter as a point mass at their centre and a rotary inertia on their own rigid-sample
!> columns (rig columns beyond the links are any bodies' frames, see flexmech_py/slaving.py).
!>
!> Slave relations (docs/theory.md section 18): a DOF k that a joint ties to others is not solved for;
!> u_k = sum_j T_j u(sl_col(j)) over its row j = sl_ptr(k) .. sl_ptr(k+1)-1 of free DOFs, with
!> time-varying coefficients tv(1:3, j) = [T, dT/dt, d2T/dt2] at the current sample (set by the
!> caller before assemble).  An item (element, point mass, rotary inertia) touching a slaved DOF
!> is assembled on the free DOFs it depends on, u_item = T w, as
!>   T^T M T w'' + T^T (2 M T' + C T) w' + T^T (M T'' + C T' + K T) w = T^T (Q - F);
!> every other item keeps the direct path.
module flexmech_ked
  use flexmech_kinds, only: dp
  use flexmech_beam, only: beam_mass, beam_stiffness, beam_gyroscopic, beam_centrifugal, &
                           beam_hac_coupling, beam_geometric, rotate_to_global, vec_to_local, vec_to_global
  use flexmech_assembly, only: band_add_element6, band_add_general, band_add_diagonal, half_bandwidth
  implicit none
  private
  public :: ked_system, LOAD_HAC, LOAD_CLASSIC, LOAD_CLASSIC_TRANSLATIONAL

  integer, parameter :: LOAD_HAC = 1, LOAD_CLASSIC = 2, LOAD_CLASSIC_TRANSLATIONAL = 3

  !> An item whose local DOFs (n of them: 6 element, 2 point mass, 1 rotary inertia) are expressed on
  !> the nm free DOFs cols through the slave rows: u_local = T(t) u(cols).
  type :: gen_item
    integer :: n = 0, nm = 0
    integer, allocatable :: cols(:)     !< (nm) free-DOF numbers
    integer, allocatable :: dir(:)      !< (n) column of a local DOF that is itself free, 0 otherwise
    integer, allocatable :: sl(:)       !< (n) slave number of a slaved local DOF, 0 otherwise
    integer, allocatable :: estart(:)   !< (n+1) first entry in emap of local DOF i's slave row
    integer, allocatable :: emap(:)     !< column of every entry of the slave rows, in row order
  end type gen_item

  type :: ked_system
    integer :: nlinks = 0, ndof = 0, nfree = 0, nel = 0, nlm = 0, nri = 0, kl = 0, ku = 0
    integer :: load_model = LOAD_CLASSIC
    real(dp) :: ray_m = 0.0_dp, ray_k = 0.0_dp   !< Rayleigh damping C = ray_m M + ray_k K
    integer, allocatable :: el_link(:), el_dof(:, :), el_free(:, :)
    !> (nel) element e has the local matrices of element e-1 on the same link (a uniform mesh): its
    !> rotated effective matrix is reused in assemble (geometric stiffness off)
    logical, allocatable :: el_same(:)
    real(dp), allocatable :: el_len(:), el_z0(:), el_ea(:)
    logical :: geo = .false.                       !< add the geometric stiffness nax(e) * kg(e)
    real(dp), allocatable :: nax(:)                !< (nel) axial force of each element [N], tension > 0
    real(dp), allocatable :: kg(:, :, :)           !< (6, 6, nel) geometric stiffness per unit axial force
    real(dp), allocatable :: m(:, :, :), k(:, :, :), g(:, :, :), c(:, :, :), m0(:, :, :)
    integer, allocatable :: lm_link(:), lm_dof(:, :), lm_free(:, :)
    real(dp), allocatable :: lm_mass(:), lm_z(:)
    integer, allocatable :: ri_link(:), ri_dof(:), ri_free(:)
    real(dp), allocatable :: ri_j(:)
    integer :: nsl = 0                              !< slaved DOFs
    integer, allocatable :: sl_ptr(:), sl_col(:)   !< (nsl+1), (nnz) slave rows over the free DOFs
    real(dp), allocatable :: tv(:, :)              !< (3, nnz) [T, T', T''] of the rows at the current sample
    type(gen_item), allocatable :: gen(:)          !< items touching a slaved DOF
    integer, allocatable :: el_gen(:), lm_gen(:), ri_gen(:)   !< item -> gen index, 0 = direct path
  contains
    procedure :: init => ked_init
    procedure :: assemble => ked_assemble
    procedure :: rigid_load => ked_rigid_load
    procedure :: element_load
    procedure :: axial_forces
  end type ked_system

contains

  !> Build the system from flat arrays; local element matrices are computed once here.
  subroutine ked_init(sys, nlinks, free_of, el_link, el_dof, el_prop, lm_link, lm_dof, lm_prop, &
                      ri_link, ri_dof, ri_prop, sl_of, sl_ptr, sl_col, load_model, rayleigh)
    class(ked_system), intent(out) :: sys
    integer, intent(in) :: nlinks
    integer, intent(in) :: free_of(:)      !< (ndof) free-DOF number of each DOF, 0 = constrained
    integer, intent(in) :: el_link(:)      !< (nel) link of each element (1-based)
    integer, intent(in) :: el_dof(:, :)    !< (6, nel) global DOF numbers [u1 w1 th1 u2 w2 th2]
    real(dp), intent(in) :: el_prop(:, :)  !< (5, nel) [L m, zeta0 m, rho*A kg/m, E*A N, E*I N m^2]
    integer, intent(in) :: lm_link(:)      !< (nlm) link whose rigid motion carries the point mass
    integer, intent(in) :: lm_dof(:, :)    !< (2, nlm) DOFs [u, w] of the node
    real(dp), intent(in) :: lm_prop(:, :)  !< (2, nlm) [mass kg, zeta of the node on its link m]
    integer, intent(in) :: ri_link(:)      !< (nri) link the rotary inertia turns with
    integer, intent(in) :: ri_dof(:)       !< (nri) rotational DOF of the node
    real(dp), intent(in) :: ri_prop(:)     !< (nri) rotary inertia [kg m^2]
    integer, intent(in) :: sl_of(:)        !< (ndof) slave number of each DOF, 0 = not slaved
    integer, intent(in) :: sl_ptr(:)       !< (nsl+1) first entry of each slave row in sl_col (1-based)
    integer, intent(in) :: sl_col(:)       !< (nnz >= 1) free-DOF numbers of the slave rows
    integer, intent(in) :: load_model      !< LOAD_HAC, LOAD_CLASSIC or LOAD_CLASSIC_TRANSLATIONAL
    real(dp), intent(in) :: rayleigh(2)    !< [ray_m 1/s, ray_k s]
    integer :: e, i
    sys%nlinks = nlinks
    sys%ndof = size(free_of)
    sys%nfree = maxval([0, free_of])
    sys%nel = size(el_link)
    sys%nlm = size(lm_link)
    sys%nri = size(ri_link)
    sys%load_model = load_model
    sys%ray_m = rayleigh(1)
    sys%ray_k = rayleigh(2)
    sys%el_link = el_link
    sys%el_dof = el_dof
    allocate (sys%el_free(6, sys%nel))
    do e = 1, sys%nel
      do i = 1, 6
        sys%el_free(i, e) = free_of(el_dof(i, e))
      end do
    end do
    call init_elements(sys, el_prop)
    sys%lm_link = lm_link
    sys%lm_dof = lm_dof
    sys%lm_mass = lm_prop(1, :)
    sys%lm_z = lm_prop(2, :)
    allocate (sys%lm_free(2, sys%nlm))
    do i = 1, sys%nlm
      sys%lm_free(:, i) = free_of(lm_dof(:, i))
    end do
    sys%ri_link = ri_link
    sys%ri_dof = ri_dof
    sys%ri_j = ri_prop
    allocate (sys%ri_free(sys%nri))
    do i = 1, sys%nri
      sys%ri_free(i) = free_of(ri_dof(i))
    end do
    allocate (sys%el_same(sys%nel))
    sys%el_same = .false.
    do e = 2, sys%nel
      sys%el_same(e) = el_link(e) == el_link(e - 1) .and. all(el_prop([1, 3, 4, 5], e) == el_prop([1, 3, 4, 5], e - 1))
    end do
    call init_slaves(sys, free_of, sl_of, sl_ptr, sl_col)
    do e = 2, sys%nel   ! an element after one on the general path has no reusable matrices before it
      if (sys%el_gen(e - 1) > 0) sys%el_same(e) = .false.
    end do
    sys%kl = half_bandwidth(sys%el_free)
    do i = 1, size(sys%gen)
      sys%kl = max(sys%kl, maxval(sys%gen(i)%cols) - minval(sys%gen(i)%cols))
    end do
    sys%ku = sys%kl
  end subroutine ked_init

  !> The elements' lengths, places, axial stiffnesses and matrices (flexmech_beam) from el_prop(5, nel).
  subroutine init_elements(sys, el_prop)
    class(ked_system), intent(inout) :: sys
    real(dp), intent(in) :: el_prop(:, :)  !< (5, nel) [L m, zeta0 m, rho*A kg/m, E*A N, E*I N m^2]
    integer :: e
    sys%el_len = el_prop(1, :)
    sys%el_z0 = el_prop(2, :)
    sys%el_ea = el_prop(4, :)
    allocate (sys%nax(sys%nel), sys%kg(6, 6, sys%nel))
    sys%nax = 0.0_dp
    allocate (sys%m(6, 6, sys%nel), sys%k(6, 6, sys%nel), sys%g(6, 6, sys%nel), &
              sys%c(6, 6, sys%nel), sys%m0(6, 4, sys%nel))
    do e = 1, sys%nel
      sys%kg(:, :, e) = beam_geometric(el_prop(1, e))
      sys%m(:, :, e) = beam_mass(el_prop(3, e), el_prop(1, e))
      sys%k(:, :, e) = beam_stiffness(el_prop(4, e), el_prop(5, e), el_prop(1, e))
      sys%g(:, :, e) = beam_gyroscopic(el_prop(3, e), el_prop(1, e))
      sys%c(:, :, e) = beam_centrifugal(el_prop(3, e), el_prop(1, e))
      sys%m0(:, :, e) = beam_hac_coupling(el_prop(3, e), el_prop(1, e))
    end do
  end subroutine init_elements

  !> The slave rows and the items that touch a slaved DOF (an item without one keeps the direct path).
  subroutine init_slaves(sys, free_of, sl_of, sl_ptr, sl_col)
    type(ked_system), intent(inout) :: sys
    integer, intent(in) :: free_of(:), sl_of(:), sl_ptr(:), sl_col(:)
    integer :: e, i, ng
    sys%nsl = size(sl_ptr) - 1
    sys%sl_ptr = sl_ptr
    sys%sl_col = sl_col
    allocate (sys%tv(3, size(sl_col)))
    sys%tv = 0.0_dp
    allocate (sys%el_gen(sys%nel), sys%lm_gen(sys%nlm), sys%ri_gen(sys%nri))
    sys%el_gen = 0; sys%lm_gen = 0; sys%ri_gen = 0
    ng = 0
    if (sys%nsl > 0) then
      do e = 1, sys%nel
        if (any(sl_of(sys%el_dof(:, e)) > 0)) then
          ng = ng + 1; sys%el_gen(e) = ng
        end if
      end do
      do i = 1, sys%nlm
        if (any(sl_of(sys%lm_dof(:, i)) > 0)) then
          ng = ng + 1; sys%lm_gen(i) = ng
        end if
      end do
      do i = 1, sys%nri
        if (sl_of(sys%ri_dof(i)) > 0) then
          ng = ng + 1; sys%ri_gen(i) = ng
        end if
      end do
    end if
    allocate (sys%gen(ng))
    do e = 1, sys%nel
      if (sys%el_gen(e) > 0) call gen_build(sys, sys%gen(sys%el_gen(e)), sys%el_dof(:, e), free_of, sl_of)
    end do
    do i = 1, sys%nlm
      if (sys%lm_gen(i) > 0) call gen_build(sys, sys%gen(sys%lm_gen(i)), sys%lm_dof(:, i), free_of, sl_of)
    end do
    do i = 1, sys%nri
      if (sys%ri_gen(i) > 0) call gen_build(sys, sys%gen(sys%ri_gen(i)), sys%ri_dof(i:i), free_of, sl_of)
    end do
  end subroutine init_slaves

  !> The free DOFs an item depends on (its own free DOFs and the masters of its slaved DOFs) and
  !> where each local DOF and slave-row entry goes among them.
  subroutine gen_build(sys, it, dofs, free_of, sl_of)
    type(ked_system), intent(in) :: sys
    type(gen_item), intent(out) :: it
    integer, intent(in) :: dofs(:), free_of(:), sl_of(:)
    integer :: i, j, k, q, nent, tmp(size(dofs) + size(sys%sl_col))
    it%n = size(dofs)
    allocate (it%dir(it%n), it%sl(it%n), it%estart(it%n + 1))
    it%nm = 0
    nent = 0
    do i = 1, it%n
      k = sl_of(dofs(i))
      it%sl(i) = k
      if (k > 0) then
        do j = sys%sl_ptr(k), sys%sl_ptr(k + 1) - 1
          call add_col(sys%sl_col(j))
        end do
        nent = nent + sys%sl_ptr(k + 1) - sys%sl_ptr(k)
      else if (free_of(dofs(i)) > 0) then
        call add_col(free_of(dofs(i)))
      end if
    end do
    it%cols = tmp(:it%nm)
    allocate (it%emap(max(1, nent)))
    q = 1
    do i = 1, it%n
      it%estart(i) = q
      it%dir(i) = 0
      k = it%sl(i)
      if (k > 0) then
        do j = sys%sl_ptr(k), sys%sl_ptr(k + 1) - 1
          it%emap(q) = findloc(it%cols, sys%sl_col(j), dim=1)
          q = q + 1
        end do
      else if (free_of(dofs(i)) > 0) then
        it%dir(i) = findloc(it%cols, free_of(dofs(i)), dim=1)
      end if
    end do
    it%estart(it%n + 1) = q
  contains
    subroutine add_col(c)
      integer, intent(in) :: c
      if (any(tmp(:it%nm) == c)) return
      it%nm = it%nm + 1
      tmp(it%nm) = c
    end subroutine add_col
  end subroutine gen_build

  !> T, T', T'' (n, nm) of an item at the current sample (sys%tv).
  pure subroutine gen_transform(sys, it, t, td, tdd)
    class(ked_system), intent(in) :: sys
    type(gen_item), intent(in) :: it
    real(dp), intent(out) :: t(:, :), td(:, :), tdd(:, :)
    integer :: i, j, q, c
    t = 0.0_dp; td = 0.0_dp; tdd = 0.0_dp
    do i = 1, it%n
      if (it%dir(i) > 0) t(i, it%dir(i)) = 1.0_dp
      if (it%sl(i) == 0) cycle
      q = it%estart(i)
      do j = sys%sl_ptr(it%sl(i)), sys%sl_ptr(it%sl(i) + 1) - 1
        c = it%emap(q)
        t(i, c) = t(i, c) + sys%tv(1, j)
        td(i, c) = td(i, c) + sys%tv(2, j)
        tdd(i, c) = tdd(i, c) + sys%tv(3, j)
        q = q + 1
      end do
    end do
  end subroutine gen_transform

  !> The local DOF values u_local = T u(cols) of an item (u over the free DOFs).
  pure subroutine gen_values(sys, it, u, ul)
    class(ked_system), intent(in) :: sys
    type(gen_item), intent(in) :: it
    real(dp), intent(in) :: u(:)
    real(dp), intent(out) :: ul(:)
    real(dp) :: t(it%n, it%nm), td(it%n, it%nm), tdd(it%n, it%nm)
    integer :: c
    call gen_transform(sys, it, t, td, tdd)
    ul = 0.0_dp
    do c = 1, it%nm
      ul = ul + t(:, c)*u(it%cols(c))
    end do
  end subroutine gen_values

  !> Add an item with slaved DOFs, given its matrices mg, cg, kg (n x n) and load fg (n) in the
  !> all-DOF components: S += T^T (cm M T + cc Cb + ck Kb), r += T^T (-F - Cb v - Kb u) with
  !> Cb = 2 M T' + C T and Kb = M T'' + C T' + K T (static: Cb = 0, Kb = K T), grouped as
  !> S += T^T [M (cm T + 2 cc T' + ck T'') + C (cc T + ck T') + ck K T] and
  !> r += T^T [-F - M (2 T' v + T'' u) - C (T v + T' u) - K T u].
  subroutine gen_add(sys, it, mg, cg, kg, fg, cm, cc, ck, qs, u, v, ab, r)
    class(ked_system), intent(in) :: sys
    type(gen_item), intent(in) :: it
    real(dp), intent(in) :: mg(:, :), cg(:, :), kg(:, :), fg(:), cm, cc, ck, u(:), v(:)
    logical, intent(in) :: qs
    real(dp), intent(inout) :: ab(:, :), r(:)
    real(dp) :: t(it%n, it%nm), td(it%n, it%nm), tdd(it%n, it%nm), a(it%n, it%nm), s(it%nm, it%nm)
    real(dp) :: um(it%nm), vm(it%nm), wm(it%n), wc(it%n), wk(it%n), rl(it%n)
    integer :: c
    call gen_transform(sys, it, t, td, tdd)
    um = u(it%cols)
    vm = v(it%cols)
    wk = matmul(t, um)
    if (qs) then
      a = ck*matmul(kg, t)
      rl = -fg - matmul(kg, wk)
    else
      a = matmul(mg, cm*t + (2.0_dp*cc)*td + ck*tdd) + matmul(cg, cc*t + ck*td) + ck*matmul(kg, t)
      wm = 2.0_dp*matmul(td, vm) + matmul(tdd, um)
      wc = matmul(t, vm) + matmul(td, um)
      rl = -fg - matmul(mg, wm) - matmul(cg, wc) - matmul(kg, wk)
    end if
    s = matmul(transpose(t), a)
    call band_add_general(ab, size(ab, 1), sys%kl, sys%ku, it%nm, it%cols, s)
    um = matmul(rl, t)                     ! T^T rl
    do c = 1, it%nm
      r(it%cols(c)) = r(it%cols(c)) + um(c)
    end do
  end subroutine gen_add

  !> Rigid acceleration of the point zeta of a link, global components [m/s^2].
  pure function point_accel(r, zeta) result(a)
    real(dp), intent(in) :: r(5), zeta
    real(dp) :: a(2), c, s
    c = cos(r(1)); s = sin(r(1))
    a(1) = r(4) - r(3)*s*zeta - r(2)**2*c*zeta
    a(2) = r(5) + r(3)*c*zeta - r(2)**2*s*zeta
  end function point_accel

  !> Rigid-inertia load of element e in the element frame (sign: the load F_rigid, to be subtracted).
  pure function element_load(sys, e, r) result(f)
    class(ked_system), intent(in) :: sys
    integer, intent(in) :: e
    real(dp), intent(in) :: r(5)   !< rigid sample of the element's link (layout above)
    real(dp) :: f(6)
    f = element_load_cs(sys, e, r, cos(r(1)), sin(r(1)))
  end function element_load

  !> element_load with c = cos(phi), s = sin(phi) of the link given.
  pure function element_load_cs(sys, e, r, c, s) result(f)
    class(ked_system), intent(in) :: sys
    integer, intent(in) :: e
    real(dp), intent(in) :: r(5), c, s
    real(dp) :: f(6), ap(2), z1, z2, om2, w4(4), w6(6)
    integer :: k
    z1 = sys%el_z0(e); z2 = z1 + sys%el_len(e)
    om2 = r(2)**2
    ap(1) = c*r(4) + s*r(5)          ! reference-point acceleration in the link frame
    ap(2) = -s*r(4) + c*r(5)
    select case (sys%load_model)
    case (LOAD_HAC)
      w4 = [ap(1) - om2*z1, ap(2) + r(3)*z1, ap(1) - om2*z2, ap(2) + r(3)*z2]
      f = 0.0_dp
      do k = 1, 4
        f = f + sys%m0(:, k, e)*w4(k)
      end do
      return
    case (LOAD_CLASSIC)
      w6 = [ap(1) - om2*z1, ap(2) + r(3)*z1, r(3), ap(1) - om2*z2, ap(2) + r(3)*z2, r(3)]
    case default
      w6 = [ap(1) - om2*z1, ap(2) + r(3)*z1, 0.0_dp, ap(1) - om2*z2, ap(2) + r(3)*z2, 0.0_dp]
    end select
    f = 0.0_dp
    do k = 1, 6
      f = f + sys%m(:, k, e)*w6(k)
    end do
  end function element_load_cs

  !> Rigid-inertia load F_rigid over ALL DOFs (constrained ones included) for one rigid sample.
  subroutine ked_rigid_load(sys, rig, f)
    class(ked_system), intent(in) :: sys
    real(dp), intent(in) :: rig(:, :)   !< (5, nlinks)
    real(dp), intent(out) :: f(:)       !< (ndof)
    integer :: e, i, j
    real(dp) :: phi
    f = 0.0_dp
    do e = 1, sys%nel
      j = sys%el_link(e)
      phi = rig(1, j)
      f(sys%el_dof(:, e)) = f(sys%el_dof(:, e)) + vec_to_global(sys%element_load(e, rig(:, j)), cos(phi), sin(phi))
    end do
    do i = 1, sys%nlm
      f(sys%lm_dof(:, i)) = f(sys%lm_dof(:, i)) + sys%lm_mass(i)*point_accel(rig(:, sys%lm_link(i)), sys%lm_z(i))
    end do
    if (sys%load_model /= LOAD_CLASSIC_TRANSLATIONAL) then
      do i = 1, sys%nri
        f(sys%ri_dof(i)) = f(sys%ri_dof(i)) + sys%ri_j(i)*rig(3, sys%ri_link(i))
      end do
    end if
  end subroutine ked_rigid_load

  !> Axial force EA (p2 - p1)/L of every element [N] from the free-DOF displacements u at a rigid sample.
  pure subroutine axial_forces(sys, rig, u, nax)
    class(ked_system), intent(in) :: sys
    real(dp), intent(in) :: rig(:, :), u(:)
    real(dp), intent(out) :: nax(:)
    integer :: e, i
    real(dp) :: ue(6), ul(6), phi
    do e = 1, sys%nel
      if (sys%el_gen(e) > 0) then
        call gen_values(sys, sys%gen(sys%el_gen(e)), u, ue)
      else
        do i = 1, 6
          ue(i) = 0.0_dp
          if (sys%el_free(i, e) > 0) ue(i) = u(sys%el_free(i, e))
        end do
      end if
      phi = rig(1, sys%el_link(e))
      ul = vec_to_local(ue, cos(phi), sin(phi))
      nax(e) = sys%el_ea(e)*(ul(4) - ul(1))/sys%el_len(e)
    end do
  end subroutine axial_forces

  !> Effective matrix S = M + cc*C + ck*K in band storage and residual
  !> r = -F_rigid - C v - K u over the free DOFs, for one rigid sample.
  !> C = Cg + Rayleigh, K = K_elastic + Kc.  u, v are full free-DOF vectors.
  !> With cm = 0 and static = .true.: S = K_elastic (+ geometric) and r = -F_rigid (quasi-static problem).
  subroutine ked_assemble(sys, rig, cc, ck, u, v, ab, r, static)
    class(ked_system), intent(in) :: sys
    logical, intent(in), optional :: static  !< assemble the quasi-static problem K u = -F_rigid
    real(dp), intent(in) :: rig(:, :)    !< (5, nlinks) rigid sample
    real(dp), intent(in) :: cc, ck       !< coefficients of C and K in S
    real(dp), intent(in) :: u(:), v(:)   !< (nfree) displacement and velocity where K, C act
    real(dp), intent(out) :: ab(:, :)    !< (2kl+ku+1, nfree) band storage of S
    real(dp), intent(out) :: r(:)        !< (nfree) residual
    integer :: e, i, j, n
    integer :: idx(6)
    real(dp) :: cs, sn, om, al, ce(6, 6), ke(6, 6), se(6, 6), me(6, 6), ue(6), ve(6), re(6), cm
    real(dp) :: ul(6), vl(6)
    integer :: jprev
    logical :: qs, general
    general = size(sys%gen) > 0   ! any item on the general path (hoisted: the direct loop stays as it was)
    qs = .false.
    if (present(static)) qs = static
    cm = merge(0.0_dp, 1.0_dp, qs)
    ab = 0.0_dp
    r = 0.0_dp
    jprev = 0
    cs = 1.0_dp; sn = 0.0_dp
    do e = 1, sys%nel
      j = sys%el_link(e)
      if (j /= jprev) then   ! elements are grouped by link: one cos/sin per link and sample
        cs = cos(rig(1, j)); sn = sin(rig(1, j)); jprev = j
      end if
      om = rig(2, j); al = rig(3, j)
      if (general) then
        if (sys%el_gen(e) > 0) cycle   ! touches a slaved DOF: assemble_slaved (its successor recomputes, el_same)
      end if
      idx = sys%el_free(:, e)
      ! the local matrices of a uniform link's elements are equal: ce, ke and the rotated effective
      ! matrix se of the previous element are reused (not with the per-element geometric stiffness)
      if (e == 1 .or. .not. sys%el_same(e) .or. sys%geo) then
        ce = (2.0_dp*om)*sys%g(:, :, e)
        if (qs) then
          ke = sys%k(:, :, e)
        else
          ke = sys%k(:, :, e) + al*sys%g(:, :, e) + (om*om)*sys%c(:, :, e)
        end if
        if (sys%geo) ke = ke + sys%nax(e)*sys%kg(:, :, e)
        if (sys%ray_m /= 0.0_dp) ce = ce + sys%ray_m*sys%m(:, :, e)
        if (sys%ray_k /= 0.0_dp) ce = ce + sys%ray_k*sys%k(:, :, e)
        me = cm*sys%m(:, :, e) + cc*ce + ck*ke
        se = rotate_to_global(me, cs, sn)
      end if
      call band_add_element6(ab, size(ab, 1), sys%kl, sys%ku, idx, se)
      do i = 1, 6
        n = idx(i)
        if (n > 0) then
          ue(i) = u(n); ve(i) = v(n)
        else
          ue(i) = 0.0_dp; ve(i) = 0.0_dp
        end if
      end do
      ul = vec_to_local(ue, cs, sn)
      vl = vec_to_local(ve, cs, sn)
      re = -element_load_cs(sys, e, rig(:, j), cs, sn)
      do n = 1, 6
        do i = 1, 6
          re(i) = re(i) - ce(i, n)*vl(n) - ke(i, n)*ul(n)
        end do
      end do
      re = vec_to_global(re, cs, sn)
      do i = 1, 6
        if (idx(i) > 0) r(idx(i)) = r(idx(i)) + re(i)
      end do
    end do
    call assemble_lumped(sys, rig, cm, cc, general, v, ab, r)
    if (general) call assemble_slaved(sys, rig, cm, cc, ck, qs, u, v, ab, r)
  end subroutine ked_assemble

  !> ked_assemble's lumped inertias: the point masses (their rigid acceleration load) and the rotary
  !> inertias (with the link's angular acceleration, except for the classic-translational load model);
  !> items touching a slaved DOF are left to assemble_slaved (general).
  subroutine assemble_lumped(sys, rig, cm, cc, general, v, ab, r)
    class(ked_system), intent(in) :: sys
    real(dp), intent(in) :: rig(:, :), cm, cc, v(:)
    logical, intent(in) :: general
    real(dp), intent(inout) :: ab(:, :), r(:)
    integer :: i, j, n
    real(dp) :: a(2), mi
    do i = 1, sys%nlm
      mi = sys%lm_mass(i)
      a = point_accel(rig(:, sys%lm_link(i)), sys%lm_z(i))
      if (general) then
        if (sys%lm_gen(i) > 0) cycle
      end if
      do n = 1, 2
        j = sys%lm_free(n, i)
        if (j == 0) cycle
        call band_add_diagonal(ab, sys%kl, sys%ku, j, mi*(cm + cc*sys%ray_m))
        r(j) = r(j) - mi*(a(n) + sys%ray_m*v(j))
      end do
    end do
    do i = 1, sys%nri
      if (general) then
        if (sys%ri_gen(i) > 0) cycle
      end if
      j = sys%ri_free(i)
      if (j == 0) cycle
      mi = sys%ri_j(i)
      call band_add_diagonal(ab, sys%kl, sys%ku, j, mi*(cm + cc*sys%ray_m))
      r(j) = r(j) - mi*sys%ray_m*v(j)
      if (sys%load_model /= LOAD_CLASSIC_TRANSLATIONAL) r(j) = r(j) - mi*rig(3, sys%ri_link(i))
    end do
  end subroutine assemble_lumped

  !> The items touching a slaved DOF (skipped by ked_assemble's direct loops) through gen_add.
  subroutine assemble_slaved(sys, rig, cm, cc, ck, qs, u, v, ab, r)
    class(ked_system), intent(in) :: sys
    real(dp), intent(in) :: rig(:, :), cm, cc, ck, u(:), v(:)
    logical, intent(in) :: qs
    real(dp), intent(inout) :: ab(:, :), r(:)
    real(dp), parameter :: eye2(2, 2) = reshape([1.0_dp, 0.0_dp, 0.0_dp, 1.0_dp], [2, 2])
    real(dp) :: mi, fr
    integer :: e, i, j
    do e = 1, sys%nel
      if (sys%el_gen(e) == 0) cycle
      j = sys%el_link(e)
      call gen_element(sys, e, rig(:, j), cos(rig(1, j)), sin(rig(1, j)), cm, cc, ck, qs, u, v, ab, r)
    end do
    do i = 1, sys%nlm
      if (sys%lm_gen(i) == 0) cycle
      mi = sys%lm_mass(i)
      call gen_add(sys, sys%gen(sys%lm_gen(i)), mi*eye2, (sys%ray_m*mi)*eye2, 0.0_dp*eye2, &
                   mi*point_accel(rig(:, sys%lm_link(i)), sys%lm_z(i)), cm, cc, ck, qs, u, v, ab, r)
    end do
    do i = 1, sys%nri
      if (sys%ri_gen(i) == 0) cycle
      mi = sys%ri_j(i)
      fr = 0.0_dp
      if (sys%load_model /= LOAD_CLASSIC_TRANSLATIONAL) fr = mi*rig(3, sys%ri_link(i))
      call gen_add(sys, sys%gen(sys%ri_gen(i)), reshape([mi], [1, 1]), reshape([sys%ray_m*mi], [1, 1]), &
                   reshape([0.0_dp], [1, 1]), [fr], cm, cc, ck, qs, u, v, ab, r)
    end do
  end subroutine assemble_slaved

  !> Element e (touching a slaved DOF) added through gen_add: its global M, C, K and load at the
  !> rigid sample r of its link (c, s its cos, sin).
  subroutine gen_element(sys, e, r5, c, s, cm, cc, ck, qs, u, v, ab, r)
    class(ked_system), intent(in) :: sys
    integer, intent(in) :: e
    real(dp), intent(in) :: r5(5), c, s, cm, cc, ck, u(:), v(:)
    logical, intent(in) :: qs
    real(dp), intent(inout) :: ab(:, :), r(:)
    real(dp) :: ce(6, 6), ke(6, 6)
    ce = (2.0_dp*r5(2))*sys%g(:, :, e)
    if (qs) then
      ke = sys%k(:, :, e)
    else
      ke = sys%k(:, :, e) + r5(3)*sys%g(:, :, e) + (r5(2)*r5(2))*sys%c(:, :, e)
    end if
    if (sys%geo) ke = ke + sys%nax(e)*sys%kg(:, :, e)
    if (sys%ray_m /= 0.0_dp) ce = ce + sys%ray_m*sys%m(:, :, e)
    if (sys%ray_k /= 0.0_dp) ce = ce + sys%ray_k*sys%k(:, :, e)
    call gen_add(sys, sys%gen(sys%el_gen(e)), rotate_to_global(sys%m(:, :, e), c, s), rotate_to_global(ce, c, s), &
                 rotate_to_global(ke, c, s), vec_to_global(element_load_cs(sys, e, r5, c, s), c, s), cm, cc, ck, &
                 qs, u, v, ab, r)
  end subroutine gen_element

end module flexmech_ked
