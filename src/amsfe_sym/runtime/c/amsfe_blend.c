/* amsfe_blend.c: the controller's start-up blends (control/blend.py): the polynomial from an
 * offset and a rate to zero, its least duration within the acceleration limits, the blend
 * through a trusted offset, and the blended reference and command-filter bandwidth while it
 * runs (amsfe_ctrl.c calls them). */
#include <math.h>
#include <string.h>

#include "amsfe_loop_internal.h"

/* control/blend.py: the r-th derivative of sum b_i s^i at s, Horner from the top. */
static const double BLEND_B0[10] = {1, 0, 0, 0, 0, -126, 420, -540, 315, -70};
static const double BLEND_B1[10] = {0, 1, 0, 0, 0, -70, 224, -280, 160, -35};
static const double BLEND_A0[3] = {9.3720, 78.751, 622.54};
static const double BLEND_A1[3] = {6.1455, 39.860, 332.92};

static double blend_poly(const double *b, int r, double s) {
  double acc = 0.0;
  for (int i = 9; i >= r; --i) {
    double f = 1.0;
    for (int m = i - r + 1; m <= i; ++m) f *= m;
    acc = acc * s + b[i] * f;
  }
  return acc;
}

/* the bound on |delta^(r)|: |d0| A0_r / Tb^r + |d1| A1_r / Tb^(r-1) */
static double blend_bound(double a, double b, double tb, int r) {
  double p = 1.0;
  for (int i = 0; i < r - 1; ++i) p *= tb;
  return a * BLEND_A0[r - 2] / (p * tb) + b * BLEND_A1[r - 2] / p;
}

/* blend_time: the least Tb (bisection) with |delta^(2)| <= accel, |delta^(3)| <= accel rate,
 * |delta^(4)| <= accel rate^2 on every joint */
double blend_time(const double *d0, const double *d1, long n, double accel,
                  double rate) {
  if (isinf(accel)) return 0.0;
  int rmax = isinf(rate) ? 2 : 4;
  double tb = 0.0;
  for (long j = 0; j < n; ++j) {
    double a = fabs(d0[j]), b = fabs(d1[j]);
    if (a == 0.0 && b == 0.0) continue;
    for (int r = 2; r <= rmax; ++r) {
      double lim = accel;
      for (int i = 0; i < r - 2; ++i) lim *= rate;
      if (tb > 0.0 && !(blend_bound(a, b, tb, r) > lim)) continue;
      double lo = tb, hi = tb > 1e-3 ? tb : 1e-3;
      for (int i = 0; i < 64; ++i) {
        if (!(blend_bound(a, b, hi, r) > lim)) break;
        lo = hi, hi = 2.0 * hi;
      }
      for (int i = 0; i < 60; ++i) {
        double mid = 0.5 * (lo + hi);
        if (blend_bound(a, b, mid, r) > lim)
          lo = mid;
        else
          hi = mid;
      }
      tb = hi;
    }
  }
  return tb;
}

/* control/blend.py's _through: (d0, d1) of the blend of duration tb whose offset and rate are
 * (e0, e1) at wait after its start; 0 when one is not finite */
static int blend_solve(const double *e0, const double *e1, long n, double wait, double tb,
                       double *d0, double *d1) {
  double tau = wait / tb;
  double a = blend_poly(BLEND_B0, 0, tau), b = tb * blend_poly(BLEND_B1, 0, tau);
  double c = blend_poly(BLEND_B0, 1, tau) / tb, d = blend_poly(BLEND_B1, 1, tau);
  double det = a * d - b * c;
  int ok = 1;
  for (long j = 0; j < n; ++j) {
    d0[j] = (d * e0[j] - b * e1[j]) / det;
    d1[j] = (a * e1[j] - c * e0[j]) / det;
    ok = ok && isfinite(d0[j]) && isfinite(d1[j]);
  }
  return ok;
}

static int blend_fits(const double *e0, const double *e1, long n, double wait, double tb,
                      double accel, double rate, double *d0, double *d1) {
  return blend_solve(e0, e1, n, wait, tb, d0, d1) &&
         !(blend_time(d0, d1, n, accel, rate) > tb);
}

/* control/blend.py's blend_through: the blend that started wait [s] ago and passes through
 * the offsets (e0, e1) now; its duration, and its offsets at its start into (d0, d1) */
double blend_through(const double *e0, const double *e1, long n, double wait,
                     double accel, double rate, double *d0, double *d1) {
  double tb0 = blend_time(e0, e1, n, accel, rate);
  if (!(wait > 0.0) || tb0 == 0.0) {
    memcpy(d0, e0, sizeof(double) * (size_t)n);
    memcpy(d1, e1, sizeof(double) * (size_t)n);
    return tb0;
  }
  double lo = wait, step = tb0, hi = wait + step;
  for (int i = 0; i < 64; ++i) { /* bracket: a blend long enough always fits */
    if (blend_fits(e0, e1, n, wait, hi, accel, rate, d0, d1)) break;
    lo = hi, step = 2.0 * step;
    hi = wait + step;
  }
  for (int i = 0; i < 60; ++i) {
    double mid = 0.5 * (lo + hi);
    if (blend_fits(e0, e1, n, wait, mid, accel, rate, d0, d1))
      hi = mid;
    else
      lo = mid;
  }
  blend_solve(e0, e1, n, wait, hi, d0, d1);
  return hi;
}

/* blend_offsets(s, Tb, d0, d1)[: orders n] into out (zero once s >= Tb) */
void blend_offsets_into(double s, double tb, const double *d0, const double *d1, long n,
                        int orders, double *out) {
  if (!(s < tb)) {
    memset(out, 0, sizeof(double) * (size_t)(orders * n));
    return;
  }
  double tau = s / tb, scale = 1.0;
  for (int r = 0; r < orders; ++r) {
    double p0 = blend_poly(BLEND_B0, r, tau), p1 = blend_poly(BLEND_B1, r, tau);
    for (long j = 0; j < n; ++j) out[r * n + j] = (d0[j] * p0 + d1[j] * tb * p1) / scale;
    scale *= tb;
  }
}

/* ref + blend_offsets(s, Tb, d0, d1) into c->refb */
const double *blended(amsfe_ctrl *c, long k, const double *ref) {
  long n = c->d.n;
  double s = (double)(k - c->blend_k0) * c->par.T + c->blend_s0, tb = c->blend_tb;
  if (!(s < tb)) return ref;
  double tau = s / tb, scale = 1.0;
  for (int r = 0; r < 5; ++r) {
    double p0 = blend_poly(BLEND_B0, r, tau), p1 = blend_poly(BLEND_B1, r, tau);
    for (long j = 0; j < n; ++j)
      c->refb[r * n + j] =
          ref[r * n + j] + (c->blend_d0[j] * p0 + c->blend_d1[j] * tb * p1) / scale;
    scale *= tb;
  }
  return c->refb;
}

/* _Cascade._blend_gains: wf + (blend_wf - wf) b0(s / Tb), at most wf (as the headroom
 * scaled it), while the blend runs */
const double *blend_bandwidth(amsfe_ctrl *c, long k, const double *wf) {
  long n = c->d.n;
  double s = (double)(k - c->blend_k0) * c->par.T + c->blend_s0, tb = c->blend_tb;
  double bwf = c->par.blend_wf;
  if (!(s < tb) || !(bwf > 0) || isinf(bwf)) return wf;
  double w = blend_poly(BLEND_B0, 0, s / tb);
  for (long j = 0; j < n; ++j) c->wfb[j] = fmin(wf[j], w * bwf + (1.0 - w) * wf[j]);
  return c->wfb;
}
