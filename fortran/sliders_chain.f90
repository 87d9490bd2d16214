!> The chain of sliders: parameters, elastic force, local elastic-energy change.
!>
!> Same representation as src/sliders/chain.py (1-based slider numbers here):
!> slider i sits at x_i = (i-1) l + u0_i + du_i, and only these enter:
!>
!> * e0(i)     elastic force (springs + cantilever) at du = 0,
!> * t0(0:n)   extension beyond l of spring k, which joins slider k and k+1
!>             (k = 0 and k = n are the springs to the walls; absent, and
!>             zero, for a free chain),
!> * w0(i)     cantilever stretch at du = 0 (sum_i w0(i) = 0).
!>
!> The elastic force is
!>
!>     E_i = E0_i + (du_{i+1} - du_i) - (du_i - du_{i-1}) - xi (du_i - mean(du))
!>
!> with the missing neighbour term dropped at a free end and du = 0 for a
!> wall.  `elastic_force` evaluates it with the same operations, in the same
!> order, as the NumPy reference (so both round alike); the kernel's hot loop
!> (sliders_steps, step_spans) writes the same formula out for the
!> interior sliders so that it fuses with the Verlet update.
module sliders_chain
  use sliders_kinds, only: dp, ip
  implicit none
  private

  public :: chain_params
  public :: elastic_force, tangential_force, total_displacement
  public :: spring_energy_change, cantilever_energy_change

  !> What the force and energy formulas need to know about the chain.
  type :: chain_params
    integer(ip) :: n = 0            !< number of sliders
    logical :: walls = .false.      !< between two immobile walls (else free ends)
    real(dp) :: xi = 0.0_dp         !< cantilever stiffness (neighbour springs: 1)
    !> The pushed end (sliders_loading): slider 1 tied by a spring of this
    !> stiffness to a driver at driver_position; 0: no driver (the tilt).
    real(dp) :: driver_stiffness = 0.0_dp
    real(dp) :: driver_position = 0.0_dp
  end type chain_params

