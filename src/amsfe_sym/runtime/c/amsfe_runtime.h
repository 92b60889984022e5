/* amsfe_runtime.h: the estimators of amsfe_sym as plain C (docs/how-to/runtime-c.md).
 *
 * Compiled into every generated robot library together with the robot's generated
 * functions (transition_step, est_camera_update, ...); a program links only that library and
 * includes this header.  One estimator object holds the posterior x(k|k), P(k|k) and the
 * history its late-frame update needs, all inside one memory block the caller owns; no call
 * after amsfe_est_init allocates.
 *
 * A step of the filter, k -> k+1, is one amsfe_est_tick (predict with u over [k, k+1],
 * paper eqs. 13-14, then the encoder sample taken at k+1, eqs. 15-17), followed by one
 * amsfe_est_camera_frame per camera frame delivered at k+1 (in increasing exposure step, as
 * the Python reference sorts them).  The control law will be appended to the tick (encoder
 * sample in, torque out): see docs/how-to/runtime-c.md.
 *
 * Matrices are dense, column-major (symmetric ones read the same either way).
 */
#ifndef AMSFE_RUNTIME_H
#define AMSFE_RUNTIME_H

#include <stddef.h>

#ifdef __cplusplus
extern "C" {
#endif

/* ---- statuses: >= 0 a decision, < 0 an error (the estimator then refuses to go on until
 * amsfe_est_reset; its state is left as it was before the failing call where possible). */
enum amsfe_status {
  AMSFE_OK = 0,                  /* tick done, or frame applied */
  AMSFE_GATED = 1,               /* frame innovation beyond the chi-square gate: not used */
  AMSFE_REFUSED_NONFINITE = 2,   /* the measurement holds NaN or inf: not used */
  AMSFE_REFUSED_TOO_OLD = 3,     /* exposure older than the history kept (buffer_steps) */
  AMSFE_REFUSED_FUTURE = 4,      /* exposure after the current step: nothing changed */
  AMSFE_REFUSED_INDEFINITE = 5,  /* oosm: A1 gives an indefinite covariance over this lag */
  AMSFE_REFUSED_NO_CLONE = 6,    /* cloning: the exposure was not scheduled (no clone) */
  AMSFE_REFUSED_NO_CLONE_LEFT = 7, /* cloning: its clone was used already or has expired */
  AMSFE_REFUSED_FULL = 8,        /* replay: max_frames_per_step frames stored for that step */
  AMSFE_IGNORED = 9,             /* encoders: frames are not used */
  AMSFE_ERR_INPUT = -1,          /* NULL pointer, or u holds NaN or inf: nothing changed */
  AMSFE_ERR_NOT_PD = -2,         /* P(k|k) (or a clone's block) lost positive definiteness */
  AMSFE_ERR_NONFINITE = -3,      /* the model (transition, inverse, camera) gave NaN or inf */
  AMSFE_ERR_S_NOT_PD = -4,       /* an innovation covariance H P H^T + R is not PD */
  AMSFE_ERR_FAILED = -5,         /* an earlier call failed: call amsfe_est_reset */
  AMSFE_ERR_CONFIG = -6,         /* bad parameter block (see amsfe_est_init) */
  AMSFE_ERR_MEMORY = -7,         /* the memory block is too small or misaligned */
  AMSFE_REFUSED_NO_CONVERGENCE = 10, /* oosm with backward_map AMSFE_BACKWARD_INVERSE: the
                                        inverse transition (eq. 22) did not converge over the
                                        lag (amsfe_est_inverse_residual says by how much) */
  AMSFE_REFUSED_DUPLICATE = 11 /* a frame of an exposure step already used (fused or gated):
                                  measurements are idempotent, a repeated one is not fused twice */
};

/* Default tolerance of the inverse transition's residual (relative to max(1, |x_next|_inf)),
 * the Python reference's CompiledTransition.inverse_tol. */
#define AMSFE_INVERSE_TOL 1e-10

enum amsfe_estimator {
  AMSFE_ENCODERS = 0, /* encoder updates only */
  AMSFE_NAIVE = 1,    /* a late frame used as if taken now */
  AMSFE_OOSM = 2,     /* the paper's A1 over the lag (eqs. 19-27) */
  AMSFE_REPLAY = 3,   /* rewind to the exposure and re-filter (exact, linear-Gaussian) */
  AMSFE_CLONING = 4   /* stochastic cloning at each scheduled exposure (exact) */
};

enum amsfe_backward_map {
  AMSFE_BACKWARD_LINEARISED = 0, /* linearised about the stored forward pass: one LU solve */
  AMSFE_BACKWARD_INVERSE = 1     /* the paper's form: L inverse transitions (eq. 22), the
                                    jacobian at the retrodicted states; a step that does not
                                    converge refuses the frame (AMSFE_REFUSED_NO_CONVERGENCE) */
};

/* Sizes of the library's model: n joints, N = 4n + p states, nw = 2n + p noise inputs,
 * ne = 2n encoder values, clone_slots clones the cloning functions carry. */
typedef struct {
  int n, N, nw, ne, nc, clone_slots;
} amsfe_dims;

/* Parameter block: copied by amsfe_est_init (the arrays need not outlive the call). */
typedef struct {
  int estimator;          /* enum amsfe_estimator */
  int buffer_steps;       /* history kept for late frames [steps] (>= camera delay) */
  int camera_iterations;  /* iterated-EKF steps of a frame applied now (naive, oosm lag 0,
                             replay); 1 = plain EKF */
  int camera_period;      /* l [steps]; 0 = unknown (cloning needs it) */
  int camera_phase;       /* exposures at k % l == phase */
  int camera_max_delay; /* cloning drops a clone this many steps after exposure; -1 =
                             buffer_steps */
  int max_frames_per_step; /* replay: frames stored per step (>= 1) */
  double gate_camera;     /* NIS threshold chi2.ppf(p, 2); INFINITY disables the gate */
  double gate_encoder;    /* the same for encoder samples (INFINITY: not gated) */
  const double *qw;       /* [nw] diagonal of Qw (eq. 3), >= 0 */
  const double *r_encoder; /* [ne] diagonal of the encoder R, > 0 */
  const double *r_camera; /* [2] diagonal of the camera R [px^2], > 0 */
  const double *x0;       /* [N] initial x(k0|k0) */
  const double *P0;       /* [N*N] initial P(k0|k0), symmetric positive definite */
  long k0;                /* step index of x0 */
  int backward_map;       /* oosm's backward map of eq. 24: enum amsfe_backward_map (0, the
                             zero of a memset block, is the linearised one) */
  /* ---- a log without the applied torque (docs/explanation/effort.md; every field 0/NULL: the applied
   * torque, as before).  input_states = n: the unknown input carried as n random-walk states
   * (effort_models.InputStateTransition): the state is [x, u] of M = N + n entries (x0 [M],
   * P0 [M*M]), the transition [F(x, u), u] with jacobian [[A, B], [0, I]], B = (A[:, qmd] +
   * e_qmd) input_gain (the trapezoid rule), qw [nw + n] (the last n: the walk's variance per
   * step, input_rate_std^2 T); the u given to amsfe_est_tick is ignored.  Every estimator
   * (oosm with backward_map linearised only; cloning clones the M states). */
  int input_states;          /* 0 or n */
  const double *input_gain;  /* [n] T / (2 Mm) [s / (kg m^2)] (input_states, net_torque) */
  /* joint_torque = 1: the encoder sample is [qm, qmd, tau_J] (ne = 3n, r_encoder [3n]),
   * tau_J = Ks (qm - q) with Ks[j] = theta[ks_theta[j]] where ks_theta[j] >= 0
   * (effort_models.SpringTorqueMeasurement, its exact jacobian) */
  int joint_torque;
  const double *ks;          /* [n] the spec's Ks [N m/rad] (joint_torque, net_torque) */
  const int *ks_theta;       /* [n] theta index of each joint's stiffness, or -1 */
  /* net_torque = 1 (effort kind none, its input reconstructed): u is the net motor torque
   * u - Ks (qm - q) (effort_models.NetTorqueTransition): the step runs F(x, u + Ks (qm - q)),
   * its jacobian A + B d(Ks (qm - q))/dx with B of input_gain; not with input_states, nor
   * with oosm's inverse backward map (AMSFE_ERR_CONFIG) */
  int net_torque;
} amsfe_params;

/* Counters and the outcome of the last calls. */
typedef struct {
  long k;                  /* step of the current posterior */
  int failed;              /* an error status was returned; 0 after reset */
  int last_error;          /* that status */
  int encoder_accepted;    /* last tick: an encoder update was applied */
  double encoder_nis;      /* last tick: its NIS (NaN when no usable sample) */
  int replayed_steps;      /* replay: steps re-filtered by the last camera_frame */
  int clones;              /* cloning: clones in flight that survive this step */
  long ticks, encoder_updates, encoder_gated, encoder_missing;
  long frames_applied, frames_gated, frames_refused, frames_ignored;
} amsfe_diag;

typedef struct amsfe_est amsfe_est;

/* The library's model sizes. */
void amsfe_dims_get(amsfe_dims *dims);

/* Bytes of the memory block amsfe_est_init needs for these parameters (0: bad parameters). */
size_t amsfe_est_memory_size(const amsfe_params *params);

/* Build an estimator inside `memory` (caller-owned, `size` bytes, 16-byte aligned; it holds
 * the object and every history buffer).  On success *out points into `memory`.  Returns
 * AMSFE_OK, AMSFE_ERR_CONFIG (bad parameter: negative variance, P0 not PD, cloning without a
 * period or with more clones in flight than clone_slots, ...) or AMSFE_ERR_MEMORY. */
int amsfe_est_init(amsfe_est **out, const amsfe_params *params, void *memory, size_t size);

/* Convenience: malloc the block and init (NULL on failure, *status says why). */
amsfe_est *amsfe_est_create(const amsfe_params *params, int *status);
void amsfe_est_destroy(amsfe_est *est);

/* Back to x0, P0, k0 with empty history and zero counters. */
void amsfe_est_reset(amsfe_est *est);

/* One step k -> k+1: predict with u [n] over [k, k+1], then the encoder sample z_encoder
 * [ne] taken at k+1 (NULL: none; NaN/inf: not used, counted as missing). */
int amsfe_est_tick(amsfe_est *est, const double *z_encoder, const double *u);

/* A camera frame z [2] exposed at step `exposure_step` (<= the current step), delivered now.
 * *nis (may be NULL) receives its NIS, or NaN when it did not reach the update. */
int amsfe_est_camera_frame(amsfe_est *est, const double *z, long exposure_step, double *nis);

/* Copy out x(k|k) [M] and P(k|k) [M*M] (either may be NULL; M = N + input_states). */
void amsfe_est_state(const amsfe_est *est, double *x, double *P);
void amsfe_est_diagnostics(const amsfe_est *est, amsfe_diag *diag);

/* Tolerance of the inverse transition's convergence check (AMSFE_REFUSED_NO_CONVERGENCE):
 * a step of oosm's backward map with AMSFE_BACKWARD_INVERSE is refused unless its residual
 * max|F(x, u) - x_next| <= tol max(1, max|x_next|).  Returns AMSFE_OK, or AMSFE_ERR_INPUT
 * (NULL, or tol not > 0). */
int amsfe_est_set_inverse_tolerance(amsfe_est *est, double tol);

/* The residual and limit of the last AMSFE_REFUSED_NO_CONVERGENCE (NaN before the first;
 * either pointer may be NULL). */
void amsfe_est_inverse_residual(const amsfe_est *est, double *residual, double *limit);

/* ---- a whole recorded log in one call (logs/replay.py's batch path; docs/how-to/logs.md, "Speed").
 * Tick k of the log is step k of the estimator's posterior x(k|k) (k0 = 0 for a log read from
 * its first encoder sample). */
typedef struct {
  long K;                     /* ticks t_0 .. t_{K-1} */
  const double *u;            /* [K x n] u(k) applied over [k, k+1] [N m] (row K-1 unused) */
  const double *z;            /* [K x ne] encoder sample at k; a row holding NaN: none (a gap);
                                 ne = 3n with joint_torque */
  const double *truth;        /* [K x N] true state (NEES), or NULL; a row holding NaN: none */
  long n_frames;              /* camera frames, sorted by arrival tick (non-decreasing) */
  const long *frame_exposure; /* [n_frames] exposure step kappa */
  const long *frame_arrival;  /* [n_frames] tick at which the frame is delivered (>= kappa) */
  const double *frame_z;      /* [n_frames x 2] pixel [px] */
} amsfe_est_log;

/* Where amsfe_est_run writes (row-major, one row per tick; nees may be NULL). */
typedef struct {
  double *x_hat, *P_diag;          /* [K x M] x(k|k) and the diagonal of P(k|k) */
  double *encoder_nis;             /* [K] NIS of the encoder update; NaN where none */
  unsigned char *encoder_accepted; /* [K] the encoder update was applied */
  double *nees;                    /* [K] e^T P^-1 e against truth (NaN where none); with
                                      input states, of the N robot states (P's N x N block) */
  double *frame_nis;               /* [n_frames] NIS of a frame that reached its update, NaN */
  int *frame_status;               /* [n_frames] its status, the screening's included */
  long failed_step;                /* the tick whose call returned an error status, else -1 */
} amsfe_est_log_out;

/* Ticks k_begin <= k < k_end of a log: row 0 records the posterior the estimator holds (call
 * with k_begin = 0 on a fresh or reset estimator), every later tick is one amsfe_est_tick with
 * u(k-1) and z(k), then the frames arriving at k screened as the Python estimators do (a
 * non-finite pixel: AMSFE_REFUSED_NONFINITE; an exposure used already or twice in the tick:
 * AMSFE_REFUSED_DUPLICATE; older than buffer_steps: AMSFE_REFUSED_TOO_OLD) and the others
 * given to amsfe_est_camera_frame in increasing exposure step (frames arriving at tick 0 are
 * not used).  Call it again with the next range to go on (a progress bar).  Returns AMSFE_OK,
 * or the first error status (out->failed_step says where; the rows before it are written). */
int amsfe_est_run(amsfe_est *est, const amsfe_est_log *log, long k_begin, long k_end,
                  amsfe_est_log_out *out);

/* A short English name of a status. */
const char *amsfe_status_string(int status);

#ifdef __cplusplus
}
#endif
#endif /* AMSFE_RUNTIME_H */
