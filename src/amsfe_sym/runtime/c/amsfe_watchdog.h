/* amsfe_watchdog.h: the watchdogs of a live node as plain C (docs/watchdogs.md).
 *
 * The twin of amsfe_sym/ros/watchdog.py (the readable reference): the same checks in the
 * same order with the same arithmetic, so both decide the same hold at the same tick
 * (tests/test_watchdog_c.py).  Robot-independent: no generated function, no middleware, no
 * allocation.  The caller owns the memory (amsfe_watchdog_memory_size, then
 * amsfe_watchdog_init) and calls
 *
 *   amsfe_watchdog_sample  once per encoder sample, after the estimator and the controller
 *                          of its tick ran (or failed), before the command is published;
 *   amsfe_watchdog_idle    when the wait for a sample timed out (no sample to process).
 *
 * Each returns AMSFE_WD_NONE (go on: publish the command) or the reason to hold (> 0):
 * publish the hold command, print amsfe_watchdog_format's line
 * "hold: <name>: <text> (<value> ...)" and exit with the hold code.  A hold is latched: every
 * later call returns the same reason until amsfe_watchdog_reset.
 *
 * Times: stamps are the samples' send times [ns] (see stamp_ns); wall-clock times are one
 * monotonic clock's [s] (CLOCK_MONOTONIC; Python's time.monotonic()).  A bound of INFINITY
 * switches its check off (not encoder_timeout).
 */
#ifndef AMSFE_WATCHDOG_H
#define AMSFE_WATCHDOG_H

#include <stddef.h>

