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
  use flexmech_coupled_rows, only: eval_row, drive_load, control_measure
  use flexmech_coupled_storage, only: link_mats
  use flexmech_coupled_assembly, only: assemble, assemble_residual
  use flexmech_coupled_solve, only: newton_solver, ns_setup, ns_factor, ns_rows, ns_correction, ns_gdot
  use flexmech_control, only: ctl_start, ctl_commit
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

  !> The state of one coupled_run: the integration constants, the step's predictor and work arrays,
  !> the Newton iteration's history, the solver (storage of S and the constraint gradients), the
  !> bookkeeping of the inputs' work and the multipliers' alternation, and the counters returned.
  type :: run_state
    real(dp) :: dt = 0.0_dp, tol = 0.0_dp, alpha_m = 0.0_dp, alpha_f = 0.0_dp, beta = 0.0_dp, gamma = 0.0_dp
    real(dp) :: c1 = 1.0_dp, betap = 0.0_dp, gammap = 0.0_dp   !< 1/(1 - alpha_m); beta', gamma' of S
    real(dp) :: lref = 1.0_dp          !< length scale of the mechanism [m] (floor of the Newton test)
    real(dp) :: t = 0.0_dp             !< time of the step being taken [s]
    integer :: maxit = 0, nf = 0, nc = 0
    real(dp), allocatable :: res(:), qs(:), vs(:), w(:), qn(:)   !< (ndof) residual, predictor, q_n
    real(dp), allocatable :: lam(:), lamn(:), gsh(:)             !< (max(1, nc)) multipliers, at t_n, shift
    integer, allocatable :: freeidx(:)                           !< (nf) the free DOFs
    ! the Newton iteration of the step
    integer :: it = 0, kat = 0          !< iteration of the step, of its current attempt
    !> restarts at q_n that kept the predictor's matrix: (1) converged with it, (2) rebuilt it after all
    integer :: restart_kept(2) = 0
    real(dp) :: da_norm = 0.0_dp, a_norm = 0.0_dp, da_prev = 0.0_dp
    logical :: converged = .false., refresh = .true., second = .false., kept = .false.
    ! the work of the inputs and the energies of the last assembly
    real(dp) :: work = 0.0_dp, energy(2) = 0.0_dp
    real(dp), allocatable :: g0(:), lam0(:), g1(:)                  !< (max(1, nc)) row values, multipliers
    real(dp), allocatable :: th0(:), tau0(:), th1(:), tau1(:)       !< (max(1, nd)) force drive states
    type(link_mats) :: lm
    type(newton_solver) :: ns
    type(alternation_monitor) :: alt     !< the multipliers' step-to-step alternation
    integer :: iters = 0                 !< Newton iterations of the run
    real(dp) :: newton(4) = 0.0_dp       !< coupled_run's newton output
  end type run_state

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
                         fail_step, iters, nvalid, newton, uf)
    type(coupled_system), intent(inout) :: sys   !< inout: the state of its controllers (sys%ctl)
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
    real(dp), intent(out), optional :: uf(:, :)   !< (controllers, nframes) their outputs [N m or N]
    type(run_state) :: rs
    integer :: nsteps, n, itmax_frame
    status = STATUS_OK; fail_step = 0; iters = 0; nvalid = 0; newton = 0.0_dp
    nsteps = size(cval, 3) - 1
    if (out_every < 1 .or. dt <= 0.0_dp .or. nsteps < 0 .or. size(qf, 2) /= nsteps/out_every + 1 .or. &
        size(cval, 2) < sys%nc .or. size(lf, 1) < sys%nc .or. size(la, 1) < sys%nc .or. size(la, 2) /= size(qf, 2) .or. &
        beta <= 0.0_dp .or. gamma < 0.5_dp .or. &
        alpha_m >= 1.0_dp .or. alpha_f >= 1.0_dp .or. .not. div_limit > 0.0_dp .or. &
        size(seg_link) /= sys%nseg .or. size(p) /= sys%ndof .or. size(carry) < max(1, sys%nc) + 2 .or. &
        start < 0 .or. start > 2) then
      status = STATUS_BAD_INPUT
      return
    end if
    if (any(seg_link < 1)) then
      status = STATUS_BAD_INPUT
      return
    end if
    call run_setup(rs, sys, dt, alpha_m, alpha_f, beta, gamma, tol, maxit, q, v)
    if (start == 2) rs%lref = carry(size(carry) - 1)
    if (start /= 2 .and. sys%ctl%n > 0) call control_step(sys, t0, q, v, .true.)
    call run_start(rs, sys, cval, t0, start, q, v, a, p, carry, status)
    if (status == STATUS_OK) then
      call store_frame(rs, 1, 0, q, v, a, qf, vf, af, lf, ef)
      if (present(uf)) uf(1:sys%ctl%n, 1) = sys%ctl%st(2, :)
      call alt_setup(rs%alt, rs%nc)
      call alt_step(rs%alt, rs%lam(1:rs%nc))
      la = 0.0_dp
      nvalid = 1
      call save_carry(rs, carry)
      itmax_frame = 0
      do n = 1, nsteps
        call run_step(rs, sys, cval(1, :, n + 1), t0 + n*dt, q, v, a, p, status)
        if (status == STATUS_OK) then
          if (coupled_elastic_measure(sys, seg_link, q) > div_limit) status = STATUS_DIVERGED
        end if
        if (status /= STATUS_OK) then
          fail_step = n
          exit
        end if
        itmax_frame = max(itmax_frame, rs%it)
        call step_work(rs, sys, q, v)
        if (sys%ctl%n > 0) then         ! the controllers' new state; the next step's work from their new output
          call control_step(sys, rs%t, q, v, .false.)
          call drive_state(sys, rs%t, q, v, rs%th0, rs%tau0)
        end if
        call alt_step(rs%alt, rs%lam(1:rs%nc))
        if (mod(n, out_every) == 0) then
          call assemble(sys, q, v, a, rs%t, .false., 0.0_dp, 0.0_dp, rs%res, rs%lm, rs%energy)
          nvalid = nvalid + 1
          call store_frame(rs, nvalid, itmax_frame, q, v, a, qf, vf, af, lf, ef)
          if (present(uf)) uf(1:sys%ctl%n, nvalid) = sys%ctl%st(2, :)
          call alt_take(rs%alt, la(1:rs%nc, nvalid))
          itmax_frame = 0
        end if
      end do
      if (status == STATUS_OK) call save_carry(rs, carry)
    end if
    iters = rs%iters
    newton = rs%newton
  end subroutine coupled_run

  !> The run's constants, the solver (the storage of S, the constraint gradients' pattern, the path)
  !> and the work arrays; lref from the configuration q.
  subroutine run_setup(rs, sys, dt, alpha_m, alpha_f, beta, gamma, tol, maxit, q, v)
    type(run_state), intent(inout) :: rs
    type(coupled_system), intent(in) :: sys
    real(dp), intent(in) :: dt, alpha_m, alpha_f, beta, gamma, tol, q(:), v(:)
    integer, intent(in) :: maxit
    integer :: nc1, nd1
    rs%dt = dt; rs%alpha_m = alpha_m; rs%alpha_f = alpha_f; rs%beta = beta; rs%gamma = gamma
    rs%tol = tol; rs%maxit = maxit
    rs%nf = sys%nfree
    rs%nc = sys%nc
    rs%c1 = 1.0_dp/(1.0_dp - alpha_m)
    rs%betap = beta*(1.0_dp - alpha_f)*rs%c1
    ! length scale of the mechanism [m] (largest nodal coordinate at the start): the absolute floor of
    ! the Newton test, for steps where the accelerations themselves vanish (a smooth start from rest)
    rs%lref = max(maxval(abs(q)), tiny(1.0_dp))
    rs%gammap = gamma*(1.0_dp - alpha_f)*rs%c1
    call ns_setup(sys, q, v, rs%lm, rs%ns)
    allocate (rs%res(sys%ndof), rs%qs(sys%ndof), rs%vs(sys%ndof), rs%w(sys%ndof), rs%qn(sys%ndof), rs%freeidx(rs%nf))
    rs%freeidx = rs%ns%freeidx
    rs%w = 0.0_dp
    nc1 = max(1, rs%nc); nd1 = max(1, sys%nd)
    allocate (rs%lam(nc1), rs%lamn(nc1), rs%g0(nc1), rs%lam0(nc1), rs%gsh(nc1), rs%g1(nc1), &
              rs%th0(nd1), rs%tau0(nd1), rs%th1(nd1), rs%tau1(nd1))
  end subroutine run_setup

  !> The state at t0 (see coupled_run's start) and the inputs' state the work is counted from.
  subroutine run_start(rs, sys, cval, t0, start, q, v, a, p, carry, status)
    type(run_state), intent(inout) :: rs
    type(coupled_system), intent(in) :: sys
    real(dp), intent(in) :: cval(:, :, :), t0, carry(:)
    integer, intent(in) :: start
    real(dp), intent(inout) :: q(:), v(:), a(:), p(:)
    integer, intent(out) :: status
    status = STATUS_OK
    if (start == 2) then
      rs%lam = 0.0_dp
      rs%lam(1:rs%nc) = carry(1:rs%nc)
      rs%work = carry(size(carry))
      call assemble(sys, q, v, a, t0, .false., 0.0_dp, 0.0_dp, rs%res, rs%lm, rs%energy)
    else
      call initial_acceleration(rs, sys, cval, t0, q, v, a, status)
      if (status /= STATUS_OK) return
      if (start == 1) p = a
      rs%work = 0.0_dp
    end if
    call drive_state(sys, t0, q, v, rs%th0, rs%tau0)
    call row_values(sys, q, v, rs%g0)
    rs%lam0 = rs%lam
  end subroutine run_start

  !> Frame k of the outputs: the state, multipliers, energies of the last assembly, work and the most
  !> Newton iterations of a step since the last frame (itmax).
  subroutine store_frame(rs, k, itmax, q, v, a, qf, vf, af, lf, ef)
    type(run_state), intent(in) :: rs
    integer, intent(in) :: k, itmax
    real(dp), intent(in) :: q(:), v(:), a(:)
    real(dp), intent(inout) :: qf(:, :), vf(:, :), af(:, :), lf(:, :), ef(:, :)
    qf(:, k) = q; vf(:, k) = v; af(:, k) = a; lf(1:rs%nc, k) = rs%lam(1:rs%nc)
    ef(:, k) = [rs%energy(1), rs%energy(2), rs%work, real(itmax, dp)]
  end subroutine store_frame

  !> One step to time t (cv: the rows' values there): predictor, Newton iterations, update of
  !> (q, v, a, p); STATUS_NEWTON when the iterations do not converge.
  subroutine run_step(rs, sys, cv, t, q, v, a, p, status)
    type(run_state), intent(inout) :: rs
    type(coupled_system), intent(in) :: sys
    real(dp), intent(in) :: cv(:), t
    real(dp), intent(inout) :: q(:), v(:), a(:), p(:)
    integer, intent(out) :: status
    real(dp) :: dt, c1
    dt = rs%dt; c1 = rs%c1
    rs%t = t
    associate (fi => rs%freeidx)
      rs%w(fi) = rs%alpha_f*a(fi) - rs%alpha_m*p(fi)     ! zero for Newmark
      rs%qs = q + dt*v + (dt*dt*(0.5_dp - rs%beta))*p + (dt*dt*rs%beta*c1)*rs%w
      rs%vs = v + (dt*(1.0_dp - rs%gamma))*p + (dt*rs%gamma*c1)*rs%w
      call newton_iterations(rs, sys, cv, q, v, a, status)
      if (status == STATUS_OK .and. .not. rs%converged) status = STATUS_NEWTON
      if (status /= STATUS_OK) return
      call set_iterate(rs, a, q, v)
      p(fi) = c1*((1.0_dp - rs%alpha_f)*a(fi) + rs%w(fi))
    end associate
  end subroutine run_step

  !> The Newton iterations of the step (predictor qs, vs set; cv the rows' values at its end):
  !> converged, it and the state at the accepted iterate; status on a failed factorization or solve.
  subroutine newton_iterations(rs, sys, cv, q, v, a, status)
    type(run_state), intent(inout) :: rs
    type(coupled_system), intent(in) :: sys
    real(dp), intent(in) :: cv(:)
    real(dp), intent(inout) :: q(:), v(:), a(:)
    integer, intent(out) :: status
    real(dp) :: h2
    integer :: it
    status = STATUS_OK
    h2 = rs%betap*rs%dt*rs%dt
    rs%converged = .false.
    rs%kept = .false.
    rs%da_prev = huge(1.0_dp)
    rs%refresh = .true.
    rs%qn = q; rs%lamn = rs%lam
    rs%second = .false.
    rs%kat = 0
    if (start_mode == START_VELOCITY) call put_at(rs, v, a, q, rs%dt)
    if (start_mode == START_POSITION) call restart_at_qn(rs, v, a)
    do it = 1, merge(2*rs%maxit, rs%maxit, start_mode /= START_ACCELERATION)
      rs%it = it
      call newton_iteration(rs, sys, cv, q, v, a, status)
      if (status /= STATUS_OK) exit
      if (rs%it == 1 .and. start_mode == START_VELOCITY .and. h2*rs%da_norm > RESTART_MOVE*rs%lref) then
        ! the start q_n + dt v_n was far (an unresolved stiff mode's velocity): start again at q_n,
        ! with the predictor's matrix while that has served the run's earlier restarts (NEWTON_AUTO)
        call restart_at_qn(rs, v, a)
        rs%kept = newton_mode == NEWTON_AUTO .and. rs%restart_kept(1) >= rs%restart_kept(2)
        rs%refresh = .not. rs%kept
        cycle
      end if
      if (rs%kept .and. rs%refresh) then     ! the kept matrix contracted too little: rebuilt after all
        rs%restart_kept(2) = rs%restart_kept(2) + 1
        rs%kept = .false.
      end if
      if (accepted(rs)) then
        rs%converged = .true.
        if (rs%kept) rs%restart_kept(1) = rs%restart_kept(1) + 1
        exit
      end if
      rs%da_prev = rs%da_norm
      if (rs%it == rs%maxit .and. start_mode /= START_ACCELERATION) then
        ! not converged from the start: a second attempt of maxit iterations from q_n, the
        ! matrix rebuilt at every iteration
        call restart_at_qn(rs, v, a)
        rs%second = .true.
      end if
      rs%refresh = rs%refresh .or. rs%second
    end do
  end subroutine newton_iterations

  !> The iterate at acceleration a on the free DOFs: q = qs + beta' dt^2 a, v = vs + gamma' dt a
  !> (the step's predictor qs, vs; the constrained DOFs keep their values).
  pure subroutine set_iterate(rs, a, q, v)
    type(run_state), intent(in) :: rs
    real(dp), intent(in) :: a(:)
    real(dp), intent(inout) :: q(:), v(:)
    associate (fi => rs%freeidx)
      q(fi) = rs%qs(fi) + (rs%betap*rs%dt*rs%dt)*a(fi)
      v(fi) = rs%vs(fi) + (rs%gammap*rs%dt)*a(fi)
    end associate
  end subroutine set_iterate

  !> One Newton iteration at the current acceleration a: the iterate (q, v), the residual (and S,
  !> factorized, when refresh), the rows and the correction of (a, lam); refresh for the next.
  subroutine newton_iteration(rs, sys, cv, q, v, a, status)
    type(run_state), intent(inout) :: rs
    type(coupled_system), intent(in) :: sys
    real(dp), intent(in) :: cv(:)
    real(dp), intent(inout) :: q(:), v(:), a(:)
    integer, intent(out) :: status
    real(dp) :: dt
    dt = rs%dt
    call set_iterate(rs, a, q, v)
    if (rs%refresh) then
      call assemble(sys, q, v, a, rs%t, .true., rs%gammap*dt, rs%betap*dt*dt, rs%res, rs%lm, rs%energy)
      call factor(rs, sys, status)
      if (status /= STATUS_OK) return
    else
      call assemble_residual(sys, q, v, a, rs%t, rs%res, rs%lm)
    end if
    ! gradients (the factorization's part with them after a factorization), values, G^T lam in res
    call ns_rows(sys, rs%lm, rs%ns, q, v, cv, rs%lam, rs%res, status)
    if (status /= STATUS_OK) return
    rs%gsh(1:rs%nc) = rs%ns%gval(1:rs%nc)/(rs%betap*dt*dt)
    call ns_correction(sys, rs%lm, rs%ns, rs%res, rs%gsh, a, rs%lam, rs%da_norm, rs%a_norm, rs%newton, status)
    if (status /= STATUS_OK) return
    rs%iters = rs%iters + 1
    rs%kat = rs%kat + 1                ! iterations of this attempt
    rs%refresh = newton_mode == NEWTON_FULL .or. &
                 (newton_mode == NEWTON_AUTO .and. rs%kat > 1 .and. rs%da_norm > NEWTON_RATE*rs%da_prev)
  end subroutine newton_iteration

  !> Accept the iterate: the correction within tol of the accelerations (or the position correction
  !> below 1e-2 tol of the mechanism size), or stagnated at the round-off level of the residual (no
  !> further contraction while already within sqrt(tol): the stiff chord terms limit the attainable
  !> precision), or the error left after it, estimated from the contraction rate rho of the last two
  !> corrections (|a - a*| ~ rho/(1 - rho) |da|), within tol.
  logical function accepted(rs)
    type(run_state), intent(in) :: rs
    real(dp) :: rho, tol, an
    rho = rs%da_norm/rs%da_prev
    tol = rs%tol
    an = rs%a_norm + 1.0e-30
    associate (da => rs%da_norm, kat => rs%kat)
      accepted = da <= tol*an .or. rs%betap*rs%dt*rs%dt*da <= 1.0e-2_dp*tol*rs%lref .or. &
                 (kat > 1 .and. rho < 0.5_dp .and. rho/(1.0_dp - rho)*da <= tol*an) .or. &
                 (kat > 1 .and. da >= 0.5_dp*rs%da_prev .and. da <= sqrt(tol)*an)
    end associate
  end function accepted

  !> Start the step's iteration (again) at the last step's position q_n and multipliers: the
  !> acceleration that puts q at qn, a fresh contraction history.
  subroutine restart_at_qn(rs, v, a)
    type(run_state), intent(inout) :: rs
    real(dp), intent(in) :: v(:)
    real(dp), intent(inout) :: a(:)
    rs%lam = rs%lamn
    call put_at(rs, v, a, rs%qn, 0.0_dp)
    rs%da_prev = huge(1.0_dp)
    rs%kat = 0
  end subroutine restart_at_qn

  !> The acceleration a (free DOFs) that puts the step's position q = qs + betap dt^2 a at
  !> qb + h v (h [s]: 0 for qb itself).
  subroutine put_at(rs, v, a, qb, h)
    type(run_state), intent(in) :: rs
    real(dp), intent(in) :: v(:), qb(:), h
    real(dp), intent(inout) :: a(:)
    integer :: i, j
    do i = 1, rs%nf             ! a loop: vector subscripts would copy through the heap
      j = rs%freeidx(i)
      a(j) = (qb(j) + h*v(j) - rs%qs(j))/(rs%betap*rs%dt*rs%dt)
    end do
  end subroutine put_at

  !> The state a continuation needs besides (q, v, a, p): multipliers, lref, work.
  subroutine save_carry(rs, carry)
    type(run_state), intent(in) :: rs
    real(dp), intent(out) :: carry(:)
    carry = 0.0_dp
    carry(1:rs%nc) = rs%lam(1:rs%nc)
    carry(size(carry) - 1) = rs%lref
    carry(size(carry)) = rs%work
  end subroutine save_carry

  !> Consistent initial acceleration and multipliers at t0: [M G; G^T 0] [a; lam] = [-R(q, v, 0);
  !> cval'' - acc0], by iterative refinement with S = M (a rigid body's J_S stands for a zero inertia
  !> in S; the refinement removes its effect).
  subroutine initial_acceleration(rs, sys, cval, t0, q, v, a, status)
    type(run_state), intent(inout) :: rs
    type(coupled_system), intent(in) :: sys
    real(dp), intent(in) :: cval(:, :, :), t0, q(:), v(:)
    real(dp), intent(inout) :: a(:)
    integer, intent(out) :: status
    integer :: k, j
    real(dp) :: dn, an, dn_prev, shift(max(1, rs%nc))
    status = STATUS_OK
    dn_prev = huge(1.0_dp)
    a(rs%freeidx) = 0.0_dp
    rs%lam = 0.0_dp
    do k = 1, max(1, rs%maxit)
      call assemble(sys, q, v, a, t0, k == 1, 0.0_dp, 0.0_dp, rs%res, rs%lm, rs%energy)
      if (k == 1) then
        call factor(rs, sys, status)
        if (status /= STATUS_OK) return
      end if
      call ns_rows(sys, rs%lm, rs%ns, q, v, cval(1, :, 1), rs%lam, rs%res, status)
      if (status /= STATUS_OK) return
      do j = 1, rs%nc        ! the rows' acceleration residual G a - (cval'' - acc0)
        shift(j) = ns_gdot(rs%ns, j, a(rs%freeidx)) - (cval(3, j, 1) - rs%ns%acc0(j))
      end do
      call ns_correction(sys, rs%lm, rs%ns, rs%res, shift, a, rs%lam, rs%da_norm, rs%a_norm, rs%newton, status)
      if (status /= STATUS_OK) return
      dn = rs%da_norm; an = rs%a_norm
      if (dn <= 1.0e-3_dp*rs%tol*(an + 1.0e-30) .or. dn > 0.5_dp*dn_prev) exit   ! converged, or round-off
      dn_prev = dn
    end do
    call assemble(sys, q, v, a, t0, .false., 0.0_dp, 0.0_dp, rs%res, rs%lm, rs%energy)
  end subroutine initial_acceleration

  !> Values of the rows (the constraint functions, not their errors) at (q, v): only the moving rows'
  !> (the others do no work).
  subroutine row_values(sys, q, v, gv)
    type(coupled_system), intent(in) :: sys
    real(dp), intent(in) :: q(:), v(:)
    real(dp), intent(inout) :: gv(:)
    integer :: ic, ncl, cols(2*MAXCOL)
    real(dp) :: gd, ac, grad(2*MAXCOL)
    type(marker_state) :: ma, mb
    do ic = 1, sys%nc
      if (sys%con(1, ic) == CON_POINT .or. sys%con(4, ic) /= 1) cycle   ! only moving rows do work
      call eval_row(sys, sys%con(1, ic), sys%con(4, ic), sys%con_dir(:, ic), sys%con(2, ic), sys%con(3, ic), &
                    q, v, gv(ic), gd, ac, ncl, cols, grad, ma, mb)
    end do
  end subroutine row_values

  !> The controllers' measurements (their drives' coordinates and rates) at (q, v) and time tt: a
  !> fresh start (first) or the commit of an accepted step (flexmech_control).
  subroutine control_step(sys, tt, q, v, first)
    type(coupled_system), intent(inout) :: sys
    real(dp), intent(in) :: tt, q(:), v(:)
    logical, intent(in) :: first
    integer :: j
    real(dp) :: y(sys%ctl%n), yd(sys%ctl%n)
    do j = 1, sys%ctl%n
      call control_measure(sys, j, q, v, y(j), yd(j))
    end do
    if (first) then
      call ctl_start(sys%ctl, tt, y, yd)
    else
      call ctl_commit(sys%ctl, tt, y, yd)
    end if
  end subroutine control_step

  !> Coordinates th and generalized forces tau of the force drives at time tt and (q, v).
  subroutine drive_state(sys, tt, q, v, th, tau)
    type(coupled_system), intent(in) :: sys
    real(dp), intent(in) :: tt, q(:), v(:)
    real(dp), intent(out) :: th(:), tau(:)
    integer :: i2, ncl, cols(2*MAXCOL)
    real(dp) :: grad(2*MAXCOL)
    type(marker_state) :: ma, mb
    do i2 = 1, sys%nd
      call drive_load(sys, i2, q, v, tt, tau(i2), th(i2), ncl, cols, grad, ma, mb)
    end do
  end subroutine drive_state

  !> Work of the inputs over the step just taken (to rs%t), trapezoidal: force drives tau d theta,
  !> moving rows (kinematic drives, whose generalized force is -lam) -lam d g.
  subroutine step_work(rs, sys, q, v)
    type(run_state), intent(inout) :: rs
    type(coupled_system), intent(in) :: sys
    real(dp), intent(in) :: q(:), v(:)
    real(dp) :: dth
    integer :: i2
    call drive_state(sys, rs%t, q, v, rs%th1, rs%tau1)
    do i2 = 1, sys%nd
      dth = rs%th1(i2) - rs%th0(i2)
      if (sys%dv(1, i2) == CON_ANGLE) dth = wrap(dth)
      rs%work = rs%work + 0.5_dp*(rs%tau0(i2) + rs%tau1(i2))*dth
    end do
    rs%th0 = rs%th1; rs%tau0 = rs%tau1
    call row_values(sys, q, v, rs%g1)
    do i2 = 1, rs%nc
      if (sys%con(1, i2) == CON_POINT .or. sys%con(4, i2) /= 1) cycle
      dth = rs%g1(i2) - rs%g0(i2)
      if (sys%con(1, i2) == CON_ANGLE) dth = wrap(dth)
      rs%work = rs%work - 0.5_dp*(rs%lam0(i2) + rs%lam(i2))*dth
    end do
    rs%g0 = rs%g1
    rs%lam0 = rs%lam
  end subroutine step_work

  !> Factorize the assembled S (flexmech_coupled_solve: its path) and count it.
  subroutine factor(rs, sys, status)
    type(run_state), intent(inout) :: rs
    type(coupled_system), intent(in) :: sys
    integer, intent(out) :: status
    rs%newton(4) = rs%newton(4) + 1.0_dp
    call ns_factor(sys, rs%lm, rs%ns, status)
  end subroutine factor

end module flexmech_coupled_run
