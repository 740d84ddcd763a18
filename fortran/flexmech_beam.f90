!> Planar Euler-Bernoulli beam element of flexmech (pure kernels).
!>
!> Local element DOF order (element frame, zeta along the undeformed axis,
!> eta = zeta rotated +90 deg):  [p1, v1, th1, p2, v2, th2]
!>   p  axial displacement [m], v transverse displacement [m], th rotation [rad].
!> Global element DOF order:      [u1, w1, th1, u2, w2, th2]
!>   u, w displacement components along global X, Y [m]; th as above.
!> The two are related by delta = T(phi) s  (seed Eq. 8-9), phi the angle of
!> the element axis from global X.
!>
!> Interpolation (seed Eq. 11-12): axial linear, transverse cubic Hermite,
!> u_local(zeta) = N(zeta) delta,  N is 2 x 6.  With R(phi) the rotation from
!> element to global components and E = blockdiag(Omega, 0, Omega, 0),
!> Omega = [0 -1; 1 0], the elastic displacement in global components is
!> u = R N T s, and (docs/theory.md)
!>   d/dt (R N T) = omega R D T,            D = Omega N - N E
!>   d2/dt2(R N T) = R (alpha D + omega^2 (Omega D - D E)) T.
!> The element matrices returned here are local; global ones are T^T A T.
!> Integrals of products of polynomials are evaluated with 4-point
!> Gauss-Legendre quadrature, exact for the degree-6 integrands that occur.
module flexmech_beam
  use flexmech_kinds, only: dp
  implicit none
  private
  public :: beam_mass, beam_stiffness, beam_gyroscopic, beam_centrifugal, beam_hac_coupling
  public :: beam_curvature, rotate_to_global, vec_to_local, vec_to_global, transformation, beam_geometric

  real(dp), parameter :: gauss_x(4) = [ &
    0.5_dp - 0.5_dp*0.8611363115940526_dp, 0.5_dp - 0.5_dp*0.3399810435848563_dp, &
    0.5_dp + 0.5_dp*0.3399810435848563_dp, 0.5_dp + 0.5_dp*0.8611363115940526_dp]
  real(dp), parameter :: gauss_w(4) = 0.5_dp*[0.3478548451374538_dp, 0.6521451548625461_dp, &
                                              0.6521451548625461_dp, 0.3478548451374538_dp]

