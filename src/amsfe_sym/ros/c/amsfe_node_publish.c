/* amsfe_node_publish.c: what the C node publishes (amsfe_node.c): a tick's command,
 * estimate, standard deviations and theta, the diagnostics JSON, and the hold command
 * at a stop. */
#define _GNU_SOURCE
#include <math.h>
#include <stdio.h>
#include <string.h>
#include <time.h>

#include "amsfe_node.h"

static void gravity_hold(node_t *s) {
  int n = s->n;
  for (int j = 0; j < n; ++j) s->u_hold[j] = 0.0;
  if (s->hold_zero || !s->have_last) return;
  for (int i = 0; i < s->N; ++i)
    if (!isfinite(s->last_x[i])) return;
  s->g_arg[0] = s->last_x;             /* q: the first n states */
  s->g_arg[1] = s->last_x + 4 * n;     /* theta */
  s->g_res[0] = s->u_hold;
  if (gravity(s->g_arg, s->g_res, s->g_iw, s->g_w, 0) != 0) {
    for (int j = 0; j < n; ++j) s->u_hold[j] = 0.0;
    return;
  }
  for (int j = 0; j < n; ++j) {
    double lim = s->hold_limit[j];
    if (s->u_hold[j] > lim) s->u_hold[j] = lim;
    if (s->u_hold[j] < -lim) s->u_hold[j] = -lim;
  }
}

static void publish_std(node_t *s, long long ns, const double *x, const double *P_diag, long k) {
  int n = s->n;
  for (int i = 0; i < 2 * n; ++i) s->stdv[i] = sqrt(P_diag[i] > 0.0 ? P_diag[i] : 0.0);
  amsfe_out_stamp(&s->m_std, ns);
  amsfe_out_fill(&s->m_std, 0, s->stdv, n);
  amsfe_out_fill(&s->m_std, 1, s->stdv + n, n);
  amsfe_publish(&s->pub_std, &s->m_std);
  amsfe_out_fill(&s->m_theta, 0, x + 4 * n, s->p);
  amsfe_publish(&s->pub_theta, &s->m_theta);
  s->std_k = (int)k;
}

/* The diagnostics JSON of the last tick into s->diag (no allocation: snprintf). */
static void diagnostics_json(node_t *s, int with_tick) {
  live_loop *L = &s->L;
  char *b = s->diag;
  size_t cap = DIAG_CAP;
  int len = 0;
#define PUT(...) (len += snprintf(b + len, cap > (size_t)len ? cap - (size_t)len : 0, __VA_ARGS__))
  if (with_tick) PUT("{\"k\": %ld, \"t\": %.17g, ", L->k, (double)L->k * s->T);
  else PUT("{\"k\": null, \"t\": null, ");
  PUT("\"frames_fused\": %ld, \"frames_refused\": %ld, \"refused\": {", L->c.frames_applied,
      L->c.frames_rejected);
  const char *rn[] = {"refused_nan", "refused_too_late", "refused_gated", "refused_indefinite",
                      "refused_no_convergence", "refused_unscheduled", "refused_other"};
  long rv[] = {L->c.refused_nan, L->c.refused_too_late, L->c.refused_gated,
               L->c.refused_indefinite, L->c.refused_no_convergence, L->c.refused_unscheduled,
               L->c.refused_other};
  int first = 1;
  for (int i = 0; i < 7; ++i)
    if (rv[i]) PUT("%s\"%s\": %ld", first ? "" : ", ", rn[i], rv[i]), first = 0;
  PUT("}, \"skipped\": {");
  first = 1;
  for (int i = 0; i < SKIP_REASONS; ++i)
    if (L->skipped[i]) PUT("%s\"%s\": %ld", first ? "" : ", ", LIVE_SKIP_TEXT[i], L->skipped[i]), first = 0;
  PUT("}");
  if (with_tick && L->k > 0) {
    PUT(", \"frame_nis\": [");
    first = 1;
    for (int i = 0; i < L->n_due; ++i)
      if (L->due_status[i] == AMSFE_OK || L->due_status[i] == AMSFE_GATED)
        PUT("%s%.17g", first ? "" : ", ", L->due_nis[i]), first = 0;
    if (isnan(L->encoder_nis)) PUT("], \"encoder_nis\": NaN");
    else PUT("], \"encoder_nis\": %.17g", L->encoder_nis);
  }
  PUT("}");
#undef PUT
}

static void publish_diag(node_t *s) {
  /* std_msgs/String: the text, laid out now (its length changes) */
  cdr_out w;
  cdr_out_init(&w, s->m_diag.ser.buffer, s->m_diag.ser.buffer_capacity);
  cdr_put_string(&w, s->diag);
  if (!w.ok) return;
  s->m_diag.ser.buffer_length = cdr_out_size(&w);
  amsfe_publish(&s->pub_diag, &s->m_diag);
}

