/* amsfe_runtime.c: the hand-written glue of the compiled estimators (docs/how-to/runtime-c.md).
 *
 * Control flow and bookkeeping: history ring buffers, the loops over a lag, gating decisions,
 * statuses.  The model's numbers (x+, A, Gamma, the inverse, the camera) come from the
 * generated functions compiled into the same library (transition_step, transition_inverse,
 * est_* of symbolic/estimator.py).  The EKF's dense linear algebra of the tick (eqs. 13-17:
 * A P A^T + Gamma Qw Gamma^T, the encoder update whose H selects qm and qmd, the Cholesky
 * check, the eq. 23 accumulation) is the small set of loops of amsfe_kernels.c, the C
 * counterpart of the numpy lines of the Python reference: CasADi's MX matrix products cost
 * 6-12 ns per multiply-add in generated code and SX expansion grows as N^3 (docs/explanation/performance.md).
 * Each branch mirrors the Python reference in estimation/ (named per function).
 *
 * This file: the estimator's memory (its layout, the parameters' checks), its life cycle
 * (init, reset, create) and accessors, the statuses' words.  The EKF steps, the replay ring
 * and the tick are in amsfe_est_tick.c, the late frames in amsfe_est_late.c, a whole log in
 * amsfe_est_run.c; amsfe_est_internal.h holds what they share.
 */
#define _POSIX_C_SOURCE 200112L /* posix_memalign */
/* The glue is small: optimise it fully whatever the library's flags (-O1 by default, chosen
 * for the size of the generated files); O3 vectorises the kernels' axpy loops.  No
 * -ffast-math: sums keep their order, so results do not depend on the flags. */
#if defined(__GNUC__) && !defined(__clang__)
#pragma GCC optimize("O3")
#endif
#include "amsfe_runtime.h"

#include <limits.h>
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "amsfe_est_internal.h"

static const cwork WORKS[] = {est_camera_update_work, est_oosm_correct_work, est_clone_camera_work,
                              STEP_WORK, transition_inverse_work, camera_measure_work};

/* ------------------------------------------------------------------ layout and life cycle */
static void model_dims(amsfe_dims *d) {
  d->N = (int)est_predict_sparsity_in(0)[0];
  d->n = (int)est_predict_sparsity_in(2)[0];
  d->nw = (int)est_predict_sparsity_in(3)[0];
  d->ne = 2 * d->n; /* qm and qmd (eq. 5) */
  d->nc = (int)est_camera_update_sparsity_in(3)[0];
  d->clone_slots = (int)est_clone_camera_sparsity_in(3)[0];
}

void amsfe_dims_get(amsfe_dims *dims) { model_dims(dims); }

/* The filter's dims for p (the model's, grown by the input states and the torque sensors);
 * returns the model's N. */
static int filter_dims(const amsfe_params *p, amsfe_dims *d) {
  model_dims(d);
  int Nm = d->N;
  d->N += p->input_states, d->nw += p->input_states;
  if (p->joint_torque) d->ne = 3 * d->n;
  return Nm;
}

/* Nonzeros of the encoder H with joint torques (rows qm, qmd: one each; row tau_j: q_j, qm_j
 * and theta's stiffness entry if any) */
static int torque_nnz(const amsfe_params *p, int n) {
  int v = 5 * n;
  for (int j = 0; j < n; ++j) v += p->ks_theta[j] >= 0;
  return v;
}