contains

  !> Elastic shape-function matrix N (seed Eq. 11) at xi = zeta/L.
  pure function shape_n(xi, len) result(n)
    real(dp), intent(in) :: xi   !< dimensionless position, 0 <= xi <= 1
    real(dp), intent(in) :: len  !< element length [m]
    real(dp) :: n(2, 6)
    n = 0.0_dp
    n(1, 1) = 1.0_dp - xi
    n(1, 4) = xi
    n(2, 2) = 1.0_dp - 3.0_dp*xi**2 + 2.0_dp*xi**3
    n(2, 3) = len*(xi - 2.0_dp*xi**2 + xi**3)
    n(2, 5) = 3.0_dp*xi**2 - 2.0_dp*xi**3
    n(2, 6) = len*(-xi**2 + xi**3)
  end function shape_n

  !> Hac's rigid-body shape function N0 (seed Eq. 4) at xi = zeta/L; 2 x 4 on [p01, v01, p02, v02].
  pure function shape_n0(xi) result(n0)
    real(dp), intent(in) :: xi
    real(dp) :: n0(2, 4)
    n0 = 0.0_dp
    n0(1, 1) = 0.5_dp
    n0(1, 3) = 0.5_dp
    n0(2, 2) = 1.0_dp - xi
    n0(2, 4) = xi
  end function shape_n0

  !> Omega*A for a 2 x 6 A (rotation of each column by +90 deg).
  pure function omega_left(a) result(b)
    real(dp), intent(in) :: a(2, 6)
    real(dp) :: b(2, 6)
    b(1, :) = -a(2, :)
    b(2, :) = a(1, :)
  end function omega_left

  !> A*E for a 2 x 6 A, E = blockdiag(Omega, 0, Omega, 0).
  pure function e_right(a) result(b)
    real(dp), intent(in) :: a(2, 6)
    real(dp) :: b(2, 6)
    b(:, 1) = a(:, 2)
    b(:, 2) = -a(:, 1)
    b(:, 3) = 0.0_dp
    b(:, 4) = a(:, 5)
    b(:, 5) = -a(:, 4)
    b(:, 6) = 0.0_dp
  end function e_right

  !> Consistent mass matrix m = rho_a int N^T N dzeta (local DOFs, no rotary inertia) [kg, kg m, kg m^2].
  pure function beam_mass(rho_a, len) result(m)
    real(dp), intent(in) :: rho_a  !< mass per unit length [kg/m]
    real(dp), intent(in) :: len    !< element length [m]
    real(dp) :: m(6, 6), n(2, 6)
    integer :: q
    m = 0.0_dp
    do q = 1, 4
      n = shape_n(gauss_x(q), len)
      m = m + (gauss_w(q)*len*rho_a)*matmul(transpose(n), n)
    end do
  end function beam_mass

  !> Gyroscopic kernel g = rho_a int N^T D dzeta; the element's Coriolis matrix is 2*omega*g (local).
  pure function beam_gyroscopic(rho_a, len) result(g)
    real(dp), intent(in) :: rho_a  !< mass per unit length [kg/m]
    real(dp), intent(in) :: len    !< element length [m]
    real(dp) :: g(6, 6), n(2, 6), d(2, 6)
    integer :: q
    g = 0.0_dp
    do q = 1, 4
      n = shape_n(gauss_x(q), len)
      d = omega_left(n) - e_right(n)
      g = g + (gauss_w(q)*len*rho_a)*matmul(transpose(n), d)
    end do
  end function beam_gyroscopic

  !> Centrifugal kernel c = rho_a int N^T (Omega D - D E) dzeta; the element's
  !> velocity-independent inertia stiffness is alpha*g + omega^2*c (local).
  pure function beam_centrifugal(rho_a, len) result(c)
    real(dp), intent(in) :: rho_a  !< mass per unit length [kg/m]
    real(dp), intent(in) :: len    !< element length [m]
    real(dp) :: c(6, 6), n(2, 6), d(2, 6)
    integer :: q
    c = 0.0_dp
    do q = 1, 4
      n = shape_n(gauss_x(q), len)
      d = omega_left(n) - e_right(n)
      c = c + (gauss_w(q)*len*rho_a)*matmul(transpose(n), omega_left(d) - e_right(d))
    end do
  end function beam_centrifugal

  !> Hac's coupling matrix m0 = rho_a int N^T N0 dzeta (seed Eq. 16, local), 6 x 4;
  !> columns act on the local rigid nodal accelerations [a_p1, a_v1, a_p2, a_v2].
  pure function beam_hac_coupling(rho_a, len) result(m0)
    real(dp), intent(in) :: rho_a  !< mass per unit length [kg/m]
    real(dp), intent(in) :: len    !< element length [m]
    real(dp) :: m0(6, 4)
    integer :: q
    m0 = 0.0_dp
    do q = 1, 4
      m0 = m0 + (gauss_w(q)*len*rho_a)*matmul(transpose(shape_n(gauss_x(q), len)), shape_n0(gauss_x(q)))
    end do
  end function beam_hac_coupling

  !> Linear elastic stiffness (local): axial EA/L, Euler-Bernoulli bending EI/L^3 [N/m, N, N m].
  pure function beam_stiffness(ea, ei, len) result(k)
    real(dp), intent(in) :: ea   !< axial rigidity E*A [N]
    real(dp), intent(in) :: ei   !< bending rigidity E*I [N m^2]
    real(dp), intent(in) :: len  !< element length [m]
    real(dp) :: k(6, 6), b, l2
    integer, parameter :: t(4) = [2, 3, 5, 6]
    k = 0.0_dp
    k(1, 1) = ea/len; k(4, 4) = ea/len; k(1, 4) = -ea/len; k(4, 1) = -ea/len
    b = ei/len**3
    l2 = len*len
    k(t, t) = b*reshape([12.0_dp, 6.0_dp*len, -12.0_dp, 6.0_dp*len, &
                         6.0_dp*len, 4.0_dp*l2, -6.0_dp*len, 2.0_dp*l2, &
                         -12.0_dp, -6.0_dp*len, 12.0_dp, -6.0_dp*len, &
                         6.0_dp*len, 2.0_dp*l2, -6.0_dp*len, 4.0_dp*l2], [4, 4])
  end function beam_stiffness

  !> Geometric stiffness per unit axial force, int N_v'^T N_v' dzeta on [v1 th1 v2 th2] (local, 1/m, -, m);
  !> the element's geometric stiffness is N * beam_geometric(L), N the axial force [N] (tension > 0).
  pure function beam_geometric(len) result(kg)
    real(dp), intent(in) :: len  !< element length [m]
    real(dp) :: kg(6, 6), l2
    integer, parameter :: t(4) = [2, 3, 5, 6]
    kg = 0.0_dp
    l2 = len*len
    kg(t, t) = 1.0_dp/(30.0_dp*len)*reshape([36.0_dp, 3.0_dp*len, -36.0_dp, 3.0_dp*len, &
                                              3.0_dp*len, 4.0_dp*l2, -3.0_dp*len, -l2, &
                                              -36.0_dp, -3.0_dp*len, 36.0_dp, -3.0_dp*len, &
                                              3.0_dp*len, -l2, -3.0_dp*len, 4.0_dp*l2], [4, 4])
  end function beam_geometric

  !> Curvature v''(zeta) [1/m] of the Hermite field at xi = zeta/L from local DOFs.
  pure function beam_curvature(dloc, len, xi) result(kappa)
    real(dp), intent(in) :: dloc(6)  !< local DOFs [p1, v1, th1, p2, v2, th2]
    real(dp), intent(in) :: len      !< element length [m]
    real(dp), intent(in) :: xi       !< dimensionless position, 0 <= xi <= 1
    real(dp) :: kappa
    kappa = ((-6.0_dp + 12.0_dp*xi)*dloc(2) + (6.0_dp - 12.0_dp*xi)*dloc(5))/len**2 &
            + ((-4.0_dp + 6.0_dp*xi)*dloc(3) + (-2.0_dp + 6.0_dp*xi)*dloc(6))/len
  end function beam_curvature

  !> T(phi) of seed Eq. 9: local = T * global.
  pure function transformation(phi) result(t)
    real(dp), intent(in) :: phi  !< element axis angle from global X [rad]
    real(dp) :: t(6, 6), c, s
    c = cos(phi); s = sin(phi)
    t = 0.0_dp
    t(1, 1) = c; t(1, 2) = s; t(2, 1) = -s; t(2, 2) = c; t(3, 3) = 1.0_dp
    t(4, 4) = c; t(4, 5) = s; t(5, 4) = -s; t(5, 5) = c; t(6, 6) = 1.0_dp
  end function transformation

  !> T^T A T for a local 6 x 6 A, with c = cos(phi), s = sin(phi); exploits the block structure.
  pure function rotate_to_global(a, c, s) result(b)
    real(dp), intent(in) :: a(6, 6), c, s
    real(dp) :: b(6, 6), w(6, 6)
    integer :: i
    do i = 1, 6   ! columns: W = A T
      w(i, 1) = a(i, 1)*c - a(i, 2)*s
      w(i, 2) = a(i, 1)*s + a(i, 2)*c
      w(i, 3) = a(i, 3)
      w(i, 4) = a(i, 4)*c - a(i, 5)*s
      w(i, 5) = a(i, 4)*s + a(i, 5)*c
      w(i, 6) = a(i, 6)
    end do
    do i = 1, 6   ! rows: B = T^T W
      b(1, i) = w(1, i)*c - w(2, i)*s
      b(2, i) = w(1, i)*s + w(2, i)*c
      b(3, i) = w(3, i)
      b(4, i) = w(4, i)*c - w(5, i)*s
      b(5, i) = w(4, i)*s + w(5, i)*c
      b(6, i) = w(6, i)
    end do
  end function rotate_to_global

  !> Local element vector T x from a global one.
  pure function vec_to_local(x, c, s) result(y)
    real(dp), intent(in) :: x(6), c, s
    real(dp) :: y(6)
    y = [c*x(1) + s*x(2), -s*x(1) + c*x(2), x(3), c*x(4) + s*x(5), -s*x(4) + c*x(5), x(6)]
  end function vec_to_local

  !> Global element vector T^T y from a local one.
  pure function vec_to_global(y, c, s) result(x)
    real(dp), intent(in) :: y(6), c, s
    real(dp) :: x(6)
    x = [c*y(1) - s*y(2), s*y(1) + c*y(2), y(3), c*y(4) - s*y(5), s*y(4) + c*y(5), y(6)]
  end function vec_to_global

end module flexmech_beam
