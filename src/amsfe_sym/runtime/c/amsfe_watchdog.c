/* amsfe_watchdog.c: the watchdogs of a live node (amsfe_watchdog.h, docs/watchdogs.md).
 *
 * Mirrors amsfe_sym/ros/watchdog.py line by line: the same checks in the same order, the
 * same floating-point operations in the same order (a running NIS sum added to and
 * subtracted from as the Python does; no product feeds an addition in one expression, so no
 * compiler may fuse them), so both decide the same hold at the same tick
 * (tests/test_watchdog_c.py).  Robot-independent; no allocation after init.
 */
#include "amsfe_watchdog.h"

#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <string.h>

#include "amsfe_runtime.h"

struct amsfe_watchdog {
  amsfe_watchdog_config c;
  amsfe_watchdog_state s; /* the hold (reason, cause, k, value, bound, gap) and the maxima */
  int first;              /* no sample yet */
  long long stamp0;       /* the first sample's stamp [ns] */
  double taken0;          /* ... and when it was taken [s] */
  double last_call;       /* the last sample's take or idle call [s] */
  double last_taken;      /* the last sample's take [s] */
  double last_done;       /* the last sample's done [s] */
  long last_k;
  double *nis;            /* [innovation_window] NIS / dimension, a ring */
  double nis_sum;
  int nis_pos, nis_count;
  unsigned char *late;    /* [deadline_window] 1: that sample was late, a ring */
  int late_pos, late_count;
  double *behind;         /* [deadline_window] the lateness of a queued late sample (0), a
                             ring at late_pos */
  double behind_sum;
  double *scale;          /* [n] the actuation scale per joint */
  long *ring_k;           /* [AMSFE_WD_ACTUATION_RING] the tick of each kept command (-1) */
  double *ring_u;         /* [AMSFE_WD_ACTUATION_RING x n] the commands */
  double *matched;        /* [n] the command last seen applied (zero first) */
  long matched_k, cmd_newest;
  int act_run;            /* judged mismatches in a row */
};

/* Python's max(a, b): b only when b > a */
static double pymax(double a, double b) { return b > a ? b : a; }

static size_t align16(size_t x) { return (x + 15u) & ~(size_t)15u; }

static int config_ok(const amsfe_watchdog_config *c) {
  if (!c) return 0;
  if (c->n < 1 || c->N < 1 || c->ne < 1 || c->innovation_window < 1 || c->deadline_window < 1)
    return 0;
  if (c->deadline_misses < 0 || c->max_gap_steps < 0 || c->actuation_ticks < 1) return 0;
  /* written so that NaN fails */
  return c->T > 0 && c->tracking_error > 0 && c->innovation_nis > 0 && c->deadline > 0 &&
         c->lag > 0 && c->compute_budget > 0 && c->encoder_timeout > 0 && c->actuation_error > 0;
}

size_t amsfe_watchdog_memory_size(const amsfe_watchdog_config *config) {
  if (!config_ok(config)) return 0;
  size_t n = (size_t)config->n;
  return align16(sizeof(struct amsfe_watchdog)) +
         align16(sizeof(double) * (size_t)config->innovation_window) +
         align16((size_t)config->deadline_window) +
         align16(sizeof(double) * (size_t)config->deadline_window) +
         2 * align16(sizeof(double) * n) +
         align16(sizeof(long) * AMSFE_WD_ACTUATION_RING) +
         align16(sizeof(double) * AMSFE_WD_ACTUATION_RING * n);
}

