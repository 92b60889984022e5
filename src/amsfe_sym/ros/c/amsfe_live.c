/* amsfe_live.c: see amsfe_live.h (the twin of amsfe_sym/ros/live.py's LiveLoop). */
#include "amsfe_live.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

const char *const LIVE_SKIP_TEXT[SKIP_REASONS] = {
    "frame exposed before the first encoder sample",
    "frame exposure off the tick grid",
    "frame with a non-finite pixel",
    "frame duplicated (an exposure already seen)",
    "torque sample off the tick grid",
    "torque sample not n finite values",
    "torque sample after its tick was estimated",
    "torque held from the previous tick",
    "encoder sample off the tick grid",
    "encoder sample duplicated",
    "encoder samples missing (predicted through)",
    "frame not kept (more than 64 pending)",
    "encoder sample with a zero header stamp (unstamped)",
    "encoder stamp behind the last one (a clock step back)",
    "encoder stamp ahead of its send time (a clock step or a corrupt stamp)",
};

static void *zalloc(size_t size) {
  void *p = NULL;
  if (posix_memalign(&p, 64, size ? size : 8) != 0) return NULL;
  memset(p, 0, size ? size : 8);
  return p;
}

static int all_finite(const double *v, int n) {
  for (int i = 0; i < n; ++i)
    if (!isfinite(v[i])) return 0;
  return 1;
}

int live_init(live_loop *L) {
  int n = L->n, N = L->N;
  L->k = -1;
  L->est_size = amsfe_est_memory_size(&L->ep);
  L->ctrl_size = L->controller ? amsfe_ctrl_memory_size(&L->cp) : 0;
  if (!L->est_size || (L->controller && !L->ctrl_size)) {
    fprintf(stderr, "error: amsfe_node: the runtime refused the %s parameter block\n",
            L->est_size ? "controller" : "estimator");
    return AMSFE_ERR_CONFIG;
  }
  L->est_mem = zalloc(L->est_size);
  L->ctrl_mem = zalloc(L->ctrl_size);
  L->x0 = zalloc(sizeof(double) * (size_t)N);
  memcpy(L->x0, L->ep.x0, sizeof(double) * (size_t)N);
  L->ep.x0 = L->x0;
  L->eff_u = zalloc(sizeof(double) * LIVE_RING * (size_t)n);
  L->cmd_u = zalloc(sizeof(double) * LIVE_RING * (size_t)n);
  L->early_eff_ns = zalloc(sizeof(long long) * LIVE_RING);
  L->early_eff_u = zalloc(sizeof(double) * LIVE_RING * (size_t)n);
  L->u_in = zalloc(sizeof(double) * (size_t)n);
  L->wd_applied = zalloc(sizeof(double) * (size_t)n);
  L->wd_applied_k = -1;
  L->x = zalloc(sizeof(double) * (size_t)N);
  L->P = zalloc(sizeof(double) * (size_t)N * (size_t)N);
  L->P_diag = zalloc(sizeof(double) * (size_t)N);
  L->u = zalloc(sizeof(double) * (size_t)n);
  L->ref_hold = zalloc(sizeof(double) * 5 * (size_t)n);
  if (!L->est_mem || !L->ctrl_mem || !L->x0 || !L->eff_u || !L->cmd_u || !L->u_in || !L->x ||
      !L->P || !L->P_diag || !L->u || !L->ref_hold || !L->early_eff_ns || !L->early_eff_u ||
      !L->wd_applied)
    return AMSFE_ERR_MEMORY;
  for (int i = 0; i < LIVE_RING; ++i) L->seen[i] = L->eff_j[i] = L->cmd_j[i] = -1;
  if (L->K_ref > 0) /* past the reference: its last angles, at rest */
    memcpy(L->ref_hold, L->ref + (L->K_ref - 1) * 5 * n, sizeof(double) * (size_t)n);
  if (L->controller) {
    int st = amsfe_ctrl_init(&L->ctrl, &L->cp, L->ctrl_mem, L->ctrl_size);
    if (st != AMSFE_OK) {
      fprintf(stderr, "error: amsfe_node: amsfe_ctrl_init: %s\n", amsfe_status_string(st));
      return st;
    }
  }
  L->encoder_nis = NAN;
  return AMSFE_OK;
}

