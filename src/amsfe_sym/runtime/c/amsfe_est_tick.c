/* amsfe_est_tick.c: the compiled estimator's EKF steps (the prediction, the encoder and the
 * camera updates), its replay ring and amsfe_est_tick (amsfe_runtime.c: the estimator's
 * memory, life cycle and accessors; docs/how-to/runtime-c.md).  Each branch mirrors the
 * Python reference in estimation/ (named per function). */
/* The glue is small: optimise it fully whatever the library's flags (-O1 by default, chosen
 * for the size of the generated files); O3 vectorises the kernels' axpy loops.  No
 * -ffast-math: sums keep their order, so results do not depend on the flags. */
#if defined(__GNUC__) && !defined(__clang__)
#pragma GCC optimize("O3")
#endif
#include <math.h>
#include <string.h>

#include "amsfe_est_internal.h"

/* ------------------------------------------------------------------ helpers */
/* SpringTorqueMeasurement.predict: h(x) = [qm, qmd, Ks (qm - q)] into h [3n] and the values
 * of its jacobian's nonzeros (the pattern ehrow/ehcol of init) into hv; Ks[j] is theta's
 * entry where the joint's stiffness is a parameter (then d/dtheta = qm - q: exact). */
EFFORT_PATH static void torque_h(const amsfe_est *e, const double *x, double *h, double *hv) {
  int n = e->d.n, v = 0;
  for (int a = 0; a < 2 * n; ++a) h[a] = x[2 * n + a], hv[v++] = 1.0;
  for (int j = 0; j < n; ++j) {
    double Ks = e->kst[j] >= 0 ? x[4 * n + e->kst[j]] : e->ks[j];
    double delta = x[2 * n + j] - x[j];
    h[2 * n + j] = Ks * delta;
    hv[v++] = -Ks, hv[v++] = Ks;
    if (e->kst[j] >= 0) hv[v++] = delta;
  }
}

/* ekf.joseph_update with the encoders' H: a selection of qm and qmd (eq. 5; enc_rows), or
 * with the joint torques [qm, qmd, Ks (qm - q)] (its nonzeros by rows) */
EFFORT_PATH static int encoder_kernel_torque(amsfe_est *e, const double *z) {
  torque_h(e, e->x, e->hz, e->ehval);
  for (int a = 0; a < e->d.ne; ++a) e->last_nu[a] = z[a] - e->hz[a];
  return amsfe_joseph_rows(e->d.N, e->d.ne, e->ehrow, e->ehcol, e->ehval, e->re, e->x, e->P,
                           e->last_nu, e->x2, e->P2, &e->nis, e->JW);
}

static int encoder_kernel(amsfe_est *e, const double *z) {
  if (e->jt) return encoder_kernel_torque(e, z);
  return amsfe_joseph_select(e->d.N, e->d.ne, e->enc_rows, e->re, e->x, e->P, z, e->x2, e->P2,
                             &e->nis, e->last_nu, e->JW);
}

/* block (o, o) of the augmented covariance into P1, then the PD check */
static int clone_block_pd(amsfe_est *e, int s) {
  int N = e->d.N, Na = (1 + e->S) * N, o = N * (1 + s);
  for (int j = 0; j < N; ++j) copy(e->P1 + (long)j * N, e->Pa + o + (long)(o + j) * Na, N);
  return pd(e, e->P1);
}

/* ------------------------------------------------------------------ EKF steps */
/* InputStateTransition.step: the model's step from x[:Nm] with the input states x[Nm:] as u,
 * A = [[A_m, B], [0, I]] with B = (A_m[:, qmd] + e_qmd) T / (2 Mm) (trapezoid_input_gain),
 * Gamma = blockdiag(Gamma_m, I) (qw's last n entries: the walk's variance per step) */
