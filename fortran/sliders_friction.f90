!> Friction laws: static threshold, kinetic force and the draw at a stop
!> (src/sliders/engine/friction.py, the specification).
!>
!> Coulomb friction with a static coefficient redrawn at every stop: a
!> resting slider withstands |F| <= mu_s N + force_tol, a moving one feels
!> mu_d N against its motion, and at its k-th stop slider n draws
!> mu_s(seed, n, k) from the keyed Gaussian above mu_d (sliders_random).
!> The event integrator asks these at event level and at crossings; the
!> per-step loop only uses the thresholds and the kinetic force they return.
module sliders_friction
  use sliders_kinds, only: dp, ip, i8
  use sliders_random, only: static_coefficient
  implicit none
  private

  public :: static_threshold, kinetic_force, draw_at_stop

contains

  !> |F| beyond which a resting slider of static coefficient mu starts under
  !> the normal load `normal`.
  elemental function static_threshold(mu, normal, force_tol) result(threshold)
    real(dp), intent(in) :: mu, normal, force_tol
    real(dp) :: threshold

    threshold = mu*normal + force_tol
  end function static_threshold

  !> Friction on a moving slider (opposite to its motion).
  pure function kinetic_force(mu_d, normal) result(force)
    real(dp), intent(in) :: mu_d, normal
    real(dp) :: force

    force = mu_d*normal
  end function kinetic_force

  !> The static coefficient of slider `slider` (0-based) at its count-th
  !> stop; status /= 0 if the keyed draw failed.
  function draw_at_stop(seed, slider, count, mu_s_mean, sigma_mu, mu_d, status) result(mu)
    integer(i8), intent(in) :: seed, slider, count
    real(dp), intent(in) :: mu_s_mean, sigma_mu, mu_d
    integer(ip), intent(out) :: status
    real(dp) :: mu

    mu = static_coefficient(seed, slider, count, mu_s_mean, sigma_mu, mu_d, status)
  end function draw_at_stop

end module sliders_friction