const double *live_ref(const live_loop *L, long k) {
  return k < L->K_ref ? L->ref + k * 5 * L->n : L->ref_hold;
}

long live_tick_of(const live_loop *L, long long stamp_ns, int *ok) {
  *ok = 0;
  if (L->k < 0) return 0;
  long long rel = stamp_ns - L->t0_ns;
  /* Python's round(rel / T): the float quotient, ties to even (the default rounding mode) */
  double k = nearbyint((double)rel / (double)L->T_ns);
  double off = fabs((double)(rel - (long long)k * L->T_ns));
  *ok = off <= L->tol * (double)L->T_ns;
  return (long)k;
}

static void skip(live_loop *L, int why, long count) { L->skipped[why] += count; }

void live_frame_in(live_loop *L, long long exposure_ns, const double z[2], long long sent) {
  if (L->k < 0) { /* before the first sample: judged by its source timestamp then */
    if (L->n_early == LIVE_MAX_FRAMES) {
      skip(L, SKIP_FRAMES_OVERFLOW, 1);
      return;
    }
    live_frame *f = &L->early[L->n_early++];
    f->exposure_ns = exposure_ns, f->z[0] = z[0], f->z[1] = z[1], f->sent = sent;
    return;
  }
  if (L->have_sent0 && sent <= L->sent0) {
    skip(L, SKIP_FRAME_BEFORE_FIRST, 1);
    return;
  }
  int ok;
  long kappa = live_tick_of(L, exposure_ns, &ok);
  if (ok) kappa -= L->exposure_shift; /* [camera] time_offset in ticks (LiveLoop.frame) */
  if (!ok) {
    skip(L, SKIP_FRAME_OFF_GRID, 1);
  } else if (kappa < 0) {
    skip(L, SKIP_FRAME_BEFORE_FIRST, 1);
  } else if (!isfinite(z[0]) || !isfinite(z[1])) {
    skip(L, SKIP_FRAME_NONFINITE, 1);
  } else if (L->seen[kappa % LIVE_RING] == kappa) {
    skip(L, SKIP_FRAME_DUPLICATE, 1);
  } else if (L->n_pending == LIVE_MAX_FRAMES) {
    skip(L, SKIP_FRAMES_OVERFLOW, 1);
  } else {
    L->seen[kappa % LIVE_RING] = kappa;
    live_frame *f = &L->pending[L->n_pending++];
    f->kappa = kappa, f->z[0] = z[0], f->z[1] = z[1], f->sent = sent;
    f->exposure_ns = exposure_ns;
  }
}

void live_applied(live_loop *L, long long stamp_ns, const double *u) {
  int n = L->n;
  if (L->k < 0) {
    /* kept until the first sample places them: the newest LIVE_RING ticks (a first sample
     * that comes late, the efforts flowing meanwhile, needs every one after it) */
    long slot = L->n_early_eff % LIVE_RING;
    L->early_eff_ns[slot] = stamp_ns;
    memcpy(L->early_eff_u + slot * n, u, sizeof(double) * (size_t)n);
    ++L->n_early_eff;
    return;
  }
  int ok;
  long j = live_tick_of(L, stamp_ns, &ok);
  if (!ok) {
    skip(L, SKIP_TORQUE_OFF_GRID, 1);
  } else if (!u || !all_finite(u, n)) {
    skip(L, SKIP_TORQUE_NOT_FINITE, 1);
  } else {
    if (j < L->k) {
      skip(L, SKIP_TORQUE_LATE, 1);
    } else {
      L->eff_j[j % LIVE_RING] = j;
      memcpy(L->eff_u + (j % LIVE_RING) * n, u, sizeof(double) * (size_t)n);
    }
    if (j >= 0 && j >= L->wd_applied_k) { /* the watchdog's (LiveLoop._for_watchdog) */
      L->wd_applied_k = j;
      memcpy(L->wd_applied, u, sizeof(double) * (size_t)n);
    }
  }
}

/* The torque over [t_j, t_j+1]: the effort topic's of tick j, else the command of j, else
 * the previous one (counted). */
