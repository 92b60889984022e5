/* amsfe_runtime.c: the hand-written glue of the compiled estimators (docs/how-to/runtime-c.md).
 *
 * Control flow and bookkeeping: history ring buffers, the loops over a lag, gating decisions,
 * statuses.  The model's numbers (x+, A, Gamma, the inverse, the camera) come from the
 * generated functions compiled into the same library (transition_step, transition_inverse,
 * est_* of symbolic/estimator.py).  The EKF's dense linear algebra of the tick (eqs. 13-17:
 * A P A^T + Gamma Qw Gamma^T, the encoder update whose H selects qm and qmd, the Cholesky
 * check, the eq. 23 accumulation) is the small set of loops in "dense kernels" below, the C
 * counterpart of the numpy lines of the Python reference: CasADi's MX matrix products cost
 * 6-12 ns per multiply-add in generated code and SX expansion grows as N^3 (docs/explanation/performance.md).
 * Each branch mirrors the Python reference in estimation/ (named per function).
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

#include "amsfe_internal.h"

#define AMSFE_MAX_ENCODERS 256 /* 2n: up to 128 joints */
/* The effort paths (docs/explanation/effort.md section 7) stay out of line: the applied path's tick is
 * compiled as before (the same inlining), whatever they add. */
#if defined(__GNUC__)
#define EFFORT_PATH __attribute__((noinline))
#else
#define EFFORT_PATH
#endif
DECLARE(est_predict)
DECLARE(est_camera_update)
DECLARE(est_oosm_correct)
DECLARE(est_clone_camera)
DECLARE(transition_step)
DECLARE(transition_inverse)
DECLARE(camera_measure)
const cint *camera_measure_sparsity_out(cint i);

#include "amsfe_model_config.h"
#if AMSFE_MODEL_CHAIN
/* rk4 libraries: the step chained from the generated stage (amsfe_model.c), the same numbers
 * as the generated transition_step in a fraction of its code */
DECLARE(transition_step_chain)
#define STEP transition_step_chain
#define STEP_WORK transition_step_chain_work
#else
#define STEP transition_step
#define STEP_WORK transition_step_work
#endif

static const cwork WORKS[] = {est_camera_update_work, est_oosm_correct_work, est_clone_camera_work,
                              STEP_WORK, transition_inverse_work, camera_measure_work};

struct amsfe_est {
  amsfe_params par; /* pointers in it point into this block */
  amsfe_dims d;     /* the filter's: N = M (the model's N + input_states), nw and ne with them */
  int Nm, ni, jt, net; /* the model's N, input states, joint torque sensors, net torque input
                          (docs/explanation/effort.md) */
  int B, R, F, S, max_delay; /* oosm ring B, replay ring R = B + 1, frames per step, slots */
  long k;
  int failed, last_error;
  amsfe_diag diag;
  /* state */
  double *x, *P, *x0, *P0, *qw, *re, *rc;
  double *x1, *P1, *A1, *x2, *P2; /* scratch */
  double nis, s_ok, chk, ok2;
  double *G, *T1, *L1, *JW; /* dense-kernel scratch */
  double *LP;                /* Cholesky factor of P (valid when lp_ok: eq. 14 uses it) */
  int lp_ok;
  int enc_rows[AMSFE_MAX_ENCODERS];     /* state row of each encoder value (H, eq. 5) */
  /* oosm */
  double *A_buf, *G_buf, *u_buf, *Phi, *Q, *Phi2, *Qb, *M, *C, *xs, *xr, *sv;
  double *xpost_buf, *xprior_buf; /* x(j|j) and x(j+1|j) of each prediction (eq. 24) */
  double *RW;                     /* amsfe_a1_retrodict's work */
  double *last_nu, *last_Pprior, has_last;
  /* replay */
  double *r_x, *r_P, *r_u, *r_z, *r_fz;
  int *r_hasz, *r_nf;
  long *seen; /* [B + 1] exposure steps of the frames used, by kappa mod (B + 1) */
  /* cloning */
  double *xa, *Pa, *xa2, *Pa2, *sel, *cl;
  long *clone_k;
  int *clone_on;
  /* input states and joint torques (amsfe_params.input_states, joint_torque) */
  double *gain, *ks, *An, *Gn; /* T / (2 Mm), Ks; the model's A and Gamma (input states) */
  int *kst;
  int *ehrow, *ehcol, *chrow, *chcol; /* nonzeros of the encoder and the camera H by rows */
  int *ccol;                          /* cloning: the camera H's columns at a clone */
  double *ehval, *last_hval, *hz, *chval, *cy, *cnu, *cJ, *OW, *RH;
  double *ut, *Bn; /* net torque: the model's input, its gain B (N x n) */
  gwork g; /* work of the generated functions */
  double inv_tol, inv_residual, inv_limit; /* the inverse's convergence check */
};