/* Lay the object out in `base` (NULL: only measure); returns the bytes needed. */
static size_t layout(amsfe_est *e, const amsfe_params *p, char *base) {
  amsfe_dims d;
  int Nm = filter_dims(p, &d);
  long N = d.N, NN = (long)d.N * d.N, n = d.n;
  long B = p->buffer_steps, R = B + 1, F = p->max_frames_per_step;
  long S = d.clone_slots, Na = (1 + S) * N;
  int est = p->estimator;
  amsfe_est tmp;
  if (!e) e = &tmp; /* only measuring: the pointers go to a scratch object */
  carver c = carve_object(base, sizeof(amsfe_est));
  e->seen = (long *)carve(&c, sizeof(long) * (size_t)R);
  e->x = DBL(&c, N), e->P = DBL(&c, NN), e->x0 = DBL(&c, N), e->P0 = DBL(&c, NN);
  e->qw = DBL(&c, d.nw), e->re = DBL(&c, d.ne), e->rc = DBL(&c, d.nc);
  e->x1 = DBL(&c, N), e->P1 = DBL(&c, NN), e->A1 = DBL(&c, NN);
  e->x2 = DBL(&c, N), e->P2 = DBL(&c, NN);
  e->last_nu = DBL(&c, d.ne), e->last_Pprior = DBL(&c, NN);
  e->G = DBL(&c, N * d.nw), e->T1 = DBL(&c, AMSFE_PREDICT_WORK(N, d.nw)), e->L1 = DBL(&c, NN), e->LP = DBL(&c, NN);
  e->JW = DBL(&c, AMSFE_JOSEPH_WORK(est == AMSFE_CLONING ? Na : N, d.ne));
  e->A_buf = e->G_buf = e->u_buf = NULL;
  e->r_x = e->r_P = e->r_u = e->r_z = e->r_fz = NULL;
  e->xa = e->Pa = e->xa2 = e->Pa2 = e->sel = e->cl = NULL;
  if (est == AMSFE_OOSM) {
    e->A_buf = DBL(&c, B * NN), e->G_buf = DBL(&c, B * N * d.nw), e->u_buf = DBL(&c, B * n);
    e->Phi = DBL(&c, NN), e->Q = DBL(&c, NN), e->Phi2 = DBL(&c, NN), e->Qb = DBL(&c, NN);
    e->M = DBL(&c, NN), e->C = DBL(&c, NN);
    e->xs = DBL(&c, N), e->xr = DBL(&c, N), e->sv = DBL(&c, N);
    e->xpost_buf = DBL(&c, B * N), e->xprior_buf = DBL(&c, B * N);
    e->RW = DBL(&c, AMSFE_RETRO_WORK(N, d.ne));
  }
  e->gain = e->ks = e->An = e->Gn = NULL;
  e->kst = e->ehrow = e->ehcol = e->chrow = e->chcol = e->ccol = NULL;
  e->ehval = e->last_hval = e->hz = e->chval = e->cy = e->cnu = e->cJ = e->OW = e->RH = NULL;
  if (p->input_states) {
    e->gain = DBL(&c, n);
    e->An = DBL(&c, (long)Nm * Nm), e->Gn = DBL(&c, (long)Nm * (d.nw - n));
    e->chrow = (int *)carve(&c, sizeof(int) * 3), e->chcol = (int *)carve(&c, sizeof(int) * 2 * n);
    e->ccol = (int *)carve(&c, sizeof(int) * 2 * n);
    e->chval = DBL(&c, 2 * n), e->cy = DBL(&c, 2), e->cnu = DBL(&c, 2);
    e->cJ = DBL(&c, 4 * n + 2); /* J dense, depth, J's nonzeros */
    if (est == AMSFE_OOSM) e->OW = DBL(&c, 8 * N + 8);
  }
  e->ut = e->Bn = NULL;
  if (p->net_torque) e->ut = DBL(&c, n), e->Bn = DBL(&c, N * n), e->gain = DBL(&c, n);
  if (p->joint_torque || p->net_torque) {
    e->ks = DBL(&c, n), e->kst = (int *)carve(&c, sizeof(int) * (size_t)n);
  }
  if (p->joint_torque) {
    int nnz = torque_nnz(p, (int)n);
    e->ehrow = (int *)carve(&c, sizeof(int) * (size_t)(d.ne + 1));
    e->ehcol = (int *)carve(&c, sizeof(int) * (size_t)nnz);
    e->ehval = DBL(&c, nnz), e->last_hval = DBL(&c, nnz), e->hz = DBL(&c, d.ne);
    if (est == AMSFE_OOSM) e->RH = DBL(&c, 2 * N * d.ne + 2L * d.ne * d.ne);
  }
  if (est == AMSFE_REPLAY) {
    e->r_x = DBL(&c, R * N), e->r_P = DBL(&c, R * NN), e->r_u = DBL(&c, R * n);
    e->r_z = DBL(&c, R * d.ne), e->r_fz = DBL(&c, R * F * d.nc);
    e->r_hasz = (int *)carve(&c, sizeof(int) * (size_t)R);
    e->r_nf = (int *)carve(&c, sizeof(int) * (size_t)R);
  }
  if (est == AMSFE_CLONING) {
    e->xa = DBL(&c, Na), e->Pa = DBL(&c, Na * Na), e->xa2 = DBL(&c, Na);
    e->Pa2 = DBL(&c, Na * Na), e->sel = DBL(&c, S), e->cl = DBL(&c, N);
    e->clone_k = (long *)carve(&c, sizeof(long) * (size_t)S);
    e->clone_on = (int *)carve(&c, sizeof(int) * (size_t)S);
  }
  carve_work(&c, WORKS, sizeof(WORKS) / sizeof(WORKS[0]), &e->g);
  e->d = d;
  e->Nm = Nm, e->ni = p->input_states, e->jt = p->joint_torque, e->net = p->net_torque;
  return c.off + 16;
}

