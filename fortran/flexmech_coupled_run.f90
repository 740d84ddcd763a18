!> The time loop of the coupled and nonlinear models (the system: flexmech_coupled_system).
!> Integration: generalized-alpha (Arnold & Bruls 2007; Newmark (beta, gamma) for am = af = 0) in
!> acceleration form with Newton iterations on the true acceleration a_{n+1}, the equations and the
!> constraints holding exactly at t_{n+1} (see flexmech_newmark and docs/theory.md section 15); the
!> iteration matrix S = M + gamma' dt C_v + beta' dt^2 K_t (flexmech_coupled_assembly) is built and
!> factorized once per step and again within the step when an iteration contracts too little
!> (NEWTON_AUTO, docs/theory.md 12.2).  M and C_v are exact; K_t holds the elastic, chord and elastic
!> inertial terms, and for the nonlinear model's absolute node angles the whole derivative of the
!> residual (docs/theory.md 12.1); the coupled model's chord dependence of the inertia, the constraint
!> curvature and the force laws' dependence on the configuration are in the residual only.  The
!> linear algebra of a correction (the structure of S with the constraint rows): flexmech_coupled_solve.
module flexmech_coupled_run
  use flexmech_kinds, only: dp
  use flexmech_lapack, only: STATUS_OK, STATUS_BAD_INPUT, STATUS_NEWTON, STATUS_DIVERGED
  use flexmech_markers, only: marker_state, CON_POINT, CON_ANGLE, MAXCOL
  use flexmech_coupled_system, only: coupled_system, set_mode, wrap
  use flexmech_coupled_rows, only: eval_row, drive_load
  use flexmech_coupled_storage, only: link_mats
  use flexmech_coupled_assembly, only: assemble, assemble_residual
  use flexmech_coupled_solve, only: newton_solver, ns_setup, ns_factor, ns_rows, ns_correction, ns_gdot
  use flexmech_alternation, only: alternation_monitor, alt_setup, alt_step, alt_take
  implicit none
  private
  public :: coupled_run, coupled_elastic_measure
  public :: coupled_set_newton, NEWTON_MODIFIED, NEWTON_FULL, NEWTON_AUTO
  public :: coupled_set_start, START_ACCELERATION, START_VELOCITY

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

