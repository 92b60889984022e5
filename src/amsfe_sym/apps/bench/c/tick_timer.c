/* tick_timer.c: the compiled estimator tick timed in pure C (amsfe bench, section 4).
 *
 * usage: tick_timer LIB INPUT
 *
 * dlopens the robot library LIB (its amsfe_runtime.h API), builds an estimator from the
 * binary INPUT written by amsfe_sym.apps.bench.tick.write_tick_input (native byte order):
 *   int32[8]  estimator, buffer_steps, camera_iterations, camera_period, camera_phase,
 *             camera_max_delay, max_frames_per_step, K (ticks)
 *   float64   gate_camera, gate_encoder, qw[nw], r_encoder[ne], r_camera[2], x0[N],
 *             P0[N*N] (column-major), then K records u[n], z[ne] (NaN: no sample)
 *   optional: int32 F, then F frames (float64 exposure step, delivery step, u px, v px) in
 *             delivery order
 * and runs K amsfe_est_tick calls, each timed with clock_gettime; with frames, after tick k
 * the frames delivered at k + 1 (amsfe_est_camera_frame, each timed on its own).
 * Prints "median_ns p99_ns" of the ticks on the first line, the final x(k|k) on the second,
 * and with frames "median_ns p99_ns frames applied" of the frames on a third.
 */
#define _POSIX_C_SOURCE 199309L
#include <dlfcn.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

typedef struct {
  int n, N, nw, ne, nc, clone_slots;
} dims_t;
typedef struct {
  int estimator, buffer_steps, camera_iterations, camera_period, camera_phase,
      camera_max_delay, max_frames_per_step;
  double gate_camera, gate_encoder;
  const double *qw, *r_encoder, *r_camera, *x0, *P0;
  long k0;
  int backward_map; /* amsfe_params.backward_map: 0, the linearised map */
  /* amsfe_params' effort fields (docs/explanation/effort.md section 7): all 0, the applied torque */
  int input_states;
  const double *input_gain;
  int joint_torque;
  const double *ks;
  const int *ks_theta;
  int net_torque;
} params_t;

static void *sym(void *h, const char *name) {
  void *p = dlsym(h, name);
  if (!p) {
    fprintf(stderr, "missing symbol %s\n", name);
    exit(2);
  }
  return p;
}

static double *doubles(FILE *f, long count) {
  double *v = malloc(sizeof(double) * (size_t)(count > 0 ? count : 1));
  if (!v || fread(v, sizeof(double), (size_t)count, f) != (size_t)count) {
    fprintf(stderr, "short input\n");
    exit(2);
  }
  return v;
}

static int cmp(const void *a, const void *b) {
  double x = *(const double *)a, y = *(const double *)b;
  return (x > y) - (x < y);
}

int main(int argc, char **argv) {
  if (argc != 3) {
    fprintf(stderr, "usage: %s LIB INPUT\n", argv[0]);
    return 2;
  }
  void *h = dlopen(argv[1], RTLD_NOW | RTLD_LOCAL);
  if (!h) {
    fprintf(stderr, "%s\n", dlerror());
    return 2;
  }
  void (*dims_get)(dims_t *) = (void (*)(dims_t *))sym(h, "amsfe_dims_get");
  void *(*create)(const params_t *, int *) =
      (void *(*)(const params_t *, int *))sym(h, "amsfe_est_create");
  int (*tick)(void *, const double *, const double *) =
      (int (*)(void *, const double *, const double *))sym(h, "amsfe_est_tick");
  void (*state)(const void *, double *, double *) =
      (void (*)(const void *, double *, double *))sym(h, "amsfe_est_state");
  dims_t d;
  dims_get(&d);
  FILE *f = fopen(argv[2], "rb");
  if (!f) {
    fprintf(stderr, "cannot open %s\n", argv[2]);
    return 2;
  }
  int hdr[8];
  if (fread(hdr, sizeof(int), 8, f) != 8) {
    fprintf(stderr, "short input\n");
    return 2;
  }
  params_t p;
  memset(&p, 0, sizeof(p)); /* the fields not read below: 0 (the applied torque) */
  p.estimator = hdr[0], p.buffer_steps = hdr[1], p.camera_iterations = hdr[2];
  p.camera_period = hdr[3], p.camera_phase = hdr[4], p.camera_max_delay = hdr[5];
  p.max_frames_per_step = hdr[6];
  long K = hdr[7];
  double *g = doubles(f, 2);
  p.gate_camera = g[0], p.gate_encoder = g[1];
  p.qw = doubles(f, d.nw), p.r_encoder = doubles(f, d.ne), p.r_camera = doubles(f, d.nc);
  p.x0 = doubles(f, d.N), p.P0 = doubles(f, (long)d.N * d.N);
  p.k0 = 0;
  p.backward_map = 0;
  double *rec = doubles(f, K * (d.n + d.ne));
  int F = 0;
  if (fread(&F, sizeof(int), 1, f) != 1) F = 0;
  double *fr = doubles(f, 4L * F);
  fclose(f);
  int status;
  void *est = create(&p, &status);
  if (!est) {
    fprintf(stderr, "amsfe_est_create failed: status %d\n", status);
    return 1;
  }
  int (*frame)(void *, const double *, long, double *) =
      (int (*)(void *, const double *, long, double *))sym(h, "amsfe_est_camera_frame");
  double *t = malloc(sizeof(double) * (size_t)(K > 0 ? K : 1));
  double *tf = malloc(sizeof(double) * (size_t)(F > 0 ? F : 1));
  int fi = 0, applied = 0;
  for (long k = 0; k < K; ++k) {
    const double *u = rec + k * (d.n + d.ne), *z = u + d.n;
    struct timespec a, b;
    clock_gettime(CLOCK_MONOTONIC, &a);
    int st = tick(est, isnan(z[0]) ? NULL : z, u);
    clock_gettime(CLOCK_MONOTONIC, &b);
    if (st < 0) {
      fprintf(stderr, "tick %ld: status %d\n", k + 1, st);
      return 1;
    }
    t[k] = 1e9 * (double)(b.tv_sec - a.tv_sec) + (double)(b.tv_nsec - a.tv_nsec);
    for (; fi < F && (long)fr[4 * fi + 1] == k + 1; ++fi) {
      double zc[2] = {fr[4 * fi + 2], fr[4 * fi + 3]}, nis;
      clock_gettime(CLOCK_MONOTONIC, &a);
      st = frame(est, zc, (long)fr[4 * fi], &nis);
      clock_gettime(CLOCK_MONOTONIC, &b);
      if (st < 0) {
        fprintf(stderr, "frame %d at tick %ld: status %d\n", fi, k + 1, st);
        return 1;
      }
      applied += st == 0;
      tf[fi] = 1e9 * (double)(b.tv_sec - a.tv_sec) + (double)(b.tv_nsec - a.tv_nsec);
    }
  }
  qsort(t, (size_t)K, sizeof(double), cmp);
  long i99 = (long)ceil(0.99 * (double)K) - 1;
  printf("%.1f %.1f\n", t[K / 2], t[i99 < 0 ? 0 : i99]);
  double *x = malloc(sizeof(double) * (size_t)d.N);
  state(est, x, NULL);
  for (int i = 0; i < d.N; ++i) printf("%.17g ", x[i]);
  printf("\n");
  if (fi > 0) {
    qsort(tf, (size_t)fi, sizeof(double), cmp);
    long f99 = (long)ceil(0.99 * (double)fi) - 1;
    printf("%.1f %.1f %d %d\n", tf[fi / 2], tf[f99 < 0 ? 0 : f99], fi, applied);
  }
  return 0;
}
