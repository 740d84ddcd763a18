!> Flat API of the coupled and nonlinear models facing f2py: plain arrays and scalars only.  Python
!> (flexmech_py/coupled.py) packs the model into ispec(ni), rspec(nr) (layout: flexmech_coupled_system,
!> coupled_build) and calls these through flexmech_py.kernels; every routine returns a status code
!> (flexmech_lapack: 4 bad input, 5 Newton failure, 6 divergence limit).
!>   ndof all DOFs (q, v, a), nfree free DOFs, nc1 = max(1, constraint rows), nframes output frames.
module flexmech_coupled_api
  use flexmech_kinds, only: dp
  use flexmech_lapack, only: STATUS_OK, STATUS_BAD_INPUT
  use flexmech_coupled_system, only: coupled_system, coupled_build
  use flexmech_coupled_rows, only: coupled_rows
  use flexmech_coupled_element, only: coupled_set_inertia
  use flexmech_coupled_assembly, only: coupled_dense, coupled_residual
  use flexmech_coupled_run, only: coupled_run, coupled_set_newton, coupled_set_start
  use flexmech_coupled_solve, only: coupled_set_solver, coupled_set_multipliers, newton_solver, ns_setup, ns_structure
  use flexmech_coupled_storage, only: link_mats
  use flexmech_coupled_post, only: coupled_post
  use flexmech_control, only: ctl_setup, ctl_save, ctl_places, CTL_NCI, CTL_NCP, CTL_NST
  use flexmech_markers, only: con_valid
  implicit none
  private
  public :: cpl_run, cpl_dense, cpl_post, cpl_set_solver, cpl_set_newton, cpl_set_start, cpl_set_inertia, cpl_residuals, cpl_rows
  public :: cpl_set_multipliers, cpl_structure