static const double *u_for(live_loop *L, long j) {
  int n = L->n;
  long slot = j % LIVE_RING;
  if (j >= 0 && L->eff_j[slot] == j) {
    memcpy(L->u_in, L->eff_u + slot * n, sizeof(double) * (size_t)n);
    L->eff_j[slot] = -1;
  } else if (j >= 0 && L->cmd_j[slot] == j) {
    memcpy(L->u_in, L->cmd_u + slot * n, sizeof(double) * (size_t)n);
  } else {
    skip(L, SKIP_TORQUE_HELD, 1);
  }
  return L->u_in;
}

static void count_frame(live_loop *L, int status) {
  int counted = amsfe_sim_count_frame(&L->c, status); /* the compiled loop's counting */
  if (counted > 0) L->tick_applied++;
  if (counted < 0) L->tick_rejected++;
}

/* One estimator step k-1 -> k (L->k is k already) with the sample z (NULL: none) and the
 * pending frames exposed at or before k and sent before the current sample. */
static int step(live_loop *L, const double *z) {
  const double *u = u_for(L, L->k - 1);
  int st = amsfe_est_tick(L->est, z, u);
  if (st < 0) return L->status = st;
  amsfe_diag d;
  amsfe_est_diagnostics(L->est, &d);
  L->encoder_nis = d.encoder_nis;
  L->encoder_accepted = d.encoder_accepted;
  if (z && !d.encoder_accepted) L->c.encoder_rejected++;
  if (!z) L->c.encoder_rejected++; /* the reference counts a step without a usable sample */
  /* the due frames, kept in their arrival order, then sorted by exposure (stable) */
  int nd = 0, keep = 0;
  for (int i = 0; i < L->n_pending; ++i) {
    live_frame *f = &L->pending[i];
    if (f->kappa <= L->k && f->sent <= L->sent) {
      L->due[nd].exposure_step = f->kappa;
      L->due[nd].z[0] = f->z[0], L->due[nd].z[1] = f->z[1];
      L->due_info[nd++] = *f;
    } else {
      L->pending[keep++] = *f;
    }
  }
  L->n_pending = keep;
  for (int i = 1; i < nd; ++i)
    for (int j = i; j > 0 && L->due[j].exposure_step < L->due[j - 1].exposure_step; --j) {
      amsfe_frame t = L->due[j];
      L->due[j] = L->due[j - 1], L->due[j - 1] = t;
      live_frame ti = L->due_info[j];
      L->due_info[j] = L->due_info[j - 1], L->due_info[j - 1] = ti;
    }
  for (int i = 0; i < nd; ++i) {
    st = amsfe_est_camera_frame(L->est, L->due[i].z, L->due[i].exposure_step, &L->due_nis[i]);
    if (st < 0) return L->status = st;
    L->due_status[i] = st;
    count_frame(L, st);
  }
  L->n_due = nd;
  return AMSFE_OK;
}

/* The controller on x(k|k) (what amsfe_loop_tick runs after the estimator). */
static int control(live_loop *L, const double *z, int with_nis) {
  int N = L->N, n = L->n;
  amsfe_est_state(L->est, L->x, L->P);
  for (int i = 0; i < N; ++i) L->P_diag[i] = L->P[i + (size_t)i * N];
  if (!L->controller) return AMSFE_OK;
  if (with_nis) amsfe_ctrl_observe_nis(L->ctrl, L->encoder_nis);
  amsfe_ctrl_observe(L->ctrl, L->P);
  amsfe_ctrl_out out = {NULL, NULL, NULL, 0};
  int st = amsfe_ctrl_torque(L->ctrl, L->k, live_ref(L, L->k), L->x, z, NULL, L->u, &out);
  if (st != AMSFE_OK) return L->status = st;
  long slot = L->k % LIVE_RING;
  L->cmd_j[slot] = L->k;
  memcpy(L->cmd_u + slot * n, L->u, sizeof(double) * (size_t)n);
  return AMSFE_OK;
}

/* Why an encoder sample's header stamp is not used (-1: it is; LiveLoop._bad_stamp):
 * a zero stamp; a stamp more than max_gap + 1 ticks behind the last used one (a clock step
 * back); that many ahead of it while the send times advanced less than a quarter as much (a
 * clock step ahead or a corrupt stamp: a stall delays both).  Skipped and counted; the run of
 * them in L->bad_run. */
