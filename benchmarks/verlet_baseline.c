/* The machine's limit for the sliders' hot loop: a plain fused
 * velocity-Verlet step over n contiguous moving sliders of a free chain,
 *
 *   half kick, drift, nearest-neighbour spring force, half kick, sign test
 *
 * with constant dynamic friction in each slider's direction.  Nothing else:
 * no crossing refinement, no bookkeeping.  benchmarks/kernel_speed.py builds
 * it with gcc -O3 -march=native (IEEE semantics, no -ffast-math) and divides
 * the kernel's ns per slider-step by this program's.
 *
 * Usage: verlet_baseline [n_sliders] [steps]; prints "ns_per_slider_step X".
 * kernel_speed.py runs it at 250 sliders (a long run of movers, where the
 * loop's fixed cost per step is hidden) and at the
 * numbers of movers per step the kernel's runs really have (mostly 1-60).
 */
#include <stdio.h>
#include <stdlib.h>
#include <time.h>

static double cpu_seconds(void) {
  struct timespec t;
  clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &t);
  return (double)t.tv_sec + 1e-9 * (double)t.tv_nsec;
}

int main(int argc, char **argv) {
  int n = argc > 1 ? atoi(argv[1]) : 250;
  long steps = argc > 2 ? atol(argv[2]) : 400000;
  if (n < 1 || steps < 1) {
    fprintf(stderr, "verlet_baseline: need n_sliders >= 1 and steps >= 1\n");
    return 2;
  }
  double *x = malloc(sizeof(double) * (size_t)(n + 2));
  double *v = malloc(sizeof(double) * (size_t)n);
  double *a = malloc(sizeof(double) * (size_t)n);
  double *e0 = malloc(sizeof(double) * (size_t)n);
  double *dir = malloc(sizeof(double) * (size_t)n);
  const double h = 1e-3, sin_a = 0.48, friction = 0.55 * 0.877;
  /* x[0] and x[n+1] are ghost copies of the ends (free chain: no spring). */
  for (int i = 0; i < n; i++) {
    x[i + 1] = 0.01 * (double)((i * 7919) % 101) / 101.0;
    v[i] = 0.1;
    a[i] = 0.0;
    e0[i] = 0.0;
    dir[i] = 1.0;
  }
  long crossings = 0;
  double start = cpu_seconds();
  for (long s = 0; s < steps; s++) {
    for (int i = 0; i < n; i++) {
      v[i] += 0.5 * h * a[i];            /* half kick */
      x[i + 1] += h * v[i];              /* drift */
    }
    x[0] = x[1];
    x[n + 1] = x[n];
    int crossed = 0;
    for (int i = 0; i < n; i++) {
      double f = e0[i] + (x[i + 2] - x[i + 1]) - (x[i + 1] - x[i]) + sin_a;
      a[i] = f - friction * dir[i];
      v[i] += 0.5 * h * a[i];            /* half kick */
      crossed |= dir[i] * v[i] < 0.0;    /* sign test */
    }
    crossings += crossed;
  }
  double elapsed = cpu_seconds() - start;
  /* print a state-dependent value so that nothing is optimised away */
  double check = 0.0;
  for (int i = 0; i < n; i++) check += x[i + 1] + v[i];
  printf("ns_per_slider_step %.6f\n", 1e9 * elapsed / ((double)steps * (double)n));
  printf("check %.17g crossings %ld\n", check, crossings);
  free(x); free(v); free(a); free(e0); free(dir);
  return 0;
}