int amsfe_watchdog_init(amsfe_watchdog **out, const amsfe_watchdog_config *config,
                        void *memory, size_t size) {
  size_t need = amsfe_watchdog_memory_size(config);
  if (!out || need == 0) return AMSFE_ERR_CONFIG;
  if (!memory || size < need || ((uintptr_t)memory & 15u)) return AMSFE_ERR_MEMORY;
  unsigned char *p = (unsigned char *)memory;
  amsfe_watchdog *wd = (amsfe_watchdog *)p;
  p += align16(sizeof(struct amsfe_watchdog));
  memset(wd, 0, sizeof *wd);
  wd->c = *config;
  wd->nis = (double *)p;
  p += align16(sizeof(double) * (size_t)config->innovation_window);
  wd->late = p;
  p += align16((size_t)config->deadline_window);
  wd->behind = (double *)p;
  p += align16(sizeof(double) * (size_t)config->deadline_window);
  size_t n = (size_t)config->n;
  wd->scale = (double *)p;
  p += align16(sizeof(double) * n);
  wd->matched = (double *)p;
  p += align16(sizeof(double) * n);
  wd->ring_k = (long *)p;
  p += align16(sizeof(long) * AMSFE_WD_ACTUATION_RING);
  wd->ring_u = (double *)p;
  for (size_t j = 0; j < n; ++j) { /* as WatchdogConfig.scale */
    double v = config->u_max ? config->u_max[j] : INFINITY;
    wd->scale[j] = isfinite(v) && v > 0 ? v : 1.0;
  }
  wd->c.u_max = NULL; /* not kept: the caller's */
  amsfe_watchdog_reset(wd);
  *out = wd;
  return AMSFE_OK;
}

void amsfe_watchdog_reset(amsfe_watchdog *wd) {
  if (!wd) return;
  memset(&wd->s, 0, sizeof wd->s);
  wd->s.reason = AMSFE_WD_NONE;
  wd->s.max_lateness = -INFINITY;
  wd->first = 1;
  wd->stamp0 = 0;
  wd->taken0 = wd->last_call = wd->last_taken = wd->last_done = 0.0;
  wd->last_k = -1;
  wd->nis_sum = 0.0;
  wd->nis_pos = wd->nis_count = 0;
  wd->late_pos = wd->late_count = 0;
  memset(wd->nis, 0, sizeof(double) * (size_t)wd->c.innovation_window);
  memset(wd->late, 0, (size_t)wd->c.deadline_window);
  wd->behind_sum = 0.0;
  for (int i = 0; i < wd->c.deadline_window; ++i) wd->behind[i] = 0.0;
  memset(wd->matched, 0, sizeof(double) * (size_t)wd->c.n);
  for (int i = 0; i < AMSFE_WD_ACTUATION_RING; ++i) wd->ring_k[i] = -1;
  wd->matched_k = wd->cmd_newest = -1;
  wd->act_run = 0;
}

/* The sample's command into the ring (none: nothing). */
static void keep_command(amsfe_watchdog *wd, const amsfe_watchdog_tick *t) {
  if (!t->u || t->k < 0) return;
  long slot = t->k % AMSFE_WD_ACTUATION_RING;
  wd->ring_k[slot] = t->k;
  memcpy(wd->ring_u + slot * wd->c.n, t->u, sizeof(double) * (size_t)wd->c.n);
  if (t->k > wd->cmd_newest) wd->cmd_newest = t->k;
}

/* max_j |a_j - c_j| / s_j */
static double distance(const amsfe_watchdog *wd, const double *a, const double *c) {
  double d = fabs(a[0] - c[0]) / wd->scale[0];
  for (int j = 1; j < wd->c.n; ++j) {
    double dj = fabs(a[j] - c[j]) / wd->scale[j];
    if (dj > d) d = dj;
  }
  return d;
}

/* The actuation check (amsfe_watchdog_sample's comment): 1 a mismatch (*value: the smallest
 * distance; the run counted), 0 matched or not judged. */
