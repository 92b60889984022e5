/* control_from_log: an arm's real-time loop, estimator + controller, without Python.
 *
 * Links only the generated robot library and includes only its headers (amsfe_loop.h and
 * amsfe_runtime.h, copied next to the library by `amsfe generate`) and this folder's
 * amsfe_log.h (the log reading both examples share):
 *
 *   D=generated/paper_2link_rk4
 *   cc -O2 examples/control_from_log.c -I$D -L$D -lpaper_2link_rk4 -Wl,-rpath,$D -lm \
 *      -o control_from_log
 *   ./control_from_log run.log > torques.txt          (add --time for the tick's cost)
 *
 * Each step is one amsfe_loop_tick: the encoder sample and the camera frames delivered at
 * that step in, the torque out (estimator step with the previous torque, frames, law,
 * actuator limit).  The log stands in for the arm's drivers; it is written by
 * amsfe_sym.runtime.compiled_loop.write_loop_log from a simulated run:
 *   the estimator block of examples/estimate_from_log.c (params, qw, r_encoder, r_camera,
 *   x0, P0), then
 *   ctrl <controller> <T> <p> <qmd_next_hold> <state_true> <link_bandwidth> <motor_bandwidth>
 *        <startup_converged> <ready_q_std> <ready_qd_std> <blend_accel> <blend_rate>
 *        <ready_nis> <ready_nis_window> <hold_motor> <blend_wf> <headroom_tau>
 *        <blend_lead>
 *   <name> <n numbers>   for h lam Lt eps phi wm tau_max wf vmax u_max Mm Fm Ks ks_theta
 *   theta_initial <p numbers>
 *   frame <exposure step> <u> <v>     (delivered at the next `step`; any number per step)
 *   step <z: 2n numbers> <ref: 5n numbers>
 * Output per step: "u <k> <u: n> <x: N>" (torque and estimate x(k|k)), 17 significant digits.
 * A malformed log (unknown record, bad number, wrong length, a block line missing, repeated
 * or out of order, frames after the last step, a truncated last line) stops with
 * "LOG:LINE: ..." on stderr and exit status 2; a runtime call that refuses the log's data
 * with its line and status 1.
 */
#include <math.h>
#include <stdlib.h>

#include "amsfe_log.h" /* the strict line reader, now_ns, the estimator block */
#include "amsfe_loop.h"

#define MAX_FRAMES 64

