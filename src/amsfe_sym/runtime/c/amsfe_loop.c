/* amsfe_loop.c: controllers, the real-time tick and the closed-loop simulation in C
 * (amsfe_loop.h, docs/how-to/runtime-c.md).
 *
 * Control flow and bookkeeping: every model number comes from the robot's generated
 * functions (control_*, plant_step, camera_measure, mass_matrix, bias) compiled into the
 * same library; the only arithmetic here is the actuator limit, the printed laws' qmd(k+1)
 * reading, truth-ct's cascade, the sensors' noise, and the NEES.  Each branch mirrors its Python reference, named in the comments
 * (control/sliding.py, control/truth.py, sim/loop.py, sim/sensors.py); the tests run both
 * and compare every recorded signal.
 */
#include "amsfe_loop.h"

#include <math.h>
#include <string.h>

#include "amsfe_internal.h"

DECLARE(control_amsfe)
DECLARE(control_dtsmc)
DECLARE(control_amsfe_paper)
DECLARE(control_dtsmc_paper)
DECLARE(plant_step)
DECLARE(camera_measure)
DECLARE(mass_matrix)
DECLARE(bias)
DECLARE(control_motor_reference)

static const cwork WORKS[] = {control_amsfe_work,       control_dtsmc_work,
                              control_amsfe_paper_work, control_dtsmc_paper_work,
                              plant_step_work,          camera_measure_work,
                              mass_matrix_work,         bias_work,
                              control_motor_reference_work};

/* The library's dimensions (amsfe_dims_get) as a value. */
static amsfe_dims dims_now(void) {
  amsfe_dims d;
  amsfe_dims_get(&d);
  return d;
}

/* ================================================================== controller */
struct amsfe_ctrl {
  amsfe_ctrl_params par; /* its pointers point into this block */
  amsfe_dims d;
  int p_theta;
  gwork g;
  double *h, *lam, *Lt, *eps, *phi, *wm, *tau_max, *wf, *vmax, *u_max, *Mm, *Fm, *Ks,
      *theta0, *zeros;
  int *ks_theta;
  double pp; /* the terminal power, as a 1-vector input */
  /* memory between ticks */
  long ticks;
  double *u_prev;  /* the last applied (limited) torque */
  double *cf;      /* cascade: command-filter state [2n] */
  int started;     /* cascade: the filter was started on the first (trusted) command */
  int ready;       /* cascade: the start-up's test passed (latched) */
  int observed;    /* amsfe_ctrl_observe ran since the last torque (else: converged) */
  int have_hold;   /* cascade: c_hold was taken */
  double *c_hold;  /* cascade: the motor's offset from qm_r at the first tick [n] */
  double *hold1, *hold0; /* the law's hold input: ones, zeros [n] */
  long blend_k0;   /* cascade: the blended start's first tick (control/blend.py) */
  double blend_s0; /* s at blend_k0 [s] (blend_lead: the plan started that long before) */
  long k_first;    /* the first tick this controller ran (blend_lead) */
  int have_kfirst;
  double blend_tb; /* its duration [s] */
  double *blend_d0, *blend_d1, *refb; /* its offsets [n], [n]; the blended reference [5n] */
  double *blend_e0, *blend_e1; /* blend_lead: the trusted offsets it passes through [n], [n] */
  double *wfb;     /* the command filter's bandwidth while the blend runs (blend_wf) [n] */
  double rho;      /* headroom_tau: the gains' scale (1: unscaled) */
  int have_udem;   /* ... the law's demand u_dem of the last tick it acted is known */
  double *u_dem, *hs, *epss, *wms, *wfs; /* ... that demand, the scaled h, eps, wm, wf [n] */
  double nis_mean; /* cascade: the encoders' mean NIS (running, then exponential window) */
  long nis_count;  /* NIS values taken into it */
  double nis_tick; /* this tick's NIS (amsfe_ctrl_observe_nis), NaN: none */
  long mhold_k0;   /* hold_motor: its first tick, duration [s], offsets [n], [n] */
  double mhold_tb;
  int have_mhold;
  double *mhold_d0, *mhold_d1, *mr[3]; /* ...; control_motor_reference's outputs [n] x 3 */
  double *vt_prev; /* printed laws: v_t(k-1) */
  int have_vt;
  double *prev_qm_d, *prev_qmd_d; /* truth-ct: the previous motor set point and rate */
  long prev_k;
  int have_prev;
  /* scratch */
  double *x, *qmd_next, *Ksv, *o[8], *M, *b, *acc, *P;
};

static int ctrl_layout(amsfe_ctrl *c, char *base) {
  const amsfe_dims d = dims_now();
  long n = d.n, N = d.N;
  amsfe_ctrl tmp;
  if (!c) c = &tmp; /* only measuring: the pointers go to a scratch object */
  carver cv = carve_object(base, sizeof(amsfe_ctrl));
  double **vecs[] = {&c->h,  &c->lam,     &c->Lt, &c->eps, &c->phi, &c->wm,
                     &c->tau_max, &c->wf, &c->vmax, &c->u_max, &c->Mm, &c->Fm,
                     &c->Ks, &c->zeros, &c->u_prev, &c->vt_prev, &c->prev_qm_d,
                     &c->prev_qmd_d, &c->qmd_next, &c->Ksv, &c->b, &c->acc,
                     &c->c_hold, &c->hold1, &c->hold0, &c->blend_d0, &c->blend_d1,
                     &c->mhold_d0, &c->mhold_d1, &c->mr[0], &c->mr[1], &c->mr[2],
                     &c->wfb, &c->u_dem, &c->hs, &c->epss, &c->wms, &c->wfs,
                     &c->blend_e0, &c->blend_e1};
  for (size_t i = 0; i < sizeof(vecs) / sizeof(vecs[0]); ++i) *vecs[i] = DBL(&cv, n);
  c->refb = DBL(&cv, 5 * n);
  c->theta0 = DBL(&cv, d.N - 4 * n + 1);
  c->ks_theta = (int *)carve(&cv, sizeof(int) * (size_t)n);
  c->cf = DBL(&cv, 2 * n);
  c->x = DBL(&cv, N);
  for (int i = 0; i < 8; ++i) c->o[i] = DBL(&cv, 2 * n);
  c->M = DBL(&cv, n * n);
  c->P = DBL(&cv, N * N);
  carve_work(&cv, WORKS, sizeof(WORKS) / sizeof(WORKS[0]), &c->g);
  return (int)(cv.off + 16);
}