static int actuation(amsfe_watchdog *wd, const amsfe_watchdog_tick *t, double *value) {
  int n = wd->c.n;
  if (!t->u || !t->applied || t->applied_k < 0) return 0;
  for (int j = 0; j < n; ++j)
    if (!isfinite(t->applied[j])) return 0;
  amsfe_watchdog_state *s = &wd->s;
  double bound = wd->c.actuation_error;
  const double *a = t->applied;
  long newest = wd->cmd_newest;
  s->actuation_judged += 1;
  long last = t->applied_k < newest ? t->applied_k : newest;
  double best = distance(wd, a, wd->matched);
  const double *best_c = NULL; /* NULL: the last seen itself */
  long best_k = wd->matched_k;
  long i = wd->matched_k + 1;
  if (newest - AMSFE_WD_ACTUATION_RING + 1 > i) i = newest - AMSFE_WD_ACTUATION_RING + 1;
  for (; i <= last; ++i) {
    long slot = i % AMSFE_WD_ACTUATION_RING;
    if (wd->ring_k[slot] != i) continue;
    double d = distance(wd, a, wd->ring_u + slot * n);
    if (d < best) best = d, best_k = i, best_c = wd->ring_u + slot * n;
  }
  s->max_actuation = pymax(s->max_actuation, best);
  if (best <= bound) { /* the command applied: the nearest (the oldest of equals) */
    if (best_c) memcpy(wd->matched, best_c, sizeof(double) * (size_t)n);
    wd->matched_k = best_k;
    wd->act_run = 0;
    return 0;
  }
  wd->act_run += 1;
  *value = best;
  return 1;
}

/* the first trip of a sample wins (set only while no reason is set yet) */
static void trip(amsfe_watchdog_state *h, int reason, int cause, long k, double value,
                 double bound, long gap) {
  if (h->reason != AMSFE_WD_NONE) return;
  h->reason = reason;
  h->cause = cause;
  h->k = k;
  h->value = value;
  h->bound = bound;
  h->gap = gap;
}

static int nonfinite(const double *v, int m) {
  if (!v) return 0;
  for (int i = 0; i < m; ++i)
    if (!isfinite(v[i])) return 1;
  return 0;
}

static void push_nis(amsfe_watchdog *wd, double v) {
  int W = wd->c.innovation_window;
  double old = wd->nis[wd->nis_pos];
  wd->nis[wd->nis_pos] = v;
  wd->nis_pos = (wd->nis_pos + 1) % W;
  if (wd->nis_count < W) {
    wd->nis_count += 1;
    wd->nis_sum = wd->nis_sum + v;
  } else {
    wd->nis_sum = (wd->nis_sum - old) + v;
  }
}