/* ------------------------------------------------------------------ helpers */
static long pmod(long a, long b) { return ((a % b) + b) % b; }

static void copy(double *dst, const double *src, long count) {
  memcpy(dst, src, sizeof(double) * (size_t)count);
}

static int fail(amsfe_est *e, int status) {
  e->failed = 1;
  e->last_error = status;
  return status;
}

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

/* P <- src; the Cholesky factor LP of P is stale until the next pd_state. */
static void set_P(amsfe_est *e, const double *src) {
  copy(e->P, src, (long)e->d.N * e->d.N);
  e->lp_ok = 0;
}

/* P <- *scratch by exchanging the two N x N buffers (*scratch then holds the old P). */
static void swap_P(amsfe_est *e, double **scratch) {
  double *t = e->P;
  e->P = *scratch, *scratch = t;
  e->lp_ok = 0;
}

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

static int scheduled(const amsfe_est *e, long k) {
  int l = e->par.camera_period;
  return l > 0 && pmod(k, l) == e->par.camera_phase;
}

/* cloning.CloningEstimator._add_clone: slot s takes x and P's rows/columns of the state */
static void add_clone(amsfe_est *e, long kappa) {
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

static void drop_clone(amsfe_est *e, int s) {
  int N = e->d.N, Na = (1 + e->S) * N, o = N * (1 + s);
  for (int i = 0; i < N; ++i) e->xa[o + i] = 0.0;
  for (int j = 0; j < Na; ++j)
    for (int i = 0; i < N; ++i) e->Pa[(o + i) + (long)j * Na] = 0.0;
  for (int j = 0; j < N; ++j)
    for (int i = 0; i < Na; ++i) e->Pa[i + (long)(o + j) * Na] = 0.0;
  e->clone_on[s] = 0;
}

/* x, P <- the state block of xa, Pa (CloningEstimator._sync) */
static void sync_clone(amsfe_est *e) {
  int N = e->d.N, Na = (1 + e->S) * N;
  copy(e->x, e->xa, N);
  for (int j = 0; j < N; ++j) copy(e->P + (long)j * N, e->Pa + (long)j * Na, N);
  e->lp_ok = 0;
}

/* require_positive_definite: Cholesky succeeds */
static int pd(amsfe_est *e, const double *P) { return amsfe_cholesky(e->d.N, P, e->L1); }

/* the same check on P itself, keeping its factor for the next prediction (eq. 14) */
static int pd_state(amsfe_est *e) { return e->lp_ok = amsfe_cholesky(e->d.N, e->P, e->LP); }

/* block (o, o) of the augmented covariance into P1, then the PD check */
static int clone_block_pd(amsfe_est *e, int s) {
  int N = e->d.N, Na = (1 + e->S) * N, o = N * (1 + s);
  for (int j = 0; j < N; ++j) copy(e->P1 + (long)j * N, e->Pa + o + (long)(o + j) * Na, N);
  return pd(e, e->P1);
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
EFFORT_PATH static int camera_h(amsfe_est *e, const double *x) {
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
static int frame_now(amsfe_est *e, const double *z, double *nis) {
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
static void replay_store(amsfe_est *e, long j) {
  long N = e->d.N, s = pmod(j, e->R);
  copy(e->r_x + s * N, e->x, N);
  copy(e->r_P + s * N * N, e->P, N * N);
}

/* ReplayEstimator._step's loop body for j -> j + 1 (report: j + 1 is the current step) */
static int replay_step(amsfe_est *e, long j, int report) {
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

/* ------------------------------------------------------------------ late frames */
/* oosm.backward_inverse (eqs. 22, 24): xr <- x_j = F^-1(x_{j+1}, u_j) for j = k-1 .. kappa
 * from x_{k} = xs, each step refused unless its residual converged (CompiledTransition.
 * inverse); Phi <- A(x_{k-1}) ... A(x_kappa), the backward map's jacobian being Phi^-1. */
static int oosm_backward_inverse(amsfe_est *e, long kappa) {
  long N = e->d.N, NN = N * N;
  cint n_out = transition_inverse_n_out();
  copy(e->xr, e->xs, N);
  memset(e->Phi, 0, sizeof(double) * (size_t)NN);
  for (long i = 0; i < N; ++i) e->Phi[i * (N + 1)] = 1.0;
  for (long j = e->k - 1; j >= kappa; --j) {
    const double *uj = e->u_buf + pmod(j, e->B) * e->d.n;
    double residual = NAN, scale = 1.0;
    for (long i = 0; i < N; ++i) scale = fmax(scale, fabs(e->xr[i])); /* max(1, |x_next|) */
    for (cint i = 2; i < n_out; ++i) e->g.res[i] = NULL;
    const double *ii[2] = {e->xr, uj};
    double *io[2] = {e->sv, &residual};
    gcall(&e->g, transition_inverse, ii, 2, io, 2);
    if (!(residual <= e->inv_tol * scale)) { /* NaN too */
      e->inv_residual = residual, e->inv_limit = e->inv_tol * scale;
      return AMSFE_REFUSED_NO_CONVERGENCE;
    }
    const double *si[2] = {e->sv, uj};
    double *so[3] = {NULL, e->A1, NULL};
    gcall(&e->g, STEP, si, 2, so, 3); /* A(x_j) */
    amsfe_matmul((int)N, e->Phi, e->A1, e->Phi2);
    copy(e->Phi, e->Phi2, NN);
    copy(e->xr, e->sv, N);
  }
  return AMSFE_OK;
}

/* oosm.a1_retrodict with the last update's joint-torque H (its nonzeros last_hval):
 * Q H^T, P_prior H^T and S = sym(H P_prior H^T) + R, then the kernel */
EFFORT_PATH static int retrodict_torque(amsfe_est *e) {
  int M = e->d.N, m = e->d.ne;
  double *QHt = e->RH, *PHt = QHt + (long)M * m, *S = PHt + (long)M * m, *T = S + m * m;
  for (int a = 0; a < m; ++a) {
    double *qa = QHt + (long)a * M, *pa = PHt + (long)a * M;
    for (int i = 0; i < M; ++i) qa[i] = pa[i] = 0.0;
    for (int v = e->ehrow[a]; v < e->ehrow[a + 1]; ++v) {
      const double *qc = e->Q + (long)e->ehcol[v] * M, *pc = e->last_Pprior + (long)e->ehcol[v] * M;
      double h = e->last_hval[v];
      for (int i = 0; i < M; ++i) qa[i] += qc[i] * h, pa[i] += pc[i] * h;
    }
  }
  for (int b = 0; b < m; ++b)
    for (int a = 0; a < m; ++a) {
      double t = 0.0;
      for (int v = e->ehrow[a]; v < e->ehrow[a + 1]; ++v)
        t += e->last_hval[v] * PHt[e->ehcol[v] + (long)b * M];
      T[a + b * m] = t;
    }
  for (int b = 0; b < m; ++b)
    for (int a = 0; a < m; ++a)
      S[a + b * m] = 0.5 * (T[a + b * m] + T[b + a * m]) + (a == b ? e->re[a] : 0.0);
  return amsfe_a1_retrodict_cols(M, m, S, QHt, PHt, e->x, e->P, e->Q, e->last_nu, e->xs, e->M,
                                 e->C, e->RW);
}

/* oosm.a1_correct on a state with input states (est_oosm_correct is the model's N): G = Hc
 * Phi^-1 at x_r = xr, Szz = sym(G M G^T) + R, W = C G^T Szz^-1, P+ = sym(P - W (C G^T)^T) */
EFFORT_PATH static int oosm_correct_inputs(amsfe_est *e, const double *z, double *nis) {
  long M = e->d.N;
  int n = e->d.n;
  double *G = e->OW, *GM = G + 2 * M, *Pxz = GM + 2 * M, *W = Pxz + 2 * M;
  /* scratch: Phi2 (Phi^T), A1 (P - W Pxz^T; oosm's predictions keep theirs in A_buf) */
  double Szz[4], Ls[4], nu[2], sn[2];
  if (!camera_h(e, e->xr)) return AMSFE_ERR_NONFINITE;
  for (int r = 0; r < 2; ++r) { /* row r of G: Phi^T g = Hc[r, :]^T */
    double *g = G + r * M;
    for (long i = 0; i < M; ++i) g[i] = 0.0;
    for (int j = 0; j < n; ++j) g[e->chcol[r * n + j]] = e->chval[r * n + j];
    for (long j = 0; j < M; ++j)
      for (long i = 0; i < M; ++i) e->Phi2[i + j * M] = e->Phi[j + i * M];
    if (!amsfe_lu_solve((int)M, e->Phi2, g)) return AMSFE_ERR_NONFINITE;
  }
  if (!all_finite(G, 2 * M)) return AMSFE_ERR_NONFINITE;
  for (int r = 0; r < 2; ++r) /* G M and C G^T (M, C: M x M) */
    for (long i = 0; i < M; ++i) {
      double gm = 0.0, pz = 0.0;
      for (long l = 0; l < M; ++l) {
        gm += G[r * M + l] * e->M[l + i * M];
        pz += e->C[i + l * M] * G[r * M + l];
      }
      GM[r * M + i] = gm, Pxz[i + r * M] = pz;
    }
  double T[4];
  for (int a = 0; a < 2; ++a)
    for (int b = 0; b < 2; ++b) {
      double t = 0.0;
      for (long i = 0; i < M; ++i) t += GM[a * M + i] * G[b * M + i];
      T[a + 2 * b] = t;
    }
  for (int a = 0; a < 2; ++a)
    for (int b = 0; b < 2; ++b)
      Szz[a + 2 * b] = 0.5 * (T[a + 2 * b] + T[b + 2 * a]) + (a == b ? e->rc[a] : 0.0);
  if (!amsfe_cholesky(2, Szz, Ls)) return AMSFE_REFUSED_INDEFINITE;
  for (int r = 0; r < 2; ++r) nu[r] = z[r] - e->cy[r], sn[r] = nu[r];
  amsfe_chol_solve(2, Ls, sn);
  e->nis = nu[0] * sn[0] + nu[1] * sn[1];
  if (nis) *nis = e->nis;
  if (!(e->nis <= e->par.gate_camera)) return AMSFE_GATED;
  for (long i = 0; i < M; ++i) { /* row i of W = Pxz Szz^-1 */
    double w2[2] = {Pxz[i], Pxz[i + M]};
    amsfe_chol_solve(2, Ls, w2);
    W[i] = w2[0], W[i + M] = w2[1];
  }
  for (long j = 0; j < M; ++j)
    for (long i = 0; i < M; ++i)
      e->A1[i + j * M] = e->P[i + j * M] - (W[i] * Pxz[j] + W[i + M] * Pxz[j + M]);
  for (long j = 0; j < M; ++j)
    for (long i = 0; i < M; ++i)
      e->P1[i + j * M] = 0.5 * (e->A1[i + j * M] + e->A1[j + i * M]);
  if (!amsfe_cholesky((int)M, e->P1, e->L1)) return AMSFE_REFUSED_INDEFINITE; /* P(k|kappa+) */
  for (long i = 0; i < M; ++i) e->x[i] += W[i] * nu[0] + W[i + M] * nu[1];
  swap_P(e, &e->P1);
  return AMSFE_OK;
}

/* OosmEstimator._late_frame (A1 over the lag) */
static int oosm_late(amsfe_est *e, const double *z, long kappa, double *nis) {
  long N = e->d.N, NN = N * N, k = e->k;
  memset(e->Phi, 0, sizeof(double) * (size_t)NN);
  memset(e->Q, 0, sizeof(double) * (size_t)NN);
  memset(e->sv, 0, sizeof(double) * (size_t)N);
  for (long i = 0; i < N; ++i) e->Phi[i * (N + 1)] = 1.0;
  for (long j = kappa; j < k; ++j) { /* eq. (23) */
    long s = pmod(j, e->B);
    const double *Aj = e->A_buf + s * NN;
    amsfe_matmul((int)N, Aj, e->Phi, e->Phi2);
    amsfe_sandwich((int)N, e->d.nw, Aj, e->Q, e->G_buf + s * N * e->d.nw, e->qw, e->Qb, e->T1);
    copy(e->Phi, e->Phi2, NN);
    copy(e->Q, e->Qb, NN);
    /* the updates' corrections carried to k (oosm.backward_map): s <- A_j s + c_{j+1} */
    for (long i = 0; i < N; ++i) e->xr[i] = 0.0;
    for (long m = 0; m < N; ++m) {
      double c = e->sv[m];
      for (long i = 0; i < N; ++i) e->xr[i] += Aj[i + m * N] * c;
    }
    if (j + 1 < k) {
      const double *post = e->xpost_buf + pmod(j + 1, e->B) * N, *prior = e->xprior_buf + s * N;
      for (long i = 0; i < N; ++i) e->xr[i] += post[i] - prior[i];
    }
    copy(e->sv, e->xr, N);
  }
  if (e->has_last > 0.5 && e->jt) { /* the same with the joint torques' H */
    if (!retrodict_torque(e)) return AMSFE_ERR_S_NOT_PD;
  } else if (e->has_last > 0.5) { /* oosm.a1_retrodict (eqs. 24-27 corrected) */
    if (!amsfe_a1_retrodict((int)N, e->d.ne, e->enc_rows, e->re, e->x, e->P, e->Q, e->last_nu,
                            e->last_Pprior, e->xs, e->M, e->C, e->RW))
      return AMSFE_ERR_S_NOT_PD;
  } else { /* no encoder update at k: x_shift = x, M = C = P - Q */
    copy(e->xs, e->x, N);
    for (long i = 0; i < NN; ++i) e->M[i] = e->C[i] = e->P[i] - e->Q[i];
  }
  if (e->par.backward_map == AMSFE_BACKWARD_INVERSE) {
    int st = oosm_backward_inverse(e, kappa);
    if (st != AMSFE_OK) return st;
  } else { /* eq. (24): x(kappa|k) = F_{kappa,k}(x_shift) linearised about the stored
              * trajectory: x(kappa|kappa) + Phi^-1 (s + x_shift - x(k|k-1)) (oosm.backward_map) */
    const double *prior_k = e->xprior_buf + pmod(k - 1, e->B) * N;
    for (long i = 0; i < N; ++i) e->xr[i] = e->sv[i] + (e->xs[i] - prior_k[i]);
    copy(e->Phi2, e->Phi, NN);
    if (!amsfe_lu_solve((int)N, e->Phi2, e->xr)) return AMSFE_ERR_NONFINITE;
    const double *post_kappa = e->xpost_buf + pmod(kappa, e->B) * N;
    for (long i = 0; i < N; ++i) e->xr[i] += post_kappa[i];
  }
  if (!all_finite(e->xr, N)) return AMSFE_ERR_NONFINITE;
  if (e->ni) return oosm_correct_inputs(e, z, nis);
  const double *in[8] = {e->x, e->P, e->xr, e->M, e->C, e->Phi, z, e->rc};
  double *out[5] = {e->x1, e->P1, &e->nis, &e->s_ok, &e->chk};
  gcall(&e->g, est_oosm_correct, in, 8, out, 5);
  if (!isfinite(e->chk)) return AMSFE_ERR_NONFINITE;
  if (!(e->s_ok > 0.5)) return AMSFE_REFUSED_INDEFINITE;
  if (nis) *nis = e->nis;
  if (!(e->nis <= e->par.gate_camera)) return AMSFE_GATED;
  if (!amsfe_cholesky((int)N, e->P1, e->L1)) return AMSFE_REFUSED_INDEFINITE; /* P(k|kappa+) */
  copy(e->x, e->x1, N);
  swap_P(e, &e->P1);
  return AMSFE_OK;
}

/* ReplayEstimator: rewind to kappa, apply the frame there, re-filter up to now */
static int replay_frame(amsfe_est *e, const double *z, long kappa, double *nis) {
  long N = e->d.N, s = pmod(kappa, e->R), k = e->k;
  if (e->r_nf[s] >= e->F) return AMSFE_REFUSED_FULL;
  if (kappa < k) {
    copy(e->x, e->r_x + s * N, N);
    set_P(e, e->r_P + s * N * N);
  }
  int st = frame_now(e, z, nis);
  if (st < 0) return st;
  copy(e->r_fz + (s * e->F + e->r_nf[s]) * e->d.nc, z, e->d.nc);
  ++e->r_nf[s];
  replay_store(e, kappa);
  for (long j = kappa; j < k; ++j) {
    int st2 = replay_step(e, j, j + 1 == k);
    if (st2) return st2;
  }
  e->diag.replayed_steps = (int)(k - kappa);
  return st;
}

/* CloningEstimator: update through the clone of kappa, then drop it */
static int cloning_frame(amsfe_est *e, const double *z, long kappa, double *nis) {
  int N = e->d.N, S = e->S, Na = (1 + S) * N, slot = -1;
  for (int s = 0; s < S; ++s)
    if (e->clone_on[s] && e->clone_k[s] == kappa) slot = s;
  if (slot < 0) return scheduled(e, kappa) ? AMSFE_REFUSED_NO_CLONE_LEFT : AMSFE_REFUSED_NO_CLONE;
  if (e->ni) { /* the generated update is the model's N: the clone's padded H, in C */
    int n = e->d.n, o = N * (1 + slot);
    if (!camera_h(e, e->xa + o)) return AMSFE_ERR_NONFINITE;
    for (int r = 0; r < 2; ++r) {
      e->cnu[r] = z[r] - e->cy[r];
      for (int j = 0; j < n; ++j) e->ccol[r * n + j] = o + j; /* the clone's q */
    }
    if (!amsfe_joseph_rows(Na, 2, e->chrow, e->ccol, e->chval, e->rc, e->xa, e->Pa, e->cnu,
                           e->xa2, e->Pa2, &e->nis, e->JW))
      return AMSFE_ERR_S_NOT_PD;
  } else {
    for (int s = 0; s < S; ++s) e->sel[s] = s == slot ? 1.0 : 0.0;
    copy(e->cl, e->xa + N * (1 + slot), N);
    const double *in[6] = {e->xa, e->Pa, e->cl, e->sel, z, e->rc};
    double *out[5] = {e->xa2, e->Pa2, &e->nis, &e->s_ok, &e->chk};
    gcall(&e->g, est_clone_camera, in, 6, out, 5);
    if (!isfinite(e->chk)) return AMSFE_ERR_NONFINITE;
    if (!(e->s_ok > 0.5)) return AMSFE_ERR_S_NOT_PD;
  }
  if (nis) *nis = e->nis;
  int st = e->nis <= e->par.gate_camera ? AMSFE_OK : AMSFE_GATED;
  if (st == AMSFE_OK) {
    copy(e->xa, e->xa2, Na);
    copy(e->Pa, e->Pa2, (long)Na * Na);
  }
  drop_clone(e, slot);
  sync_clone(e);
  int alive = 0;
  for (int s = 0; s < S; ++s) alive += e->clone_on[s] && e->k - e->clone_k[s] < e->max_delay;
  e->diag.clones = alive;
  return st;
}

int amsfe_est_camera_frame(amsfe_est *e, const double *z, long kappa, double *nis) {
  if (nis) *nis = NAN;
  if (!e || !z) return AMSFE_ERR_INPUT;
  if (e->failed) return AMSFE_ERR_FAILED;
  if (kappa > e->k) return AMSFE_REFUSED_FUTURE; /* the reference raises; nothing changed */
  int st;
  long oldest = e->k - e->B > e->par.k0 ? e->k - e->B : e->par.k0;
  e->diag.replayed_steps = 0;
  if (e->par.estimator == AMSFE_ENCODERS) st = AMSFE_IGNORED;
  else if (!all_finite(z, e->d.nc)) st = AMSFE_REFUSED_NONFINITE;
  else if (kappa < oldest) st = AMSFE_REFUSED_TOO_OLD;
  else if (e->seen[pmod(kappa, e->B + 1)] == kappa) st = AMSFE_REFUSED_DUPLICATE;
  else {
    switch (e->par.estimator) {
      case AMSFE_NAIVE: st = frame_now(e, z, nis); break;
      case AMSFE_OOSM:
        st = kappa == e->k ? frame_now(e, z, nis) : oosm_late(e, z, kappa, nis);
        break;
      case AMSFE_REPLAY:
        st = replay_frame(e, z, kappa, nis);
        break;
      default: st = cloning_frame(e, z, kappa, nis);
    }
    if (st < 0) return fail(e, st);
    if (!pd_state(e)) return fail(e, AMSFE_ERR_NOT_PD);
  }
  if (st == AMSFE_OK || st == AMSFE_GATED) e->seen[pmod(kappa, e->B + 1)] = kappa;
  if (st == AMSFE_OK) ++e->diag.frames_applied;
  else if (st == AMSFE_GATED) ++e->diag.frames_gated;
  else if (st == AMSFE_IGNORED) ++e->diag.frames_ignored;
  else ++e->diag.frames_refused;
  return st;
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

/* ------------------------------------------------------------------ a whole log */
/* NEES of the robot's Nm states against a truth row [Nm] (input states left out: their
 * marginal covariance P[:Nm, :Nm]); scratch A1, L1, x1, x2 (free between ticks) */
EFFORT_PATH static void nees_inputs(amsfe_est *e, const amsfe_est_log *log, long k,
                                    amsfe_est_log_out *out) {
  long M = e->d.N, N = e->Nm;
  const double *t = log->truth ? log->truth + k * N : NULL;
  if (!t || !all_finite(t, N)) return;
  for (long j = 0; j < N; ++j) copy(e->A1 + j * N, e->P + j * M, N);
  if (!amsfe_cholesky((int)N, e->A1, e->L1)) return;
  double *err = e->x1, *w = e->x2, acc = 0.0;
  for (long i = 0; i < N; ++i) err[i] = t[i] - e->x[i], w[i] = err[i];
  amsfe_chol_solve((int)N, e->L1, w);
  for (long i = 0; i < N; ++i) acc += err[i] * w[i];
  out->nees[k] = acc;
}

static void record_row(amsfe_est *e, const amsfe_est_log *log, long k, amsfe_est_log_out *out) {
  long N = e->d.N;
  copy(out->x_hat + k * N, e->x, N);
  for (long i = 0; i < N; ++i) out->P_diag[k * N + i] = e->P[i + i * N];
  if (!out->nees) return;
  out->nees[k] = NAN;
  if (e->ni) { /* the truth is the robot's state: NEES of P's N x N block */
    nees_inputs(e, log, k, out);
    return;
  }
  const double *t = log->truth ? log->truth + k * N : NULL;
  const double *L = t && all_finite(t, N) ? amsfe_est_factor(e) : NULL;
  if (!L) return;
  double *err = e->x1, *w = e->x2; /* scratch: both are written before they are read */
  for (long i = 0; i < N; ++i) err[i] = t[i] - e->x[i], w[i] = err[i];
  amsfe_chol_solve((int)N, L, w);
  double acc = 0.0;
  for (long i = 0; i < N; ++i) acc += err[i] * w[i];
  out->nees[k] = acc;
}

/* Estimator._screen_frames, then one amsfe_est_camera_frame per usable frame in increasing
 * exposure step; frames [first, last) arrive at the current step. */
#define FRAME_PENDING (-1000) /* screened as usable, not yet given to the estimator */
static int run_frames(amsfe_est *e, const amsfe_est_log *log, long first, long last,
                      amsfe_est_log_out *out) {
  long k = e->k, oldest = k - e->B > e->par.k0 ? k - e->B : e->par.k0, pending = 0;
  for (long f = first; f < last; ++f) {
    long kappa = log->frame_exposure[f];
    int st = FRAME_PENDING;
    out->frame_nis[f] = NAN;
    if (e->par.estimator == AMSFE_ENCODERS) st = AMSFE_IGNORED;
    else if (!all_finite(log->frame_z + 2 * f, 2)) st = AMSFE_REFUSED_NONFINITE;
    else if (kappa >= oldest && e->seen[pmod(kappa, e->B + 1)] == kappa)
      st = AMSFE_REFUSED_DUPLICATE;
    else if (kappa < oldest) st = AMSFE_REFUSED_TOO_OLD;
    else
      for (long g = first; g < f; ++g)
        if (out->frame_status[g] == FRAME_PENDING && log->frame_exposure[g] == kappa)
          st = AMSFE_REFUSED_DUPLICATE;
    pending += st == FRAME_PENDING;
    out->frame_status[f] = st;
  }
  for (; pending > 0; --pending) {
    long best = -1;
    for (long f = first; f < last; ++f)
      if (out->frame_status[f] == FRAME_PENDING &&
          (best < 0 || log->frame_exposure[f] < log->frame_exposure[best]))
        best = f;
    double nis = NAN;
    int st = amsfe_est_camera_frame(e, log->frame_z + 2 * best, log->frame_exposure[best], &nis);
    if (st < 0) return st;
    out->frame_status[best] = st;
    out->frame_nis[best] = st == AMSFE_OK || st == AMSFE_GATED ? nis : NAN;
  }
  return AMSFE_OK;
}

int amsfe_est_run(amsfe_est *e, const amsfe_est_log *log, long k_begin, long k_end,
                  amsfe_est_log_out *out) {
  if (!e || !log || !out || !log->u || !log->z || !out->x_hat || !out->P_diag ||
      !out->encoder_nis || !out->encoder_accepted || k_begin < 0 || k_end > log->K ||
      (log->n_frames > 0 && (!log->frame_exposure || !log->frame_arrival || !log->frame_z ||
                             !out->frame_nis || !out->frame_status)))
    return AMSFE_ERR_INPUT;
  long n = e->d.n, ne = e->d.ne;
  out->failed_step = -1;
  long lo = 0, hi = log->n_frames; /* the first frame arriving at or after k_begin */
  while (lo < hi) {
    long mid = lo + (hi - lo) / 2;
    if (log->frame_arrival[mid] < k_begin) lo = mid + 1;
    else hi = mid;
  }
  long f = lo;
  for (long k = k_begin; k < k_end; ++k) {
    long first = f;
    while (f < log->n_frames && log->frame_arrival[f] == k) ++f;
    if (k == 0) {
      out->encoder_nis[0] = NAN, out->encoder_accepted[0] = 0;
      record_row(e, log, 0, out);
      continue;
    }
    int st = amsfe_est_tick(e, log->z + k * ne, log->u + (k - 1) * n);
    if (st >= 0) st = run_frames(e, log, first, f, out);
    if (st < 0) {
      out->failed_step = k;
      return st;
    }
    /* after the frames: replay re-runs the current step's encoder update */
    out->encoder_nis[k] = e->diag.encoder_nis;
    out->encoder_accepted[k] = (unsigned char)e->diag.encoder_accepted;
    record_row(e, log, k, out);
  }
  return AMSFE_OK;
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
