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
 *   <name> <n numbers>   for h lam Lt eps phi wm tau_max wf vmax u_max Mm Fm Ks ks_theta
 *   theta_initial <p numbers>
 *   frame <exposure step> <u> <v>     (delivered at the next `step`; any number per step)
 *   step <z: 2n numbers> <ref: 5n numbers>
 * Output per step: "u <k> <u: n> <x: N>" (torque and estimate x(k|k)), 17 significant digits.
 */
#include <math.h>
#include <stdlib.h>

#include "amsfe_log.h" /* read_numbers, now_ns, the estimator block; amsfe_runtime.h */
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
  FILE *f = fopen(argv[1], "r");
  if (!f) {
    perror(argv[1]);
    return 2;
  }
  amsfe_dims d;
  amsfe_dims_get(&d);
  int n = d.n, np = d.N - 4 * d.n;
  est_block blk;
  est_block_init(&blk, &d);
  double *x = malloc(sizeof(double) * d.N), *u = malloc(sizeof(double) * n);
  double *z = malloc(sizeof(double) * 2 * n), *ref = malloc(sizeof(double) * 5 * n);
  double *theta0 = malloc(sizeof(double) * (np + 1)), *ks_d = malloc(sizeof(double) * n);
  static const char *vec_names[] = {"h",   "lam",   "Lt", "eps", "phi", "wm", "tau_max",
                                    "wf",  "vmax", "u_max", "Mm", "Fm", "Ks"};
  enum { NV = sizeof(vec_names) / sizeof(vec_names[0]) };
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
  char *line = NULL;
  size_t len = 0;
  while (getline(&line, &len, f) > 0) {
    char key[16];
    int used = 0;
    if (sscanf(line, "%15s %n", key, &used) != 1) continue;
    char *rest = line + used;
    int ok = 1, vi = -1;
    for (int i = 0; i < NV; ++i)
      if (strcmp(key, vec_names[i]) == 0) vi = i;
    if (est_block_line(&blk, &d, key, rest, &ok, &est)) {
    } else if (strcmp(key, "ctrl") == 0) {
      ok = sscanf(rest, "%d %lf %lf %d %d %lf %lf %d %lf %lf %lf %lf", &cp.controller, &cp.T,
                  &cp.p, &cp.qmd_next_hold, &cp.state_true, &cp.link_bandwidth,
                  &cp.motor_bandwidth, &cp.startup_converged, &cp.ready_q_std, &cp.ready_qd_std,
                  &cp.blend_accel, &cp.blend_rate) == 12;
    } else if (vi >= 0) {
      ok = read_numbers(rest, vec[vi], n);
    } else if (strcmp(key, "ks_theta") == 0) {
      ok = read_numbers(rest, ks_d, n);
      for (int j = 0; j < n; ++j) ks_theta[j] = (int)ks_d[j];
    } else if (strcmp(key, "theta_initial") == 0) {
      ok = read_numbers(rest, theta0, np);
      cp.h = vec[0], cp.lam = vec[1], cp.Lt = vec[2], cp.eps = vec[3], cp.phi = vec[4];
      cp.wm = vec[5], cp.tau_max = vec[6], cp.wf = vec[7], cp.vmax = vec[8];
      cp.u_max = vec[9], cp.Mm = vec[10], cp.Fm = vec[11], cp.Ks = vec[12];
      cp.ks_theta = ks_theta, cp.theta_initial = theta0;
      size_t size = amsfe_ctrl_memory_size(&cp);
      void *mem = size ? aligned(size) : NULL;
      int status = mem ? amsfe_ctrl_init(&ctrl, &cp, mem, size) : AMSFE_ERR_CONFIG;
      if (status != AMSFE_OK) {
        fprintf(stderr, "amsfe_ctrl_init: %s\n", amsfe_status_string(status));
        return 1;
      }
    } else if (strcmp(key, "frame") == 0) {
      if (nf == MAX_FRAMES) {
        fprintf(stderr, "more than %d frames in one step\n", MAX_FRAMES);
        return 2;
      }
      frames[nf].exposure_step = strtol(rest, &rest, 10);
      ok = read_numbers(rest, frames[nf].z, 2);
      ++nf;
    } else if (strcmp(key, "step") == 0 && est && ctrl) {
      ok = read_numbers(rest, z, 2 * n);
      char *rs = rest;
      for (int i = 0; i < 2 * n; ++i) strtod(rs, &rs); /* skip z */
      ok = ok && read_numbers(rs, ref, 5 * n);
      double t0 = timing ? now_ns() : 0.0;
      amsfe_ctrl_out out = {NULL, NULL, NULL, 0};
      int status = amsfe_loop_tick(est, ctrl, z, frames, nf, status_buf, ref, NULL, u, &out);
      if (timing) {
        if (nt == cap) tick_ns = realloc(tick_ns, sizeof(double) * (cap *= 2));
        tick_ns[nt++] = now_ns() - t0;
      }
      if (status < 0) {
        fprintf(stderr, "step %ld: %s\n", k, amsfe_status_string(status));
        return 1;
      }
      amsfe_est_state(est, x, NULL);
      printf("u %ld", k);
      for (int i = 0; i < n; ++i) printf(" %.17g", u[i]);
      for (int i = 0; i < d.N; ++i) printf(" %.17g", x[i]);
      printf("\n");
      nf = 0;
      ++k;
    }
    if (!ok) {
      fprintf(stderr, "bad line: %s", line);
      return 2;
    }
  }
  if (timing && nt) {
    double sum = 0.0;
    for (size_t i = 0; i < nt; ++i) sum += tick_ns[i];
    qsort(tick_ns, nt, sizeof(double), cmp_double);
    fprintf(stderr, "ticks %zu: median %.0f ns, p99 %.0f ns, mean %.0f ns\n", nt,
            tick_ns[nt / 2], tick_ns[(size_t)(0.99 * (double)(nt - 1))], sum / (double)nt);
  }
  amsfe_est_destroy(est);
  fclose(f);
  free(line);
  return 0;
}