/* Every value of a per-joint array finite (or +inf where allowed) and >= low (> low if
 * strict). */
static int vec_ok(const double *v, int n, double low, int strict, int inf_ok) {
  if (!v) return 0;
  for (int j = 0; j < n; ++j) {
    double x = v[j];
    if (isnan(x) || (!inf_ok && !isfinite(x)) || (strict ? !(x > low) : !(x >= low))) return 0;
  }
  return 1;
}

/* The parameter block is usable: every gain finite and in range, limits positive, sizes
 * within the library's (issue 20: NaN gains or a negative u_max used to run for tens of
 * ticks before failing elsewhere). */
static int ctrl_params_ok(const amsfe_ctrl_params *p) {
  const amsfe_dims d = dims_now();
  int n = d.n;
  if (!p || p->controller < AMSFE_CTRL_AMSFE || p->controller > AMSFE_CTRL_TRUTH_CT) return 0;
  if (!(p->T > 0) || !isfinite(p->T) || !p->ks_theta || !p->theta_initial) return 0;
  if (!vec_ok(p->u_max, n, 0.0, 1, 1) || !vec_ok(p->Mm, n, 0.0, 1, 0) ||
      !vec_ok(p->Fm, n, 0.0, 0, 0) || !vec_ok(p->Ks, n, 0.0, 1, 0))
    return 0;
  for (int j = 0; j < d.N - 4 * d.n; ++j)
    if (!isfinite(p->theta_initial[j])) return 0;
  for (int j = 0; j < n; ++j)
    if (p->ks_theta[j] < -1 || p->ks_theta[j] >= d.N - 4 * d.n) return 0;
  if (p->startup_converged && (isnan(p->ready_q_std) || !(p->ready_q_std > 0) ||
                               isnan(p->ready_qd_std) || !(p->ready_qd_std > 0) ||
                               !(p->blend_accel > 0) || !(p->blend_rate > 0) ||
                               !(p->ready_nis >= 0) || !(p->blend_wf >= 0) ||
                               !(p->headroom_tau >= 0) ||
                               !(p->blend_lead >= 0 && p->blend_lead <= 1) ||
                               (p->ready_nis > 0 && !(p->ready_nis_window > 0))))
    return 0;
  if (p->controller == AMSFE_CTRL_TRUTH_CT)
    return isfinite(p->link_bandwidth) && p->link_bandwidth > 0 &&
           isfinite(p->motor_bandwidth) && p->motor_bandwidth > 0;
  if (!(p->p > 0 && p->p <= 1)) return 0;
  if (!vec_ok(p->h, n, 0.0, 0, 0) || !vec_ok(p->lam, n, 0.0, 0, 0) ||
      !vec_ok(p->Lt, n, 0.0, 0, 0) || !vec_ok(p->eps, n, 0.0, 0, 0) ||
      !vec_ok(p->phi, n, 0.0, 0, 0))
    return 0;
  if (p->controller <= AMSFE_CTRL_TRUTH &&
      (!vec_ok(p->wm, n, 0.0, 1, 0) || !vec_ok(p->tau_max, n, 0.0, 1, 1) ||
       !vec_ok(p->wf, n, 0.0, 0, 0) || !vec_ok(p->vmax, n, 0.0, 0, 0)))
    return 0;
  return 1;
}

size_t amsfe_ctrl_memory_size(const amsfe_ctrl_params *params) {
  if (!ctrl_params_ok(params)) return 0;
  return (size_t)ctrl_layout(NULL, NULL);
}

static void vcopy(double *dst, const double *src, long count) {
  if (src) memcpy(dst, src, sizeof(double) * (size_t)count);
}

void amsfe_ctrl_reset(amsfe_ctrl *c) {
  long n = c->d.n;
  c->ticks = 0;
  memset(c->u_prev, 0, sizeof(double) * (size_t)n);
  memset(c->cf, 0, sizeof(double) * (size_t)(2 * n));
  c->started = 0;
  c->ready = 0;
  c->have_hold = 0;
  c->have_mhold = 0;
  c->have_kfirst = 0;
  c->blend_s0 = 0.0;
  c->rho = 1.0;
  c->have_udem = 0;
  c->nis_mean = 0.0;
  c->nis_count = 0;
  c->nis_tick = NAN;
  c->have_vt = 0;
  c->have_prev = 0;
  c->prev_k = 0;
}

