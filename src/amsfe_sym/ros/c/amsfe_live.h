/* amsfe_live.h: what amsfe_node computes per message, without any middleware: the C twin of
 * amsfe_sym/ros/live.py's LiveLoop for an effort topic of kind "applied" (docs/how-to/ros.md, "How
 * the node reads its inputs"), over the library's estimator and controller (amsfe_runtime.h,
 * amsfe_loop.h).
 *
 * Each encoder sample is placed on the tick grid by its header stamp (k = round((stamp -
 * stamp_0) / T), the first sample is tick 0 and makes x(0|0)); at k > 0 the estimator goes
 * k-1 -> k with the torque applied over [t_k-1, t_k] (the effort topic's of tick k-1, else
 * the command of k-1, else the previous torque), the sample, and the camera frames sent
 * before the sample (their DDS source timestamps) in increasing exposure step; then the
 * controller (amsfe_ctrl_observe_nis, amsfe_ctrl_observe, amsfe_ctrl_torque: what
 * amsfe_loop_tick runs, so a lockstep run is amsfe_sim_run's tick for tick).  Up to
 * max_gap_steps missing samples are predicted through.  Everything skipped is counted with
 * the Python reference's reasons.  All memory is allocated by live_init; nothing after. */
#ifndef AMSFE_LIVE_H
#define AMSFE_LIVE_H

#include "amsfe_loop.h"

#define LIVE_MAX_FRAMES 64  /* frames pending at once (a camera at 1/10 of the rate: 6 s) */
#define LIVE_RING 4096      /* ticks kept of efforts, commands and exposures seen */

/* Why a message was skipped (the Python reference's words: live.py, logs/read.py). */
enum live_skip {
  SKIP_FRAME_BEFORE_FIRST = 0,
  SKIP_FRAME_OFF_GRID,
  SKIP_FRAME_NONFINITE,
  SKIP_FRAME_DUPLICATE,
  SKIP_TORQUE_OFF_GRID,
  SKIP_TORQUE_NOT_FINITE,
  SKIP_TORQUE_LATE,
  SKIP_TORQUE_HELD,
  SKIP_ENCODER_OFF_GRID,
  SKIP_ENCODER_DUPLICATE,
  SKIP_ENCODER_MISSING,
  SKIP_FRAMES_OVERFLOW,
  SKIP_ENCODER_ZERO_STAMP, /* the live stamp rules (LiveLoop._bad_stamp) */
  SKIP_ENCODER_STEP_BACK,
  SKIP_ENCODER_AHEAD,
  SKIP_REASONS
};
extern const char *const LIVE_SKIP_TEXT[SKIP_REASONS];

/* The estimator's decisions (sim/result.py's DECISION_COUNTERS): the compiled loop's
 * counters, the frames' and encoder_rejected (the rest stay 0). */
typedef amsfe_sim_state live_counters;

typedef struct {
  long kappa;
  double z[2];
  long long sent, exposure_ns;
} live_frame;

typedef struct {
  /* ---- configuration (set before live_init) */
  int n, N, controller, x0_from_encoders;
  long long T_ns;
  double tol;            /* grid tolerance [T] */
  int max_gap;           /* missing samples predicted through */
  long exposure_shift;   /* the camera's time offset in ticks ([camera] time_offset): a frame
                            stamped at tick k was exposed at tick k - exposure_shift */
  amsfe_params ep;       /* the estimator's block (x0's motor part from the first sample) */
  double inverse_tol;    /* amsfe_est_set_inverse_tolerance (oosm's inverse backward map) */
  amsfe_ctrl_params cp;  /* the controller's block */
  const double *ref;     /* [K_ref x 5n] reference per tick */
  long K_ref;
  /* ---- state */
  amsfe_est *est;
  amsfe_ctrl *ctrl;
  void *est_mem, *ctrl_mem;
  size_t est_size, ctrl_size;
  double *x0;            /* [N] the block's x0, its motor part filled at the first sample */
  long k;                /* the current tick (-1: no sample yet) */
  long long t0_ns, sent0, sent;
  int have_sent0;
  long long last_sent;         /* the last used sample's send time (0: unknown) */
  int bad_run;                 /* encoder samples with a bad stamp in a row */
  int bad_why;                 /* the last one's reason (a SKIP_ENCODER_* of a stamp) */
  double bad_size;             /* its distance from the last used stamp [s] (0: none) */
  live_frame pending[LIVE_MAX_FRAMES], early[LIVE_MAX_FRAMES], due_info[LIVE_MAX_FRAMES];
  int n_pending, n_early;
  long seen[LIVE_RING];        /* exposures seen, by kappa % LIVE_RING (-1: none) */
  long eff_j[LIVE_RING], cmd_j[LIVE_RING]; /* the tick of each stored torque (-1: none) */
  double *eff_u, *cmd_u;       /* [LIVE_RING x n] */
  long long *early_eff_ns;     /* [LIVE_RING] efforts before the first sample, a ring */
  double *early_eff_u;
  long n_early_eff;            /* received before it (the newest LIVE_RING kept) */
  double *u_in;                /* [n] the torque applied over the last tick */
  double *wd_applied;          /* [n] the newest (by tick) applied torque received since the
                                  last sample, for the watchdog (also one too late for the
                                  estimator); wd_applied_k its tick, -1: none */
  long wd_applied_k;
  amsfe_frame due[LIVE_MAX_FRAMES];
  int due_status[LIVE_MAX_FRAMES];
  double due_nis[LIVE_MAX_FRAMES];
  int n_due;                   /* frames given to the estimator at the last tick */
  /* ---- the last tick's outputs */
  double *x, *P, *P_diag, *u, *ref_hold;
  double encoder_nis;          /* NaN at tick 0 or without a usable sample */
  int encoder_accepted;        /* its update was applied (not gated) */
  int gap;                     /* samples predicted through before it */
  int tick_applied, tick_rejected; /* frames fused / refused at it */
  int status;                  /* the estimator's status (< 0: failed) */
  live_counters c;
  long skipped[SKIP_REASONS];
} live_loop;

/* Allocate and check (0 or the runtime's error status; a message on stderr). */
int live_init(live_loop *L);
long live_tick_of(const live_loop *L, long long stamp_ns, int *ok);
void live_frame_in(live_loop *L, long long exposure_ns, const double z[2], long long sent);
void live_applied(live_loop *L, long long stamp_ns, const double *u);
/* An encoder sample z [2n] sent at `sent` (its DDS source timestamp [ns]; 0: unknown): 1 a
 * tick computed (L->k, x, P_diag, u), 0 skipped (counted), -1 more than max_gap missing (L->gap
 * says how many), LIVE_BAD_STAMPS more than max_gap samples in a row with a bad header stamp
 * (a zero stamp, a clock step back or ahead: live_bad_stamp_line says which), < -100: the
 * estimator's error status - 100 (L->status holds it). */
#define LIVE_BAD_STAMPS (-2)
int live_encoders(live_loop *L, long long stamp_ns, const double *z, long long sent);
/* The message of LIVE_BAD_STAMPS (LiveLoop._bad_stamp's EstimatorError, word for word). */
void live_bad_stamp_line(const live_loop *L, char *out, size_t cap);
/* The reference row of tick k (the last row's angles, at rest, past the end). */
const double *live_ref(const live_loop *L, long k);

#endif /* AMSFE_LIVE_H */
