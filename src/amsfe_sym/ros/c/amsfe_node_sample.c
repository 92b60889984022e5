/* amsfe_node_sample.c: the C node's per-sample path (amsfe_node.c): one encoder
 * sample read, the messages sent before it taken, the live loop's tick, the watchdogs'
 * judgement, then the tick's outputs published. */
#define _GNU_SOURCE
#include <math.h>
#include <stdio.h>
#include <string.h>

#include "amsfe_node.h"

/* One encoder sample in s->in (sent at `sent`, received by the middleware at `received`,
 * system clock [ns]). */
void on_encoders(node_t *s, long long sent, long long received, double taken) {
  live_loop *L = &s->L;
  int n = s->n;
  if (!s->active) return; /* a managed node, not active: the sample is dropped */
  if (s->first_command && L->controller) { /* before the watchdog's clock starts */
    wait_subscriber(s);
    taken = amsfe_mono_s();
  }
  long long ns;
  int has_eff;
  if (read_joint_state(s, &ns, s->pos, s->vel, s->eff, &has_eff) < 0) {
    if (s->stop_code < 0) ++L->skipped[SKIP_ENCODER_OFF_GRID]; /* malformed: not a sample */
    return;
  }
  for (int j = 0; j < n; ++j) s->z[j] = s->pos[j], s->z[n + j] = s->vel[j];
  /* frames, efforts and the truth sent before this sample (already here: take them now) */
  take_frames(s);
  if (s->read_effort && !s->effort_in_encoders) {
    take_efforts(s);
    if (await_effort(s, ns)) taken = amsfe_mono_s(); /* a wait is not the tick's compute time */
  }
  if (s->recording) take_truth(s);
  int r = live_encoders(L, ns, s->z, sent);
  if (r == 1 && L->k == 0) /* the efforts taken before it, placed now: the stream's newest */
    for (long j = 0; j < LIVE_RING; ++j)
      if (L->eff_j[j] == j && j > s->eff_last) s->eff_last = j;
  if (r == 0) return; /* skipped (counted): not judged */
  if (r == LIVE_BAD_STAMPS) { /* held by the stamps' name, not as a stall */
    char why[768];
    live_bad_stamp_line(L, why, sizeof why);
    snprintf(s->stop_line, sizeof s->stop_line, "hold: the estimator stopped: %s", why);
    s->stop_code = EXIT_HOLD;
    return;
  }
  double done = amsfe_mono_s();
  /* the watchdogs judge the tick (or the failure) before its command goes out */
  amsfe_watchdog_tick tick;
  memset(&tick, 0, sizeof tick);
  tick.k = r == -1 ? L->k + L->gap + 1 : L->k;
  tick.gap = L->gap;
  tick.stamp_ns = sent; /* the DDS source timestamp: this node's delay, not the arm's pace */
  tick.taken = taken, tick.done = done;
  tick.encoder_nis = NAN;
  tick.applied_k = -1; /* the newest applied torque since the last sample (LiveLoop.watch) */
  if (L->wd_applied_k >= 0) tick.applied = L->wd_applied, tick.applied_k = L->wd_applied_k;
  L->wd_applied_k = -1;
  if (r < 0) {
    tick.status = r == -1 ? AMSFE_ERR_NOT_PD : L->status; /* as LiveLoop.watch judges them */
  } else {
    tick.x_hat = L->x, tick.P_diag = L->P_diag;
    if (L->controller) {
      tick.q_des = live_ref(L, L->k), tick.u = L->u;
      tick.handed_over = amsfe_ctrl_handed_over(L->ctrl, L->k);
    }
    if (L->k > 0 && L->encoder_accepted) tick.encoder_nis = L->encoder_nis;
    int nf = 0;
    for (int i = 0; i < L->n_due; ++i)
      if (L->due_status[i] == AMSFE_OK) s->frame_nis[nf++] = L->due_nis[i];
    tick.frame_nis = s->frame_nis, tick.n_frames = nf;
  }
  if (amsfe_watchdog_sample(s->wd, &tick) != AMSFE_WD_NONE) {
    amsfe_watchdog_format(s->wd, s->stop_line, sizeof s->stop_line);
    s->stop_code = EXIT_HOLD;
    return;
  }
  if (r == -1) { /* not held (a watchdog off): the Python node's line */
    snprintf(s->stop_line, sizeof s->stop_line,
             "hold: the estimator stopped: encoder sample at t = %.3f s: expected at most "
             "max_gap_steps = %d missing samples before it, found %d missing. Fix: the arm's "
             "encoders stalled: check the driver (or raise [timing] max_gap_steps in the topic "
             "spec)",
             (double)(L->k + L->gap + 1) * s->T, L->max_gap, L->gap);
    s->stop_code = EXIT_HOLD;
    return;
  }
  if (r < -1) {
    snprintf(s->stop_line, sizeof s->stop_line,
             "hold: the estimator stopped: step %ld: expected a usable numerical result, found "
             "status %d: %s. Fix: check the filter's noise and the samples' stamps",
             L->k, L->status, amsfe_status_string(L->status));
    s->stop_code = EXIT_HOLD;
    return;
  }
  if (s->effort_in_encoders && s->read_effort && has_eff) { /* the torque over the next tick */
    live_applied(L, ns, s->eff);
    record_effort(s, ns, s->eff);
  }
  s->cmd_wall = 0;
  long std_k = s->std_k;
  publish_tick(s, ns, s->z, sent);
  if (s->cmd_wall && s->n_lat < s->cap_lat) {
    int kind = L->k < 10 ? LAT_FIRST : L->n_due > 0 ? LAT_FRAME : s->prev_kind;
    s->lat_kind[s->n_lat] = (unsigned char)kind;
    s->lat[s->n_lat++] = 1e-9 * (double)(s->cmd_wall - received);
  }
  s->prev_kind = L->n_due > 0 ? LAT_AFTER_FRAME : s->std_k != std_k ? LAT_AFTER_STD : LAT_OTHER;
  s->last_rx = amsfe_mono_s(); /* after the work: a slow first tick is no silence */
  s->started = 1;
}