static int params_ok(const amsfe_params *p) {
  amsfe_dims d;
  if (!p) return 0;
  model_dims(&d);
  if (p->input_states != 0 && p->input_states != d.n) return 0;
  if (p->joint_torque != 0 && p->joint_torque != 1) return 0;
  if (p->input_states) { /* the trapezoid gain; oosm's inverse map is not here */
    if (!p->input_gain || !all_finite(p->input_gain, d.n)) return 0;
    if (p->estimator == AMSFE_OOSM && p->backward_map != AMSFE_BACKWARD_LINEARISED) return 0;
  }
  if (p->net_torque != 0 && p->net_torque != 1) return 0;
  if (p->net_torque) {
    if (p->input_states || !p->input_gain || !all_finite(p->input_gain, d.n)) return 0;
    if (p->estimator == AMSFE_OOSM && p->backward_map != AMSFE_BACKWARD_LINEARISED) return 0;
  }
  if (p->joint_torque || p->net_torque) {
    if (!p->ks || !p->ks_theta || !all_finite(p->ks, d.n)) return 0;
    for (int j = 0; j < d.n; ++j)
      if (p->ks_theta[j] < -1 || p->ks_theta[j] >= d.N - 4 * d.n) return 0;
  }
  filter_dims(p, &d);
  if (!p->qw || !p->r_encoder || !p->r_camera || !p->x0 || !p->P0) return 0;
  if (d.ne > AMSFE_MAX_ENCODERS) return 0;
  if (p->estimator < AMSFE_ENCODERS || p->estimator > AMSFE_CLONING) return 0;
  if (p->buffer_steps < 1 || p->camera_iterations < 1 || p->max_frames_per_step < 1) return 0;
  if (p->backward_map != AMSFE_BACKWARD_LINEARISED && p->backward_map != AMSFE_BACKWARD_INVERSE)
    return 0;
  if (isnan(p->gate_camera) || isnan(p->gate_encoder)) return 0;
  for (int i = 0; i < d.nw; ++i)
    if (!(p->qw[i] >= 0 && isfinite(p->qw[i]))) return 0;
  for (int i = 0; i < d.ne; ++i)
    if (!(p->r_encoder[i] > 0 && isfinite(p->r_encoder[i]))) return 0;
  for (int i = 0; i < d.nc; ++i)
    if (!(p->r_camera[i] > 0 && isfinite(p->r_camera[i]))) return 0;
  if (!all_finite(p->x0, d.N) || !all_finite(p->P0, (long)d.N * d.N)) return 0;
  if (p->camera_period < 0 || (p->camera_period > 0 && (p->camera_phase < 0 ||
                                                         p->camera_phase >= p->camera_period)))
    return 0;
  if (p->estimator == AMSFE_CLONING) {
    if (p->camera_period < 1) return 0;
    int lat = p->camera_max_delay < 0 || p->camera_max_delay > p->buffer_steps
                  ? p->buffer_steps
                  : p->camera_max_delay;
    if (lat / p->camera_period + 1 > d.clone_slots) return 0; /* more clones than slots */
  }
  return 1;
}

size_t amsfe_est_memory_size(const amsfe_params *params) {
  if (!params_ok(params)) return 0;
  return layout(NULL, params, NULL);
}

/* cloning.CloningEstimator._add_clone: slot s takes x and P's rows/columns of the state */
void add_clone(amsfe_est *e, long kappa) {
  int N = e->d.N, S = e->S, Na = (1 + S) * N, s = 0;
  while (s < S && e->clone_on[s]) ++s;
  if (s == S) return; /* cannot happen: init checked the slots against the latency */
  int o = N * (1 + s);
  for (int i = 0; i < N; ++i) e->xa[o + i] = e->xa[i];
  for (int j = 0; j < Na; ++j)
    for (int i = 0; i < N; ++i) e->Pa[(o + i) + (long)j * Na] = e->Pa[i + (long)j * Na];
  for (int j = 0; j < N; ++j)
    for (int i = 0; i < Na; ++i) e->Pa[i + (long)(o + j) * Na] = e->Pa[i + (long)j * Na];
  e->clone_on[s] = 1;
  e->clone_k[s] = kappa;
}

