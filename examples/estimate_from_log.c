/* estimate_from_log: run a compiled amsfe_sym estimator over a recorded log, without Python.
 *
 * Links only the generated robot library (generated/<robot>/lib<robot>.so) and includes only
 * its amsfe_runtime.h (and this folder's amsfe_log.h, the log reading both examples share):
 *
 *   cc -O2 examples/estimate_from_log.c -Igenerated/paper_2link_rk4 \
 *      -Lgenerated/paper_2link_rk4 -lpaper_2link_rk4 -Wl,-rpath,generated/paper_2link_rk4 \
 *      -lm -o estimate_from_log
 *   ./estimate_from_log run.log > estimates.txt      (add --time for per-call costs)
 *
 * Log (text, one record per line, written by amsfe_sym.runtime.compiled_estimator.write_log):
 *   params <estimator> <buffer_steps> <camera_iterations> <camera_period> <camera_phase>
 *          <camera_max_delay> <max_frames_per_step> <gate_camera> <gate_encoder> <k0>
 *   qw <nw numbers>    r_encoder <ne numbers>    r_camera <2 numbers>
 *   x0 <N numbers>     P0 <N*N numbers, column-major>
 *   tick <u: n numbers> <z: ne numbers, or "nan" for a missing sample>
 *   frame <exposure step> <z: 2 numbers>       (frames delivered at the step of the last tick)
 * Output: per frame "frame <k> <kappa> <status> <nis>", per step (after its frames)
 * "est <k> <x: N> <P: N*N>", all with 17 significant digits.
 */
#include "amsfe_log.h" /* read_numbers, now_ns, the estimator block; amsfe_runtime.h */

static void print_state(const amsfe_est *est, const amsfe_dims *d, double *x, double *P) {
  amsfe_diag diag;
  amsfe_est_diagnostics(est, &diag);
  amsfe_est_state(est, x, P);
  printf("est %ld", diag.k);
  for (int i = 0; i < d->N; ++i) printf(" %.17g", x[i]);
  for (int i = 0; i < d->N * d->N; ++i) printf(" %.17g", P[i]);
  printf("\n");
}

int main(int argc, char **argv) {
  if (argc < 2) {
    fprintf(stderr, "usage: %s LOG [--time]\n", argv[0]);
    return 2;
  }
  int timing = argc > 2 && strcmp(argv[2], "--time") == 0;
  FILE *f = fopen(argv[1], "r");
  if (!f) {
    perror(argv[1]);
    return 2;
  }
  amsfe_dims d;
  amsfe_dims_get(&d);
  est_block blk;
  est_block_init(&blk, &d);
  double *x = malloc(sizeof(double) * d.N), *P = malloc(sizeof(double) * d.N * d.N);
  double *u = malloc(sizeof(double) * d.n), *z = malloc(sizeof(double) * d.ne), zc[2];
  amsfe_est *est = NULL;
  size_t cap = 1 << 16, nt = 0;
  double *tick_ns = timing ? malloc(sizeof(double) * cap) : NULL, frame_ns = 0.0;
  long frames = 0;
  int have_step = 0;
  char *line = NULL;
  size_t len = 0;
  while (getline(&line, &len, f) > 0) {
    char key[16];
    int used = 0;
    if (sscanf(line, "%15s %n", key, &used) != 1) continue;
    char *rest = line + used;
    int ok = 1;
    if (est_block_line(&blk, &d, key, rest, &ok, &est)) {
    } else if (strcmp(key, "tick") == 0 && est) {
      if (have_step) print_state(est, &d, x, P);
      ok = read_numbers(rest, u, d.n);
      char *zs = rest;
      for (int i = 0; i < d.n; ++i) strtod(zs, &zs); /* skip u */
      int has_z = read_numbers(zs, z, d.ne);
      double t0 = timing ? now_ns() : 0.0;
      int status = amsfe_est_tick(est, has_z ? z : NULL, u);
      if (timing) {
        if (nt == cap) tick_ns = realloc(tick_ns, sizeof(double) * (cap *= 2));
        tick_ns[nt++] = now_ns() - t0;
      }
      if (status < 0) {
        fprintf(stderr, "tick: %s\n", amsfe_status_string(status));
        return 1;
      }
      have_step = 1;
    } else if (strcmp(key, "frame") == 0 && est) {
      long kappa = strtol(rest, &rest, 10);
      ok = read_numbers(rest, zc, 2);
      double nis, t0 = timing ? now_ns() : 0.0;
      int status = amsfe_est_camera_frame(est, zc, kappa, &nis);
      if (timing) frame_ns += now_ns() - t0, ++frames;
      if (status < 0) {
        fprintf(stderr, "camera frame: %s\n", amsfe_status_string(status));
        return 1;
      }
      amsfe_diag diag;
      amsfe_est_diagnostics(est, &diag);
      printf("frame %ld %ld %d %.17g\n", diag.k, kappa, status, nis);
    }
    if (!ok) {
      fprintf(stderr, "bad line: %s", line);
      return 2;
    }
  }
  if (have_step) print_state(est, &d, x, P);
  if (timing && nt) {
    qsort(tick_ns, nt, sizeof(double), cmp_double);
    fprintf(stderr, "ticks %zu: median %.0f ns, p99 %.0f ns; frames %ld: mean %.0f ns\n", nt,
            tick_ns[nt / 2], tick_ns[(size_t)(0.99 * (double)(nt - 1))], frames,
            frames ? frame_ns / (double)frames : 0.0);
  }
  amsfe_est_destroy(est);
  fclose(f);
  free(line);
  return 0;
}
