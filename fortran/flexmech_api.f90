!> Thin flat API of flexmech facing f2py: plain arrays and scalars only.
!> Python wraps it in flexmech_py.kernels (validation, status -> exception).
!>
!> System description shared by the ked_* routines (all indices 1-based):
!>   nlinks            number of links
!>   free_of(ndof)     free-DOF number of each global DOF, 0 = constrained
!>   el_link(nel)      link of each element
!>   el_dof(6,nel)     global DOFs of each element, order [u1 w1 th1 u2 w2 th2]
!>   el_prop(5,nel)    [L m, zeta0 m (start along its link), rho*A kg/m, E*A N, E*I N m^2]
!>   lm_link(nlm), lm_dof(2,nlm), lm_prop(2,nlm)   point masses: link, [u w] DOFs, [mass kg, zeta m]
!>   ri_link(nri), ri_dof(nri), ri_prop(nri)       rotary inertias: link turned with, DOF, J kg m^2
!>   sl_of(ndof), sl_ptr(nsl+1), sl_col(nnz)       slave relations: slave number of each DOF (0: none),
!>                     first entry of each slave's row, free-DOF numbers of the rows (nsl = 0: sl_ptr = [1],
!>                     one dummy sl_col entry); their coefficients are sl_val(3,nnz,...) or tv(3,nnz)
!>                     [T, dT/dt, d2T/dt2] per sample (flexmech_ked, docs/theory.md section 18)
!>   load_model        1 hac (case I), 2 classic (case II), 3 classic-translational
!>   rayleigh(2)       Rayleigh damping [a_M 1/s, a_K s]
!> Rigid samples rig(5,nlinks,...) : [phi, omega, alpha, a_Ox - g_x, a_Oy - g_y] per link (nlinks counts
!> every column: links, then any further bodies' frames; flexmech_py.model.FEModel.rig_samples).
!> Every routine returns `status` (codes in flexmech_lapack; 5 = Newton failure, 6 = divergence limit).
module flexmech_api
  use flexmech_kinds, only: dp
  use flexmech_lapack, only: STATUS_OK, STATUS_BAD_INPUT, dgbtrf, dgbtrs, dgetrf, dgetrs, lapack_status
  use flexmech_beam, only: beam_mass, beam_stiffness, beam_gyroscopic, beam_centrifugal, &
                           beam_hac_coupling, beam_curvature, vec_to_local, beam_geometric
  use flexmech_assembly, only: band_rows, band_to_dense, half_bandwidth
  use flexmech_ked, only: ked_system
  use flexmech_newmark, only: newmark_run, consistent_acceleration, initial_axial_forces
  implicit none
  private
  public :: element_matrices, element_curvatures, ked_run, ked_matrices, ked_loads, ked_bandwidth
  public :: ked_geometric_matrix
  public :: bench_solve, bench_peak   ! benchmark-only (flexmech bench), at the end of this module

contains

  !> Local element matrices of one beam element (DOFs [p1 v1 th1 p2 v2 th2]).
  !> m mass, k stiffness, g gyroscopic kernel (Coriolis = 2 omega g),
  !> c centrifugal kernel (inertia stiffness = alpha g + omega^2 c), m0 Hac coupling (6 x 4),
  !> kg geometric stiffness per unit axial force (N kg, N in newtons, tension > 0).
  subroutine element_matrices(rho_a, ea, ei, length, m, k, g, c, m0, kg)
    real(dp), intent(in) :: rho_a, ea, ei, length
    real(dp), intent(out) :: m(6, 6), k(6, 6), g(6, 6), c(6, 6), m0(6, 4), kg(6, 6)
    m = beam_mass(rho_a, length)
    k = beam_stiffness(ea, ei, length)
    g = beam_gyroscopic(rho_a, length)
    c = beam_centrifugal(rho_a, length)
    m0 = beam_hac_coupling(rho_a, length)
    kg = beam_geometric(length)
  end subroutine element_matrices

  !> Curvature v'' [1/m] at xi of one element over n frames, from its global DOFs and axis angle.
  subroutine element_curvatures(n, dglob, phi, length, xi, kappa)
    integer, intent(in) :: n
    real(dp), intent(in) :: dglob(6, n)  !< global element DOFs per frame
    real(dp), intent(in) :: phi(n)       !< element axis angle per frame [rad]
    real(dp), intent(in) :: length, xi
    real(dp), intent(out) :: kappa(n)
    integer :: i
    do i = 1, n
      kappa(i) = beam_curvature(vec_to_local(dglob(:, i), cos(phi(i)), sin(phi(i))), length, xi)
    end do
  end subroutine element_curvatures

  !> Validate index arrays and build the system. status = STATUS_BAD_INPUT on bad indices.
  subroutine build(sys, nlinks, ndof, free_of, el_link, el_dof, el_prop, lm_link, lm_dof, lm_prop, &
                   ri_link, ri_dof, ri_prop, sl_of, sl_ptr, sl_col, load_model, rayleigh, status)
    type(ked_system), intent(out) :: sys
    integer, intent(in) :: nlinks, ndof, free_of(:), el_link(:), el_dof(:, :), lm_link(:), lm_dof(:, :)
    integer, intent(in) :: ri_link(:), ri_dof(:), load_model, sl_of(:), sl_ptr(:), sl_col(:)
    real(dp), intent(in) :: el_prop(:, :), lm_prop(:, :), ri_prop(:), rayleigh(2)
    integer, intent(out) :: status
    integer :: nsl
    status = STATUS_BAD_INPUT
    nsl = size(sl_ptr) - 1
    if (size(sl_of) /= ndof .or. nsl < 0 .or. size(sl_col) < 1) return
    if (sl_ptr(1) /= 1 .or. sl_ptr(nsl + 1) - 1 > size(sl_col)) return
    if (nsl > 0) then
      if (any(sl_ptr(2:) < sl_ptr(:nsl))) return
      if (any(sl_col(:sl_ptr(nsl + 1) - 1) < 1) .or. any(sl_col(:sl_ptr(nsl + 1) - 1) > maxval(free_of))) return
    end if
    if (any(sl_of < 0) .or. any(sl_of > nsl) .or. any(sl_of > 0 .and. free_of > 0)) return
    if (size(free_of) /= ndof .or. ndof < 1 .or. nlinks < 1) return
    if (any(el_link < 1) .or. any(el_link > nlinks)) return
    if (any(lm_link < 1) .or. any(lm_link > nlinks)) return
    if (any(ri_link < 1) .or. any(ri_link > nlinks)) return
    if (any(el_dof < 1) .or. any(el_dof > ndof)) return
    if (any(lm_dof < 1) .or. any(lm_dof > ndof)) return
    if (any(ri_dof < 1) .or. any(ri_dof > ndof)) return
    if (any(el_prop(1, :) <= 0.0_dp)) return
    if (load_model < 1 .or. load_model > 3) return
    if (maxval([0, free_of]) < 1) return
    call sys%init(nlinks, free_of, el_link, el_dof, el_prop, lm_link, lm_dof, lm_prop, &
                  ri_link, ri_dof, ri_prop, sl_of, sl_ptr, sl_col, load_model, rayleigh)
    status = STATUS_OK
  end subroutine build

  !> Half bandwidth of the free system (for reporting and benchmarks).
  subroutine ked_bandwidth(ndof, nel, free_of, el_dof, kb)
    integer, intent(in) :: ndof, nel
    integer, intent(in) :: free_of(ndof), el_dof(6, nel)
    integer, intent(out) :: kb
    kb = half_bandwidth(reshape(free_of(reshape(el_dof, [6*nel])), [6, nel]))
  end subroutine ked_bandwidth

  !> Run the superposition KED model with the generalized-alpha family (alpha_m, alpha_f, beta, gamma;
  !> Newmark: alpha_m = alpha_f = 0) over nsteps steps (flexmech_newmark, docs/theory.md section 15).
  !> On entry u0, v0 are the initial state (free DOFs); if init_accel /= 0 the initial acceleration
  !> a0 is computed from the equations of motion and the pseudo-acceleration p0 set to it (a fresh
  !> start), else a0 and p0 are used as given.  Outputs frames (nfree, nframes) at steps 0,
  !> out_every, ...; nvalid of them are valid (all unless status /= 0); the final state in u0, v0,
  !> a0, p0 (so a long run can be continued chunk by chunk).
  !> geo_mode: 0 no geometric stiffness; 1 axial forces of the current state, iterated in each step
  !> (geo_tol, geo_maxit); 2 axial forces lagged one step; 3 quasi-static axial forces from
  !> K u = -F_rigid at each step.  nf (nel, nframes) returns the axial forces used [N].
  !> div_limit [m] > 0: the run stops with status 6 when a free translational DOF exceeds it.
  subroutine ked_run(nlinks, ndof, nel, nlm, nri, nq, nsteps, nfree, nframes, nsl1, nnz, &
                     free_of, el_link, el_dof, el_prop, lm_link, lm_dof, lm_prop, ri_link, ri_dof, ri_prop, &
                     sl_of, sl_ptr, sl_col, &
                     load_model, rayleigh, rig, sl_val, q_free, q_val, dt, alpha_m, alpha_f, beta, gamma, out_every, &
                     init_accel, geo_mode, geo_tol, geo_maxit, div_limit, u0, v0, a0, p0, uf, vf, af, nf, &
                     status, fail_step, geo_iters, nvalid)
    integer, intent(in) :: nlinks, ndof, nel, nlm, nri, nq, nsteps, nfree, nframes, nsl1, nnz
    ! Python passes none of the sizes: f2py takes them from the arrays' shapes, nframes from out_every
    !f2py intent(hide) :: nlinks, ndof, nel, nlm, nri, nq, nsteps, nfree, nsl1, nnz
    !f2py integer intent(hide), depend(rig, out_every) :: nframes = (out_every > 0 ? (shape(rig, 2) - 1)/out_every + 1 : 1)
    integer, intent(in) :: sl_of(ndof), sl_ptr(nsl1), sl_col(nnz)
    real(dp), intent(in) :: sl_val(3, nnz, nsteps + 1)
    integer, intent(in) :: free_of(ndof), el_link(nel), el_dof(6, nel)
    real(dp), intent(in) :: el_prop(5, nel)
    integer, intent(in) :: lm_link(nlm), lm_dof(2, nlm)
    real(dp), intent(in) :: lm_prop(2, nlm)
    integer, intent(in) :: ri_link(nri), ri_dof(nri)
    real(dp), intent(in) :: ri_prop(nri)
    integer, intent(in) :: load_model
    real(dp), intent(in) :: rayleigh(2)
    real(dp), intent(in) :: rig(5, nlinks, nsteps + 1)
    integer, intent(in) :: q_free(nq)
    real(dp), intent(in) :: q_val(nq, nsteps + 1)
    real(dp), intent(in) :: dt, alpha_m, alpha_f, beta, gamma, div_limit
    integer, intent(in) :: out_every, init_accel, geo_mode, geo_maxit
    real(dp), intent(in) :: geo_tol
    real(dp), intent(inout) :: u0(nfree), v0(nfree), a0(nfree), p0(nfree)
    real(dp), intent(out) :: uf(nfree, nframes), vf(nfree, nframes), af(nfree, nframes), nf(nel, nframes)
    integer, intent(out) :: status, fail_step, geo_iters, nvalid
    type(ked_system) :: sys
    logical :: trans(nfree)
    integer :: e, i
    uf = 0.0_dp; vf = 0.0_dp; af = 0.0_dp; nf = 0.0_dp; geo_iters = 0
    fail_step = 0; nvalid = 0
    call build(sys, nlinks, ndof, free_of, el_link, el_dof, el_prop, lm_link, lm_dof, lm_prop, &
               ri_link, ri_dof, ri_prop, sl_of, sl_ptr, sl_col, load_model, rayleigh, status)
    if (status /= STATUS_OK) return
    if (sys%nfree /= nfree .or. any(q_free < 1) .or. any(q_free > nfree)) then
      status = STATUS_BAD_INPUT
      return
    end if
    if (geo_mode < 0 .or. geo_mode > 3) then
      status = STATUS_BAD_INPUT
      return
    end if
    trans = .false.    ! the translational DOFs [u1 w1 . u2 w2 .] of the elements and point masses watched by the guard
    do e = 1, nel
      do i = 1, 6
        if (i == 3 .or. i == 6) cycle
        if (free_of(el_dof(i, e)) > 0) trans(free_of(el_dof(i, e))) = .true.
      end do
    end do
    do e = 1, nlm
      do i = 1, 2
        if (free_of(lm_dof(i, e)) > 0) trans(free_of(lm_dof(i, e))) = .true.
      end do
    end do
    if (sys%nsl > 0) sys%tv = sl_val(:, :, 1)
    if (init_accel /= 0) then   ! with the geometric stiffness of the first sample (starts away from rest)
      call initial_axial_forces(sys, geo_mode, rig(:, :, 1), q_free, q_val, u0, status)
      if (status /= STATUS_OK) return
      call consistent_acceleration(sys, rig(:, :, 1), q_free, q_val(:, 1), u0, v0, a0, status)
      if (status /= STATUS_OK) return
      p0 = a0
    end if
    call newmark_run(sys, rig, sl_val, q_free, q_val, dt, alpha_m, alpha_f, beta, gamma, out_every, u0, v0, a0, p0, &
                     uf, vf, af, status, fail_step, nvalid, geo_mode, geo_tol, geo_maxit, nf, geo_iters, &
                     trans, div_limit)
  end subroutine ked_run

  !> Dense system matrices over the free DOFs at one rigid sample:
  !> mm = M, cm = Cg + Rayleigh, km = K + Kc; f = rigid-inertia load over ALL DOFs.
  subroutine ked_matrices(nlinks, ndof, nel, nlm, nri, nfree, nsl1, nnz, &
                          free_of, el_link, el_dof, el_prop, lm_link, lm_dof, lm_prop, ri_link, ri_dof, ri_prop, &
                          sl_of, sl_ptr, sl_col, load_model, rayleigh, rig, tv, mm, cm, km, f, status)
    integer, intent(in) :: nlinks, ndof, nel, nlm, nri, nfree, nsl1, nnz
    integer, intent(in) :: sl_of(ndof), sl_ptr(nsl1), sl_col(nnz)
    real(dp), intent(in) :: tv(3, nnz)   !< slave-row coefficients at the sample
    integer, intent(in) :: free_of(ndof), el_link(nel), el_dof(6, nel)
    real(dp), intent(in) :: el_prop(5, nel)
    integer, intent(in) :: lm_link(nlm), lm_dof(2, nlm)
    real(dp), intent(in) :: lm_prop(2, nlm)
    integer, intent(in) :: ri_link(nri), ri_dof(nri)
    real(dp), intent(in) :: ri_prop(nri)
    integer, intent(in) :: load_model
    real(dp), intent(in) :: rayleigh(2)
    real(dp), intent(in) :: rig(5, nlinks)
    real(dp), intent(out) :: mm(nfree, nfree), cm(nfree, nfree), km(nfree, nfree), f(ndof)
    integer, intent(out) :: status
    type(ked_system) :: sys
    real(dp), allocatable :: ab(:, :), r(:), z(:)
    mm = 0.0_dp; cm = 0.0_dp; km = 0.0_dp; f = 0.0_dp
    call build(sys, nlinks, ndof, free_of, el_link, el_dof, el_prop, lm_link, lm_dof, lm_prop, &
               ri_link, ri_dof, ri_prop, sl_of, sl_ptr, sl_col, load_model, rayleigh, status)
    if (status /= STATUS_OK) return
    if (sys%nfree /= nfree) then
      status = STATUS_BAD_INPUT
      return
    end if
    sys%tv = tv
    allocate (ab(band_rows(sys%kl, sys%ku), nfree), r(nfree), z(nfree))
    z = 0.0_dp
    call sys%assemble(rig, 0.0_dp, 0.0_dp, z, z, ab, r)
    mm = band_to_dense(ab, sys%kl, sys%ku, nfree)
    call sys%assemble(rig, 1.0_dp, 0.0_dp, z, z, ab, r)
    cm = band_to_dense(ab, sys%kl, sys%ku, nfree) - mm
    call sys%assemble(rig, 0.0_dp, 1.0_dp, z, z, ab, r)
    km = band_to_dense(ab, sys%kl, sys%ku, nfree) - mm
    call sys%rigid_load(rig, f)
  end subroutine ked_matrices

  !> Rigid-inertia loads over ALL DOFs at ns rigid samples (for output and comparison).
  subroutine ked_loads(nlinks, ndof, nel, nlm, nri, ns, nsl1, nnz, &
                       free_of, el_link, el_dof, el_prop, lm_link, lm_dof, lm_prop, ri_link, ri_dof, ri_prop, &
                       sl_of, sl_ptr, sl_col, load_model, rig, f, status)
    integer, intent(in) :: nlinks, ndof, nel, nlm, nri, ns, nsl1, nnz
    integer, intent(in) :: sl_of(ndof), sl_ptr(nsl1), sl_col(nnz)
    integer, intent(in) :: free_of(ndof), el_link(nel), el_dof(6, nel)
    real(dp), intent(in) :: el_prop(5, nel)
    integer, intent(in) :: lm_link(nlm), lm_dof(2, nlm)
    real(dp), intent(in) :: lm_prop(2, nlm)
    integer, intent(in) :: ri_link(nri), ri_dof(nri)
    real(dp), intent(in) :: ri_prop(nri)
    integer, intent(in) :: load_model
    real(dp), intent(in) :: rig(5, nlinks, ns)
    real(dp), intent(out) :: f(ndof, ns)
    integer, intent(out) :: status
    type(ked_system) :: sys
    integer :: i
    f = 0.0_dp
    call build(sys, nlinks, ndof, free_of, el_link, el_dof, el_prop, lm_link, lm_dof, lm_prop, &
               ri_link, ri_dof, ri_prop, sl_of, sl_ptr, sl_col, load_model, [0.0_dp, 0.0_dp], status)
    if (status /= STATUS_OK) return
    do i = 1, ns
      call sys%rigid_load(rig(:, :, i), f(:, i))
    end do
  end subroutine ked_loads

  !> Dense geometric stiffness over the free DOFs at one rigid sample for given element axial
  !> forces nax [N] (tension > 0): kgm = sum_e nax(e) Kg_e rotated to the link angle.
  subroutine ked_geometric_matrix(nlinks, ndof, nel, nlm, nri, nfree, nsl1, nnz, &
                                  free_of, el_link, el_dof, el_prop, lm_link, lm_dof, lm_prop, ri_link, ri_dof, &
                                  ri_prop, sl_of, sl_ptr, sl_col, rig, tv, nax, kgm, status)
    integer, intent(in) :: nlinks, ndof, nel, nlm, nri, nfree, nsl1, nnz
    integer, intent(in) :: sl_of(ndof), sl_ptr(nsl1), sl_col(nnz)
    real(dp), intent(in) :: tv(3, nnz)
    integer, intent(in) :: free_of(ndof), el_link(nel), el_dof(6, nel)
    real(dp), intent(in) :: el_prop(5, nel)
    integer, intent(in) :: lm_link(nlm), lm_dof(2, nlm)
    real(dp), intent(in) :: lm_prop(2, nlm)
    integer, intent(in) :: ri_link(nri), ri_dof(nri)
    real(dp), intent(in) :: ri_prop(nri)
    real(dp), intent(in) :: rig(5, nlinks), nax(nel)
    real(dp), intent(out) :: kgm(nfree, nfree)
    integer, intent(out) :: status
    type(ked_system) :: sys
    real(dp), allocatable :: ab(:, :), r(:), z(:)
    kgm = 0.0_dp
    call build(sys, nlinks, ndof, free_of, el_link, el_dof, el_prop, lm_link, lm_dof, lm_prop, &
               ri_link, ri_dof, ri_prop, sl_of, sl_ptr, sl_col, 1, [0.0_dp, 0.0_dp], status)
    if (status /= STATUS_OK) return
    if (sys%nfree /= nfree) then
      status = STATUS_BAD_INPUT
      return
    end if
    sys%tv = tv
    allocate (ab(band_rows(sys%kl, sys%ku), nfree), r(nfree), z(nfree))
    z = 0.0_dp
    sys%nax = nax
    sys%geo = .true.
    call sys%assemble(rig, 0.0_dp, 1.0_dp, z, z, ab, r, static=.true.)
    kgm = band_to_dense(ab, sys%kl, sys%ku, nfree)
    sys%geo = .false.
    call sys%assemble(rig, 0.0_dp, 1.0_dp, z, z, ab, r, static=.true.)
    kgm = kgm - band_to_dense(ab, sys%kl, sys%ku, nfree)
  end subroutine ked_geometric_matrix

  ! ---------------------------------------------------------------- benchmark-only routines (flexmech bench)

  !> nrep factorizations and solves of the n x n matrix a with b: mode 1 banded LU (dgbtrf/dgbtrs,
  !> half bandwidth kb, a copied into band storage each time), mode 2 dense LU (dgetrf/dgetrs, a copied).
  !> x returns the last solution. For timing the two LAPACK paths against each other (flexmech bench).
  subroutine bench_solve(n, kb, nrep, mode, a, b, x, status)
    integer, intent(in) :: n, kb, nrep, mode
    real(dp), intent(in) :: a(n, n), b(n)
    real(dp), intent(out) :: x(n)
    integer, intent(out) :: status
    real(dp), allocatable :: ab(:, :), ad(:, :)
    integer, allocatable :: ipiv(:)
    integer :: rep, i, j, info, ld
    status = STATUS_BAD_INPUT
    x = 0.0_dp
    if (n < 1 .or. kb < 0 .or. kb >= max(n, 1) + 1 .or. nrep < 1 .or. mode < 1 .or. mode > 2) return
    allocate (ipiv(n))
    info = 0
    if (mode == 1) then
      ld = 3*kb + 1
      allocate (ab(ld, n))
      do rep = 1, nrep
        ab = 0.0_dp
        do j = 1, n
          do i = max(1, j - kb), min(n, j + kb)
            ab(2*kb + 1 + i - j, j) = a(i, j)
          end do
        end do
        x = b
        call dgbtrf(n, n, kb, kb, ab, ld, ipiv, info)
        if (info /= 0) exit
        call dgbtrs('N', n, kb, kb, 1, ab, ld, ipiv, x, n, info)
      end do
    else
      allocate (ad(n, n))
      do rep = 1, nrep
        ad = a
        x = b
        call dgetrf(n, n, ad, n, ipiv, info)
        if (info /= 0) exit
        call dgetrs('N', n, 1, ad, n, ipiv, x, n, info)
      end do
    end if
    status = lapack_status(info)
  end subroutine bench_solve

  !> A tight scalar multiply-add loop: 8 independent chains s = s*c + d, n iterations, 16*n flops
  !> (the achievable arithmetic rate of one core with the kernels' compiler flags); s returns their sum.
  subroutine bench_peak(n, c, d, s)
    integer, intent(in) :: n
    real(dp), intent(in) :: c, d
    real(dp), intent(out) :: s
    real(dp) :: s1, s2, s3, s4, s5, s6, s7, s8
    integer :: i
    s1 = 0.0_dp; s2 = 0.1_dp; s3 = 0.2_dp; s4 = 0.3_dp; s5 = 0.4_dp; s6 = 0.5_dp; s7 = 0.6_dp; s8 = 0.7_dp
    do i = 1, n
      s1 = s1*c + d; s2 = s2*c + d; s3 = s3*c + d; s4 = s4*c + d
      s5 = s5*c + d; s6 = s6*c + d; s7 = s7*c + d; s8 = s8*c + d
    end do
    s = s1 + s2 + s3 + s4 + s5 + s6 + s7 + s8
  end subroutine bench_peak

end module flexmech_api
