!> Kind parameters of the sliders kernel, taken from iso_c_binding so that
!> every value crossing the f2py boundary has a C (and NumPy) counterpart.
module sliders_kinds
  use, intrinsic :: iso_c_binding, only: c_double, c_int, c_int64_t
  implicit none
  private

  public :: dp, ip, i8

  integer, parameter :: dp = c_double    !< real(dp): float64
  integer, parameter :: ip = c_int       !< integer(ip): int32 (sizes, status)
  integer, parameter :: i8 = c_int64_t   !< integer(i8): int64 (random keys)

end module sliders_kinds
