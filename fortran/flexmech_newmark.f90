!> Time integration of the superposition KED equations with the generalized-alpha family in the
!> form of Arnold & Bruls (Multibody Syst. Dyn. 18 (2007) 185-202); time-varying matrices, one
!> banded LU per step, no allocation in the loop.  docs/theory.md section 15.
!>
!> State (u, v, a, p): displacement, velocity, true acceleration a_n (the equations of motion hold
!> exactly at every t_n) and the pseudo-acceleration p_n of the recurrence
!>   (1 - am) p_{n+1} + am p_n = (1 - af) a_{n+1} + af a_n,
!>   u_{n+1} = u_n + dt v_n + dt^2 (1/2 - beta) p_n + dt^2 beta p_{n+1},
!>   v_{n+1} = v_n + dt (1 - gamma) p_n + dt gamma p_{n+1}.
!> Eliminating p_{n+1} leaves Newmark's structure with w = af a_n - am p_n, c1 = 1/(1 - am):
!>   u* = u_n + dt v_n + dt^2 (1/2 - beta) p_n + dt^2 beta c1 w,   v* = v_n + dt (1 - gamma) p_n + dt gamma c1 w
!>   (M + gamma' dt C + beta' dt^2 K)_{n+1} a_{n+1} = Q_{n+1} - F_{n+1} - C v* - K u*
!>   u_{n+1} = u* + beta' dt^2 a_{n+1},  v_{n+1} = v* + gamma' dt a_{n+1},  p_{n+1} = c1 ((1 - af) a_{n+1} + w)
!> with beta' = beta (1 - af) c1, gamma' = gamma (1 - af) c1.  am = af = 0 is Newmark (beta, gamma)
!> (then p = a exactly); beta = 1/4, gamma = 1/2 the average-acceleration rule.
module flexmech_newmark
  use, intrinsic :: ieee_arithmetic, only: ieee_is_finite
  use flexmech_kinds, only: dp
  use flexmech_lapack, only: dgbtrf, dgbtrs, lapack_status, STATUS_OK, STATUS_NONFINITE, STATUS_BAD_INPUT, &
                             STATUS_GEO => STATUS_NEWTON, STATUS_DIVERGED

  use flexmech_assembly, only: band_rows
  use flexmech_ked, only: ked_system
  implicit none
  private
  public :: newmark_run, consistent_acceleration, initial_axial_forces
  public :: GEO_NONE, GEO_CURRENT, GEO_LAGGED, GEO_QUASI_STATIC

  !> Source of the axial forces of the geometric stiffness
  integer, parameter :: GEO_NONE = 0, GEO_CURRENT = 1, GEO_LAGGED = 2, GEO_QUASI_STATIC = 3

