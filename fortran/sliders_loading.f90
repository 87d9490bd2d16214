!> Loading protocols: how the drive parameter lambda enters the chain
!> (src/sliders/parts/loading.py, the specification).
!>
!> * The tilt (lambda = alpha): every slider feels sin(alpha) along the
!>   incline and presses with cos(alpha) on it; a resting slider of elastic
!>   force E and static coefficient mu destabilises at the closed-form roots
!>   of E + sin a = +-mu cos a.
!> * The pushed end (lambda = D): the incline fixed at `incline`, slider 1 tied
!>   by a spring of stiffness K to a driver at D (the chain's
!>   driver_stiffness/driver_position, whose force sliders_chain adds); only
!>   slider 1's force depends on D, so the next instability is slider 1's
!>   threshold crossing, in closed form (pushed_next).  The run ends after
!>   the first event in which every slider moved, the onset of sliding.
!>
!> Every branch on the protocol is here: the kernel reads the loading from
!> the packed parameters (unpack_loading, with the driver it ties to the
!> chain: driver_stiffness), and the event integrator (sliders_events) asks
!> this module for the drive's terms once per event, for the next critical
!> drive between events (loading_next_drive; the tilt's is the smallest
!> instability angle, which sliders_next_angle finds from the roots below),
!> for the loading's work and for the run's end; nothing here runs per
!> integration step.
module sliders_loading
  use, intrinsic :: ieee_arithmetic, only: ieee_value, ieee_positive_inf
  use sliders_kinds, only: dp, ip, i8
  use sliders_contract, only: loading_tilt, loading_pushed_end, par_loading, par_incline, &
                              par_driver_stiffness, par_alpha_max, par_drive_max
  implicit none
  private

  public :: loading_params
  public :: unpack_loading, driver_stiffness
  public :: drive_terms, loading_work, loading_runaway, beyond_limit, spanning_ends_run
  public :: loading_next_drive
  public :: tilt_root_cache, instability_roots, roots_from, root_lower_bounds
  public :: tie_tol

  !> The loading protocol of a run (from the packed parameters).
  type :: loading_params
    integer(ip) :: protocol = loading_tilt   !< loading_tilt or loading_pushed_end
    real(dp) :: incline = 0.0_dp             !< pushed end: the fixed incline
    real(dp) :: stiffness = 0.0_dp           !< pushed end: K of the driver's spring
    real(dp) :: limit = 0.0_dp               !< end of loading: alpha_max or drive_max
  end type loading_params

  !> Sliders whose instability angles tie within this start together.
  real(dp), parameter :: tie_tol = 1.0e-12_dp
  real(dp), parameter :: pi = 3.141592653589793_dp   ! == numpy.pi
  !> Absolute widening of the asin bounds of root_lower_bound: far above the
  !> rounding of angles <= pi (1e-15), far below the spread of the angles.
  real(dp), parameter :: bound_slack = 1.0e-12_dp