EFFORT_PATH static int predict_inputs(amsfe_est *e, double *A, double *G) {
  int M = e->d.N, N = e->Nm, n = e->d.n, nw = e->d.nw - n;
  const double *in[2] = {e->x, e->x + N};
  double *out[3] = {e->x1, e->An, e->Gn};
  gcall(&e->g, STEP, in, 2, out, 3); /* x+, A, Gamma (eqs. 13, 4) */
  if (!all_finite(e->x1, N) || !all_finite(e->An, (long)N * N)) return AMSFE_ERR_NONFINITE;
  for (int i = N; i < M; ++i) e->x1[i] = e->x[i];
  memset(A, 0, sizeof(double) * (size_t)M * (size_t)M);
  memset(G, 0, sizeof(double) * (size_t)M * (size_t)e->d.nw);
  for (long c = 0; c < N; ++c) copy(A + c * M, e->An + c * N, N);
  for (int j = 0; j < n; ++j) {
    double *Aj = A + (long)(N + j) * M, g = e->gain[j];
    const double *Am = e->An + (long)(3 * n + j) * N;
    for (int i = 0; i < N; ++i) Aj[i] = (i == 3 * n + j ? Am[i] + 1.0 : Am[i]) * g;
    Aj[N + j] = 1.0;
  }
  for (long c = 0; c < nw; ++c) copy(G + c * M, e->Gn + c * N, N);
  for (int j = 0; j < n; ++j) G[(N + j) + (long)(nw + j) * M] = 1.0;
  if (!e->lp_ok && !pd_state(e)) return AMSFE_ERR_NOT_PD; /* P = LP LP^T */
  amsfe_predict_cov(M, e->d.nw, A, e->LP, G, e->qw, e->P1, e->T1); /* eq. (14) */
  copy(e->x, e->x1, M);
  swap_P(e, &e->P1);
  return AMSFE_OK;
}

/* NetTorqueTransition.spring: ut <- u + Ks (qm - q) (the model's input for a net torque u) */
EFFORT_PATH static void net_input(amsfe_est *e, const double *u) {
  int n = e->d.n;
  for (int j = 0; j < n; ++j) {
    double Ks = e->kst[j] >= 0 ? e->x[4 * n + e->kst[j]] : e->ks[j];
    e->ut[j] = u[j] + Ks * (e->x[2 * n + j] - e->x[j]);
  }
}

/* NetTorqueTransition.step's jacobian: A <- A + B ds/dx, B = (A[:, qmd] + e_qmd) T / (2 Mm)
 * (trapezoid_input_gain, of the model's A), ds/dx: -Ks at q_j, Ks at qm_j, qm_j - q_j at
 * theta's stiffness entry */
EFFORT_PATH static void net_jacobian(amsfe_est *e, double *A) {
  long N = e->d.N;
  int n = e->d.n;
  for (int j = 0; j < n; ++j) {
    const double *Am = A + (long)(3 * n + j) * N;
    double *B = e->Bn + (long)j * N, g = e->gain[j];
    for (long i = 0; i < N; ++i) B[i] = (i == 3 * n + j ? Am[i] + 1.0 : Am[i]) * g;
  }
  for (int j = 0; j < n; ++j) {
    const double *B = e->Bn + (long)j * N;
    double Ks = e->kst[j] >= 0 ? e->x[4 * n + e->kst[j]] : e->ks[j];
    double delta = e->x[2 * n + j] - e->x[j];
    double *Aq = A + (long)j * N, *Aqm = A + (long)(2 * n + j) * N;
    for (long i = 0; i < N; ++i) Aq[i] += B[i] * -Ks, Aqm[i] += B[i] * Ks;
    if (e->kst[j] >= 0) {
      double *At = A + (long)(4 * n + e->kst[j]) * N;
      for (long i = 0; i < N; ++i) At[i] += B[i] * delta;
    }
  }
}

/* ekf.predict on (x, P) with u; A and Gamma written to A, G (N x N, N x nw) */
static int predict(amsfe_est *e, const double *u, double *A, double *G) {
  if (e->ni) return predict_inputs(e, A, G);
  int N = e->d.N;
  if (e->net) net_input(e, u), u = e->ut;
  const double *in[2] = {e->x, u};
  double *out[3] = {e->x1, A, G};
  gcall(&e->g, STEP, in, 2, out, 3); /* x+, A, Gamma (eqs. 13, 4) */
  if (!all_finite(e->x1, N) || !all_finite(A, (long)N * N)) return AMSFE_ERR_NONFINITE;
  if (e->net) net_jacobian(e, A); /* at x, before x moves */
  if (!e->lp_ok && !pd_state(e)) return AMSFE_ERR_NOT_PD; /* P = LP LP^T */
  amsfe_predict_cov(N, e->d.nw, A, e->LP, G, e->qw, e->P1, e->T1); /* eq. (14) */
  copy(e->x, e->x1, N);
  swap_P(e, &e->P1);
  return AMSFE_OK;
}