contains

  !> Solve S x = r in place (S band-factorized in place). Returns a status code.
  subroutine band_solve(sys, ab, ipiv, r, status)
    type(ked_system), intent(in) :: sys
    real(dp), intent(inout) :: ab(:, :), r(:)
    integer, intent(out) :: ipiv(:), status
    integer :: info
    call dgbtrf(sys%nfree, sys%nfree, sys%kl, sys%ku, ab, size(ab, 1), ipiv, info)
    status = lapack_status(info)
    if (status /= STATUS_OK) return
    call dgbtrs('N', sys%nfree, sys%kl, sys%ku, 1, ab, size(ab, 1), ipiv, r, sys%nfree, info)
    status = lapack_status(info)
    if (status == STATUS_OK .and. .not. ieee_is_finite(sum(abs(r)))) status = STATUS_NONFINITE
  end subroutine band_solve

  !> Acceleration consistent with the equations of motion at a rigid sample: M a = Q - F - C v - K u.
  subroutine consistent_acceleration(sys, rig, q_free, q_val, u, v, a, status)
    type(ked_system), intent(in) :: sys
    real(dp), intent(in) :: rig(:, :)      !< (5, nlinks)
    integer, intent(in) :: q_free(:)       !< (nq) free DOFs loaded by applied generalized forces
    real(dp), intent(in) :: q_val(:)       !< (nq) their values [N or N m]
    real(dp), intent(in) :: u(:), v(:)     !< (nfree)
    real(dp), intent(out) :: a(:)          !< (nfree)
    integer, intent(out) :: status
    real(dp), allocatable :: ab(:, :)
    integer, allocatable :: ipiv(:)
    integer :: i
    allocate (ab(band_rows(sys%kl, sys%ku), sys%nfree), ipiv(sys%nfree))
    call sys%assemble(rig, 0.0_dp, 0.0_dp, u, v, ab, a)
    do i = 1, size(q_free)
      a(q_free(i)) = a(q_free(i)) + q_val(i)
    end do
    call band_solve(sys, ab, ipiv, a, status)
  end subroutine consistent_acceleration

  !> Integrate nsteps = size(rig,3) - 1 steps of size dt from the state (u, v, a, p) at rig(:,:,1)
  !> (a the true and p the pseudo-acceleration; a fresh start has p = a).  Frames are stored at
  !> steps 0, out_every, 2*out_every, ...; nvalid is the number of frames stored.
  !> On return (u, v, a, p) is the last state reached; on failure status /= 0 and fail_step is the
  !> step (1-based) that failed, frames after the last valid one untouched.
  !> Divergence guard: after every step, max |u| over the DOFs marked in trans (the translations,
  !> metres) above div_limit [m] stops the run with STATUS_DIVERGED.
  subroutine newmark_run(sys, rig, sl_val, q_free, q_val, dt, alpha_m, alpha_f, beta, gamma, out_every, u, v, a, p, &
                         uf, vf, af, status, fail_step, nvalid, geo_mode, geo_tol, geo_maxit, nf, geo_iters, &
                         trans, div_limit)
    type(ked_system), intent(inout) :: sys
    integer, intent(in) :: geo_mode                !< GEO_* source of the axial forces
    real(dp), intent(in) :: geo_tol                !< GEO_CURRENT: relative tolerance on the axial forces
    integer, intent(in) :: geo_maxit               !< GEO_CURRENT: fixed-point iterations allowed per step
    real(dp), intent(inout) :: nf(:, :)            !< (nel, nframes) axial forces at the frames [N]
    integer, intent(out) :: geo_iters              !< total axial-force iterations
    real(dp), intent(in) :: rig(:, :, :)   !< (5, nlinks, nsteps+1) rigid samples on the time grid
    real(dp), intent(in) :: sl_val(:, :, :) !< (3, nnz, nsteps+1) slave-row coefficients [T, T', T''] (flexmech_ked)
    integer, intent(in) :: q_free(:)       !< (nq) free DOFs loaded by applied generalized forces
    real(dp), intent(in) :: q_val(:, :)    !< (nq, nsteps+1) their values
    real(dp), intent(in) :: dt             !< step [s]
    real(dp), intent(in) :: alpha_m, alpha_f, beta, gamma   !< generalized-alpha parameters (Newmark: am = af = 0)
    integer, intent(in) :: out_every
    real(dp), intent(inout) :: u(:), v(:), a(:), p(:)   !< (nfree) state [m or rad, /s, /s^2, /s^2]
    real(dp), intent(inout) :: uf(:, :), vf(:, :), af(:, :)  !< (nfree, nframes)
    integer, intent(out) :: status, fail_step, nvalid
    logical, intent(in) :: trans(:)       !< (nfree) DOFs watched by the divergence guard
    real(dp), intent(in) :: div_limit     !< divergence limit on |u| [m]
    real(dp), allocatable :: ab(:, :), up(:), vp(:), nnew(:), us(:), z(:), w(:)
    logical, allocatable :: locked(:)
    integer, allocatable :: ipiv(:)
    integer :: n, nsteps
    real(dp) :: c1, betap, gammap
    status = STATUS_OK; fail_step = 0; nvalid = 0
    nsteps = size(rig, 3) - 1
    if (.not. integrator_valid(dt, alpha_m, alpha_f, beta, gamma, out_every, nsteps, size(uf, 2)) .or. &
        .not. div_limit > 0.0_dp .or. size(trans) /= sys%nfree) then
      status = STATUS_BAD_INPUT
      return
    end if
    c1 = 1.0_dp/(1.0_dp - alpha_m)
    betap = beta*(1.0_dp - alpha_f)*c1
    gammap = gamma*(1.0_dp - alpha_f)*c1
    allocate (ab(band_rows(sys%kl, sys%ku), sys%nfree), ipiv(sys%nfree), up(sys%nfree), vp(sys%nfree))
    allocate (nnew(sys%nel), us(sys%nfree), z(sys%nfree), w(sys%nfree), locked(size(q_free)))
    z = 0.0_dp
    locked = any(q_val /= 0.0_dp, dim=2)   ! DOFs an applied torque ever acts on (locked in the quasi-static solve)
    geo_iters = 0
    if (sys%nsl > 0) sys%tv = sl_val(:, :, 1)
    call initial_axial_forces(sys, geo_mode, rig(:, :, 1), q_free, q_val, u, status)
    if (status /= STATUS_OK) then
      fail_step = 1
      return
    end if
    uf(:, 1) = u; vf(:, 1) = v; af(:, 1) = a; nf(:, 1) = sys%nax
    nvalid = 1
    do n = 1, nsteps
      w = alpha_f*a - alpha_m*p            ! zero for Newmark
      up = u + dt*v + (dt*dt*(0.5_dp - beta))*p + (dt*dt*beta*c1)*w
      vp = v + (dt*(1.0_dp - gamma))*p + (dt*gamma*c1)*w
      if (sys%nsl > 0) sys%tv = sl_val(:, :, n + 1)
      if (geo_mode == GEO_QUASI_STATIC) &   ! N from K u = -F_rigid at this configuration
        call quasi_static_axial(sys, rig(:, :, n + 1), q_free, q_val(:, n + 1), locked, ab, ipiv, us, z, status)
      if (status == STATUS_OK) call solve_step(sys, rig(:, :, n + 1), q_free, q_val(:, n + 1), gammap*dt, betap*dt*dt, &
                                               up, vp, ab, ipiv, a, nnew, geo_mode, geo_tol, geo_maxit, geo_iters, status)
      if (status /= STATUS_OK) then
        fail_step = n
        return
      end if
      u = up + (betap*dt*dt)*a
      v = vp + (gammap*dt)*a
      p = c1*((1.0_dp - alpha_f)*a + w)
      if (geo_mode == GEO_LAGGED) call sys%axial_forces(rig(:, :, n + 1), u, sys%nax)
      if (maxval(abs(u), mask=trans, dim=1) > div_limit) then
        status = STATUS_DIVERGED
        fail_step = n
        return
      end if
      if (mod(n, out_every) == 0) then
        nvalid = nvalid + 1
        uf(:, nvalid) = u; vf(:, nvalid) = v; af(:, nvalid) = a; nf(:, nvalid) = sys%nax
      end if
    end do
  end subroutine newmark_run

  !> The generalized-alpha parameters and the output frames of a run of nsteps steps are valid.
  pure logical function integrator_valid(dt, alpha_m, alpha_f, beta, gamma, out_every, nsteps, nframes)
    real(dp), intent(in) :: dt, alpha_m, alpha_f, beta, gamma
    integer, intent(in) :: out_every, nsteps, nframes
    integrator_valid = .false.
    if (out_every < 1) return
    integrator_valid = dt > 0.0_dp .and. beta > 0.0_dp .and. gamma >= 0.5_dp .and. alpha_m < 1.0_dp .and. &
                       alpha_f < 1.0_dp .and. nframes == nsteps/out_every + 1
  end function integrator_valid

  !> The acceleration a of one step at the rigid sample rig1 from the predictor (up, vp): the banded
  !> solve of (M + hg C + hb K) a = Q - F - C vp - K up (hg = gamma' dt, hb = beta' dt^2), with
  !> GEO_CURRENT's fixed-point iteration on the axial forces of the geometric stiffness (sys%nax;
  !> geo_iters counts its iterations; STATUS_GEO when they do not settle within geo_maxit).
  subroutine solve_step(sys, rig1, q_free, qv, hg, hb, up, vp, ab, ipiv, a, nnew, geo_mode, geo_tol, geo_maxit, &
                        geo_iters, status)
    type(ked_system), intent(inout) :: sys
    real(dp), intent(in) :: rig1(:, :)     !< (5, nlinks) the rigid sample at the step's end
    integer, intent(in) :: q_free(:)       !< (nq)
    real(dp), intent(in) :: qv(:)          !< (nq) applied generalized forces there
    real(dp), intent(in) :: hg, hb, up(:), vp(:), geo_tol
    real(dp), intent(inout) :: ab(:, :), a(:), nnew(:)
    integer, intent(inout) :: ipiv(:), geo_iters
    integer, intent(in) :: geo_mode, geo_maxit
    integer, intent(out) :: status
    integer :: it, i
    do it = 1, merge(geo_maxit, 1, geo_mode == GEO_CURRENT)
      call sys%assemble(rig1, hg, hb, up, vp, ab, a)
      do i = 1, size(q_free)
        a(q_free(i)) = a(q_free(i)) + qv(i)
      end do
      call band_solve(sys, ab, ipiv, a, status)
      if (status /= STATUS_OK .or. geo_mode /= GEO_CURRENT) return
      ! GEO_CURRENT: axial forces of the new state; iterate until they stop changing
      geo_iters = geo_iters + 1
      call sys%axial_forces(rig1, up + hb*a, nnew)
      if (maxval(abs(nnew - sys%nax)) <= geo_tol*max(maxval(abs(nnew)), tiny(1.0_dp))) then
        sys%nax = nnew
        return
      end if
      ! plain substitution first; if it has not settled after 5 iterations, relax it (the axial
      ! forces near the Euler load make the plain iteration oscillate)
      if (it <= 5) then
        sys%nax = nnew
      else
        sys%nax = 0.5_dp*(sys%nax + nnew)
      end if
    end do
    status = STATUS_GEO
  end subroutine solve_step

  !> Axial forces of the geometric stiffness at the first sample (sys%geo, sys%nax), so that the
  !> consistent initial acceleration and the first step see the same stiffness as every later step:
  !> GEO_QUASI_STATIC from the quasi-static solution at rig1, the other sources from u.
  !> (Matters for a start away from rest, e.g. the monodromy runs of flexmech_py/floquet.py.)
  subroutine initial_axial_forces(sys, geo_mode, rig1, q_free, q_val, u, status)
    type(ked_system), intent(inout) :: sys
    integer, intent(in) :: geo_mode
    real(dp), intent(in) :: rig1(:, :)     !< (5, nlinks) first rigid sample
    integer, intent(in) :: q_free(:)       !< (nq)
    real(dp), intent(in) :: q_val(:, :)    !< (nq, nsteps+1) applied generalized forces
    real(dp), intent(in) :: u(:)           !< (nfree) initial displacements
    integer, intent(out) :: status
    real(dp), allocatable :: ab(:, :), us(:), z(:)
    integer, allocatable :: ipiv(:)
    status = STATUS_OK
    sys%geo = geo_mode /= GEO_NONE
    if (geo_mode == GEO_QUASI_STATIC) then
      allocate (ab(band_rows(sys%kl, sys%ku), sys%nfree), ipiv(sys%nfree), us(sys%nfree), z(sys%nfree))
      z = 0.0_dp
      call quasi_static_axial(sys, rig1, q_free, q_val(:, 1), any(q_val /= 0.0_dp, dim=2), ab, ipiv, us, z, status)
    else if (sys%geo) then
      call sys%axial_forces(rig1, u, sys%nax)
    end if
  end subroutine initial_axial_forces

  !> Quasi-static axial forces: sys%nax from K us = Q - F_rigid at one rigid sample (sys%geo = .true. on
  !> return).  Driven joints locked: a stiff spring on every DOF an applied torque ever acts on (joints
  !> left free with 'torque' are otherwise zero-stiffness modes of K).  ab, ipiv, us, z: work arrays.
  subroutine quasi_static_axial(sys, rig, q_free, qv, locked, ab, ipiv, us, z, status)
    type(ked_system), intent(inout) :: sys
    real(dp), intent(in) :: rig(:, :)      !< (5, nlinks)
    integer, intent(in) :: q_free(:)       !< (nq)
    real(dp), intent(in) :: qv(:)          !< (nq) applied generalized forces at this sample
    logical, intent(in) :: locked(:)       !< (nq)
    real(dp), intent(inout) :: ab(:, :), us(:), z(:)
    integer, intent(inout) :: ipiv(:)
    integer, intent(out) :: status
    integer :: i
    real(dp) :: penalty
    sys%geo = .false.
    call sys%assemble(rig, 0.0_dp, 1.0_dp, z, z, ab, us, static=.true.)
    penalty = 1.0e8_dp*maxval(abs(ab(sys%kl + sys%ku + 1, :)))
    do i = 1, size(q_free)
      us(q_free(i)) = us(q_free(i)) + qv(i)
      if (locked(i)) ab(sys%kl + sys%ku + 1, q_free(i)) = ab(sys%kl + sys%ku + 1, q_free(i)) + penalty
    end do
    call band_solve(sys, ab, ipiv, us, status)
    if (status /= STATUS_OK) return
    call sys%axial_forces(rig, us, sys%nax)
    sys%geo = .true.
  end subroutine quasi_static_axial

end module flexmech_newmark