int amsfe_watchdog_sample(amsfe_watchdog *wd, const amsfe_watchdog_tick *t) {
  if (!wd || !t) return AMSFE_WD_NONE;
  amsfe_watchdog_state *s = &wd->s;
  if (s->reason != AMSFE_WD_NONE) return s->reason;
  const amsfe_watchdog_config *c = &wd->c;
  if (wd->first) { /* the clock offset; nothing judged */
    wd->first = 0;
    wd->stamp0 = t->stamp_ns;
    wd->taken0 = t->taken;
    wd->last_call = wd->last_taken = t->taken;
    wd->last_done = t->done;
    wd->last_k = t->k;
    s->samples += 1;
    keep_command(wd, t);
    return AMSFE_WD_NONE;
  }
  s->samples += 1;
  /* volatile: the product is rounded before the sum, as in Python (no fused multiply-add) */
  volatile double rel = (double)(t->stamp_ns - wd->stamp0) * 1e-9;
  double due = wd->taken0 + rel;
  double wall_gap = t->taken - wd->last_call;
  s->max_wall_gap = pymax(s->max_wall_gap, wall_gap);
  wd->last_call = wd->last_taken = t->taken;
  wd->last_k = t->k;
  long k = t->k, gap = t->gap;
  if (gap > c->max_gap_steps) { /* 1 */
    double late_at_take = t->taken - due;
    int lost = late_at_take > c->deadline;
    trip(s, lost ? AMSFE_WD_NODE_STALLED : AMSFE_WD_ENCODER_STALL,
         lost ? AMSFE_WD_CAUSE_LOST : AMSFE_WD_CAUSE_GAP, k, (double)gap,
         (double)c->max_gap_steps, gap);
  }
  if (wall_gap > c->encoder_timeout) /* 2 */
    trip(s, AMSFE_WD_NODE_STALLED, AMSFE_WD_CAUSE_UNSCHEDULED, k, wall_gap, c->encoder_timeout,
         gap);
  if (t->status < 0) /* 3 */
    trip(s, AMSFE_WD_COVARIANCE, gap > 0 ? AMSFE_WD_CAUSE_BEHIND : AMSFE_WD_CAUSE_INCONSISTENT,
         k, (double)t->status, 0.0, gap);
  if (nonfinite(t->x_hat, c->N) || nonfinite(t->P_diag, c->N)) /* 4 */
    trip(s, AMSFE_WD_NONFINITE, AMSFE_WD_CAUSE_ESTIMATE, k, NAN, 0.0, gap);
  else if (nonfinite(t->u, c->n))
    trip(s, AMSFE_WD_NONFINITE, AMSFE_WD_CAUSE_COMMAND, k, NAN, 0.0, gap);
  double compute = t->done - t->taken; /* 5 */
  s->max_compute = pymax(s->max_compute, compute);
  if (compute > c->compute_budget)
    trip(s, AMSFE_WD_COMPUTE, AMSFE_WD_CAUSE_NONE, k, compute, c->compute_budget, gap);
  /* queued: due before the previous sample's command was done (the arm ran on an older
   * command; never in lockstep, whose arm sends a sample after the previous command came) */
  int queued = due < wd->last_done;
  wd->last_done = t->done;
  double lateness = t->done - due; /* 6 */
  s->max_lateness = pymax(s->max_lateness, lateness);
  int late = lateness > c->deadline ? 1 : 0;
  int pos = wd->late_pos;
  wd->late_count += late - (int)wd->late[pos];
  wd->late[pos] = (unsigned char)late;
  wd->late_pos = (pos + 1) % c->deadline_window;
  if (wd->late_count > s->max_late_in_window) s->max_late_in_window = wd->late_count;
  if (wd->late_count > c->deadline_misses)
    trip(s, AMSFE_WD_DEADLINE, AMSFE_WD_CAUSE_NONE, k, (double)wd->late_count,
         (double)c->deadline_misses, gap);
  /* 7: a sample past deadline counts deadline (a burst of them is deadline's to count) */
  double behind = 0.0;
  if (queued && lateness > 0.0) behind = lateness < c->deadline ? lateness : c->deadline;
  wd->behind_sum = (wd->behind_sum - wd->behind[pos]) + behind;
  wd->behind[pos] = behind;
  double lag = wd->behind_sum / (double)c->deadline_window;
  s->max_lag = pymax(s->max_lag, lag);
  if (lag > c->lag) trip(s, AMSFE_WD_LAG, AMSFE_WD_CAUSE_NONE, k, lag, c->lag, gap);
  double mismatch = 0.0; /* 8 */
  if (actuation(wd, t, &mismatch) && wd->act_run >= c->actuation_ticks)
    trip(s, AMSFE_WD_ACTUATION, AMSFE_WD_CAUSE_NONE, k, mismatch, c->actuation_error, gap);
  keep_command(wd, t);
  if (isfinite(t->encoder_nis)) push_nis(wd, t->encoder_nis / (double)c->ne); /* 9 */
  for (int i = 0; t->frame_nis && i < t->n_frames; ++i)
    if (isfinite(t->frame_nis[i])) push_nis(wd, t->frame_nis[i] / 2.0);
  if (wd->nis_count == c->innovation_window) {
    double mean = wd->nis_sum / (double)c->innovation_window;
    s->max_innovation = pymax(s->max_innovation, mean);
    if (mean > c->innovation_nis)
      trip(s, AMSFE_WD_INNOVATION, AMSFE_WD_CAUSE_NONE, k, mean, c->innovation_nis, gap);
  }
  if (t->handed_over && t->q_des && t->x_hat) { /* 10: numpy's max (NaN wins) */
    double err = fabs(t->q_des[0] - t->x_hat[0]);
    for (int j = 1; j < c->n; ++j) {
      double d = fabs(t->q_des[j] - t->x_hat[j]);
      if (isnan(d) || d > err) err = d;
    }
    s->max_tracking = pymax(s->max_tracking, err);
    if (err > c->tracking_error)
      trip(s, AMSFE_WD_TRACKING, AMSFE_WD_CAUSE_NONE, k, err, c->tracking_error, gap);
  }
  /* 11: a late sample that was due before the previous one was done (it waited in the
   * queue while the arm ran on older commands; never in lockstep) names the node behind
   * before what its lateness caused: the arm's torque, innovations, path */
  if (late && queued && (s->reason == AMSFE_WD_ACTUATION || s->reason == AMSFE_WD_INNOVATION ||
               s->reason == AMSFE_WD_TRACKING)) {
    int first = s->reason;
    s->reason = AMSFE_WD_NONE;
    trip(s, AMSFE_WD_DEADLINE, AMSFE_WD_CAUSE_LATE, k, lateness, c->deadline, gap);
    s->caused = first;
  }
  return s->reason;
}