#ifdef __cplusplus
extern "C" {
#endif

/* Why the node holds.  The stable names (amsfe_watchdog_reason_name) are what a hold line
 * prints and what tests match: "tracking", "innovation", "covariance", "deadline",
 * "compute", "encoder_stall", "node_stalled", "nonfinite", "actuation", "lag". */
enum amsfe_watchdog_reason {
  AMSFE_WD_NONE = 0,          /* no hold */
  AMSFE_WD_TRACKING = 1,      /* max_j |q_d - q_hat| > tracking_error after the hand-over */
  AMSFE_WD_INNOVATION = 2,    /* mean normalised NIS over the last innovation_window fused
                                 updates > innovation_nis */
  AMSFE_WD_COVARIANCE = 3,    /* the estimator failed: P lost definiteness or turned
                                 non-finite (status < 0) */
  AMSFE_WD_DEADLINE = 4,      /* more than deadline_misses of the last deadline_window
                                 samples processed later than deadline after their stamp */
  AMSFE_WD_COMPUTE = 5,       /* one tick's computation took longer than compute_budget */
  AMSFE_WD_ENCODER_STALL = 6, /* no encoder sample (the driver silent or gone) */
  AMSFE_WD_NODE_STALLED = 7,  /* the node itself was not scheduled (its own wall-clock gap) */
  AMSFE_WD_NONFINITE = 8,     /* the estimate or the command holds NaN or inf */
  AMSFE_WD_ACTUATION = 9,     /* the torque the arm reports applying is none of the commands
                                 it may have applied, actuation_ticks judged samples in a row */
  AMSFE_WD_LAG = 10           /* the mean lateness of the queued samples of the last
                                 deadline_window > lag (the node behind on average) */
};
#define AMSFE_WD_REASONS 11

/* Ticks of commands kept for the actuation check (ros/watchdog.py's ACTUATION_RING). */
#define AMSFE_WD_ACTUATION_RING 1024

/* Which cause of a reason (the text differs; the reason name does not). */
enum amsfe_watchdog_cause {
  AMSFE_WD_CAUSE_NONE = 0,
  AMSFE_WD_CAUSE_BEHIND = 1,       /* covariance: prediction over missing samples */
  AMSFE_WD_CAUSE_INCONSISTENT = 2, /* covariance: no sample missing: model / noise */
  AMSFE_WD_CAUSE_SILENT = 3,       /* encoder_stall: the publisher is there, no sample */
  AMSFE_WD_CAUSE_GONE = 4,         /* encoder_stall: no publisher left in the graph */
  AMSFE_WD_CAUSE_GAP = 5,          /* encoder_stall: a sample after more than max_gap_steps
                                      missing, the wall clock as long (the driver paused) */
  AMSFE_WD_CAUSE_LOST = 6,         /* node_stalled: more than max_gap_steps missing, arrived
                                      at once (the queue overflowed while the node lagged) */
  AMSFE_WD_CAUSE_UNSCHEDULED = 7,  /* node_stalled: no call for longer than encoder_timeout */
  AMSFE_WD_CAUSE_ESTIMATE = 8,     /* nonfinite: the estimate x_hat or diag P */
  AMSFE_WD_CAUSE_COMMAND = 9,      /* nonfinite: the command u */
  AMSFE_WD_CAUSE_LATE = 10         /* deadline: actuation, innovation or tracking tripped on
                                      a sample processed past deadline (the node behind) */
};
#define AMSFE_WD_CAUSES 11

/* The bounds: the keys of the topic spec's [watchdog] table, same names and units
 * (docs/watchdogs.md gives each default and how it was measured).  Copied by init. */
typedef struct {
  int n;                    /* joints */
  int N;                    /* states of x_hat and P_diag (4n + p) */
  int ne;                   /* dimension of the encoder innovation (2n; 3n with a joint
                               torque) */
  double T;                 /* tick [s] */
  double tracking_error;    /* [rad]; INFINITY = off */
  double innovation_nis;    /* mean of NIS / dimension [-]; INFINITY = off */
  int innovation_window;    /* fused updates averaged (>= 1) */
  double deadline;          /* [s] lateness of a processed sample (see _sample) */
  int deadline_misses;      /* hold when more than this many of the window are late (>= 0) */
  int deadline_window;      /* samples [ticks] (>= 1); deadline INFINITY = off */
  double compute_budget;    /* [s] one tick's computation; INFINITY = off */
  double encoder_timeout;   /* [s] wall clock without a sample (and without a call) */
  int max_gap_steps;        /* missing samples predicted through; more: stall (>= 0) */
  double actuation_error;   /* [-] max_j |applied_j - command_j| / s_j, s_j = u_max[j] (1 N m
                               where u_max is NULL or not finite > 0); INFINITY = off */
  int actuation_ticks;      /* hold after this many judged mismatches in a row (>= 1) */
  const double *u_max;      /* [n] the actuator limits [N m] (NULL: none); copied by init */
  double lag;               /* [s] largest mean over the last deadline_window samples of the
                               lateness of each queued late sample, at most deadline (0 for
                               the others);
                               INFINITY = off (0 in a config written before it: refused) */
} amsfe_watchdog_config;

/* One encoder sample as processed. */
typedef struct {
  long k;               /* its tick (k = round((stamp - stamp_0) / T)) */
  long gap;             /* samples missing just before it (predicted through, or more than
                           max_gap_steps: then the estimator was not run, x_hat may be NULL) */
  long long stamp_ns;   /* when it was sent [ns]: its DDS source timestamp (the publisher's
                           clock; so a lockstep arm slower than real time is not "late"), or
                           its header stamp when that is unknown; one kind for a whole run */
  double taken;         /* wall clock when it was taken from the queue [s] */
  double done;          /* wall clock when its command was computed [s] */
  int status;           /* the estimator's status of this tick: AMSFE_OK (0) or < 0 */
  const double *x_hat;  /* [N] x(k|k); NULL: none (estimator failed or not run) */
  const double *P_diag; /* [N] diag P(k|k); NULL: none */
  const double *q_des;  /* [n] the desired link angle q_d(t_k); NULL: no controller */
  const double *u;      /* [n] the command computed; NULL: none */
  int handed_over;      /* the start-up handed over (the blend ended): tracking is judged */
  double encoder_nis;   /* NIS of the encoder update of this tick; NaN: none fused */
  const double *frame_nis; /* [n_frames] NIS of the camera frames fused this tick */
  int n_frames;
  const double *applied;   /* [n] the torque the arm reports applying over tick applied_k
                              [N m] (the effort topic of kind "applied": the newest by tick
                              received since the previous sample); NULL: none new, or the
                              effort is of another kind.  Judged (actuation) only with u. */
  long applied_k;          /* its tick (>= 0) */
} amsfe_watchdog_tick;

/* What the watchdog holds for, and what it has seen (the largest value of each monitored
 * quantity since init or reset: how the defaults were measured). */
typedef struct {
  int reason;            /* enum amsfe_watchdog_reason: AMSFE_WD_NONE while running */
  int cause;             /* enum amsfe_watchdog_cause */
  long k;                /* the tick of the hold (the last sample's for _idle) */
  double value, bound;   /* the quantity that tripped and its bound (units of the key) */
  long gap;              /* covariance / stall: samples missing */
  long samples;          /* samples judged */
  double max_tracking;   /* [rad] after the hand-over */
  double max_innovation; /* mean normalised NIS over a full window */
  double max_lateness;   /* [s] */
  int max_late_in_window; /* most late samples in one window */
  double max_compute;    /* [s] */
  double max_wall_gap;   /* [s] between two calls */
  double max_actuation;  /* [-] largest distance of a judged applied torque to its command */
  long actuation_judged; /* applied torques judged */
  int caused;            /* deadline with AMSFE_WD_CAUSE_LATE: the reason that tripped first
                            (what the lateness caused); else AMSFE_WD_NONE */
  double max_lag;        /* [s] the largest mean lateness of lag */
} amsfe_watchdog_state;

typedef struct amsfe_watchdog amsfe_watchdog;

/* Bytes of the block init needs (0: a bad config: n, N, ne < 1, T <= 0, a window < 1,
 * a negative count or bound, NaN). */
size_t amsfe_watchdog_memory_size(const amsfe_watchdog_config *config);
/* Build it inside `memory` (`size` bytes, 16-byte aligned).  Returns AMSFE_OK (0),
 * AMSFE_ERR_CONFIG (-6) or AMSFE_ERR_MEMORY (-7) (amsfe_runtime.h's statuses). */
int amsfe_watchdog_init(amsfe_watchdog **out, const amsfe_watchdog_config *config,
                        void *memory, size_t size);
void amsfe_watchdog_reset(amsfe_watchdog *wd);

/* Judge one processed sample: returns the reason to hold, or AMSFE_WD_NONE.  Order of the
 * checks (the first that trips wins): stall (gap > max_gap_steps), node_stalled (no call for
 * encoder_timeout), covariance (status < 0), nonfinite, compute (done - taken), deadline
 * (lateness = done - (stamp + offset), offset = taken - stamp of the first sample), lag (the
 * sum over the last deadline_window samples of the lateness of each sample that is late
 * (> 0) and was queued (due before the previous sample was done), at most deadline,
 * divided by deadline_window, > lag), actuation, innovation, tracking; then, when the sample itself is late (lateness > deadline) and was
 * queued (due before the previous sample was done: the arm ran on; never in lockstep) and the
 * reason is actuation, innovation or tracking, deadline with AMSFE_WD_CAUSE_LATE instead
 * (value: the lateness [s]): the node behind is named before what its lateness caused (the
 * arm on older commands meanwhile).  The first sample only sets the offset (no compute or
 * deadline check) and keeps its command.
 *
 * actuation: the arm applies over tick j one of the node's commands of ticks <= j (late ones
 * arrive late: then an older one; before the first, zero), never an older one than before.
 * Candidates: the command last seen applied (zero at first), then the kept commands (the
 * last AMSFE_WD_ACTUATION_RING ticks' u) after it up to applied_k; distance
 * max_j |applied_j - c_j| / s_j.  The nearest (the oldest of equals) within actuation_error is
 * the one applied (it becomes the last seen); none: a mismatch (value: the smallest
 * distance), actuation_ticks in a row hold. */
int amsfe_watchdog_sample(amsfe_watchdog *wd, const amsfe_watchdog_tick *tick);

/* The wait for a sample timed out at wall clock `now` [s]; `publishers` = the encoder topic's
 * publisher count in the graph (-1: unknown).  Holds (encoder_stall or node_stalled) when no
 * sample came for encoder_timeout since the last one (nothing before the first sample). */
int amsfe_watchdog_idle(amsfe_watchdog *wd, double now, int publishers);

void amsfe_watchdog_get_state(const amsfe_watchdog *wd, amsfe_watchdog_state *state);

/* The stable name of a reason ("tracking", ...; "none"; "unknown" out of range). */
const char *amsfe_watchdog_reason_name(int reason);
/* One line: the real cause and its fix, for a reason and its cause. */
const char *amsfe_watchdog_cause_text(int reason, int cause);
/* Write "hold: <name>: <text> (<value> vs <bound> at tick k, m missing)[; <caused> tripped]"
 * into buf (NUL-terminated,
 * truncated to size).  Returns the length snprintf would write. */
int amsfe_watchdog_format(const amsfe_watchdog *wd, char *buf, size_t size);

#ifdef __cplusplus
}
#endif
#endif /* AMSFE_WATCHDOG_H */