void wait_subscriber(node_t *s) {
  s->first_command = 0;
  double deadline = amsfe_mono_s() + s->subscriber_wait;
  size_t count = 0;
  while (rcl_publisher_get_subscription_count(&s->pub_cmd, &count) == RCL_RET_OK && count < 1 &&
         amsfe_mono_s() < deadline && !amsfe_signal) {
    struct timespec ts = {0, 10000000};
    nanosleep(&ts, NULL);
  }
  if (count < 1)
    fprintf(stderr, "[WARN] [amsfe_node]: no subscriber on %s after %g s: commands go nowhere\n",
            s->topic[T_CMD], s->subscriber_wait);
}

/* Publish the outputs of the tick just computed (the command first: the arm waits for it). */
void publish_tick(node_t *s, long long ns, const double *z, long long sent) {
  live_loop *L = &s->L;
  int n = s->n, N = s->N;
  for (int i = 0; i < N; ++i)
    if (!isfinite(L->x[i]) || !isfinite(L->P_diag[i])) {
      snprintf(s->stop_line, sizeof s->stop_line, "hold: non-finite estimate at t = %.3f s",
               (double)L->k * s->T);
      s->stop_code = EXIT_HOLD;
      return;
    }
  if (L->controller)
    for (int j = 0; j < n; ++j)
      if (!isfinite(L->u[j])) {
        snprintf(s->stop_line, sizeof s->stop_line, "hold: non-finite command at t = %.3f s",
                 (double)L->k * s->T);
        s->stop_code = EXIT_HOLD;
        return;
      }
  memcpy(s->last_x, L->x, sizeof(double) * (size_t)N);
  memcpy(s->last_P_diag, L->P_diag, sizeof(double) * (size_t)N);
  s->have_last = 1, s->last_k = L->k, s->last_ns = ns;
  if (L->controller) {
    if (s->first_command) wait_subscriber(s);
    amsfe_out_fill(&s->m_cmd, 0, L->u, n);
    amsfe_publish(&s->pub_cmd, &s->m_cmd);
    s->cmd_wall = amsfe_wall_ns(); /* the latency's end: the command out, as the Python node's */
  }
  amsfe_out_stamp(&s->m_est, ns);
  amsfe_out_fill(&s->m_est, 0, L->x, n);
  amsfe_out_fill(&s->m_est, 1, L->x + n, n);
  amsfe_publish(&s->pub_est, &s->m_est);
  if (L->k % s->std_every == 0 || (s->end_k >= 0 && L->k >= s->end_k))
    publish_std(s, ns, L->x, L->P_diag, L->k);
  if (L->k == 0 || L->tick_applied || L->tick_rejected) {
    diagnostics_json(s, 1);
    publish_diag(s);
    if (s->recording) record_diag(s, ns);
  }
  if (s->recording) record_tick(s, ns, z, sent);
  if (s->end_k >= 0 && L->k >= s->end_k) {
    snprintf(s->stop_line, sizeof s->stop_line, "done: %ld ticks (%.3f s of samples)", L->k + 1,
             (double)L->k * s->T);
    s->stop_code = 0;
  }
}

static void print_hold_list(const double *u, int n, char *out, size_t cap) {
  int len = snprintf(out, cap, "[");
  for (int j = 0; j < n; ++j) {
    double v = round(u[j] * 1e6) / 1e6;
    char num[64];
    snprintf(num, sizeof num, "%.6f", v == 0.0 ? 0.0 : v);
    char *e = num + strlen(num) - 1; /* as Python prints round(v, 6) */
    while (*e == '0' && e[-1] != '.') *e-- = 0;
    len += snprintf(out + len, cap > (size_t)len ? cap - (size_t)len : 0, "%s%s",
                    j ? ", " : "", num);
  }
  snprintf(out + len, cap > (size_t)len ? cap - (size_t)len : 0, "]");
}

/* The last estimate's std and theta if not out yet, then the hold command (with a
 * controller), acknowledged within 0.5 s; its list for the stop line into `held`. */
void publish_hold(node_t *s, char *held, size_t cap) {
  int n = s->n;
  held[0] = 0;
  if (s->have_last && s->std_k != s->last_k)
    publish_std(s, s->last_ns, s->last_x, s->last_P_diag, s->last_k);
  if (!s->L.controller) return;
  gravity_hold(s);
  amsfe_out_fill(&s->m_cmd, 0, s->u_hold, n);
  amsfe_publish(&s->pub_cmd, &s->m_cmd);
  if (rcl_publisher_wait_for_all_acked(&s->pub_cmd, RCL_MS_TO_NS(500)) != RCL_RET_OK)
    ++amsfe_publish_failed; /* not acknowledged in time (best effort: never) */
  char list[768];
  print_hold_list(s->u_hold, n, list, sizeof list);
  snprintf(held, cap, "; hold command %s N m published", list);
  if (s->recording) {
    s->rec.has_hold = 1, s->rec.hold_ns = s->have_last ? s->last_ns : 0;
    memcpy(s->rec.hold_u, s->u_hold, sizeof(double) * (size_t)n);
  }
}