contains

  !> Elastic force E_i on slider i for displacements du of mean `mean`
  !> (`mean` is not used when xi = 0).
  pure function elastic_force(chain, e0, du, i, mean) result(e)
    type(chain_params), intent(in) :: chain
    real(dp), contiguous, intent(in) :: e0(:)
    real(dp), contiguous, intent(in) :: du(:)
    integer(ip), intent(in) :: i
    real(dp), intent(in) :: mean
    real(dp) :: e

    e = force_formula(chain, e0, du, i, mean)
  end function elastic_force

  !> The formula itself; private, so that the compiler inlines it in the
  !> list loop even in position-independent code.
  pure function force_formula(chain, e0, du, i, mean) result(e)
    type(chain_params), intent(in) :: chain
    real(dp), contiguous, intent(in) :: e0(:)
    real(dp), contiguous, intent(in) :: du(:)
    integer(ip), intent(in) :: i
    real(dp), intent(in) :: mean
    real(dp) :: e
    real(dp) :: right, left

    ! spring i (right of slider i) stretches by du(i+1) - du(i) ...
    if (i < chain%n) then
      right = du(i + 1) - du(i)
    else if (chain%walls) then
      right = -du(i)
    else
      right = 0.0_dp
    end if
    ! ... and spring i-1 (left of it) by du(i) - du(i-1)
    if (i > 1) then
      left = du(i) - du(i - 1)
    else if (chain%walls) then
      left = du(i)
    else
      left = 0.0_dp
    end if
    e = e0(i) + (right - left)
    if (chain%xi /= 0.0_dp) e = e - chain%xi*(du(i) - mean)
  end function force_formula

  !> Tangential force on slider i of elastic force `elastic` and displacement
  !> du_i: the elastic force plus the weight, plus on slider 1 the driver's
  !> spring if there is one, (E + w) + K (D - du_1): the order of the
  !> reference (loading.PushedEndLoading.tangential).
  pure function tangential_force(chain, i, elastic, weight, du_i) result(f)
    type(chain_params), intent(in) :: chain
    integer(ip), intent(in) :: i
    real(dp), intent(in) :: elastic, weight, du_i
    real(dp) :: f

    f = elastic + weight
    if (i == 1 .and. chain%driver_stiffness /= 0.0_dp) &
      f = f + chain%driver_stiffness*(chain%driver_position - du_i)
  end function tangential_force

  !> Sum of du (plain left-to-right sum).
  pure function total_displacement(du) result(s)
    real(dp), contiguous, intent(in) :: du(:)
    real(dp) :: s
    integer(ip) :: i

    s = 0.0_dp
    do i = 1, size(du, kind=ip)
      s = s + du(i)
    end do
  end function total_displacement

  !> Change of the spring energy 1/2 sum_k T_k**2 when the sliders in `moved`
  !> (increasing order) go from du_old to du_new; every other slider has
  !> du_old = du_new.  Only the springs touching a moved slider change:
  !> dU_k = dT_k (T_k,old + dT_k/2), T_k = t0(k) + du(k+1) - du(k).
  pure function spring_energy_change(chain, t0, du_old, du_new, moved) result(du_energy)
    type(chain_params), intent(in) :: chain
    real(dp), intent(in) :: t0(0:)
    real(dp), contiguous, intent(in) :: du_old(:)
    real(dp), contiguous, intent(in) :: du_new(:)
    integer(ip), contiguous, intent(in) :: moved(:)
    real(dp) :: du_energy
    integer(ip) :: j, k, last, i
    real(dp) :: t_old, dt

    du_energy = 0.0_dp
    last = -1
    do j = 1, size(moved, kind=ip)
      i = moved(j)
      do k = max(i - 1, last + 1), i          ! springs i-1 and i, each once
        if (.not. chain%walls .and. (k == 0 .or. k == chain%n)) cycle
        t_old = t0(k) + (at(du_old, k + 1) - at(du_old, k))
        dt = (at(du_new, k + 1) - at(du_old, k + 1)) - (at(du_new, k) - at(du_old, k))
        du_energy = du_energy + dt*(t_old + 0.5_dp*dt)
      end do
      last = i
    end do

  contains

    !> du of slider k, 0 for a wall (k = 0 or n + 1).
    pure function at(du, k) result(x)
      real(dp), intent(in) :: du(:)
      integer(ip), intent(in) :: k
      real(dp) :: x

      if (k < 1 .or. k > chain%n) then
        x = 0.0_dp
      else
        x = du(k)
      end if
    end function at

  end function spring_energy_change

  !> Change of the cantilever energy xi/2 sum_i w_i**2, w_i = w0_i + du_i -
  !> mean(du), when the sliders in `moved` go from du_old (of mean mean_old)
  !> to du_new.  With d_i = du_new - du_old and D its mean, sum_i w_i,old = 0
  !> gives dU = xi [sum_moved w_i,old d_i + (sum_moved d_i**2 - n D**2)/2].
  pure function cantilever_energy_change(chain, w0, du_old, du_new, moved, mean_old) &
      result(du_energy)
    type(chain_params), intent(in) :: chain
    real(dp), contiguous, intent(in) :: w0(:)
    real(dp), contiguous, intent(in) :: du_old(:)
    real(dp), contiguous, intent(in) :: du_new(:)
    integer(ip), contiguous, intent(in) :: moved(:)
    real(dp), intent(in) :: mean_old
    real(dp) :: du_energy
    integer(ip) :: j, i
    real(dp) :: d, linear, square, total, shift

    du_energy = 0.0_dp
    if (chain%xi == 0.0_dp) return
    linear = 0.0_dp
    square = 0.0_dp
    total = 0.0_dp
    do j = 1, size(moved, kind=ip)
      i = moved(j)
      d = du_new(i) - du_old(i)
      linear = linear + (w0(i) + du_old(i) - mean_old)*d
      square = square + d*d
      total = total + d
    end do
    shift = total/real(chain%n, dp)
    du_energy = chain%xi*(linear + 0.5_dp*(square - real(chain%n, dp)*shift*shift))
  end function cantilever_energy_change

end module sliders_chain