contains

  ! ----------------------------------------------------------- the protocol

  !> The loading of a kernel call from its packed parameters (positions:
  !> sliders_contract): the protocol and its values; its limit is the tilt's
  !> alpha_max, or the pushed end's drive_max.
  pure function unpack_loading(real_params, int_params) result(load)
    real(dp), intent(in) :: real_params(:)
    integer(i8), intent(in) :: int_params(:)
    type(loading_params) :: load

    load%protocol = int(int_params(par_loading), ip)
    load%incline = real_params(par_incline)
    load%stiffness = real_params(par_driver_stiffness)
    load%limit = real_params(par_alpha_max)
    if (load%protocol == loading_pushed_end) load%limit = real_params(par_drive_max)
  end function unpack_loading

  !> Stiffness of the spring by which the loading ties slider 1 to a driver
  !> (sliders_chain's driver_stiffness): the pushed end's K; 0 (no driver)
  !> for the tilt.
  pure function driver_stiffness(load) result(stiffness)
    type(loading_params), intent(in) :: load
    real(dp) :: stiffness

    stiffness = 0.0_dp
    if (load%protocol == loading_pushed_end) stiffness = load%stiffness
  end function driver_stiffness

  !> The next critical drive >= drive when the loading gives it in closed
  !> form (closed_form true): the pushed end's, where slider 1 (the only one
  !> that feels the driver) starts downwards (pushed_next), with that
  !> trigger and direction.  The tilt's (closed_form false) is the smallest
  !> instability angle of the resting sliders, which the caller finds from
  !> their roots (sliders_next_angle); critical, trigger and direction are
  !> then not set.
  pure subroutine loading_next_drive(load, elastic1, mu1, du1, drive, force_tol, &
                                     closed_form, critical, trigger, direction)
    type(loading_params), intent(in) :: load
    real(dp), intent(in) :: elastic1, mu1, du1, drive, force_tol
    logical, intent(out) :: closed_form
    real(dp), intent(inout) :: critical
    integer(ip), intent(inout) :: trigger
    real(dp), intent(inout) :: direction

    closed_form = load%protocol == loading_pushed_end
    if (closed_form) then
      critical = pushed_next(load, elastic1, mu1, du1, drive, force_tol)
      trigger = 1
      direction = 1.0_dp
    end if
  end subroutine loading_next_drive

  ! ------------------------------------------------------- the drive's terms

  !> Tangential force the drive adds to every slider (weight) and the normal
  !> load that scales friction (normal) at drive lambda, fixed during an
  !> event: the tilt's sin/cos(lambda), the pushed end's sin/cos(incline).
  pure subroutine drive_terms(load, lambda, weight, normal)
    type(loading_params), intent(in) :: load
    real(dp), intent(in) :: lambda
    real(dp), intent(out) :: weight, normal

    if (load%protocol == loading_pushed_end) then
      call incline_terms(load%incline, weight, normal)
    else
      call incline_terms(lambda, weight, normal)
    end if
  end subroutine drive_terms

  !> Work of the loading in an event whose displacements sum to `step`:
  !> gravity's, plus for the pushed end the driver's spring on slider 1 as
  !> it moves by s1 against the fixed driver at `drive` from du1_start,
  !> K (D - du1_start) s1 - K s1**2/2 (the reference's order).
  pure function loading_work(load, weight, step, drive, s1, du1_start) result(work)
    type(loading_params), intent(in) :: load
    real(dp), intent(in) :: weight, step, drive, s1, du1_start
    real(dp) :: work

    work = tilt_work(weight, step)
    if (load%protocol == loading_pushed_end) &
      work = work + load%stiffness*((drive - du1_start)*s1 - 0.5_dp*s1*s1)
  end function loading_work

  !> The run ends in a runaway: the tilt's avalanche (tilt_runaway); the
  !> pushed end never runs away (its incline is below atan(mu_d)).
  pure function loading_runaway(load, walls, n, n_moving, n_down, weight, kinetic) &
      result(runaway)
    type(loading_params), intent(in) :: load
    logical, intent(in) :: walls
    integer(ip), intent(in) :: n, n_moving, n_down
    real(dp), intent(in) :: weight, kinetic
    logical :: runaway

    runaway = load%protocol == loading_tilt .and. &
              tilt_runaway(walls, n, n_moving, n_down, weight, kinetic)
  end function loading_runaway

  !> The drive went past the end of loading (alpha_max or drive_max).
  pure function beyond_limit(load, lambda) result(beyond)
    type(loading_params), intent(in) :: load
    real(dp), intent(in) :: lambda
    logical :: beyond

    beyond = lambda > load%limit
  end function beyond_limit

  !> The run ends after the first event in which every slider moved (the
  !> pushed end's onset of sliding); the tilt runs on.
  pure function spanning_ends_run(load) result(ends)
    type(loading_params), intent(in) :: load
    logical :: ends

    ends = load%protocol == loading_pushed_end
  end function spanning_ends_run

  !> The pushed end's next critical drive >= drive: slider 1 (elastic force
  !> elastic1, static coefficient mu1, displacement du1) starts downwards
  !> when E_1 + sin(incline) + K (D - du_1) reaches mu_1 cos(incline) + force_tol.
  pure function pushed_next(load, elastic1, mu1, du1, drive, force_tol) result(critical)
    type(loading_params), intent(in) :: load
    real(dp), intent(in) :: elastic1, mu1, du1, drive, force_tol
    real(dp) :: critical
    real(dp) :: weight, normal

    call incline_terms(load%incline, weight, normal)
    critical = du1 + (((mu1*normal + force_tol) - elastic1) - weight)/load%stiffness
    critical = max(critical, drive)
  end function pushed_next

  !> Tangential force on every slider (weight = sin alpha) and normal load
  !> (normal = cos alpha) on an incline at angle alpha: the tilt's drive, or
  !> the pushed end's fixed incline; fixed during an event.
  pure subroutine incline_terms(alpha, weight, normal)
    real(dp), intent(in) :: alpha
    real(dp), intent(out) :: weight, normal

    weight = sin(alpha)
    normal = cos(alpha)
  end subroutine incline_terms

  !> Work of gravity in an event whose displacements sum to `step`.
  pure function tilt_work(weight, step) result(work)
    real(dp), intent(in) :: weight, step
    real(dp) :: work

    work = weight*step
  end function tilt_work

  !> The paper's avalanche: a free chain whose n sliders all slide down
  !> (n_moving == n_down == n) with the weight beating kinetic friction.
  pure function tilt_runaway(walls, n, n_moving, n_down, weight, kinetic) result(runaway)
    logical, intent(in) :: walls
    integer(ip), intent(in) :: n, n_moving, n_down
    real(dp), intent(in) :: weight, kinetic
    logical :: runaway

    runaway = .not. walls .and. n_moving == n .and. n_down == n .and. weight > kinetic
  end function tilt_runaway

  ! ------------------------------------------------------------------ angles

  !> hypot(1, mu) and atan(mu), cached per slider by the kernel (they change
  !> only when mu does).  Callers mark their loops novector: a vectorised
  !> loop would call glibc's libmvec variants (_ZGV*_atan, _ZGV*_hypot),
  !> which differ from the scalar functions in the last bit and would break
  !> the bit-for-bit agreement with the reference.
  elemental subroutine tilt_root_cache(mu, radius, phi)
    real(dp), intent(in) :: mu
    real(dp), intent(out) :: radius, phi

    radius = hypot(1.0_dp, mu)
    phi = atan(mu)
  end subroutine tilt_root_cache

  !> Instability angles of one resting slider of elastic force `elastic` and
  !> static coefficient `mu` (loading.next_instability): downwards the root
  !> of E + sin a = mu cos a, phi + asin(-E/R) if E >= -1; upwards the root of
  !> E + sin a = -mu cos a, pi - phi - asin(-E/R) if E <= -1 (R = hypot(1, mu),
  !> phi = atan(mu)); +inf where there is none in [0, pi/2].
  elemental subroutine instability_roots(elastic, mu, down, up)
    real(dp), intent(in) :: elastic, mu
    real(dp), intent(out) :: down, up

    call roots_from(elastic, hypot(1.0_dp, mu), atan(mu), down, up)
  end subroutine instability_roots

  !> instability_roots with R = hypot(1, mu) and phi = atan(mu) given (they
  !> change only when mu does, so the kernel caches them per slider).
  elemental subroutine roots_from(elastic, radius, phi, down, up)
    real(dp), intent(in) :: elastic, radius, phi
    real(dp), intent(out) :: down, up
    real(dp) :: ratio, s

    down = ieee_value(down, ieee_positive_inf)
    up = down
    ratio = -elastic/radius
    if (abs(ratio) <= 1.0_dp) then
      s = asin(ratio)
      if (elastic >= -1.0_dp) down = phi + s
      if (elastic <= -1.0_dp) up = (pi - phi) - s
    end if
  end subroutine roots_from

  !> Bounds of asin(x), |x| <= 1, without a transcendental: with y = |x|,
  !> P(y) = y + y**3/6 + 3 y**5/40 <= asin(y) <= P(y) + 0.33 y**7 (the series
  !> of asin has positive coefficients, and its tail beyond y**5 is at most
  !> (pi/2 - P(1)) y**7 = 0.3291 y**7), widened by bound_slack for rounding.
  elemental subroutine asin_bounds(x, lower, upper)
    real(dp), intent(in) :: x
    real(dp), intent(out) :: lower, upper
    real(dp) :: y, y2, p, tail

    y = abs(x)
    y2 = y*y
    p = y*(1.0_dp + y2*(1.0_dp/6.0_dp + y2*(3.0_dp/40.0_dp)))
    tail = 0.33_dp*y*y2*y2*y2
    if (x >= 0.0_dp) then
      lower = p - bound_slack
      upper = p + tail + bound_slack
    else
      lower = -(p + tail) - bound_slack
      upper = -p + bound_slack
    end if
  end subroutine asin_bounds

  !> A lower bound of max(min(down, up), alpha) of roots_from, without asin
  !> (+inf where roots_from finds no root: the same tests).
  elemental function root_lower_bound(elastic, radius, phi, alpha) result(bound)
    real(dp), intent(in) :: elastic, radius, phi, alpha
    real(dp) :: bound
    real(dp) :: ratio, lower, upper

    bound = ieee_value(bound, ieee_positive_inf)
    ratio = -elastic/radius
    if (abs(ratio) <= 1.0_dp) then
      call asin_bounds(ratio, lower, upper)
      if (elastic >= -1.0_dp) bound = phi + lower
      if (elastic <= -1.0_dp) bound = min(bound, (pi - phi) - upper)
      bound = max(bound, alpha) - bound_slack
    end if
  end function root_lower_bound

  !> root_lower_bound of sliders 1..n into bound (one call per event: the
  !> loop, a polynomial, vectorises here).
  pure subroutine root_lower_bounds(n, elastic, radius, phi, alpha, bound)
    integer(ip), intent(in) :: n
    real(dp), intent(in) :: elastic(:), radius(:), phi(:)
    real(dp), intent(in) :: alpha
    real(dp), intent(inout) :: bound(:)

    bound(1:n) = root_lower_bound(elastic(1:n), radius(1:n), phi(1:n), alpha)
  end subroutine root_lower_bounds

end module sliders_loading