contains

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
  !> la (nc, nframes): the largest step-to-step alternating part of every multiplier since the last
  !> frame (flexmech_alternation; 0 where none), in the multipliers' units.
  !> Divergence guard: coupled_elastic_measure > div_limit [m] after a step stops the run with
  !> STATUS_DIVERGED (fail_step = that step).  newton(4) on return: [norm of the residual (free DOFs,
  !> with the constraint forces) before the last iteration, norm of its acceleration correction, norm
  !> of the accelerations, number of factorizations of the iteration matrix].
  subroutine coupled_run(sys, cval, t0, dt, alpha_m, alpha_f, beta, gamma, out_every, tol, maxit, &
                         start, div_limit, seg_link, q, v, a, p, carry, qf, vf, af, lf, la, ef, status, &
                         fail_step, iters, nvalid, newton)
    type(coupled_system), intent(in) :: sys
    real(dp), intent(in) :: cval(:, :, :)        !< (3, >= nc, nsteps+1) [value, rate, acceleration] of the rows
    real(dp), intent(in) :: t0, dt, tol
    real(dp), intent(in) :: alpha_m, alpha_f, beta, gamma   !< generalized-alpha parameters
    integer, intent(in) :: out_every, maxit, start
    real(dp), intent(in) :: div_limit              !< divergence limit [m]
    integer, intent(in) :: seg_link(:)             !< (nseg) link of each segment
    real(dp), intent(inout) :: q(:), v(:), a(:), p(:)
    real(dp), intent(inout) :: carry(:)            !< (nc1 + 2) [multipliers, lref [m], work [J]]
    real(dp), intent(out) :: qf(:, :), vf(:, :), af(:, :), lf(:, :), la(:, :), ef(:, :)
    integer, intent(out) :: status, fail_step, iters, nvalid
    real(dp), intent(out) :: newton(4)
    real(dp), allocatable :: res(:), qs(:), vs(:), w(:)
    real(dp), allocatable :: qn(:), lamn(:), lam(:), g0(:), lam0(:), th0(:), tau0(:), gsh(:)
    real(dp), allocatable :: th1(:), tau1(:), g1(:)      ! step_work's drive states and row values
    integer, allocatable :: freeidx(:)
    integer :: nsteps, n, it, frame, itmax_frame, nf, nc, kat
    !> restarts at q_n that kept the predictor's matrix: (1) converged with it, (2) rebuilt it after all
    integer :: restart_kept(2)
    real(dp) :: energy(2), work, da_norm, a_norm, da_prev, c1, betap, gammap, lref, t
    logical :: converged, refresh, second, kept
    type(link_mats) :: lm
    type(newton_solver) :: ns
    type(alternation_monitor) :: alt     ! the multipliers' step-to-step alternation
    status = STATUS_OK; fail_step = 0; iters = 0; nvalid = 0; newton = 0.0_dp
    nsteps = size(cval, 3) - 1
    nf = sys%nfree
    nc = sys%nc
    restart_kept = 0
    if (out_every < 1 .or. dt <= 0.0_dp .or. nsteps < 0 .or. size(qf, 2) /= nsteps/out_every + 1 .or. &
        size(cval, 2) < nc .or. size(lf, 1) < nc .or. size(la, 1) < nc .or. size(la, 2) /= size(qf, 2) .or. &
        beta <= 0.0_dp .or. gamma < 0.5_dp .or. &
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
    call alt_setup(alt, nc)
    call alt_step(alt, lam(1:nc))
    la = 0.0_dp
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
      call alt_step(alt, lam(1:nc))
      if (mod(n, out_every) == 0) then
        call assemble(sys, q, v, a, t, .false., 0.0_dp, 0.0_dp, res, lm, energy)
        frame = frame + 1
        qf(:, frame) = q; vf(:, frame) = v; af(:, frame) = a; lf(1:nc, frame) = lam(1:nc)
        call alt_take(alt, la(1:nc, frame))
        ef(:, frame) = [energy(1), energy(2), work, real(itmax_frame, dp)]
        nvalid = frame
        itmax_frame = 0
      end if
    end do
    call save_carry()

  contains

    !> The solver (the storage of S, the constraint gradients' pattern, the path) and the work arrays.
    subroutine setup_work()
      call ns_setup(sys, q, v, lm, ns)
      allocate (res(sys%ndof), qs(sys%ndof), vs(sys%ndof), w(sys%ndof), qn(sys%ndof), freeidx(nf))
      freeidx = ns%freeidx
      w = 0.0_dp
      allocate (lam(max(1, nc)), lamn(max(1, nc)), g0(max(1, nc)), lam0(max(1, nc)), gsh(max(1, nc)), &
                th0(max(1, sys%nd)), tau0(max(1, sys%nd)), th1(max(1, sys%nd)), tau1(max(1, sys%nd)), g1(max(1, nc)))
    end subroutine setup_work

    !> The Newton iterations of step n (predictor qs, vs set): converged, it and the state at the
    !> accepted iterate; status on a failed factorization or solve.
    subroutine newton_iterations(n)
      integer, intent(in) :: n
      converged = .false.
      kept = .false.
      da_prev = huge(1.0_dp)
      refresh = .true.
      qn = q; lamn = lam
      second = .false.
      kat = 0
      if (start_mode == START_VELOCITY) call put_at(q, dt)
      if (start_mode == START_POSITION) call restart_at_qn()
      do it = 1, merge(2*maxit, maxit, start_mode /= START_ACCELERATION)
        q(freeidx) = qs(freeidx) + (betap*dt*dt)*a(freeidx)
        v(freeidx) = vs(freeidx) + (gammap*dt)*a(freeidx)
        if (refresh) then
          call assemble(sys, q, v, a, t, .true., gammap*dt, betap*dt*dt, res, lm, energy)
        else
          call assemble_residual(sys, q, v, a, t, res, lm)
        end if
        if (refresh) then
          call factor()
          if (status /= STATUS_OK) exit
        end if
        ! gradients (the factorization's part with them after a factorization), values, G^T lam in res
        call ns_rows(sys, lm, ns, q, v, cval(1, :, n + 1), lam, res, status)
        if (status /= STATUS_OK) exit
        gsh(1:nc) = ns%gval(1:nc)/(betap*dt*dt)
        call ns_correction(sys, lm, ns, res, gsh, a, lam, da_norm, a_norm, newton, status)
        if (status /= STATUS_OK) exit
        iters = iters + 1
        kat = kat + 1                ! iterations of this attempt
        refresh = newton_mode == NEWTON_FULL .or. &
                  (newton_mode == NEWTON_AUTO .and. kat > 1 .and. da_norm > NEWTON_RATE*da_prev)
        if (it == 1 .and. start_mode == START_VELOCITY .and. betap*dt*dt*da_norm > RESTART_MOVE*lref) then
          ! the start q_n + dt v_n was far (an unresolved stiff mode's velocity): start again at q_n,
          ! with the predictor's matrix while that has served the run's earlier restarts (NEWTON_AUTO)
          call restart_at_qn()
          kept = newton_mode == NEWTON_AUTO .and. restart_kept(1) >= restart_kept(2)
          refresh = .not. kept
          cycle
        end if
        if (kept .and. refresh) then     ! the kept matrix contracted too little: rebuilt after all
          restart_kept(2) = restart_kept(2) + 1
          kept = .false.
        end if
        if (accepted()) then
          converged = .true.
          if (kept) restart_kept(1) = restart_kept(1) + 1
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
      call put_at(qn, 0.0_dp)
      da_prev = huge(1.0_dp)
      kat = 0
    end subroutine restart_at_qn

    !> The acceleration a (free DOFs) that puts the step's position q = qs + betap dt^2 a at
    !> qb + h v (h [s]: 0 for qb itself).
    subroutine put_at(qb, h)
      real(dp), intent(in) :: qb(:), h
      integer :: i, j
      do i = 1, nf             ! a loop: vector subscripts would copy through the heap
        j = freeidx(i)
        a(j) = (qb(j) + h*v(j) - qs(j))/(betap*dt*dt)
      end do
    end subroutine put_at

    !> The state a continuation needs besides (q, v, a, p): multipliers, lref, work.
    subroutine save_carry()
      carry = 0.0_dp
      carry(1:nc) = lam(1:nc)
      carry(size(carry) - 1) = lref
      carry(size(carry)) = work
    end subroutine save_carry

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
        call ns_rows(sys, lm, ns, q, v, cval(1, :, 1), lam, res, status)
        if (status /= STATUS_OK) return
        do j = 1, nc        ! the rows' acceleration residual G a - (cval'' - acc0)
          shift(j) = ns_gdot(ns, j, a(freeidx)) - (cval(3, j, 1) - ns%acc0(j))
        end do
        call ns_correction(sys, lm, ns, res, shift, a, lam, da_norm, a_norm, newton, status)
        if (status /= STATUS_OK) return
        dn = da_norm; an = a_norm
        if (dn <= 1.0e-3_dp*tol*(an + 1.0e-30) .or. dn > 0.5_dp*dn_prev) exit   ! converged, or round-off
        dn_prev = dn
      end do
      call assemble(sys, q, v, a, t0, .false., 0.0_dp, 0.0_dp, res, lm, energy)
    end subroutine initial_acceleration

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
      real(dp) :: dth
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

    !> Factorize the assembled S (flexmech_coupled_solve: its path) and count it.
    subroutine factor()
      newton(4) = newton(4) + 1.0_dp
      call ns_factor(sys, lm, ns, status)
    end subroutine factor

  end subroutine coupled_run

end module flexmech_coupled_run
