!> Explicit interfaces to the LAPACK (and BLAS) routines flexmech uses, and the
!> status codes every compiled routine returns.
!>
!> Status codes (the only place they are defined; Python turns them into
!> sentences in `flexmech_py.kernels.check_status`):
!>   0  success
!>   1  singular system matrix (LAPACK factorization info > 0)
!>   2  non-finite value (NaN or Inf) in the solution
!>   3  illegal argument passed to LAPACK (info < 0): a bug, please report
!>   4  invalid input to a compiled routine (sizes, indices, coefficients)
!>   5  iterations inside a step did not converge (Newton in the coupled and nonlinear models,
!>      the axial forces of the geometric stiffness)
!>   6  the elastic state exceeded the divergence limit `div_limit` given to the time loop
!>      (flexmech_newmark: max |u| over the free translational DOFs; flexmech_coupled_run: the largest
!>      node offset from the straight link chord or change of the chord length); the step that
!>      crossed it is returned in fail_step
!>   7  the mechanism reached a singular position: its constraint Jacobian (with the kinematic drives)
!>      lost rank (a toggle or dead centre of a driven coordinate, a change point of a loop)
!>   8  the mechanism cannot assemble: the position equations of the joints and drives have no
!>      solution near the last configuration (Newton did not converge)
module flexmech_lapack
  use flexmech_kinds, only: dp
  implicit none
  private
  public :: dgbtrf, dgbtrs, dgetrf, dgetrs, dgecon, dtbsv
  public :: STATUS_OK, STATUS_SINGULAR, STATUS_NONFINITE, STATUS_LAPACK_ARG, STATUS_BAD_INPUT, STATUS_NEWTON, &
            STATUS_DIVERGED, STATUS_SINGULAR_POSITION, STATUS_ASSEMBLY
  public :: lapack_status

  integer, parameter :: STATUS_OK = 0, STATUS_SINGULAR = 1, STATUS_NONFINITE = 2, &
                        STATUS_LAPACK_ARG = 3, STATUS_BAD_INPUT = 4, STATUS_NEWTON = 5, &
                        STATUS_DIVERGED = 6, STATUS_SINGULAR_POSITION = 7, STATUS_ASSEMBLY = 8

  interface
    subroutine dgbtrf(m, n, kl, ku, ab, ldab, ipiv, info)
      import :: dp
      integer, intent(in) :: m, n, kl, ku, ldab
      real(dp), intent(inout) :: ab(ldab, *)
      integer, intent(out) :: ipiv(*), info
    end subroutine dgbtrf
    subroutine dgbtrs(trans, n, kl, ku, nrhs, ab, ldab, ipiv, b, ldb, info)
      import :: dp
      character, intent(in) :: trans
      integer, intent(in) :: n, kl, ku, nrhs, ldab, ldb
      real(dp), intent(in) :: ab(ldab, *)
      integer, intent(in) :: ipiv(*)
      real(dp), intent(inout) :: b(ldb, *)
      integer, intent(out) :: info
    end subroutine dgbtrs
    subroutine dgetrf(m, n, a, lda, ipiv, info)
      import :: dp
      integer, intent(in) :: m, n, lda
      real(dp), intent(inout) :: a(lda, *)
      integer, intent(out) :: ipiv(*), info
    end subroutine dgetrf
    subroutine dgecon(norm, n, a, lda, anorm, rcond, work, iwork, info)
      import :: dp
      character, intent(in) :: norm
      integer, intent(in) :: n, lda
      real(dp), intent(in) :: a(lda, *), anorm
      real(dp), intent(out) :: rcond, work(*)
      integer, intent(out) :: iwork(*), info
    end subroutine dgecon
    subroutine dgetrs(trans, n, nrhs, a, lda, ipiv, b, ldb, info)
      import :: dp
      character, intent(in) :: trans
      integer, intent(in) :: n, nrhs, lda, ldb
      real(dp), intent(in) :: a(lda, *)
      integer, intent(in) :: ipiv(*)
      real(dp), intent(inout) :: b(ldb, *)
      integer, intent(out) :: info
    end subroutine dgetrs
    subroutine dtbsv(uplo, trans, diag, n, k, a, lda, x, incx)
      import :: dp
      character, intent(in) :: uplo, trans, diag
      integer, intent(in) :: n, k, lda, incx
      real(dp), intent(in) :: a(lda, *)
      real(dp), intent(inout) :: x(*)
    end subroutine dtbsv
  end interface

contains

  !> Map a LAPACK `info` to a flexmech status code.
  pure integer function lapack_status(info) result(status)
    integer, intent(in) :: info  !< LAPACK info argument
    if (info == 0) then
      status = STATUS_OK
    else if (info > 0) then
      status = STATUS_SINGULAR
    else
      status = STATUS_LAPACK_ARG
    end if
  end function lapack_status

end module flexmech_lapack
