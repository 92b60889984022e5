/* amsfe_loop.h: the controllers and the closed loop of amsfe_sym as plain C
 * (docs/how-to/runtime-c.md).
 *
 * Compiled into every full generated robot library beside amsfe_runtime.{c,h} (the
 * estimators).  Three layers, each usable alone:
 *
 *   amsfe_ctrl   a controller: the generated law of the robot (control_amsfe, ...) and the
 *                few values it keeps between ticks; gains, torque limits and actuator data in
 *                a parameter block;
 *   amsfe_loop_tick  the real-time tick of an arm: encoder sample and the camera frames
 *                delivered now in, torque out (estimator step with the previous torque,
 *                frames, control law, actuator limit), in one call;
 *   amsfe_sim    the closed-loop simulation: plant substeps (plant_step), encoders, camera
 *                and disturbance from noise arrays the caller draws in one batch, then
 *                amsfe_loop_tick, for many ticks per call, recording every signal.
 *
 * Nothing allocates after init; every object lives in a memory block the caller owns.
 * Matrices are column-major; arrays of records are row-major (one row per tick).
 */
#ifndef AMSFE_LOOP_H
#define AMSFE_LOOP_H

#include <stddef.h>

#include "amsfe_runtime.h"

#ifdef __cplusplus
extern "C" {
#endif

/* The controllers (the names of amsfe_sym.control). */
enum amsfe_controller {
  AMSFE_CTRL_AMSFE = 0,       /* cascade on (31)-(34), on the estimate x(k|k) */
  AMSFE_CTRL_DTSMC = 1,       /* cascade, surface of (54), on the encoders (plan removed) */
  AMSFE_CTRL_DTSMC_EKF = 2,   /* cascade, surface of (54) (Lt = 0), on the estimate */
  AMSFE_CTRL_TRUTH = 3,       /* AMSFE_CTRL_AMSFE on the true state and theta (oracle) */
  AMSFE_CTRL_AMSFE_PAPER = 4, /* law (37) as printed */
  AMSFE_CTRL_DTSMC_PAPER = 5, /* law (54) as printed, on the raw encoders */
  AMSFE_CTRL_TRUTH_CT = 6     /* cascaded computed torque on the true state (oracle) */
};

/* Controller parameter block (copied by amsfe_ctrl_init).  Per-joint arrays have n entries. */
typedef struct {
  int controller;            /* enum amsfe_controller */
  double T;                  /* control period [s] (the library's) */
  /* sliding-mode gains, eqs. (31)-(34): all laws but truth-ct */
  const double *h, *lam, *Lt, *eps, *phi;
  double p;                  /* terminal power p1/p2 in (0, 1] */
  /* the cascades: motor-loop bandwidth [rad/s], spring-torque limit [N m], command-filter
   * bandwidth [rad/s], motor rate bound [rad/s] */
  const double *wm, *tau_max, *wf, *vmax;
  int qmd_next_hold;         /* printed laws: 0 = predict qmd(k+1) by (1c), 1 = hold */
  int state_true;            /* amsfe-paper: 1 = the true state (an oracle) */
  double link_bandwidth, motor_bandwidth; /* truth-ct [rad/s] */
  const double *u_max;       /* actuator limit [N m]; INFINITY = none */
  const double *Mm, *Fm;     /* motor inertia, viscous friction (the spec's) */
  const double *Ks;          /* nominal stiffness [N m/rad] */
  const int *ks_theta;       /* [n]: index of theta holding joint j's stiffness, or -1 */
  const double *theta_initial; /* [p] (the encoder-only laws use it) */
  /* the cascades' start-up (docs/explanation/control.md, "Start-up"): 0 = the filter starts at rest on
   * the first command; 1 = wait until every link angle's and rate's posterior standard
   * deviation (amsfe_ctrl_observe) is below these (and the filter consistent: ready_nis), the
   * motor held meanwhile (hold_motor), then start at rest on the first trusted command */
  int startup_converged;
  double ready_q_std, ready_qd_std; /* [rad], [rad/s] */
  /* with startup_converged: the reference starts from the state the law acts on and joins
   * the desired one within this offset acceleration [rad/s^2] (control/blend.py); INFINITY =
   * no blend; its jerk and snap stay below blend_accel * blend_rate and * blend_rate^2
   * [rad/s]; INFINITY = no bound */
  double blend_accel, blend_rate;
  /* with startup_converged, the filter's consistency too: the mean NIS of the encoder
   * innovations (amsfe_ctrl_observe_nis) over the last ready_nis_window ticks (a running
   * mean, then an exponential window of that many ticks) at most ready_nis (INFINITY or 0,
   * the value of a zeroed block, = not tested; a controller never given a NIS is not tested
   * either) */
  double ready_nis, ready_nis_window;
  /* the hold while waiting: 0 (a zeroed block) = the reference's motor trajectory offset to
   * where the motor was at the first tick; 1 = from the motor's own angle and rate (the
   * encoders), joining the reference's motor trajectory within the blend's budget
   * (control/blend.py) */
  int hold_motor;
  /* with startup_converged and a blend: the command filter's bandwidth at the trusted tick
   * [rad/s], returning to wf along the blend (wf + (blend_wf - wf) b0(s / Tb), at most wf;
   * control/sliding.py); 0 (a zeroed block) or INFINITY = wf throughout */
  double blend_wf;
  /* with startup_converged and a blend: a saturation-aware hand-over
   * (docs/explanation/control.md, "Start-up"): while the blend runs, with
   * r = min_j min(1, u_max_j / |u_j(k-1)|) the share of the last tick's demand the actuators
   * could apply (after it, r = 1), h, eps, wm and wf are scaled by rho, which drops to r at
   * once and returns towards it as rho += T / headroom_tau (r - rho) [s]; 0 (a zeroed block)
   * or INFINITY = off (control/sliding.py) */
  double headroom_tau;
  /* with startup_converged and a blend, in [0, 1]: the blend is planned as if it had started
   * blend_lead times the wait (from the first tick the controller ran to the trusted one)
   * before the trusted tick, through the trusted estimate there (control/blend.py's
   * blend_through); 0 (a zeroed block) = planned from the trusted tick */
  double blend_lead;
} amsfe_ctrl_params;

/* What a tick computed besides the torque. */
typedef struct {
  double *s;       /* [n] sliding variable s(k) of eq. (33) (NaN for truth-ct); may be NULL */
  double *bound;   /* [n] norm inside the gain condition (38) (NaN for truth-ct); or NULL */
  double *tau_d;   /* [n] cascades: spring torque the link loop asks for; or NULL */
  int saturated;   /* the actuator limit clipped u(k) */
} amsfe_ctrl_out;

typedef struct amsfe_ctrl amsfe_ctrl;

size_t amsfe_ctrl_memory_size(const amsfe_ctrl_params *params); /* 0: bad parameters */
int amsfe_ctrl_init(amsfe_ctrl **out, const amsfe_ctrl_params *params, void *memory,
                    size_t size);
void amsfe_ctrl_reset(amsfe_ctrl *ctrl);
/* The estimate's covariance P(k|k) [N x N] for the start-up's test (before amsfe_ctrl_torque
 * of the same tick; amsfe_loop_tick calls it).  NULL: the estimate is taken as converged. */
void amsfe_ctrl_observe(amsfe_ctrl *ctrl, const double *P);
/* This tick's encoder NIS for the start-up's consistency test (before amsfe_ctrl_observe of
 * the same tick; amsfe_loop_tick calls it after each estimator step).  NaN: no sample. */
void amsfe_ctrl_observe_nis(amsfe_ctrl *ctrl, double nis);

/* u(k) [n] (limited), from the reference ref [5n] = [q_d, qd_d, qdd_d, jerk_d, snap_d] at t_k,
 * the estimate x_hat [N], the encoder sample z [2n] at t_k and, for the oracles only, the true
 * state x_true [N] = [q, qd, qm, qmd, theta] (may be NULL otherwise).  Returns AMSFE_OK or
 * AMSFE_ERR_INPUT (a pointer the law needs is NULL, or ref, or the z or x_true the law uses,
 * holds NaN or inf: nothing changed). */
int amsfe_ctrl_torque(amsfe_ctrl *ctrl, long k, const double *ref, const double *x_hat,
                      const double *z, const double *x_true, double *u, amsfe_ctrl_out *out);

/* 1 when the law tracks q_d itself at tick k (after amsfe_ctrl_torque of that tick): without
 * startup_converged always; with it, once the estimate was trusted and the blended start
 * ended ((k - k0) T + s0 >= Tb).  A live node's tracking watchdog (amsfe_watchdog.h) judges
 * from then on.  control/sliding.py's handed_over. */
int amsfe_ctrl_handed_over(const amsfe_ctrl *ctrl, long k);

/* ------------------------------------------------------------------ the real-time tick */
typedef struct {
  long exposure_step; /* kappa: the step the frame was exposed at */
  double z[2];        /* pixel [u, v] */
} amsfe_frame;

/* One tick at step k: if ctrl has run before, the estimator goes k-1 -> k with the torque of
 * the previous tick and the encoder sample z [2n] (amsfe_est_tick), then takes the frames
 * delivered now in increasing exposure step (their statuses go to frame_status [n_frames],
 * may be NULL); then the controller computes u [n] on x(k|k).  The first tick only runs the
 * controller (x(k0|k0) already holds the sample it was made from).  Returns the estimator's
 * error status (< 0) or AMSFE_OK; frames is reordered in place. */
int amsfe_loop_tick(amsfe_est *est, amsfe_ctrl *ctrl, const double *z, amsfe_frame *frames,
                    int n_frames, int *frame_status, const double *ref, const double *x_true,
                    double *u, amsfe_ctrl_out *out);

/* ------------------------------------------------------------------ the simulation */
typedef struct {
  long K;                   /* ticks of the run (t_k = k T, k = 0 .. K-1) */
  const double *x_plant0;   /* [4n] true initial [q, qd, qm, qmd] */
  const double *theta_true; /* [p] */
  const double *ref;        /* [K x 5n] reference per tick (see amsfe_ctrl_torque) */
  const double *enc_noise;  /* [K x 2n] encoder noise [rad, rad/s], already scaled; row 0
                               made the first sample z0 */
  double enc_resolution;    /* angle of one count [rad]; 0 = no quantization */
  const double *tau_d;      /* [K x 2n] disturbance torques [link, motor] over [t_k, t_k+T] */
  int cam_period, cam_phase, cam_delay; /* steps */
  double cam_width, cam_height;         /* [px] */
  double pixel_std;                     /* [px] */
  int round_to_pixel;
  double drop_probability;
  long n_exposures;         /* entries of the three camera arrays (>= exposures taken) */
  const double *cam_noise;  /* [n_exposures x 2] standard normals, one pair per exposure */
  const double *cam_uniform; /* [n_exposures] uniforms in [0, 1): dropped when < drop_p */
  const int *cam_jitter;    /* [n_exposures] extra delivery delay [steps] */
  int max_in_flight;        /* frames queued at once (>= (delay + max jitter) / period + 2) */
  double diverged_error;    /* stop when |q - q_d| exceeds this [rad] (pi) */
} amsfe_sim_params;

/* Where a run writes (row-major, K rows; a NULL array is not recorded). */
typedef struct {
  double *x_true, *x_hat, *P_diag; /* [K x N] */
  double *nees;                    /* [K] e^T P^-1 e */
  double *u;                       /* [K x n] applied torque */
  double *z_enc;                   /* [K x 2n] */
  double *s, *bound;               /* [K x n] */
  unsigned char *saturated;        /* [K] */
  double *frames;                  /* [frames_capacity x 4]: exposure, delivery, u, v */
  long frames_capacity;
} amsfe_sim_records;

/* Counters of a run (the names of summary.json's counters). */
typedef struct {
  long k;            /* next tick to run */
  long ticks_done;   /* rows recorded */
  int diverged;      /* the loop stopped: non-finite or |q - q_d| > diverged_error */
  int status;        /* < 0: an estimator error stopped the run (AMSFE_ERR_...) */
  long frames_applied, frames_rejected, encoder_rejected;
  long refused_nan, refused_too_late, refused_gated, refused_indefinite,
      refused_no_convergence, refused_unscheduled, refused_other;
  long frames_exposed, frames_delivered, frames_dropped, frames_out_of_image,
      frames_out_of_image_true, frames_out_of_order;
  long frames_recorded;
  int plant_nonfinite; /* the error is the plant state turning NaN or inf (not the estimator) */
} amsfe_sim_state;

typedef struct amsfe_sim amsfe_sim;

size_t amsfe_sim_memory_size(const amsfe_sim_params *params);
/* est and ctrl are freshly initialised (or reset) by the caller; the parameter block's
 * arrays must outlive the simulation (they are read, not copied). */
int amsfe_sim_init(amsfe_sim **out, const amsfe_sim_params *params, amsfe_est *est,
                   amsfe_ctrl *ctrl, void *memory, size_t size);
/* Run up to `ticks` more ticks (until K, or divergence, or an error).  Returns the status. */
int amsfe_sim_run(amsfe_sim *sim, long ticks, const amsfe_sim_records *rec);
/* Count one camera frame's status (amsfe_est_camera_frame's) in st: frames_applied, or
 * frames_rejected and its refused_* kind (sim/loop.py's REFUSAL_KINDS).  Returns 1 fused,
 * 0 ignored, -1 refused.  The live node counts its frames with it too. */
int amsfe_sim_count_frame(amsfe_sim_state *st, int status);
void amsfe_sim_get_state(const amsfe_sim *sim, amsfe_sim_state *state);

#ifdef __cplusplus
}
#endif
#endif /* AMSFE_LOOP_H */
