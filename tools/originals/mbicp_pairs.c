/* Feeds pairs to Minguez's original MbICP (Player's server/drivers/position/mbicp), as Player's
   mbicp driver calls it; built by build.sh against the original sources, never committed here.
   stdin, first line: max_range Bw Br L laserStep MaxDistInter filter ProjectionFilter AsocError MaxIter
               errorRatio errx erry errt IterSmoothConv
   then per pair: n, n lines "r t" (reference), n lines (object; invalid readings beyond max_range),
   then "x y th" (the guess). stdout per pair: "code x y th"; stderr at the end: seconds, count. */
#include <stdio.h>
#include <time.h>
#include "TData.h"
#include "MbICP.h"

int main(void) {
  float mr, bw, br, L, mdi, filt, ae, er, ex, ey, et; int ls, pf, mi, isc;
  if (scanf("%f %f %f %f %d %f %f %d %f %d %f %f %f %f %d", &mr, &bw, &br, &L, &ls, &mdi, &filt, &pf, &ae, &mi,
            &er, &ex, &ey, &et, &isc) != 15) return 1;
  Init_MbICP_ScanMatching(mr, bw, br, L, ls, mdi, filt, pf, ae, mi, er, ex, ey, et, isc);
  static Tpfp ref[MAXLASERPOINTS], obj[MAXLASERPOINTS];
  int n; double total = 0; int count = 0;
  while (scanf("%d", &n) == 1) {
    for (int i = 0; i < MAXLASERPOINTS; i++) { ref[i].r = 1e6f; ref[i].t = 0; obj[i].r = 1e6f; obj[i].t = 0; }
    for (int i = 0; i < n; i++) scanf("%f %f", &ref[i].r, &ref[i].t);
    for (int i = 0; i < n; i++) scanf("%f %f", &obj[i].r, &obj[i].t);
    Tsc guess, sol;
    scanf("%f %f %f", &guess.x, &guess.y, &guess.tita);
    sol = guess;
    struct timespec t0, t1; clock_gettime(CLOCK_MONOTONIC, &t0);
    int code = MbICPmatcher(ref, obj, &guess, &sol);
    clock_gettime(CLOCK_MONOTONIC, &t1); total += (t1.tv_sec - t0.tv_sec) + 1e-9 * (t1.tv_nsec - t0.tv_nsec); count++;
    printf("%d %.9g %.9g %.9g\n", code, sol.x, sol.y, sol.tita);
  }
  fprintf(stderr, "%.6f %d\n", total, count);
  return 0;
}