contains

  !> Build and check the sizes the caller expects (ndof DOFs; nc1 >= the constraint rows).
  subroutine build_checked(ispec, rspec, ndof, nc1, sys, status)
    integer, intent(in) :: ispec(:), ndof, nc1
    real(dp), intent(in) :: rspec(:)
    type(coupled_system), intent(out) :: sys
    integer, intent(out) :: status
    call coupled_build(ispec, rspec, sys, status)
    if (status /= STATUS_OK) return
    if (sys%ndof /= ndof .or. nc1 < max(1, sys%nc)) status = STATUS_BAD_INPUT
  end subroutine build_checked

  !> Run the model (generalized-alpha-Newton; Newmark for alpha_m = alpha_f = 0) over nsteps steps of
  !> dt from time t0 [s].  cval (3, nc1, nsteps+1): [value, rate, acceleration] of every constraint row
  !> at every step.  q, v, a, pa (ndof) and carry (nc1 + 2) [multipliers, Newton length scale [m],
  !> work of the inputs [J]]: on entry the initial state (fixed entries hold their values), on exit the
  !> last state reached.  start = 1: a fresh run (the free accelerations a and the multipliers made
  !> consistent, pa = a, carry not read); 0: the same with pa as given; 2: continue the run that left
  !> (q, v, a, pa, carry) (the same steps as one uninterrupted run).  div_limit [m] > 0: the run stops
  !> with status 6 when coupled_elastic_measure (flexmech_coupled_run) exceeds it; seg_link(nseg) is the
  !> mechanism link of each segment (segments of a link listed consecutively from its start).  Frames: qf, vf, af (ndof, nframes), lf (nc1, nframes)
  !> the multipliers (constraint forces), la (nc1, nframes) their largest step-to-step alternating part
  !> since the last frame (flexmech_alternation), ef (4, nframes) [kinetic, potential, work of the inputs, max
  !> Newton iterations since the last frame]; nvalid: number of valid frames; newton(4): the last
  !> iteration's residual, correction and acceleration norms, factorizations (coupled_run).
  !> Feedback controllers (flexmech_control: the layout of cint (12, ncl), cpar (17, ncl), the tables'
  !> splines ctab_t (nct), ctab_c (4, nct) and their state cst (NST, ncl), read on a continued run and
  !> written back); padding controllers have cint(1, :) = 0.  uf (ncl, nframes): their outputs.
  subroutine cpl_run(ni, nr, ndof, nc1, nsteps, nframes, nseg, ncl, nct, nst, ispec, rspec, cval, t0, dt, &
                     alpha_m, alpha_f, beta, gamma, out_every, tol, maxit, start, div_limit, seg_link, q, v, a, &
                     pa, carry, cint, cpar, ctab_t, ctab_c, cst, qf, vf, af, lf, la, ef, uf, status, fail_step, &
                     iters, nvalid, newton)
    integer, intent(in) :: ni, nr, ndof, nc1, nsteps, nframes, nseg, ncl, nct, nst
    ! Python passes none of the sizes: f2py takes them from the arrays' shapes, nframes from out_every
    !f2py intent(hide) :: ni, nr, ndof, nc1, nsteps, nseg, ncl, nct, nst
    !f2py integer intent(hide), depend(cval, out_every) :: nframes = (out_every > 0 ? (shape(cval, 2) - 1)/out_every + 1 : 1)
    integer, intent(in) :: ispec(ni)
    real(dp), intent(in) :: rspec(nr)
    real(dp), intent(in) :: cval(3, nc1, nsteps + 1)
    real(dp), intent(in) :: t0, dt, alpha_m, alpha_f, beta, gamma, tol, div_limit
    integer, intent(in) :: out_every, maxit, start
    integer, intent(in) :: seg_link(nseg)
    real(dp), intent(inout) :: q(ndof), v(ndof), a(ndof), pa(ndof), carry(nc1 + 2)
    integer, intent(in) :: cint(12, ncl)
    real(dp), intent(in) :: cpar(17, ncl), ctab_t(nct), ctab_c(4, nct)
    real(dp), intent(inout) :: cst(nst, ncl)
    real(dp), intent(out) :: qf(ndof, nframes), vf(ndof, nframes), af(ndof, nframes), ef(4, nframes)
    real(dp), intent(out) :: lf(nc1, nframes), la(nc1, nframes), uf(ncl, nframes)
    integer, intent(out) :: status, fail_step, iters, nvalid
    real(dp), intent(out) :: newton(4)
    type(coupled_system) :: sys
    real(dp) :: ufc(ncl, nframes)
    logical :: ok
    qf = 0.0_dp; vf = 0.0_dp; af = 0.0_dp; ef = 0.0_dp; lf = 0.0_dp; la = 0.0_dp; fail_step = 0; iters = 0; nvalid = 0
    newton = 0.0_dp; uf = 0.0_dp
    call build_checked(ispec, rspec, ndof, nc1, sys, status)
    if (status /= STATUS_OK) return
    call ctl_setup(sys%ctl, cint, cpar, ctab_t, ctab_c, cst, dt, sys%nd, ok)
    ok = ok .and. .not. any(cint(10, :) /= 0 .and. (cint(11, :) < 1 .or. cint(11, :) > sys%nmk .or. &
                                                    cint(12, :) < 1 .or. cint(12, :) > sys%nmk))
    if (.not. ok .or. nst /= CTL_NST .or. CTL_NCI /= 12 .or. CTL_NCP /= 17) then
      status = STATUS_BAD_INPUT
      return
    end if
    ufc = 0.0_dp
    call coupled_run(sys, cval, t0, dt, alpha_m, alpha_f, beta, gamma, out_every, tol, maxit, start, &
                     div_limit, seg_link, q, v, a, pa, carry, qf, vf, af, lf, la, ef, status, fail_step, iters, &
                     nvalid, newton, ufc(1:sys%ctl%n, :))
    call ctl_save(sys%ctl, cint, cst)
    uf(ctl_places(cint), :) = ufc(1:sys%ctl%n, :)
  end subroutine cpl_run


  !> Linear solver of every later cpl_run in this process: mode -1 (default) automatic, 1 condensed
  !> onto the segment-end positions, 0 the whole band, 2 the bordered saddle band of a layout that
  !> has one (the nonlinear model; docs/theory.md sections 11.3, 12.6).  status 4 for another mode.
  subroutine cpl_set_solver(mode, status)
    integer, intent(in) :: mode
    integer, intent(out) :: status
    call coupled_set_solver(mode, status)
  end subroutine cpl_set_solver

  !> How every later cpl_run reaches the constraint rows' multipliers when S is one band: -1 (default)
  !> the cheaper by a flop estimate, 0 the dense Schur complement, 1 the band LU of the whole
  !> saddle-point system (flexmech_saddle_band).  status 4 for another mode.
  subroutine cpl_set_multipliers(mode, status)
    integer, intent(in) :: mode
    integer, intent(out) :: status
    call coupled_set_multipliers(mode, status)
  end subroutine cpl_set_multipliers

  !> When every later cpl_run rebuilds the iteration matrix in a step: 0 once per step (modified
  !> Newton), 1 at every iteration (Newton), 2 (default) once and again when an iteration contracts
  !> the correction by less than 0.1.  status 4 for another mode.
  subroutine cpl_set_newton(mode, status)
    integer, intent(in) :: mode
    integer, intent(out) :: status
    call coupled_set_newton(mode, status)
  end subroutine cpl_set_newton

  !> Where every later cpl_run starts a step's Newton iterations: 0 at the last acceleration, 1
  !> (default) at the position q_n + dt v_n, 2 at q_n.  status 4 for another mode.
  subroutine cpl_set_start(mode, status)
    integer, intent(in) :: mode
    integer, intent(out) :: status
    call coupled_set_start(mode, status)
  end subroutine cpl_set_start

  !> Inertia in every later call: 0 (default) in closed form (one-element segments; the residual of
  !> longer ones), 1 by Gauss points (the check of the closed form).  status 4 for another mode.
  subroutine cpl_set_inertia(mode, status)
    integer, intent(in) :: mode
    integer, intent(out) :: status
    call coupled_set_inertia(mode, status)
  end subroutine cpl_set_inertia

  !> Residual (all DOFs; inertia, elastic, gravity and force drives, no constraint forces), M, C_v, K_t
  !> (dense, free DOFs) and [kinetic, potential] energy at one state and time t [s].
  subroutine cpl_dense(ni, nr, ndof, nfree, ispec, rspec, q, v, a, t, res, mm, cm, km, energy, status)
    integer, intent(in) :: ni, nr, ndof, nfree
    integer, intent(in) :: ispec(ni)
    real(dp), intent(in) :: rspec(nr), q(ndof), v(ndof), a(ndof), t
    real(dp), intent(out) :: res(ndof), mm(nfree, nfree), cm(nfree, nfree), km(nfree, nfree), energy(2)
    integer, intent(out) :: status
    type(coupled_system) :: sys
    res = 0.0_dp; mm = 0.0_dp; cm = 0.0_dp; km = 0.0_dp; energy = 0.0_dp
    call build_checked(ispec, rspec, ndof, huge(1), sys, status)
    if (status /= STATUS_OK) return
    if (sys%nfree /= nfree) then
      status = STATUS_BAD_INPUT
      return
    end if
    call coupled_dense(sys, q, v, a, t, res, mm, cm, km, energy)
  end subroutine cpl_dense

  !> Residuals res(:, s) (all DOFs, no constraint forces; as cpl_dense) at ns configurations q(:, s)
  !> with the velocities v and accelerations a of all of them, at time t [s].
  subroutine cpl_residuals(ni, nr, ndof, ns, ispec, rspec, q, v, a, t, res, status)
    integer, intent(in) :: ni, nr, ndof, ns
    integer, intent(in) :: ispec(ni)
    real(dp), intent(in) :: rspec(nr), q(ndof, ns), v(ndof), a(ndof), t
    real(dp), intent(out) :: res(ndof, ns)
    integer, intent(out) :: status
    type(coupled_system) :: sys
    res = 0.0_dp
    call build_checked(ispec, rspec, ndof, huge(1), sys, status)
    if (status /= STATUS_OK) return
    call coupled_residual(sys, q, v, a, t, res)
  end subroutine cpl_residuals

  !> Constraint rows at ns configurations q(:, s) (velocities v): values g (nc1, ns) (angles not
  !> wrapped) and gradients gq (nc1, ndof, ns) over all DOFs; rows past the model's nc are zero.
  subroutine cpl_rows(ni, nr, ndof, nc1, ns, ispec, rspec, q, v, g, gq, status)
    integer, intent(in) :: ni, nr, ndof, nc1, ns
    integer, intent(in) :: ispec(ni)
    real(dp), intent(in) :: rspec(nr), q(ndof, ns), v(ndof)
    real(dp), intent(out) :: g(nc1, ns), gq(nc1, ndof, ns)
    integer, intent(out) :: status
    type(coupled_system) :: sys
    g = 0.0_dp; gq = 0.0_dp
    call build_checked(ispec, rspec, ndof, nc1, sys, status)
    if (status /= STATUS_OK) return
    if (sys%nc > 0) call coupled_rows(sys, q, v, g(1:sys%nc, :), gq(1:sys%nc, :, :))
  end subroutine cpl_rows

  !> Frames (qf, vf, af (ndof, nf), multipliers lf (nc1, nf), times tf (nf)) evaluated on the model
  !> (flexmech_coupled_post): marker states mks (9, nmk, nf), measure rows meas (4, nm) with
  !> directions meas_dir (2, nm) -> mv (3, nm, nf), force-drive values dvals (nd1, nf) (nd1 >= the
  !> force drives), segment-end residuals rend (4, nseg, nf).
  subroutine cpl_post(ni, nr, ndof, nc1, nf, nmk, nm, nd1, nseg, ispec, rspec, qf, vf, af, lf, tf, meas, &
                      meas_dir, mks, mv, dvals, rend, status)
    integer, intent(in) :: ni, nr, ndof, nc1, nf, nmk, nm, nd1, nseg
    integer, intent(in) :: ispec(ni), meas(4, nm)
    real(dp), intent(in) :: rspec(nr), qf(ndof, nf), vf(ndof, nf), af(ndof, nf), lf(nc1, nf), tf(nf)
    real(dp), intent(in) :: meas_dir(2, nm)
    real(dp), intent(out) :: mks(9, nmk, nf), mv(3, nm, nf), dvals(nd1, nf), rend(4, nseg, nf)
    integer, intent(out) :: status
    type(coupled_system) :: sys
    integer :: i
    mks = 0.0_dp; mv = 0.0_dp; dvals = 0.0_dp; rend = 0.0_dp
    call build_checked(ispec, rspec, ndof, nc1, sys, status)
    if (status /= STATUS_OK) return
    if (sys%nmk /= nmk .or. sys%nseg /= nseg .or. nd1 < sys%nd .or. any(meas(2:3, :) < 1) .or. &
        any(meas(2:3, :) > nmk) .or. .not. all([(con_valid(meas(1, i), meas(4, i)), i = 1, nm)])) then
      status = STATUS_BAD_INPUT
      return
    end if
    call coupled_post(sys, qf, vf, af, lf, tf, meas, meas_dir, mks, mv, dvals, rend)
  end subroutine cpl_post

  !> The linear algebra a cpl_run would use now (the solver modes set), at the configuration (q, v):
  !> info = [path (0 band with the multipliers' Schur complement, 1 saddle band, 2 condensed segments,
  !> 3 bordered saddle band), unknowns in the band, its half width, unknowns eliminated densely,
  !> floating-point operations of one factorization, of one solve] (flexmech_coupled_solve:
  !> ns_structure; machine-independent).
  subroutine cpl_structure(ni, nr, ndof, ispec, rspec, q, v, info, status)
    integer, intent(in) :: ni, nr, ndof
    integer, intent(in) :: ispec(ni)
    real(dp), intent(in) :: rspec(nr), q(ndof), v(ndof)
    real(dp), intent(out) :: info(6)
    integer, intent(out) :: status
    type(coupled_system) :: sys
    type(link_mats) :: lm
    type(newton_solver) :: ns
    info = 0.0_dp
    call build_checked(ispec, rspec, ndof, huge(1), sys, status)
    if (status /= STATUS_OK) return
    call ns_setup(sys, q, v, lm, ns)
    info = ns_structure(sys, lm, ns)
  end subroutine cpl_structure

end module flexmech_coupled_api