void amsfe_est_reset(amsfe_est *e) {
  int N = e->d.N;
  copy(e->x, e->x0, N);
  set_P(e, e->P0);
  e->k = e->par.k0;
  e->failed = 0, e->last_error = 0, e->has_last = 0.0;
  memset(&e->diag, 0, sizeof(e->diag));
  e->diag.encoder_nis = NAN;
  for (int j = 0; j <= e->B; ++j) e->seen[j] = LONG_MIN;
  if (e->r_hasz) {
    for (int j = 0; j < e->R; ++j) e->r_hasz[j] = 0, e->r_nf[j] = 0;
    long s = pmod(e->k, e->R);
    copy(e->r_x + s * N, e->x, N);
    copy(e->r_P + s * (long)N * N, e->P, (long)N * N);
  }
  if (e->xa) {
    int Na = (1 + e->S) * N;
    memset(e->xa, 0, sizeof(double) * (size_t)Na);
    memset(e->Pa, 0, sizeof(double) * (size_t)Na * (size_t)Na);
    copy(e->xa, e->x, N);
    for (int j = 0; j < N; ++j) copy(e->Pa + (long)j * Na, e->P + (long)j * N, N);
    for (int s = 0; s < e->S; ++s) e->clone_on[s] = 0;
    if (scheduled(e, e->k)) add_clone(e, e->k);
  }
}

int amsfe_est_init(amsfe_est **out, const amsfe_params *p, void *memory, size_t size) {
  if (!out || !memory) return AMSFE_ERR_MEMORY;
  *out = NULL;
  if (!params_ok(p)) return AMSFE_ERR_CONFIG;
  if (((size_t)memory & 15u) != 0 || layout(NULL, p, NULL) > size) return AMSFE_ERR_MEMORY;
  amsfe_est *e = (amsfe_est *)memory;
  /* layout() sets the pointers inside e; the object itself sits at offset 0 */
  memset(memory, 0, sizeof(amsfe_est));
  layout(e, p, (char *)memory);
  amsfe_dims d = e->d;
  e->par = *p;
  e->B = p->buffer_steps, e->R = p->buffer_steps + 1, e->F = p->max_frames_per_step;
  e->S = d.clone_slots;
  e->max_delay = p->camera_max_delay < 0 || p->camera_max_delay > p->buffer_steps
                       ? p->buffer_steps
                       : p->camera_max_delay;
  e->inv_tol = AMSFE_INVERSE_TOL;
  for (int r = 0; r < 2 * d.n; ++r) e->enc_rows[r] = r < d.n ? 2 * d.n + r : 3 * d.n + (r - d.n);
  if (e->ni) {
    copy(e->gain, p->input_gain, d.n);
    e->par.input_gain = e->gain;
    e->chrow[0] = 0, e->chrow[1] = d.n, e->chrow[2] = 2 * d.n;
    for (int r = 0; r < 2; ++r)
      for (int j = 0; j < d.n; ++j) e->chcol[r * d.n + j] = j; /* the camera sees q */
  }
  if (e->jt || e->net) {
    copy(e->ks, p->ks, d.n);
    for (int j = 0; j < d.n; ++j) e->kst[j] = p->ks_theta[j];
    e->par.ks = e->ks, e->par.ks_theta = e->kst;
  }
  if (e->net) copy(e->gain, p->input_gain, d.n), e->par.input_gain = e->gain;
  if (e->jt) {
    int v = 0;
    for (int a = 0; a < 2 * d.n; ++a) e->ehrow[a] = v, e->ehcol[v++] = 2 * d.n + a;
    for (int j = 0; j < d.n; ++j) {
      e->ehrow[2 * d.n + j] = v;
      e->ehcol[v++] = j, e->ehcol[v++] = 2 * d.n + j;
      if (e->kst[j] >= 0) e->ehcol[v++] = 4 * d.n + e->kst[j];
    }
    e->ehrow[3 * d.n] = v;
  }
  e->inv_residual = NAN, e->inv_limit = NAN;
  copy(e->x0, p->x0, d.N);
  copy(e->P0, p->P0, (long)d.N * d.N);
  copy(e->qw, p->qw, d.nw);
  copy(e->re, p->r_encoder, d.ne);
  copy(e->rc, p->r_camera, d.nc);
  e->par.qw = e->qw, e->par.r_encoder = e->re, e->par.r_camera = e->rc;
  e->par.x0 = e->x0, e->par.P0 = e->P0;
  for (long j = 0; j < d.N; ++j) /* P0 symmetric and PD (validate_spd) */
    for (long i = 0; i < j; ++i)
      if (fabs(e->P0[i + j * d.N] - e->P0[j + i * d.N]) >
          1e-9 * fmax(1.0, fabs(e->P0[i + j * d.N])))
        return AMSFE_ERR_CONFIG;
  if (!pd(e, e->P0)) return AMSFE_ERR_CONFIG;
  amsfe_est_reset(e);
  *out = e;
  return AMSFE_OK;
}