int amsfe_watchdog_idle(amsfe_watchdog *wd, double now, int publishers) {
  if (!wd) return AMSFE_WD_NONE;
  amsfe_watchdog_state *s = &wd->s;
  if (s->reason != AMSFE_WD_NONE) return s->reason;
  if (wd->first) return AMSFE_WD_NONE;
  double wall_gap = now - wd->last_call;
  s->max_wall_gap = pymax(s->max_wall_gap, wall_gap);
  wd->last_call = now;
  double silence = now - wd->last_taken;
  /* the node's own loop paused (a blocked write to a peer that died, no CPU): the samples
     an arm sent meanwhile may not be taken yet, so the silence is judged at the next call
     (ros/watchdog.py, Watchdog.idle) */
  if (wall_gap > wd->c.encoder_timeout) return s->reason;
  if (silence > wd->c.encoder_timeout)
    trip(s, AMSFE_WD_ENCODER_STALL, publishers == 0 ? AMSFE_WD_CAUSE_GONE : AMSFE_WD_CAUSE_SILENT,
         wd->last_k, silence, wd->c.encoder_timeout, 0);
  return s->reason;
}

void amsfe_watchdog_get_state(const amsfe_watchdog *wd, amsfe_watchdog_state *state) {
  if (wd && state) *state = wd->s;
}

static const char *const NAMES[AMSFE_WD_REASONS] = {
    "none",     "tracking",      "innovation",   "covariance", "deadline",
    "compute",  "encoder_stall", "node_stalled", "nonfinite",  "actuation", "lag"};

const char *amsfe_watchdog_reason_name(int reason) {
  return reason >= 0 && reason < AMSFE_WD_REASONS ? NAMES[reason] : "unknown";
}

