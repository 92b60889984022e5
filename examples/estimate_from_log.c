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
 * A malformed log (unknown record, bad number, wrong length, a record out of order, a
 * truncated last line) stops with "LOG:LINE: ..." on stderr and exit status 2; a runtime
 * call that refuses the log's data (e.g. a NaN input u) with its line and status 1.
 */
#include "amsfe_log.h" /* the strict line reader, now_ns, the estimator block */

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
  log_reader r;
  log_open(&r, argv[1]);
  amsfe_dims d;
  amsfe_dims_get(&d);
  est_block blk;
  est_block_init(&blk, &d);
  double *x = malloc(sizeof(double) * d.N), *P = malloc(sizeof(double) * d.N * d.N);
  double *uz = malloc(sizeof(double) * (d.n + d.ne)), zc[2];
  amsfe_est *est = NULL;
  size_t cap = 1 << 16, nt = 0;
  double *tick_ns = timing ? malloc(sizeof(double) * cap) : NULL, frame_ns = 0.0;
  long frames = 0;
  int have_step = 0;
  while (log_next(&r)) {
    if (est_block_line(&blk, &d, &r, &est)) {
      if (est && have_step) log_fail(&r, "%s: expected the estimator block first, found it "
                                         "after the ticks", r.key);
    } else if (strcmp(r.key, "tick") == 0) {
      if (!est) log_fail(&r, "tick: expected the estimator block (params .. P0) before it");
      if (have_step) print_state(est, &d, x, P);
      log_vector(&r, "tick (u, then z or nan)", uz, d.n + d.ne);
      double t0 = timing ? now_ns() : 0.0; /* a NaN sample: the runtime counts it missing */
      int status = amsfe_est_tick(est, uz + d.n, uz);
      if (timing) {
        if (nt == cap) tick_ns = realloc(tick_ns, sizeof(double) * (cap *= 2));
        tick_ns[nt++] = now_ns() - t0;
      }
      if (status < 0) log_exit(&r, LOG_EXIT_RUNTIME, "tick: %s", amsfe_status_string(status));
      have_step = 1;
    } else if (strcmp(r.key, "frame") == 0) {
      if (!est) log_fail(&r, "frame: expected the estimator block (params .. P0) before it");
      char *t[3];
      log_fixed(&r, "frame (exposure step, u, v)", t, 3);
      long kappa = log_parse_long(&r, "frame", 0, t[0], LONG_MIN, LONG_MAX);
      zc[0] = log_parse_double(&r, "frame", 1, t[1]);
      zc[1] = log_parse_double(&r, "frame", 2, t[2]);
      double nis, t0 = timing ? now_ns() : 0.0;
      int status = amsfe_est_camera_frame(est, zc, kappa, &nis);
      if (timing) frame_ns += now_ns() - t0, ++frames;
      if (status < 0) log_exit(&r, LOG_EXIT_RUNTIME, "camera frame: %s", amsfe_status_string(status));
      amsfe_diag diag;
      amsfe_est_diagnostics(est, &diag);
      printf("frame %ld %ld %d %.17g\n", diag.k, kappa, status, nis);
    } else {
      log_fail(&r, "expected a record params, qw, r_encoder, r_camera, x0, P0, tick or frame, "
                   "found '%s'", r.key);
    }
  }
  if (!est) log_fail(&r, "expected the estimator block (params .. P0), found the end of the log");
  if (have_step) print_state(est, &d, x, P);
  if (timing && nt) {
    qsort(tick_ns, nt, sizeof(double), cmp_double);
    fprintf(stderr, "ticks %zu: median %.0f ns, p99 %.0f ns; frames %ld: mean %.0f ns\n", nt,
            tick_ns[nt / 2], tick_ns[(size_t)(0.99 * (double)(nt - 1))], frames,
            frames ? frame_ns / (double)frames : 0.0);
  }
  amsfe_est_destroy(est);
  fclose(r.f);
  free(r.buf);
  return 0;
}