/* Estimator._encoder_update (z NULL: no sample); report: count it in diag */
static int encoder_update(amsfe_est *e, const double *z, int report) {
  int N = e->d.N;
  e->has_last = 0.0;
  if (report) e->diag.encoder_accepted = 0, e->diag.encoder_nis = NAN;
  if (!z) return AMSFE_OK;
  if (!encoder_kernel(e, z)) return AMSFE_ERR_S_NOT_PD;
  int accepted = e->nis <= e->par.gate_encoder;
  if (report) {
    e->diag.encoder_nis = e->nis;
    e->diag.encoder_accepted = accepted;
    if (accepted) ++e->diag.encoder_updates;
    else ++e->diag.encoder_gated;
  }
  if (accepted) {
    double *prior = e->P; /* last_Pprior <- P(k|k-1), P <- P2 (a rotation, no copy) */
    e->P = e->P2, e->P2 = e->last_Pprior, e->last_Pprior = prior;
    e->lp_ok = 0;
    copy(e->x, e->x2, N);
    e->has_last = 1.0;
    if (e->jt) copy(e->last_hval, e->ehval, e->ehrow[e->d.ne]); /* its H, for oosm's A1 */
  }
  return AMSFE_OK;
}

/* CameraMeasurement.predict for a state with input states: y = I_k(q) into cy and the values
 * of H's nonzeros (the q columns, row by row) into chval; 0 when they are not finite */
EFFORT_PATH int camera_h(amsfe_est *e, const double *x) {
  int n = e->d.n;
  const double *in[2] = {x, x + 4 * n};
  double *out[3] = {e->cy, e->cJ + 2 * n + 1, e->cJ + 2 * n};
  gcall(&e->g, camera_measure, in, 2, out, 3);
  /* J's nonzeros (CasADi's compressed columns) to dense 2 x n, column-major */
  const cint *sp = camera_measure_sparsity_out(1);
  const double *nz = e->cJ + 2 * n + 1;
  double *J = e->cJ;
  if (sp[2] == 1 && sp[1] > 0) {
    for (int i = 0; i < 2 * n; ++i) J[i] = nz[i];
  } else {
    for (int i = 0; i < 2 * n; ++i) J[i] = 0.0;
    for (cint j = 0; j < sp[1]; ++j)
      for (cint v = sp[2 + j]; v < sp[3 + j]; ++v) J[sp[3 + sp[1] + v] + 2 * j] = nz[v];
  }
  if (!all_finite(e->cy, 2) || !all_finite(J, 2 * n)) return 0;
  for (int r = 0; r < 2; ++r)
    for (int j = 0; j < n; ++j) e->chval[r * n + j] = J[r + 2 * j];
  return 1;
}

/* Estimator._frame_update_now on a state with input states (the generated camera update is
 * the model's N): the iterated EKF with the camera's H padded with zero columns */
EFFORT_PATH static int frame_now_inputs(amsfe_est *e, const double *z, double *nis) {
  int M = e->d.N, n = e->d.n;
  if (!camera_h(e, e->x)) return AMSFE_ERR_NONFINITE;
  for (int r = 0; r < 2; ++r) e->cnu[r] = z[r] - e->cy[r];
  if (!amsfe_joseph_rows(M, 2, e->chrow, e->chcol, e->chval, e->rc, e->x, e->P, e->cnu, e->x1,
                         e->P1, &e->nis, e->JW))
    return AMSFE_ERR_S_NOT_PD;
  double first = e->nis;
  if (nis) *nis = first;
  if (!(first <= e->par.gate_camera)) return AMSFE_GATED;
  for (int it = 1; it < e->par.camera_iterations; ++it) {
    copy(e->x2, e->x1, M); /* x_i */
    if (!camera_h(e, e->x2)) return AMSFE_ERR_NONFINITE;
    for (int r = 0; r < 2; ++r) { /* z - h(x_i) - H_i (x- - x_i) */
      double hx = 0.0;
      for (int j = 0; j < n; ++j) hx += e->chval[r * n + j] * (e->x[j] - e->x2[j]);
      e->cnu[r] = z[r] - e->cy[r] - hx;
    }
    if (!amsfe_joseph_rows(M, 2, e->chrow, e->chcol, e->chval, e->rc, e->x, e->P, e->cnu, e->x1,
                           e->P1, &e->nis, e->JW))
      return AMSFE_ERR_S_NOT_PD;
  }
  copy(e->x, e->x1, M);
  swap_P(e, &e->P1);
  return AMSFE_OK;
}