/* ros/watchdog.py's CAUSE_TEXT, character for character */
const char *amsfe_watchdog_cause_text(int reason, int cause) {
  switch (reason) {
    case AMSFE_WD_TRACKING:
      return "the arm left its path: a link angle is farther from q_d than tracking_error; "
             "check the arm (a broken encoder, a torque loss, a collision) and the gains";
    case AMSFE_WD_INNOVATION:
      return "the measurements disagree with the model: the mean NIS of the last fused "
             "updates is above innovation_nis; check the encoders and the camera (a jump, a "
             "frozen sample), the torque the arm applies and the spec's noise";
    case AMSFE_WD_COVARIANCE:
      if (cause == AMSFE_WD_CAUSE_BEHIND)
        return "the node fell behind: the covariance lost positive definiteness after a "
               "prediction over missing samples; give the node CPU (priority, fewer jobs) or "
               "a deeper queue";
      return "model/noise inconsistent: the covariance lost positive definiteness with no "
             "sample missing; check the robot spec's model and the [filter] noise";
    case AMSFE_WD_DEADLINE:
      if (cause == AMSFE_WD_CAUSE_LATE)
        return "this node is behind, not the arm: it processed this sample later than "
               "deadline after its stamp, and what the arm did meanwhile on older commands "
               "(its innovations, its path, its torque) left a bound; give the node CPU "
               "(real-time priority, fewer jobs)";
      return "this node is behind (CPU load / priority), not the driver: samples processed "
             "later than deadline after their stamp; give the node CPU (real-time priority, "
             "fewer jobs)";
    case AMSFE_WD_COMPUTE:
      return "one tick's computation took longer than compute_budget: the machine is too "
             "loaded or too slow for this loop; give the node CPU or run the C node";
    case AMSFE_WD_ENCODER_STALL:
      if (cause == AMSFE_WD_CAUSE_GONE)
        return "the arm's driver is gone: no publisher of the encoders is left; restart the "
               "driver";
      if (cause == AMSFE_WD_CAUSE_GAP)
        return "the arm's driver paused: more than max_gap_steps samples missing, the next "
               "one on time; check the driver (or raise [timing] max_gap_steps)";
      return "the arm's driver is silent: its publisher is in the graph but sends no sample; "
             "check the driver and the arm's hardware";
    case AMSFE_WD_NODE_STALLED:
      if (cause == AMSFE_WD_CAUSE_LOST)
        return "this node is behind, not the driver: more than max_gap_steps samples lost "
               "from its queue while it lagged; give the node CPU (priority) or a deeper "
               "queue ([qos] depth)";
      return "this node was not scheduled, not the driver: its own loop paused longer than "
             "encoder_timeout; give the node CPU (real-time priority, fewer jobs)";
    case AMSFE_WD_NONFINITE:
      if (cause == AMSFE_WD_CAUSE_COMMAND)
        return "the command turned NaN or inf; check the gains and the reference";
      return "the estimate turned NaN or inf; check the encoder values and the robot spec";
    case AMSFE_WD_ACTUATION:
      return "the arm does not apply the command (drive fault, e-stop, brakes): the torque it "
             "reports differs from every command it may have applied by more than "
             "actuation_error; check the drives";
    case AMSFE_WD_LAG:
      return "this node is behind on average, not the arm: the mean lateness of the last "
             "deadline_window samples (each queued while the arm ran on an older command) is "
             "above lag, so the arm runs on stale commands; give the node CPU (real-time "
             "priority, fewer jobs) or run the C node";
    default:
      return "";
  }
}

/* %.6g, with NaN printed "nan" whatever its sign (Python's) */
static void number(char *out, size_t size, double v) {
  if (isnan(v))
    snprintf(out, size, "nan");
  else
    snprintf(out, size, "%.6g", v);
}

int amsfe_watchdog_format(const amsfe_watchdog *wd, char *buf, size_t size) {
  if (!wd || wd->s.reason == AMSFE_WD_NONE) {
    if (buf && size) buf[0] = '\0';
    return 0;
  }
  char value[32], bound[32];
  number(value, sizeof value, wd->s.value);
  number(bound, sizeof bound, wd->s.bound);
  char caused[48] = "";
  if (wd->s.caused != AMSFE_WD_NONE)
    snprintf(caused, sizeof caused, "; %s tripped", amsfe_watchdog_reason_name(wd->s.caused));
  return snprintf(buf, size, "hold: %s: %s (%s vs bound %s at tick %ld, %ld missing)%s",
                  amsfe_watchdog_reason_name(wd->s.reason),
                  amsfe_watchdog_cause_text(wd->s.reason, wd->s.cause), value, bound,
                  wd->s.k, wd->s.gap, caused);
}