int amsfe_ctrl_init(amsfe_ctrl **out, const amsfe_ctrl_params *p, void *memory, size_t size) {
  if (!out || !memory) return AMSFE_ERR_INPUT;
  if (!ctrl_params_ok(p)) return AMSFE_ERR_CONFIG;
  if ((size_t)ctrl_layout(NULL, NULL) > size || ((size_t)memory & 15u)) return AMSFE_ERR_MEMORY;
  memset(memory, 0, size);
  amsfe_ctrl *c = (amsfe_ctrl *)memory;
  ctrl_layout(c, (char *)memory);
  amsfe_dims_get(&c->d);
  long n = c->d.n;
  c->p_theta = c->d.N - 4 * c->d.n;
  c->par = *p;
  int laws = p->controller != AMSFE_CTRL_TRUTH_CT;
  if (laws) {
    vcopy(c->h, p->h, n), vcopy(c->lam, p->lam, n), vcopy(c->Lt, p->Lt, n);
    vcopy(c->eps, p->eps, n), vcopy(c->phi, p->phi, n);
  }
  if (p->controller <= AMSFE_CTRL_TRUTH) {
    vcopy(c->wm, p->wm, n), vcopy(c->tau_max, p->tau_max, n);
    vcopy(c->wf, p->wf, n), vcopy(c->vmax, p->vmax, n);
  }
  vcopy(c->u_max, p->u_max, n), vcopy(c->Mm, p->Mm, n), vcopy(c->Fm, p->Fm, n);
  vcopy(c->Ks, p->Ks, n), vcopy(c->theta0, p->theta_initial, c->p_theta);
  memcpy(c->ks_theta, p->ks_theta, sizeof(int) * (size_t)n);
  c->pp = p->p;
  /* the block's copies replace the caller's pointers */
  c->par.h = c->h, c->par.lam = c->lam, c->par.Lt = c->Lt, c->par.eps = c->eps;
  c->par.phi = c->phi, c->par.wm = c->wm, c->par.tau_max = c->tau_max, c->par.wf = c->wf;
  c->par.vmax = c->vmax, c->par.u_max = c->u_max, c->par.Mm = c->Mm, c->par.Fm = c->Fm;
  c->par.Ks = c->Ks, c->par.ks_theta = c->ks_theta, c->par.theta_initial = c->theta0;
  for (long j = 0; j < n; ++j) c->hold1[j] = 1.0, c->hold0[j] = 0.0;
  amsfe_ctrl_reset(c);
  *out = c;
  return AMSFE_OK;
}

/* Ks at theta (runtime/library.py: ModelLibrary.stiffness). */
static void stiffness(const amsfe_ctrl *c, const double *theta, double *Ks) {
  for (int j = 0; j < c->d.n; ++j) Ks[j] = c->ks_theta[j] >= 0 ? theta[c->ks_theta[j]] : c->Ks[j];
}

void amsfe_ctrl_observe_nis(amsfe_ctrl *c, double nis) { c->nis_tick = nis; }