/* Estimator._frame_update_now: iterated EKF camera update of (x, P) */
int frame_now(amsfe_est *e, const double *z, double *nis) {
  if (e->ni) return frame_now_inputs(e, z, nis);
  int N = e->d.N;
  const double *in[5] = {e->x, e->P, e->x, z, e->rc};
  double *out[5] = {e->x1, e->P1, &e->nis, &e->s_ok, &e->chk};
  gcall(&e->g, est_camera_update, in, 5, out, 5);
  if (!isfinite(e->chk)) return AMSFE_ERR_NONFINITE;
  if (!(e->s_ok > 0.5)) return AMSFE_ERR_S_NOT_PD;
  double first = e->nis;
  if (nis) *nis = first;
  if (!(first <= e->par.gate_camera)) return AMSFE_GATED;
  for (int it = 1; it < e->par.camera_iterations; ++it) {
    copy(e->x2, e->x1, N);
    const double *in2[5] = {e->x, e->P, e->x2, z, e->rc};
    gcall(&e->g, est_camera_update, in2, 5, out, 5);
    if (!isfinite(e->chk)) return AMSFE_ERR_NONFINITE;
    if (!(e->s_ok > 0.5)) return AMSFE_ERR_S_NOT_PD;
  }
  copy(e->x, e->x1, N);
  swap_P(e, &e->P1);
  return AMSFE_OK;
}

/* ------------------------------------------------------------------ replay */
void replay_store(amsfe_est *e, long j) {
  long N = e->d.N, s = pmod(j, e->R);
  copy(e->r_x + s * N, e->x, N);
  copy(e->r_P + s * N * N, e->P, N * N);
}

/* ReplayEstimator._step's loop body for j -> j + 1 (report: j + 1 is the current step) */
int replay_step(amsfe_est *e, long j, int report) {
  long s = pmod(j, e->R), s1 = pmod(j + 1, e->R);
  int st = predict(e, e->r_u + s * e->d.n, e->A1, e->G);
  if (st) return st;
  st = encoder_update(e, e->r_hasz[s1] ? e->r_z + s1 * e->d.ne : NULL, report);
  if (st) return st;
  for (int f = 0; f < e->r_nf[s1]; ++f) {
    st = frame_now(e, e->r_fz + (s1 * e->F + f) * e->d.nc, NULL);
    if (st < 0) return st;
  }
  replay_store(e, j + 1);
  return AMSFE_OK;
}

