/* amsfe_ctrl.c: the controllers of the compiled loop (amsfe_loop.h, docs/how-to/runtime-c.md):
 * their parameters and memory, the cascade with its start-up, the printed laws, truth-ct's
 * computed torque and the actuator limit (amsfe_blend.c: the start-up's blends; amsfe_loop.c:
 * the tick and the simulation that call them).
 *
 * Control flow and bookkeeping: every model number comes from the robot's generated
 * functions (control_*, mass_matrix, bias) compiled into the same library; the only
 * arithmetic here is the actuator limit, the printed laws' qmd(k+1) reading and truth-ct's
 * cascade.  Each branch mirrors its Python reference, named in the comments (control/sliding.py,
 * control/truth.py); the tests run both and compare every recorded signal.
 */
#include "amsfe_loop.h"

#include <math.h>
#include <string.h>

#include "amsfe_loop_internal.h"

/* ================================================================== controller */
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
 * within the library's (NaN gains or a negative u_max used to run for tens of
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