static int bad_stamp(live_loop *L, long long stamp_ns, long long sent) {
  int why = -1;
  double size = 0.0;
  long long span = (long long)(L->max_gap + 1) * L->T_ns;
  long long d = stamp_ns - (L->t0_ns + (long long)L->k * L->T_ns);
  if (stamp_ns == 0) {
    why = SKIP_ENCODER_ZERO_STAMP;
  } else if (d < -span) {
    why = SKIP_ENCODER_STEP_BACK, size = (double)-d * 1e-9;
  } else if (d > span && sent != 0 && L->last_sent != 0 && d > 4 * (sent - L->last_sent)) {
    why = SKIP_ENCODER_AHEAD, size = (double)d * 1e-9;
  }
  if (why < 0) {
    L->bad_run = 0;
    L->last_sent = sent;
    return -1;
  }
  skip(L, why, 1);
  ++L->bad_run;
  L->bad_why = why, L->bad_size = size;
  return why;
}

void live_bad_stamp_line(const live_loop *L, char *out, size_t cap) {
  char size[96] = "";
  if (L->bad_size != 0.0)
    snprintf(size, sizeof size, ", the last %.4g s from the last used stamp", L->bad_size);
  snprintf(out, cap,
           "encoder stamps at t = %.3f s: expected header stamps on the clock the node started "
           "on, found %s: %d samples in a row after tick %ld%s. Fix: fix the driver's stamping "
           "clock (slew, do not step; stamp every sample) and restart the node",
           (double)L->k * ((double)L->T_ns * 1e-9), LIVE_SKIP_TEXT[L->bad_why], L->bad_run, L->k,
           size);
}

int live_encoders(live_loop *L, long long stamp_ns, const double *z, long long sent) {
  int n = L->n;
  L->sent = sent;
  L->tick_applied = L->tick_rejected = 0;
  L->n_due = 0;
  L->gap = 0;
  if (L->k < 0) { /* the first sample: x(0|0) from it, no estimator step */
    L->t0_ns = stamp_ns, L->k = 0, L->sent0 = sent, L->have_sent0 = 1;
    L->last_sent = sent;
    if (L->x0_from_encoders) {
      memcpy(L->x0 + 2 * n, z, sizeof(double) * (size_t)n);
      memcpy(L->x0 + 3 * n, z + n, sizeof(double) * (size_t)n);
    }
    int st = amsfe_est_init(&L->est, &L->ep, L->est_mem, L->est_size);
    if (st == AMSFE_OK) st = amsfe_est_set_inverse_tolerance(L->est, L->inverse_tol);
    if (st != AMSFE_OK) {
      L->status = st;
      return st - 100;
    }
    L->n_pending = 0; /* the loop uses no frame at tick 0 */
    for (long i = L->n_early_eff > LIVE_RING ? L->n_early_eff - LIVE_RING : 0;
         i < L->n_early_eff; ++i)
      live_applied(L, L->early_eff_ns[i % LIVE_RING], L->early_eff_u + (i % LIVE_RING) * n);
    L->n_early_eff = 0;
    for (int i = 0; i < L->n_early; ++i)
      live_frame_in(L, L->early[i].exposure_ns, L->early[i].z, L->early[i].sent);
    L->n_early = 0;
    L->encoder_nis = NAN;
    int cs = control(L, z, 0);
    return cs < 0 ? cs - 100 : 1;
  }
  if (bad_stamp(L, stamp_ns, sent) >= 0) /* named, not "stalled" */
    return L->bad_run > L->max_gap ? LIVE_BAD_STAMPS : 0;
  int ok;
  long k = live_tick_of(L, stamp_ns, &ok);
  if (!ok) {
    skip(L, SKIP_ENCODER_OFF_GRID, 1);
    return 0;
  }
  if (k <= L->k) {
    skip(L, SKIP_ENCODER_DUPLICATE, 1);
    return 0;
  }
  long gap = k - L->k - 1;
  L->gap = (int)gap;
  if (gap > L->max_gap) return -1;
  for (long i = 0; i < gap; ++i) { /* predicted through, as a log's gaps are */
    ++L->k;
    int st = step(L, NULL);
    if (st < 0) return st - 100;
  }
  if (gap) skip(L, SKIP_ENCODER_MISSING, gap);
  L->k = k;
  int st = step(L, all_finite(z, 2 * n) ? z : NULL);
  if (st < 0) return st - 100;
  int cs = control(L, z, 1);
  return cs < 0 ? cs - 100 : 1;
}
