/* amsfe_est_internal.h: what the files of the compiled estimator share inside a generated
 * library (amsfe_runtime.c: its memory and life cycle; amsfe_est_tick.c: the EKF steps, the
 * replay ring and the tick; amsfe_est_late.c: the late frames; amsfe_est_run.c: a whole
 * log).  Not part of the public API (not copied next to the library): the estimator's
 * object, the generated functions it calls, the small helpers every file uses (static
 * inline), and the functions one file defines for another (hidden from the exports).  It
 * includes the robot's amsfe_model_config.h: every file including it is a robot's unit. */
#ifndef AMSFE_EST_INTERNAL_H
#define AMSFE_EST_INTERNAL_H

#include <math.h>
#include <string.h>

#include "amsfe_internal.h"
#include "amsfe_runtime.h"

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
static inline long pmod(long a, long b) { return ((a % b) + b) % b; }

static inline void copy(double *dst, const double *src, long count) {
  memcpy(dst, src, sizeof(double) * (size_t)count);
}

static inline int fail(amsfe_est *e, int status) {
  e->failed = 1;
  e->last_error = status;
  return status;
}

/* P <- src; the Cholesky factor LP of P is stale until the next pd_state. */
static inline void set_P(amsfe_est *e, const double *src) {
  copy(e->P, src, (long)e->d.N * e->d.N);
  e->lp_ok = 0;
}

/* P <- *scratch by exchanging the two N x N buffers (*scratch then holds the old P). */
static inline void swap_P(amsfe_est *e, double **scratch) {
  double *t = e->P;
  e->P = *scratch, *scratch = t;
  e->lp_ok = 0;
}

static inline int scheduled(const amsfe_est *e, long k) {
  int l = e->par.camera_period;
  return l > 0 && pmod(k, l) == e->par.camera_phase;
}

static inline void drop_clone(amsfe_est *e, int s) {
  int N = e->d.N, Na = (1 + e->S) * N, o = N * (1 + s);
  for (int i = 0; i < N; ++i) e->xa[o + i] = 0.0;
  for (int j = 0; j < Na; ++j)
    for (int i = 0; i < N; ++i) e->Pa[(o + i) + (long)j * Na] = 0.0;
  for (int j = 0; j < N; ++j)
    for (int i = 0; i < Na; ++i) e->Pa[i + (long)(o + j) * Na] = 0.0;
  e->clone_on[s] = 0;
}

/* x, P <- the state block of xa, Pa (CloningEstimator._sync) */
static inline void sync_clone(amsfe_est *e) {
  int N = e->d.N, Na = (1 + e->S) * N;
  copy(e->x, e->xa, N);
  for (int j = 0; j < N; ++j) copy(e->P + (long)j * N, e->Pa + (long)j * Na, N);
  e->lp_ok = 0;
}

/* require_positive_definite: Cholesky succeeds */
static inline int pd(amsfe_est *e, const double *P) { return amsfe_cholesky(e->d.N, P, e->L1); }

/* the same check on P itself, keeping its factor for the next prediction (eq. 14) */
static inline int pd_state(amsfe_est *e) {
  return e->lp_ok = amsfe_cholesky(e->d.N, e->P, e->LP);
}

/* cloning.CloningEstimator._add_clone (amsfe_runtime.c, used by amsfe_est_tick.c too) */
AMSFE_HIDDEN void add_clone(amsfe_est *e, long kappa);
/* Defined in amsfe_est_tick.c, used by amsfe_est_late.c too. */
/* CameraMeasurement.predict for a state with input states (see its definition) */
AMSFE_HIDDEN int camera_h(amsfe_est *e, const double *x);
/* Estimator._frame_update_now: iterated EKF camera update of (x, P) */
AMSFE_HIDDEN int frame_now(amsfe_est *e, const double *z, double *nis);
/* the replay ring: store step j's (x, P); re-run step j from the ring */
AMSFE_HIDDEN void replay_store(amsfe_est *e, long j);
AMSFE_HIDDEN int replay_step(amsfe_est *e, long j, int report);

#endif /* AMSFE_EST_INTERNAL_H */