amsfe_est *amsfe_est_create(const amsfe_params *p, int *status) {
  int st = AMSFE_ERR_CONFIG;
  amsfe_est *e = NULL;
  size_t size = amsfe_est_memory_size(p);
  if (size) {
    void *mem = NULL;
    if (posix_memalign(&mem, 16, size) != 0) {
      st = AMSFE_ERR_MEMORY;
    } else {
      st = amsfe_est_init(&e, p, mem, size);
      if (st != AMSFE_OK) free(mem);
    }
  }
  if (status) *status = st;
  return st == AMSFE_OK ? e : NULL;
}

void amsfe_est_destroy(amsfe_est *e) { free(e); }

const double *amsfe_est_factor(amsfe_est *e) {
  if (!e->lp_ok) pd_state(e);
  return e->lp_ok ? e->LP : NULL;
}

void amsfe_est_state(const amsfe_est *e, double *x, double *P) {
  long N = e->d.N;
  if (x) copy(x, e->x, N);
  if (P) copy(P, e->P, N * N);
}

void amsfe_est_diagnostics(const amsfe_est *e, amsfe_diag *diag) {
  *diag = e->diag;
  diag->k = e->k;
  diag->failed = e->failed;
  diag->last_error = e->last_error;
}

int amsfe_est_set_inverse_tolerance(amsfe_est *e, double tol) {
  if (!e || !(tol > 0)) return AMSFE_ERR_INPUT;
  e->inv_tol = tol;
  return AMSFE_OK;
}

void amsfe_est_inverse_residual(const amsfe_est *e, double *residual, double *limit) {
  if (residual) *residual = e ? e->inv_residual : NAN;
  if (limit) *limit = e ? e->inv_limit : NAN;
}

const char *amsfe_status_string(int status) {
  switch (status) {
    case AMSFE_OK: return "ok";
    case AMSFE_GATED: return "gated out (NIS above the chi-square gate)";
    case AMSFE_REFUSED_NONFINITE: return "refused: the measurement holds NaN or inf";
    case AMSFE_REFUSED_TOO_OLD: return "refused: older than the history kept (buffer_steps)";
    case AMSFE_REFUSED_FUTURE: return "refused: exposure after the current step";
    case AMSFE_REFUSED_INDEFINITE:
      return "refused: the A1 update gives an indefinite covariance over this lag";
    case AMSFE_REFUSED_NO_CLONE: return "refused: not a scheduled exposure (no clone)";
    case AMSFE_REFUSED_NO_CLONE_LEFT:
      return "refused: its clone was used already or is older than camera_max_delay";
    case AMSFE_REFUSED_FULL: return "refused: max_frames_per_step frames stored for that step";
    case AMSFE_IGNORED: return "ignored (the encoders estimator uses no frames)";
    case AMSFE_REFUSED_DUPLICATE:
      return "refused: a frame of this exposure step was used already (a duplicate)";
    case AMSFE_REFUSED_NO_CONVERGENCE:
      return "refused: the inverse transition (eq. 22) did not converge over the lag";
    case AMSFE_ERR_INPUT: return "error: NULL pointer or non-finite input u";
    case AMSFE_ERR_NOT_PD: return "error: the covariance lost positive definiteness";
    case AMSFE_ERR_NONFINITE: return "error: the model gave NaN or inf";
    case AMSFE_ERR_S_NOT_PD: return "error: an innovation covariance is not positive definite";
    case AMSFE_ERR_FAILED: return "error: an earlier call failed; call amsfe_est_reset";
    case AMSFE_ERR_CONFIG: return "error: bad parameter block";
    case AMSFE_ERR_MEMORY: return "error: memory block too small or not 16-byte aligned";
    default: return "unknown status";
  }
}