void amsfe_ctrl_observe(amsfe_ctrl *c, const double *P) {
  /* _Cascade._converged: latched; the oracles and the encoder-only law need no estimate */
  int ctl = c->par.controller;
  double nis = c->nis_tick;
  c->nis_tick = NAN;
  c->observed = 1;
  if (c->ready) return;
  if (!P || ctl == AMSFE_CTRL_TRUTH || ctl == AMSFE_CTRL_DTSMC) {
    c->ready = 1;
    return;
  }
  if (isfinite(nis) && c->par.ready_nis_window > 0) { /* running, then exponential mean */
    c->nis_count += 1;
    double w = (double)c->nis_count < c->par.ready_nis_window ? (double)c->nis_count
                                                               : c->par.ready_nis_window;
    c->nis_mean += (nis - c->nis_mean) / w;
  }
  int consistent = isinf(c->par.ready_nis) || c->par.ready_nis == 0.0 || c->nis_count == 0 ||
                   ((double)c->nis_count >= c->par.ready_nis_window &&
                    c->nis_mean <= c->par.ready_nis);
  long n = c->d.n, N = c->d.N;
  int ok = 1;
  for (long j = 0; j < n; ++j) {
    ok &= sqrt(P[j * N + j]) <= c->par.ready_q_std;
    ok &= sqrt(P[(n + j) * N + n + j]) <= c->par.ready_qd_std;
  }
  c->ready = ok && consistent;
}

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
static double blend_time(const double *d0, const double *d1, long n, double accel,
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
static double blend_through(const double *e0, const double *e1, long n, double wait,
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
static void blend_offsets_into(double s, double tb, const double *d0, const double *d1, long n,
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
static const double *blended(amsfe_ctrl *c, long k, const double *ref) {
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
static const double *blend_bandwidth(amsfe_ctrl *c, long k, const double *wf) {
  long n = c->d.n;
  double s = (double)(k - c->blend_k0) * c->par.T + c->blend_s0, tb = c->blend_tb;
  double bwf = c->par.blend_wf;
  if (!(s < tb) || !(bwf > 0) || isinf(bwf)) return wf;
  double w = blend_poly(BLEND_B0, 0, s / tb);
  for (long j = 0; j < n; ++j) c->wfb[j] = fmin(wf[j], w * bwf + (1.0 - w) * wf[j]);
  return c->wfb;
}

/* _Cascade._headroom: rho from the last tick's demand (cut: the blend runs; else r = 1), and
 * h, eps, wm, wf scaled by it into the law's inputs (in[ih], in[ie], in[iw]); returns the
 * command filter's wf */
static const double *headroom(amsfe_ctrl *c, const double **in, int ih, int ie, int iw,
                              int cut) {
  long n = c->d.n;
  double tau = c->par.headroom_tau;
  if (!(tau > 0) || isinf(tau) || !c->have_udem) return c->wf;
  double r = 1.0;
  for (long j = 0; cut && j < n; ++j) {
    double dem = fabs(c->u_dem[j]);
    if (dem > c->u_max[j] && c->u_max[j] / dem < r) r = c->u_max[j] / dem;
  }
  double rho = c->rho;
  if (rho == 1.0 && r == 1.0) return c->wf; /* unscaled, as the Python returns early */
  c->rho = r < rho ? r : rho + c->par.T / tau * (r - rho);
  for (long j = 0; j < n; ++j) {
    c->hs[j] = c->h[j] * c->rho, c->epss[j] = c->eps[j] * c->rho;
    c->wms[j] = c->wm[j] * c->rho, c->wfs[j] = c->wf[j] * c->rho;
  }
  in[ih] = c->hs, in[ie] = c->epss, in[iw] = c->wms;
  return c->wfs;
}

/* _Cascade.torque: control_amsfe / control_dtsmc, with the start-up. */
static int cascade(amsfe_ctrl *c, long k, const double *lead0, const double *lead1,
                   const double *ref, const double *z, double *u, amsfe_ctrl_out *out) {
  long n = c->d.n;
  int dtsmc = c->par.controller == AMSFE_CTRL_DTSMC;
  if (!c->have_kfirst) c->k_first = k, c->have_kfirst = 1;
  const double *lt = c->par.controller == AMSFE_CTRL_DTSMC_EKF ? c->zeros : c->Lt;
  const double *in[16];
  int m = 0;
  in[m++] = lead0;
  if (dtsmc) in[m++] = lead1;
  in[m++] = ref, in[m++] = c->cf;
  int ih = m, ie, iw;
  in[m++] = c->h, in[m++] = c->lam;
  if (!dtsmc) in[m++] = lt;
  ie = m, in[m++] = c->eps, in[m++] = &c->pp, in[m++] = c->phi;
  iw = m, in[m++] = c->wm;
  in[m++] = c->tau_max;
  const double **wf_in = &in[m];
  in[m++] = c->wf, in[m++] = c->vmax;
  cfun f = dtsmc ? control_dtsmc : control_amsfe;
  const double **hold = &in[m++];
  if (!c->observed) c->ready = 1; /* no covariance given: the estimate is taken as converged */
  c->observed = 0;
  if (c->par.startup_converged && !c->ready) {
    /* wait: the filter held where the motor is (an offset from qm_r fixed at the first tick) */
    *hold = c->hold1;
    if (c->par.hold_motor) { /* from the motor's own angle and rate onto qm_r */
      if (!c->have_mhold) {
        const double *min[2] = {ref, lead0 + 4 * n};
        if (gcall(&c->g, control_motor_reference, min, 2, c->mr, 3)) return AMSFE_ERR_NONFINITE;
        for (long j = 0; j < n; ++j) {
          c->mhold_d0[j] = z[j] - c->mr[0][j];
          c->mhold_d1[j] = z[n + j] - c->mr[1][j];
        }
        c->mhold_k0 = k;
        c->mhold_tb =
            blend_time(c->mhold_d0, c->mhold_d1, n, c->par.blend_accel, c->par.blend_rate);
        c->have_mhold = 1;
      }
      blend_offsets_into((double)(k - c->mhold_k0) * c->par.T, c->mhold_tb, c->mhold_d0,
                         c->mhold_d1, n, 2, c->cf);
    } else {
      if (!c->have_hold) {
        if (gcall(&c->g, f, in, m, c->o, 8)) return AMSFE_ERR_NONFINITE;
        for (long j = 0; j < n; ++j) c->c_hold[j] = z[j] - (c->o[3][j] - c->o[7][j]);
        c->have_hold = 1;
      }
      memcpy(c->cf, c->c_hold, sizeof(double) * (size_t)n);
      memset(c->cf + n, 0, sizeof(double) * (size_t)n);
    }
    if (gcall(&c->g, f, in, m, c->o, 8)) return AMSFE_ERR_NONFINITE;
  } else {
    *hold = c->hold0;
    if (!c->started && c->par.startup_converged) {
      /* the blended reference starts from the state the law acts on */
      for (long j = 0; j < n; ++j) {
        c->blend_d0[j] = lead0[j] - ref[j];
        c->blend_d1[j] = lead0[n + j] - ref[n + j];
      }
      c->blend_k0 = k;
      /* planned as if started s0 ago, through the estimate now (s0 = 0: from now) */
      c->blend_s0 = c->par.blend_lead * ((double)(k - c->k_first) * c->par.T);
      memcpy(c->blend_e0, c->blend_d0, sizeof(double) * (size_t)n);
      memcpy(c->blend_e1, c->blend_d1, sizeof(double) * (size_t)n);
      c->blend_tb = blend_through(c->blend_e0, c->blend_e1, n, c->blend_s0, c->par.blend_accel,
                                  c->par.blend_rate, c->blend_d0, c->blend_d1);
    }
    if (c->par.startup_converged) { /* once started */
      double sb = (double)(k - c->blend_k0) * c->par.T + c->blend_s0;
      const double *wf = headroom(c, in, ih, ie, iw, sb < c->blend_tb);
      in[dtsmc ? 2 : 1] = blended(c, k, ref);
      *wf_in = blend_bandwidth(c, k, wf);
    }
    if (gcall(&c->g, f, in, m, c->o, 8)) return AMSFE_ERR_NONFINITE;
    if (!c->started) { /* start at rest on the first trusted command */
      memcpy(c->cf, c->o[7], sizeof(double) * (size_t)n);
      memset(c->cf + n, 0, sizeof(double) * (size_t)n);
      c->started = 1;
      if (gcall(&c->g, f, in, m, c->o, 8)) return AMSFE_ERR_NONFINITE;
    }
    memcpy(c->u_dem, c->o[0], sizeof(double) * (size_t)n);
    c->have_udem = 1;
  }
  memcpy(c->cf, c->o[6], sizeof(double) * (size_t)(2 * n));
  memcpy(u, c->o[0], sizeof(double) * (size_t)n);
  if (out && out->s) memcpy(out->s, c->o[1], sizeof(double) * (size_t)n);
  if (out && out->bound) memcpy(out->bound, c->o[5], sizeof(double) * (size_t)n);
  if (out && out->tau_d) memcpy(out->tau_d, c->o[2], sizeof(double) * (size_t)n);
  return AMSFE_OK;
}

int amsfe_ctrl_handed_over(const amsfe_ctrl *c, long k) {
  if (!c) return 0;
  if (!c->par.startup_converged) return 1;
  if (!c->started) return 0;
  double sb = (double)(k - c->blend_k0) * c->par.T + c->blend_s0;
  return !(sb < c->blend_tb);
}

/* _Printed.torque: (37) / (54) as printed, with qmd(k+1) predicted by (1c) or held. */
static int printed(amsfe_ctrl *c, const double *x, const double *z, const double *ref, double *u,
                   amsfe_ctrl_out *out) {
  long n = c->d.n;
  const double *q = x, *qm = x + 2 * n, *qmd = x + 3 * n, *q_d = ref, *qd_d = ref + n;
  if (!c->par.qmd_next_hold) {
    stiffness(c, x + 4 * n, c->Ksv);
    for (long j = 0; j < n; ++j)
      c->qmd_next[j] = /* as numpy evaluates qmd + T * (...) / Mm */
          qmd[j] + (c->par.T * (c->u_prev[j] - c->Fm[j] * qmd[j] - c->Ksv[j] * (qm[j] - q[j]))) /
                       c->Mm[j];
  } else {
    memcpy(c->qmd_next, qmd, sizeof(double) * (size_t)n);
  }
  if (!c->have_vt) { /* first tick: no v_t(k-1) yet */
    for (long j = 0; j < n; ++j) c->vt_prev[j] = qd_d[j] - c->Lt[j] * (q[j] - q_d[j]);
    c->have_vt = 1;
  }
  const double *in[16];
  int m = 0;
  int paper54 = c->par.controller == AMSFE_CTRL_DTSMC_PAPER;
  if (paper54) {
    in[m++] = z, in[m++] = c->theta0;
  } else {
    in[m++] = x;
  }
  in[m++] = c->qmd_next, in[m++] = q_d, in[m++] = qd_d, in[m++] = c->vt_prev;
  in[m++] = c->h, in[m++] = c->lam;
  if (!paper54) in[m++] = c->Lt;
  in[m++] = c->eps, in[m++] = &c->pp, in[m++] = c->phi;
  cfun f = paper54 ? control_dtsmc_paper : control_amsfe_paper;
  if (gcall(&c->g, f, in, m, c->o, 5)) return AMSFE_ERR_NONFINITE;
  memcpy(c->vt_prev, c->o[2], sizeof(double) * (size_t)n);
  memcpy(u, c->o[0], sizeof(double) * (size_t)n);
  if (out && out->s) memcpy(out->s, c->o[1], sizeof(double) * (size_t)n);
  if (out && out->bound) memcpy(out->bound, c->o[4], sizeof(double) * (size_t)n);
  return AMSFE_OK;
}

/* control/truth.py: TruthComputedTorque.torque. */
static int truth_ct(amsfe_ctrl *c, long k, const double *xt, const double *ref, double *u) {
  long n = c->d.n;
  const double *q = xt, *qd = xt + n, *qm = xt + 2 * n, *qmd = xt + 3 * n, *th = xt + 4 * n;
  const double *q_d = ref, *qd_d = ref + n, *qdd_d = ref + 2 * n;
  double wl = c->par.link_bandwidth, wm = c->par.motor_bandwidth, T = c->par.T;
  double Kp = wl * wl, Kd = 2.0 * wl, Kpm = wm * wm, Kdm = 2.0 * wm;
  stiffness(c, th, c->Ksv);
  const double *in[3] = {q, th, NULL};
  double *res[1] = {c->M};
  if (gcall(&c->g, mass_matrix, in, 2, res, 1)) return AMSFE_ERR_NONFINITE;
  const double *inb[3] = {q, qd, th};
  res[0] = c->b;
  if (gcall(&c->g, bias, inb, 3, res, 1)) return AMSFE_ERR_NONFINITE;
  for (long j = 0; j < n; ++j) c->acc[j] = qdd_d[j] + Kd * (qd_d[j] - qd[j]) + Kp * (q_d[j] - q[j]);
  double *qm_d = c->o[0], *qmd_d = c->o[1], *qmdd_d = c->o[2];
  for (long i = 0; i < n; ++i) {
    double tau = 0.0;
    for (long j = 0; j < n; ++j) tau += c->M[i + j * n] * c->acc[j];
    tau += c->b[i];
    qm_d[i] = q[i] + tau / c->Ksv[i];
  }
  int have = c->have_prev && c->prev_k == k - 1;
  for (long j = 0; j < n; ++j) {
    if (have) {
      qmd_d[j] = (qm_d[j] - c->prev_qm_d[j]) / T;
      qmdd_d[j] = (qmd_d[j] - c->prev_qmd_d[j]) / T;
    } else { /* first step (or a gap): no history to difference */
      qmd_d[j] = qd[j];
      qmdd_d[j] = 0.0;
    }
  }
  memcpy(c->prev_qm_d, qm_d, sizeof(double) * (size_t)n);
  memcpy(c->prev_qmd_d, qmd_d, sizeof(double) * (size_t)n);
  c->prev_k = k, c->have_prev = 1;
  for (long j = 0; j < n; ++j)
    u[j] = c->Ksv[j] * (qm[j] - q[j]) + c->Fm[j] * qmd[j] +
           c->Mm[j] * (qmdd_d[j] + Kpm * (qm_d[j] - qm[j]) + Kdm * (qmd_d[j] - qmd[j]));
  return AMSFE_OK;
}

int amsfe_ctrl_torque(amsfe_ctrl *c, long k, const double *ref, const double *x_hat,
                      const double *z, const double *x_true, double *u, amsfe_ctrl_out *out) {
  if (!c || !ref || !u) return AMSFE_ERR_INPUT;
  long n = c->d.n;
  int ctl = c->par.controller;
  int oracle = ctl == AMSFE_CTRL_TRUTH || ctl == AMSFE_CTRL_TRUTH_CT ||
               (ctl == AMSFE_CTRL_AMSFE_PAPER && c->par.state_true);
  int encoders = ctl == AMSFE_CTRL_DTSMC || ctl == AMSFE_CTRL_DTSMC_PAPER;
  if ((oracle && !x_true) || (encoders && !z) || (!oracle && !encoders && !x_hat))
    return AMSFE_ERR_INPUT;
  /* a NaN or inf input the law uses would give a NaN torque (the limit keeps NaN) */
  if (!all_finite(ref, 5 * n) || (oracle && !all_finite(x_true, c->d.N)) ||
      (encoders && !all_finite(z, 2 * n)))
    return AMSFE_ERR_INPUT;
  if (out && out->s)
    for (long j = 0; j < n; ++j) out->s[j] = NAN;
  if (out && out->bound)
    for (long j = 0; j < n; ++j) out->bound[j] = NAN;
  int st;
  switch (ctl) {
    case AMSFE_CTRL_AMSFE:
    case AMSFE_CTRL_DTSMC_EKF:
      st = cascade(c, k, x_hat, NULL, ref, z, u, out);
      break;
    case AMSFE_CTRL_TRUTH:
      st = cascade(c, k, x_true, NULL, ref, z, u, out);
      break;
    case AMSFE_CTRL_DTSMC:
      st = cascade(c, k, z, c->theta0, ref, z, u, out);
      break;
    case AMSFE_CTRL_AMSFE_PAPER:
      st = printed(c, oracle ? x_true : x_hat, z, ref, u, out);
      break;
    case AMSFE_CTRL_DTSMC_PAPER:
      /* the law's state is [qm, qmd, qm, qmd, theta0] (q = qm, qd = qmd) */
      memcpy(c->x, z, sizeof(double) * (size_t)(2 * n));
      memcpy(c->x + 2 * n, z, sizeof(double) * (size_t)(2 * n));
      memcpy(c->x + 4 * n, c->theta0, sizeof(double) * (size_t)c->p_theta);
      st = printed(c, c->x, z, ref, u, out);
      break;
    default:
      st = truth_ct(c, k, x_true, ref, u);
  }
  if (st != AMSFE_OK) return st;
  int clipped = 0;
  for (long j = 0; j < n; ++j) { /* Controller.saturate: np.clip */
    double v = u[j], lim = c->u_max[j];
    double w = v < -lim ? -lim : v;
    w = w > lim ? lim : w;
    clipped |= w != v;
    u[j] = w;
  }
  if (out) out->saturated = clipped;
  memcpy(c->u_prev, u, sizeof(double) * (size_t)n);
  c->ticks++;
  return AMSFE_OK;
}

/* ================================================================== the real-time tick */
static void sort_frames(amsfe_frame *f, int count) { /* insertion sort: stable, tiny counts */
  for (int i = 1; i < count; ++i) {
    amsfe_frame v = f[i];
    int j = i - 1;
    while (j >= 0 && f[j].exposure_step > v.exposure_step) f[j + 1] = f[j], --j;
    f[j + 1] = v;
  }
}

int amsfe_loop_tick(amsfe_est *est, amsfe_ctrl *ctrl, const double *z, amsfe_frame *frames,
                    int n_frames, int *frame_status, const double *ref, const double *x_true,
                    double *u, amsfe_ctrl_out *out) {
  if (!est || !ctrl || !u || (n_frames > 0 && !frames)) return AMSFE_ERR_INPUT;
  if (ctrl->ticks > 0) {
    int st = amsfe_est_tick(est, z, ctrl->u_prev);
    if (st < 0) return st;
    amsfe_diag diag;
    amsfe_est_diagnostics(est, &diag);
    amsfe_ctrl_observe_nis(ctrl, diag.encoder_nis); /* the start-up's consistency test */
    sort_frames(frames, n_frames);
    for (int i = 0; i < n_frames; ++i) {
      double nis;
      st = amsfe_est_camera_frame(est, frames[i].z, frames[i].exposure_step, &nis);
      if (st < 0) return st;
      if (frame_status) frame_status[i] = st;
    }
  }
  amsfe_est_state(est, ctrl->x, ctrl->P);
  amsfe_ctrl_observe(ctrl, ctrl->P);
  return amsfe_ctrl_torque(ctrl, ctrl->ticks, ref, ctrl->x, z, x_true, u, out);
}

/* ================================================================== the simulation */
typedef struct {
  long delivery, exposure;
  double z[2];
} pending;

struct amsfe_sim {
  amsfe_sim_params par;
  amsfe_dims d;
  amsfe_est *est;
  amsfe_ctrl *ctrl;
  amsfe_sim_state st;
  gwork g;
  long exposures, last_delivered_exposure;
  int have_last, in_flight;
  pending *queue;
  amsfe_frame *due;
  int *status;
  double *xp, *xp_next, *xt, *xh, *P, *err, *z, *u, *y, *J, *depth, *s, *bound;
};

static size_t sim_layout(amsfe_sim *s, const amsfe_sim_params *p, char *base) {
  const amsfe_dims d = dims_now();
  long n = d.n, N = d.N;
  amsfe_sim tmp;
  if (!s) s = &tmp; /* only measuring, as ctrl_layout */
  carver cv = carve_object(base, sizeof(amsfe_sim));
  s->queue = (pending *)carve(&cv, sizeof(pending) * (size_t)p->max_in_flight);
  s->due = (amsfe_frame *)carve(&cv, sizeof(amsfe_frame) * (size_t)p->max_in_flight);
  s->status = (int *)carve(&cv, sizeof(int) * (size_t)p->max_in_flight);
  s->xp = DBL(&cv, 4 * n), s->xp_next = DBL(&cv, 4 * n), s->xt = DBL(&cv, N);
  s->xh = DBL(&cv, N), s->P = DBL(&cv, N * N), s->err = DBL(&cv, N);
  s->z = DBL(&cv, 2 * n), s->u = DBL(&cv, n), s->y = DBL(&cv, 2), s->J = DBL(&cv, 2 * N);
  s->depth = DBL(&cv, 1), s->s = DBL(&cv, n), s->bound = DBL(&cv, n);
  carve_work(&cv, WORKS, sizeof(WORKS) / sizeof(WORKS[0]), &s->g);
  return cv.off + 16;
}

static int sim_params_ok(const amsfe_sim_params *p) {
  if (!p || p->K < 1 || !p->x_plant0 || !p->theta_true || !p->ref || !p->enc_noise || !p->tau_d)
    return 0;
  if (p->cam_period < 1 || p->cam_phase < 0 || p->cam_phase >= p->cam_period ||
      p->cam_delay < 0 || p->max_in_flight < 1 || p->n_exposures < 0)
    return 0;
  if (p->n_exposures > 0 && (!p->cam_noise || !p->cam_uniform || !p->cam_jitter)) return 0;
  return p->enc_resolution >= 0 && p->diverged_error > 0;
}

size_t amsfe_sim_memory_size(const amsfe_sim_params *params) {
  if (!sim_params_ok(params)) return 0;
  return sim_layout(NULL, params, NULL);
}

int amsfe_sim_init(amsfe_sim **out, const amsfe_sim_params *p, amsfe_est *est, amsfe_ctrl *ctrl,
                   void *memory, size_t size) {
  if (!out || !memory || !est || !ctrl) return AMSFE_ERR_INPUT;
  if (!sim_params_ok(p)) return AMSFE_ERR_CONFIG;
  if (sim_layout(NULL, p, NULL) > size || ((size_t)memory & 15u)) return AMSFE_ERR_MEMORY;
  memset(memory, 0, size);
  amsfe_sim *s = (amsfe_sim *)memory;
  sim_layout(s, p, (char *)memory);
  amsfe_dims_get(&s->d);
  s->par = *p, s->est = est, s->ctrl = ctrl;
  memcpy(s->xp, p->x_plant0, sizeof(double) * (size_t)(4 * s->d.n));
  *out = s;
  return AMSFE_OK;
}

void amsfe_sim_get_state(const amsfe_sim *s, amsfe_sim_state *state) { *state = s->st; }

/* Camera._inside */
static int inside(const amsfe_sim *s, const double *y) {
  return isfinite(y[0]) && isfinite(y[1]) && y[0] >= 0.0 && y[0] < s->par.cam_width &&
         y[1] >= 0.0 && y[1] < s->par.cam_height;
}

/* Camera._expose at step k: project, draw (always), decide, queue. */
static int expose(amsfe_sim *s, long k, const double *q) {
  const amsfe_sim_params *p = &s->par;
  long e = s->exposures;
  if (e >= p->n_exposures) return AMSFE_ERR_INPUT; /* the caller drew too few */
  const double *in[2] = {q, p->theta_true};
  double *res[3] = {s->y, s->J, s->depth};
  if (gcall(&s->g, camera_measure, in, 2, res, 3)) return AMSFE_ERR_NONFINITE;
  if (!(s->depth[0] > 0)) s->y[0] = s->y[1] = NAN;
  s->exposures++;
  s->st.frames_exposed++;
  if (!inside(s, s->y)) {
    s->st.frames_out_of_image++, s->st.frames_out_of_image_true++;
    return AMSFE_OK;
  }
  double z[2];
  for (int i = 0; i < 2; ++i) {
    z[i] = s->y[i] + p->pixel_std * p->cam_noise[2 * e + i];
    if (p->round_to_pixel) z[i] = nearbyint(z[i]); /* np.round: half to even */
  }
  if (!inside(s, z)) {
    s->st.frames_out_of_image++;
    return AMSFE_OK;
  }
  if (p->cam_uniform[e] < p->drop_probability) {
    s->st.frames_dropped++;
    return AMSFE_OK;
  }
  if (s->in_flight >= p->max_in_flight) return AMSFE_ERR_MEMORY;
  pending *slot = &s->queue[s->in_flight++];
  slot->delivery = k + p->cam_delay + p->cam_jitter[e];
  slot->exposure = k;
  slot->z[0] = z[0], slot->z[1] = z[1];
  return AMSFE_OK;
}

/* Camera.tick: expose if due, then hand out the frames due now, sorted by exposure. */
static int camera_tick(amsfe_sim *s, long k, const double *q, int *count) {
  const amsfe_sim_params *p = &s->par;
  *count = 0;
  if (k % p->cam_period == p->cam_phase) {
    int st = expose(s, k, q);
    if (st != AMSFE_OK) return st;
  }
  int keep = 0;
  for (int i = 0; i < s->in_flight; ++i) {
    pending *f = &s->queue[i];
    if (f->delivery <= k) {
      s->due[*count].exposure_step = f->exposure;
      s->due[*count].z[0] = f->z[0], s->due[*count].z[1] = f->z[1];
      ++*count;
    } else {
      s->queue[keep++] = *f;
    }
  }
  s->in_flight = keep;
  sort_frames(s->due, *count);
  for (int i = 0; i < *count; ++i) {
    long ex = s->due[i].exposure_step;
    if (s->have_last && ex < s->last_delivered_exposure) s->st.frames_out_of_order++;
    if (!s->have_last || ex > s->last_delivered_exposure) s->last_delivered_exposure = ex;
    s->have_last = 1;
  }
  s->st.frames_delivered += *count;
  return AMSFE_OK;
}

/* e^T P^-1 e with L the Cholesky factor of P (NaN when there is none: P not positive
 * definite); w: N of scratch. */
static double nees(int N, const double *L, const double *e, double *w) {
  if (!L) return NAN;
  memcpy(w, e, sizeof(double) * (size_t)N);
  amsfe_chol_solve(N, L, w);
  double acc = 0.0;
  for (int i = 0; i < N; ++i) acc += e[i] * w[i];
  return acc;
}

/* sim/loop.py's REFUSAL_KINDS, from the runtime's statuses (amsfe_loop.h). */
int amsfe_sim_count_frame(amsfe_sim_state *st, int status) {
  switch (status) {
    case AMSFE_OK: st->frames_applied++; return 1;
    case AMSFE_IGNORED: return 0;
    case AMSFE_GATED: st->refused_gated++; break;
    case AMSFE_REFUSED_NONFINITE: st->refused_nan++; break;
    case AMSFE_REFUSED_TOO_OLD:
    case AMSFE_REFUSED_NO_CLONE_LEFT: st->refused_too_late++; break;
    case AMSFE_REFUSED_INDEFINITE: st->refused_indefinite++; break;
    case AMSFE_REFUSED_NO_CLONE: st->refused_unscheduled++; break;
    case AMSFE_REFUSED_NO_CONVERGENCE: st->refused_no_convergence++; break;
    default: st->refused_other++;
  }
  st->frames_rejected++;
  return -1;
}

int amsfe_sim_run(amsfe_sim *s, long ticks, const amsfe_sim_records *rec) {
  const amsfe_sim_params *p = &s->par;
  amsfe_sim_state *st = &s->st;
  long n = s->d.n, N = s->d.N, pth = N - 4 * n;
  if (!rec) return AMSFE_ERR_INPUT;
  if (st->status < 0) return st->status;
  long end = st->k + ticks < p->K ? st->k + ticks : p->K;
  if (st->diverged) end = st->k;
  amsfe_ctrl_out out = {s->s, s->bound, NULL, 0};
  for (long k = st->k; k < end; ++k) {
    const double *xp = s->xp;
    memcpy(s->xt, xp, sizeof(double) * (size_t)(4 * n));
    memcpy(s->xt + 4 * n, p->theta_true, sizeof(double) * (size_t)pth);
    /* 1. sensors at t_k (Encoders.measure; row 0 made z0) */
    if (!all_finite(xp, 4 * n)) {
      st->plant_nonfinite = 1;
      return st->status = AMSFE_ERR_NONFINITE;
    }
    const double *v = p->enc_noise + k * 2 * n;
    for (long j = 0; j < n; ++j) {
      double zq = xp[2 * n + j] + v[j];
      if (p->enc_resolution > 0) zq = nearbyint(zq / p->enc_resolution) * p->enc_resolution;
      s->z[j] = zq;
      s->z[n + j] = xp[3 * n + j] + v[n + j];
    }
    int nf;
    int cst = camera_tick(s, k, xp, &nf);
    if (cst != AMSFE_OK) return st->status = cst;
    if (rec->frames)
      for (int i = 0; i < nf; ++i) {
        if (st->frames_recorded >= rec->frames_capacity) return st->status = AMSFE_ERR_MEMORY;
        double *row = rec->frames + 4 * st->frames_recorded++;
        row[0] = (double)s->due[i].exposure_step, row[1] = (double)k;
        row[2] = s->due[i].z[0], row[3] = s->due[i].z[1];
      }
    /* 2.-3. estimator k-1 -> k, controller, actuator limit */
    int tst = amsfe_loop_tick(s->est, s->ctrl, s->z, s->due, nf, s->status, p->ref + k * 5 * n,
                              s->xt, s->u, &out);
    if (tst < 0) return st->status = tst;
    if (k > 0) {
      amsfe_diag dg;
      amsfe_est_diagnostics(s->est, &dg);
      for (int i = 0; i < nf; ++i) amsfe_sim_count_frame(st, s->status[i]);
      if (!dg.encoder_accepted) {
        st->encoder_rejected++;
        if (isnan(dg.encoder_nis)) st->refused_nan++; else st->refused_gated++;
      }
    }
    /* record */
    amsfe_est_state(s->est, s->xh, s->P);
    for (long i = 0; i < N; ++i) s->err[i] = s->xt[i] - s->xh[i];
    if (rec->x_true) memcpy(rec->x_true + k * N, s->xt, sizeof(double) * (size_t)N);
    if (rec->x_hat) memcpy(rec->x_hat + k * N, s->xh, sizeof(double) * (size_t)N);
    if (rec->P_diag)
      for (long i = 0; i < N; ++i) rec->P_diag[k * N + i] = s->P[i + i * N];
    /* the estimator's own factor of P: the one its next prediction uses (eq. 14) */
    if (rec->nees) rec->nees[k] = nees((int)N, amsfe_est_factor(s->est), s->err, s->J);
    if (rec->u) memcpy(rec->u + k * n, s->u, sizeof(double) * (size_t)n);
    if (rec->z_enc) memcpy(rec->z_enc + k * 2 * n, s->z, sizeof(double) * (size_t)(2 * n));
    if (rec->s) memcpy(rec->s + k * n, s->s, sizeof(double) * (size_t)n);
    if (rec->bound) memcpy(rec->bound + k * n, s->bound, sizeof(double) * (size_t)n);
    if (rec->saturated) rec->saturated[k] = (unsigned char)out.saturated;
    st->ticks_done = k + 1;
    st->k = k + 1;
    /* _diverged: not finite, or the link tracking error beyond the limit */
    int bad = !all_finite(xp, 4 * n) || !all_finite(s->u, n);
    for (long j = 0; j < n && !bad; ++j)
      bad = fabs(xp[j] - p->ref[k * 5 * n + j]) > p->diverged_error;
    if (bad) {
      st->diverged = 1;
      return AMSFE_OK;
    }
    /* 4. plant over [t_k, t_k + T] */
    if (k + 1 < p->K) {
      const double *in[4] = {s->xp, s->u, p->theta_true, p->tau_d + k * 2 * n};
      double *res[1] = {s->xp_next};
      if (gcall(&s->g, plant_step, in, 4, res, 1)) return st->status = AMSFE_ERR_NONFINITE;
      memcpy(s->xp, s->xp_next, sizeof(double) * (size_t)(4 * n));
    }
  }
  return AMSFE_OK;
}
