!> Friction laws: static threshold, kinetic force and the draw at a stop
!> (src/sliders/parts/friction.py, the specification).
!>
!> Coulomb friction with a static coefficient redrawn at every stop: a
!> resting slider withstands |F| <= mu_s N + force_tol, a moving one feels
!> mu_d N against its motion, and at its k-th stop slider n draws
!> mu_s(seed, n, k) from the keyed Gaussian above mu_d (sliders_random).
!> The law's parameters are a coulomb_friction, read from the packed
!> parameters by unpack_friction; nothing outside this module reads them.
!> The event integrator asks these at event level and at crossings; the
!> per-step loop only uses the thresholds and the kinetic force they return.
module sliders_friction
  use sliders_kinds, only: dp, ip, i8
  use sliders_random, only: static_coefficient
  use sliders_contract, only: par_mu_d, par_mu_s_mean, par_sigma_mu
  implicit none
  private

  public :: coulomb_friction
  public :: unpack_friction, static_threshold, kinetic_force, draw_at_stop

  !> Coulomb friction's parameters (parts/friction.py, Coulomb).
  type :: coulomb_friction
    real(dp) :: mu_d = 0.0_dp        !< kinetic coefficient
    real(dp) :: mu_s_mean = 0.0_dp   !< mean of the static coefficient's draw
    real(dp) :: sigma_mu = 0.0_dp    !< its width (drawn above mu_d)
  end type coulomb_friction

contains

  !> The friction law of a kernel call from its packed real parameters
  !> (positions: sliders_contract).
  pure function unpack_friction(real_params) result(friction)
    real(dp), intent(in) :: real_params(:)
    type(coulomb_friction) :: friction

    friction%mu_d = real_params(par_mu_d)
    friction%mu_s_mean = real_params(par_mu_s_mean)
    friction%sigma_mu = real_params(par_sigma_mu)
  end function unpack_friction

  !> |F| beyond which a resting slider of static coefficient mu starts under
  !> the normal load `normal`.
  elemental function static_threshold(mu, normal, force_tol) result(threshold)
    real(dp), intent(in) :: mu, normal, force_tol
    real(dp) :: threshold

    threshold = mu*normal + force_tol
  end function static_threshold

  !> Friction on a moving slider (opposite to its motion) under the normal
  !> load `normal`.
  pure function kinetic_force(friction, normal) result(force)
    type(coulomb_friction), intent(in) :: friction
    real(dp), intent(in) :: normal
    real(dp) :: force

    force = friction%mu_d*normal
  end function kinetic_force

  !> The static coefficient of slider `slider` (0-based) at its count-th
  !> stop, keyed by the run's seed; status /= 0 if the keyed draw failed.
  function draw_at_stop(friction, seed, slider, count, status) result(mu)
    type(coulomb_friction), intent(in) :: friction
    integer(i8), intent(in) :: seed, slider, count
    integer(ip), intent(out) :: status
    real(dp) :: mu

    mu = static_coefficient(seed, slider, count, friction%mu_s_mean, friction%sigma_mu, &
                            friction%mu_d, status)
  end function draw_at_stop

end module sliders_friction