/* ------------------------------------------------------------------ tick */
int amsfe_est_tick(amsfe_est *e, const double *z_encoder, const double *u) {
  if (!e || !u) return AMSFE_ERR_INPUT;
  if (e->failed) return AMSFE_ERR_FAILED;
  int N = e->d.N, n = e->d.n, st;
  if (!all_finite(u, n)) return AMSFE_ERR_INPUT;
  const double *z = z_encoder && all_finite(z_encoder, e->d.ne) ? z_encoder : NULL;
  long k = e->k, k1 = k + 1;
  e->diag.replayed_steps = 0;
  if (!z) ++e->diag.encoder_missing;
  switch (e->par.estimator) {
    case AMSFE_REPLAY: {
      long s = pmod(k, e->R), s1 = pmod(k1, e->R);
      copy(e->r_u + s * n, u, n);
      e->r_hasz[s1] = z != NULL;
      if (z) copy(e->r_z + s1 * e->d.ne, z, e->d.ne);
      e->r_nf[s1] = 0; /* the slot held step k1 - R, now forgotten */
      st = replay_step(e, k, 1);
      break;
    }
    case AMSFE_CLONING: {
      int Na = (1 + e->S) * N;
      for (int s = 0; s < e->S; ++s) /* clones expired at the end of step k */
        if (e->clone_on[s] && k - e->clone_k[s] >= e->max_delay) drop_clone(e, s);
      /* CloningEstimator._predict_augmented: the state block by the tick's kernels (x, P
       * mirror it), the state-clone blocks P_xc <- A P_xc, the clones unchanged */
      st = predict(e, u, e->A1, e->G);
      if (st) break;
      double *cross = e->Pa2; /* N x (Na - N), leading dimension N */
      amsfe_matmul_cols(N, Na - N, e->A1, e->Pa + (long)N * Na, Na, cross);
      copy(e->xa, e->x, N);
      for (int j = 0; j < N; ++j) copy(e->Pa + (long)j * Na, e->P + (long)j * N, N);
      for (int j = 0; j < Na - N; ++j)
        for (int i = 0; i < N; ++i)
          e->Pa[i + (long)(N + j) * Na] = e->Pa[(N + j) + (long)i * Na] = cross[i + (long)j * N];
      e->diag.encoder_accepted = 0, e->diag.encoder_nis = NAN;
      st = AMSFE_OK;
      if (z) {
        /* the encoder update on the augmented state (H selects qm, qmd of the state block;
         * with joint torques, its nonzeros, in the state block's columns) */
        int ok;
        if (e->jt) {
          torque_h(e, e->xa, e->hz, e->ehval);
          for (int a = 0; a < e->d.ne; ++a) e->last_nu[a] = z[a] - e->hz[a];
          ok = amsfe_joseph_rows(Na, e->d.ne, e->ehrow, e->ehcol, e->ehval, e->re, e->xa, e->Pa,
                                 e->last_nu, e->xa2, e->Pa2, &e->nis, e->JW);
        } else {
          ok = amsfe_joseph_select(Na, e->d.ne, e->enc_rows, e->re, e->xa, e->Pa, z, e->xa2,
                                   e->Pa2, &e->nis, e->last_nu, e->JW);
        }
        if (!ok) {
          st = AMSFE_ERR_S_NOT_PD;
          break;
        }
        int accepted = e->nis <= e->par.gate_encoder;
        e->diag.encoder_nis = e->nis, e->diag.encoder_accepted = accepted;
        if (accepted) {
          ++e->diag.encoder_updates;
          copy(e->xa, e->xa2, Na);
          copy(e->Pa, e->Pa2, (long)Na * Na);
        } else {
          ++e->diag.encoder_gated;
        }
      }
      if (scheduled(e, k1)) add_clone(e, k1);
      sync_clone(e);
      break;
    }
    default: /* encoders, naive, oosm */
      if (e->par.estimator == AMSFE_OOSM) {
        long s = pmod(k, e->B), NN = (long)N * N;
        copy(e->xpost_buf + s * N, e->x, N);
        st = predict(e, u, e->A_buf + s * NN, e->G_buf + s * N * e->d.nw); /* kept for eq. 23 */
        if (st) break;
        copy(e->xprior_buf + s * N, e->x, N);
        copy(e->u_buf + s * n, u, n);
      } else {
        st = predict(e, u, e->A1, e->G);
        if (st) break;
      }
      st = encoder_update(e, z, 1);
  }
  if (st) return fail(e, st);
  e->k = k1;
  ++e->diag.ticks;
  if (!pd_state(e)) return fail(e, AMSFE_ERR_NOT_PD);
  if (e->par.estimator == AMSFE_CLONING) {
    int alive = 0;
    for (int s = 0; s < e->S; ++s) {
      if (!e->clone_on[s] || k1 - e->clone_k[s] >= e->max_delay) continue;
      ++alive;
      if (!clone_block_pd(e, s)) return fail(e, AMSFE_ERR_NOT_PD);
    }
    e->diag.clones = alive;
  }
  return AMSFE_OK;
}
