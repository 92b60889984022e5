/* amsfe_arm_sensors.c: the C arm's sensors at tick k (amsfe_arm.c): the camera's
 * exposures and the frames due (amsfe_loop.c's expose / camera_tick), the encoder
 * sample and its faults, and the call of a generated function. */
#define _GNU_SOURCE
#include <math.h>
#include <string.h>

#include "amsfe_arm.h"

int gcall(gfun *g, const double **in, int n_in, double **out, int n_out) {
  for (int i = 0; i < n_in; ++i) g->arg[i] = in[i];
  for (int i = 0; i < n_out; ++i) g->res[i] = out[i];
  return g->f(g->arg, g->res, g->iw, g->w, 0);
}

static int inside(const arm_t *s, const double *y) {
  return isfinite(y[0]) && isfinite(y[1]) && y[0] >= 0.0 && y[0] < s->cam_width && y[1] >= 0.0 &&
         y[1] < s->cam_height;
}

/* amsfe_loop.c's expose: project, draw (always), decide, queue.  0 or -1 (queue full or the
 * noise arrays too short: a refusal). */
static int expose(arm_t *s, long k) {
  long e = s->exposures;
  if (e >= s->n_exposures) return -1;
  const double *in[2] = {s->x, s->theta};
  double *res[3] = {s->y, s->J, s->depth};
  if (gcall(&s->g_cam, in, 2, res, 3)) s->y[0] = s->y[1] = NAN;
  if (!(s->depth[0] > 0)) s->y[0] = s->y[1] = NAN;
  s->exposures++;
  if (!inside(s, s->y)) return 0;
  double z[2];
  for (int i = 0; i < 2; ++i) {
    z[i] = s->y[i] + s->pixel_std * s->cam_noise[2 * e + i];
    if (s->round_to_pixel) z[i] = nearbyint(z[i]); /* np.round: half to even */
  }
  if (!inside(s, z) || s->cam_uniform[e] < s->drop_probability) return 0;
  if (s->in_flight >= s->max_in_flight) return -1;
  pending *slot = &s->queue[s->in_flight++];
  slot->delivery = k + s->cam_delay + (long)s->cam_jitter[e];
  slot->exposure = k;
  slot->z[0] = z[0], slot->z[1] = z[1];
  return 0;
}

/* amsfe_loop.c's camera_tick: the frames due at k into s->due sorted by exposure; count. */
int camera_tick(arm_t *s, long k) {
  if (k % s->cam_period == s->cam_phase && expose(s, k) < 0) return -1;
  int count = 0, keep = 0;
  for (int i = 0; i < s->in_flight; ++i) {
    if (s->queue[i].delivery <= k) s->due[count++] = s->queue[i];
    else s->queue[keep++] = s->queue[i];
  }
  s->in_flight = keep;
  for (int i = 1; i < count; ++i) { /* insertion sort: stable, tiny counts */
    pending f = s->due[i];
    int j = i - 1;
    for (; j >= 0 && s->due[j].exposure > f.exposure; --j) s->due[j + 1] = s->due[j];
    s->due[j + 1] = f;
  }
  return count;
}

/* Encoders.measure at x (row k of the noise; row 0 made z0), then the faults' sample. */
void encoders(arm_t *s, long k) {
  int n = s->n;
  const double *v = s->enc_noise + k * 2 * n;
  for (int j = 0; j < n; ++j) {
    double zq = s->x[2 * n + j] + v[j];
    if (s->enc_resolution > 0) zq = nearbyint(zq / s->enc_resolution) * s->enc_resolution;
    s->z[j] = zq;
    s->z[n + j] = s->x[3 * n + j] + v[n + j];
  }
  memcpy(s->zs, s->z, sizeof(double) * 2 * (size_t)n);
  if (s->f_frozen >= 0 && k >= s->f_frozen) {
    if (!s->have_frozen) memcpy(s->frozen, s->z, sizeof(double) * 2 * (size_t)n), s->have_frozen = 1;
    memcpy(s->zs, s->frozen, sizeof(double) * 2 * (size_t)n);
  }
  if (s->f_jump >= 0 && k >= s->f_jump)
    for (int j = 0; j < n; ++j) s->zs[j] += s->jump;
}
