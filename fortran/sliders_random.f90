!> Keyed random numbers, bit for bit the same as src/sliders/keyed_random.py.
!>
!> A counter-based generator: every number is a pure function of the key
!> (seed, slider, count, draw), hashed with Wellons' "lowbias32" (docs/model.md,
!> "Keyed randomness").  Unsigned 32-bit values are held in integer(i8) in [0, 2**32);
!> keys outside that range are reduced modulo 2**32, like NumPy's uint32 cast.
module sliders_random
  use, intrinsic :: ieee_arithmetic, only: ieee_value, ieee_quiet_nan
  use sliders_kinds, only: dp, ip, i8
  implicit none
  private

  public :: mix32, key_hash, uniform, static_coefficient, draw_static_coefficient
  public :: max_attempts, preparation_stream

  integer(ip), parameter :: max_attempts = 1000          !< rejection attempts
  integer(i8), parameter :: preparation_stream = 4294967295_i8  !< 0xFFFFFFFF

  integer(i8), parameter :: mask32 = 4294967295_i8       ! 0xFFFFFFFF
  integer(i8), parameter :: mask16 = 65535_i8            ! 0xFFFF
  integer(i8), parameter :: golden = 2654435769_i8       ! 0x9E3779B9
  integer(i8), parameter :: mul1 = 2146121005_i8         ! 0x7FEB352D
  integer(i8), parameter :: mul2 = 2221713035_i8         ! 0x846CA68B
  real(dp), parameter :: two_pow_26 = 67108864.0_dp
  real(dp), parameter :: two_pow_53 = 9007199254740992.0_dp
  real(dp), parameter :: pi = 3.141592653589793_dp       ! == numpy.pi

contains

  !> (a*b) mod 2**32 for a, b in [0, 2**32) without signed overflow:
  !> a = a_hi*2**16 + a_lo, every intermediate product is below 2**49.
  elemental function mulmod32(a, b) result(r)
    integer(i8), intent(in) :: a, b
    integer(i8) :: r
    integer(i8) :: a_lo, a_hi

    a_lo = iand(a, mask16)
    a_hi = ishft(a, -16)
    r = iand(a_lo*b + ishft(iand(a_hi*b, mask16), 16), mask32)
  end function mulmod32

  !> Wellons' lowbias32 hash of a uint32 value.
  elemental function mix32(x) result(h)
    integer(i8), intent(in) :: x
    integer(i8) :: h

    h = iand(x, mask32)
    h = ieor(h, ishft(h, -16))
    h = mulmod32(h, mul1)
    h = ieor(h, ishft(h, -15))
    h = mulmod32(h, mul2)
    h = ieor(h, ishft(h, -16))
  end function mix32

  !> Hash of the key (seed, slider, count, draw), a uint32 in integer(i8).
  elemental function key_hash(seed, slider, count, draw) result(h)
    integer(i8), intent(in) :: seed, slider, count, draw
    integer(i8) :: h

    h = mix32(ieor(iand(seed, mask32), golden))
    h = mix32(ieor(h, iand(slider, mask32)))
    h = mix32(ieor(h, iand(count, mask32)))
    h = mix32(ieor(h, iand(draw, mask32)))
  end function key_hash

  !> Uniform double in the open interval (0, 1), 53 bits, keyed.
  elemental function uniform(seed, slider, count, draw) result(u)
    integer(i8), intent(in) :: seed, slider, count, draw
    real(dp) :: u
    integer(i8) :: d2, a, b

    d2 = iand(2_i8*iand(draw, mask32), mask32)      ! uint32 arithmetic: 2*draw
    a = ishft(key_hash(seed, slider, count, d2), -5)
    b = ishft(key_hash(seed, slider, count, d2 + 1_i8), -6)
    u = ((real(a, dp)*two_pow_26 + real(b, dp)) + 0.5_dp)/two_pow_53
  end function uniform

  !> Static coefficient drawn by slider `slider` at its `count`-th stop:
  !> Gaussian (Box-Muller on two keyed uniforms) of mean `mu_s_mean` and width
  !> `sigma_mu`, redrawn until it exceeds `mu_d`.  On exhaustion of
  !> `max_attempts` the result is NaN and `status` is 1, else 0.
  elemental subroutine draw_static_coefficient(seed, slider, count, mu_s_mean, &
                                               sigma_mu, mu_d, mu, status)
    integer(i8), intent(in) :: seed, slider, count
    real(dp), intent(in) :: mu_s_mean, sigma_mu, mu_d
    real(dp), intent(out) :: mu
    integer(ip), intent(out) :: status
    integer(i8) :: attempt
    real(dp) :: u1, u2, z

    do attempt = 0_i8, int(max_attempts, i8) - 1_i8
      u1 = uniform(seed, slider, count, 2_i8*attempt)
      u2 = uniform(seed, slider, count, 2_i8*attempt + 1_i8)
      z = sqrt(-2.0_dp*log(u1))*cos((2.0_dp*pi)*u2)
      mu = mu_s_mean + sigma_mu*z
      if (mu > mu_d) then
        status = 0
        return
      end if
    end do
    mu = ieee_value(mu, ieee_quiet_nan)
    status = 1
  end subroutine draw_static_coefficient

  !> Function form of draw_static_coefficient (not pure: `status` is an output).
  function static_coefficient(seed, slider, count, mu_s_mean, sigma_mu, mu_d, &
                              status) result(mu)
    integer(i8), intent(in) :: seed, slider, count
    real(dp), intent(in) :: mu_s_mean, sigma_mu, mu_d
    integer(ip), intent(out) :: status
    real(dp) :: mu

    call draw_static_coefficient(seed, slider, count, mu_s_mean, sigma_mu, &
                                 mu_d, mu, status)
  end function static_coefficient

end module sliders_random