static void *aligned(size_t size) {
  void *p = NULL;
  return posix_memalign(&p, 16, size) == 0 ? p : NULL;
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
  int n = d.n, np = d.N - 4 * d.n;
  est_block blk;
  est_block_init(&blk, &d);
  double *x = malloc(sizeof(double) * d.N), *u = malloc(sizeof(double) * n);
  double *zr = malloc(sizeof(double) * 7 * n); /* a step: z (2n), then ref (5n) */
  double *theta0 = malloc(sizeof(double) * (np + 1)), *ks_d = malloc(sizeof(double) * n);
  /* the controller block: ctrl, the vectors, ks_theta, then theta_initial (creates it) */
  static const char *vec_names[] = {"h",   "lam",   "Lt", "eps", "phi", "wm", "tau_max",
                                    "wf",  "vmax", "u_max", "Mm", "Fm", "Ks", "ks_theta",
                                    "ctrl"};
  enum { NV = 13, NCTRL = NV + 2 };
  unsigned seen = 0;
  double *vec[NV];
  for (int i = 0; i < NV; ++i) vec[i] = malloc(sizeof(double) * n);
  int *ks_theta = malloc(sizeof(int) * n);
  amsfe_ctrl_params cp;
  memset(&cp, 0, sizeof(cp));
  amsfe_est *est = NULL;
  amsfe_ctrl *ctrl = NULL;
  amsfe_frame frames[MAX_FRAMES];
  int status_buf[MAX_FRAMES], nf = 0;
  long k = 0;
  size_t cap = 1 << 16, nt = 0;
  double *tick_ns = timing ? malloc(sizeof(double) * cap) : NULL;
  while (log_next(&r)) {
    int vi = -1;
    for (int i = 0; i < NCTRL; ++i)
      if (strcmp(r.key, vec_names[i]) == 0) vi = i;
    if (vi >= 0 || strcmp(r.key, "theta_initial") == 0) {
      if (ctrl) log_fail(&r, "%s: expected the controller block once, found it again", r.key);
      if (vi >= 0 && (seen & (1u << vi)))
        log_fail(&r, "%s: expected one such line, found a second", r.key);
    }
    if (est_block_line(&blk, &d, &r, &est)) {
      if (k) log_fail(&r, "%s: expected the estimator block first, found it after steps", r.key);
    } else if (vi == NCTRL - 1) { /* ctrl */
      char *t[18];
      log_fixed(&r, "ctrl", t, 18);
      int *ints[] = {&cp.controller, &cp.qmd_next_hold, &cp.state_true, &cp.startup_converged,
                     &cp.hold_motor};
      int int_at[] = {0, 3, 4, 7, 14};
      for (int i = 0; i < 5; ++i)
        *ints[i] = (int)log_parse_long(&r, "ctrl", int_at[i], t[int_at[i]], INT_MIN, INT_MAX);
      double *dbl[] = {&cp.T,           &cp.p,           &cp.link_bandwidth, &cp.motor_bandwidth,
                       &cp.ready_q_std, &cp.ready_qd_std, &cp.blend_accel, &cp.blend_rate,
                       &cp.ready_nis,   &cp.ready_nis_window, &cp.blend_wf, &cp.headroom_tau,
                       &cp.blend_lead};
      int dbl_at[] = {1, 2, 5, 6, 8, 9, 10, 11, 12, 13, 15, 16, 17};
      for (int i = 0; i < 13; ++i) *dbl[i] = log_parse_double(&r, "ctrl", dbl_at[i], t[dbl_at[i]]);
      seen |= 1u << vi;
    } else if (vi == NV) { /* ks_theta: integers (-1 = the spec's Ks) */
      log_vector(&r, "ks_theta", ks_d, n);
      for (int j = 0; j < n; ++j) {
        if (!(ks_d[j] >= -1 && ks_d[j] <= np - 1 && ks_d[j] == floor(ks_d[j])))
          log_fail(&r, "ks_theta value %d: expected an integer in [-1, %d], found %.17g", j + 1,
                   np - 1, ks_d[j]);
        ks_theta[j] = (int)ks_d[j];
      }
      seen |= 1u << vi;
    } else if (vi >= 0) {
      log_vector(&r, r.key, vec[vi], n);
      seen |= 1u << vi;
    } else if (strcmp(r.key, "theta_initial") == 0) {
      for (int i = 0; i < NCTRL; ++i)
        if (!(seen & (1u << i)))
          log_fail(&r, "theta_initial: expected the controller block's lines before it, found "
                       "no %s line", vec_names[i]);
      log_vector(&r, "theta_initial", theta0, np);
      cp.h = vec[0], cp.lam = vec[1], cp.Lt = vec[2], cp.eps = vec[3], cp.phi = vec[4];
      cp.wm = vec[5], cp.tau_max = vec[6], cp.wf = vec[7], cp.vmax = vec[8];
      cp.u_max = vec[9], cp.Mm = vec[10], cp.Fm = vec[11], cp.Ks = vec[12];
      cp.ks_theta = ks_theta, cp.theta_initial = theta0;
      size_t size = amsfe_ctrl_memory_size(&cp);
      void *mem = size ? aligned(size) : NULL;
      int status = mem ? amsfe_ctrl_init(&ctrl, &cp, mem, size) : AMSFE_ERR_CONFIG;
      if (status != AMSFE_OK)
        log_exit(&r, LOG_EXIT_RUNTIME, "amsfe_ctrl_init: %s", amsfe_status_string(status));
    } else if (strcmp(r.key, "frame") == 0) {
      if (!est || !ctrl)
        log_fail(&r, "frame: expected the estimator and controller blocks before it");
      if (nf == MAX_FRAMES)
        log_fail(&r, "frame: expected at most %d frames in one step, found more", MAX_FRAMES);
      char *t[3];
      log_fixed(&r, "frame (exposure step, u, v)", t, 3);
      frames[nf].exposure_step = log_parse_long(&r, "frame", 0, t[0], LONG_MIN, LONG_MAX);
      frames[nf].z[0] = log_parse_double(&r, "frame", 1, t[1]);
      frames[nf].z[1] = log_parse_double(&r, "frame", 2, t[2]);
      ++nf;
    } else if (strcmp(r.key, "step") == 0) {
      if (!est || !ctrl)
        log_fail(&r, "step: expected the estimator and controller blocks before it");
      log_vector(&r, "step (z: 2n, then ref: 5n)", zr, 7 * n);
      double t0 = timing ? now_ns() : 0.0;
      amsfe_ctrl_out out = {NULL, NULL, NULL, 0};
      int status = amsfe_loop_tick(est, ctrl, zr, frames, nf, status_buf, zr + 2 * n, NULL, u,
                                   &out);
      if (timing) {
        if (nt == cap) tick_ns = realloc(tick_ns, sizeof(double) * (cap *= 2));
        tick_ns[nt++] = now_ns() - t0;
      }
      if (status < 0)
        log_exit(&r, LOG_EXIT_RUNTIME, "step %ld: %s", k, amsfe_status_string(status));
      for (int i = 0; i < n; ++i) /* never send a NaN torque to an arm */
        if (!isfinite(u[i]))
          log_exit(&r, LOG_EXIT_RUNTIME, "step %ld: expected a finite torque, found u[%d] = %g "
                   "(not applied; the loop has diverged)", k, i, u[i]);
      amsfe_est_state(est, x, NULL);
      printf("u %ld", k);
      for (int i = 0; i < n; ++i) printf(" %.17g", u[i]);
      for (int i = 0; i < d.N; ++i) printf(" %.17g", x[i]);
      printf("\n");
      nf = 0;
      ++k;
    } else {
      log_fail(&r, "expected a record of the estimator or controller block, frame or step, "
                   "found '%s'", r.key);
    }
  }
  if (!est || !ctrl)
    log_fail(&r, "expected the estimator and controller blocks, found the end of the log");
  if (nf) log_fail(&r, "expected a step after the last %d frame(s), found the end of the log", nf);
  if (timing && nt) {
    double sum = 0.0;
    for (size_t i = 0; i < nt; ++i) sum += tick_ns[i];
    qsort(tick_ns, nt, sizeof(double), cmp_double);
    fprintf(stderr, "ticks %zu: median %.0f ns, p99 %.0f ns, mean %.0f ns\n", nt,
            tick_ns[nt / 2], tick_ns[(size_t)(0.99 * (double)(nt - 1))], sum / (double)nt);
  }
  amsfe_est_destroy(est);
  fclose(r.f);
  free(r.buf);
  return 0;
}
