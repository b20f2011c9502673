/* Feeds pairs to Censi's CSM sm_icp with the options its sm2 program sets; built by build.sh
   against the original sources, never committed here.
   argv: use_point_to_line_distance (0: ICP, 1: PL-ICP).
   stdin per pair: n, n lines "r t valid" (reference), n lines (object), "x y th" (first guess).
   stdout per pair: "valid x y th iterations"; stderr at the end: seconds, count. */
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>
#include <options/options.h>
#include <csm/csm_all.h>

extern void sm_options(struct sm_params *p, struct option *ops);

static LDP read_scan(int n) {
  LDP ld = ld_alloc_new(n);
  for (int i = 0; i < n; i++) {
    double r, t; int v;
    if (scanf("%lf %lf %d", &r, &t, &v) != 3) exit(2);
    ld->readings[i] = v ? r : NAN; ld->theta[i] = t; ld->valid[i] = v;
  }
  ld->min_theta = ld->theta[0]; ld->max_theta = ld->theta[n - 1];
  for (int k = 0; k < 3; k++) { ld->odometry[k] = 0; ld->estimate[k] = 0; ld->true_pose[k] = 0; }
  return ld;
}

int main(int argc, const char **argv) {
  struct sm_params params; struct sm_result result;
  struct option *ops = options_allocate(100);
  sm_options(&params, ops);
  params.use_point_to_line_distance = atoi(argv[1]);
  sm_debug_write(0);
  int n; double total = 0; int count = 0;
  while (scanf("%d", &n) == 1) {
    LDP ref = read_scan(n), sens = read_scan(n);
    double g[3];
    if (scanf("%lf %lf %lf", &g[0], &g[1], &g[2]) != 3) return 5;
    params.laser_ref = ref; params.laser_sens = sens;
    copy_d(g, 3, params.first_guess);
    struct timespec t0, t1; clock_gettime(CLOCK_MONOTONIC, &t0);
    sm_icp(&params, &result);
    clock_gettime(CLOCK_MONOTONIC, &t1);
    total += (t1.tv_sec - t0.tv_sec) + 1e-9 * (t1.tv_nsec - t0.tv_nsec); count++;
    printf("%d %.12g %.12g %.12g %d\n", result.valid, result.x[0], result.x[1], result.x[2], result.iterations);
    ld_free(ref); ld_free(sens);
  }
  fprintf(stderr, "%.6f %d\n", total, count);
  return 0;
}
