/* amsfe_node: the per-sample path of `amsfe node` in C, on rcl (docs/live-control.md).
 *
 *   amsfe_node PARAMS [--ros-args ...]
 *
 * PARAMS is written by amsfe_sym.ros.cnode (the scenario's estimator and controller
 * parameter blocks as the compiled loop builds them, the reference, and the topic spec
 * resolved: topics, joint order, QoS depths, rates; amsfe_node_params.h).  The node subscribes
 * the encoders, the camera, the applied torque (and the truth when it records) and publishes,
 * per encoder sample, the command, the estimate, every std_every-th tick the estimate's
 * standard deviations and theta, and diagnostics (JSON) when frames were fused or refused:
 * the topics, types and QoS of the Python node (amsfe_sym/ros/node.py).
 *
 * The sample path: one wait set; rcl_take_serialized_message into buffers allocated at start
 * (amsfe_cdr.h reads them); amsfe_live.c's tick (the library's estimator and controller);
 * rcl_publish_serialized_message of messages whose bytes were laid out at start (only the
 * numbers and the stamp are written).  No allocation, no Python.
 *
 * Stops: the end of `duration` (exit 0), encoder silence, the estimator failing, a
 * non-finite estimate or command, more than max_gap_steps samples missing (exit 3, the hold:
 * EXIT_HOLD of node.py), a joint missing from a JointState (exit 2), SIGINT / SIGTERM (exit
 * 130 / 143).  Every stop publishes the hold command first (gravity g(q_hat, theta_hat) or
 * zero, within the actuator limits) and prints one line "node: <why>; hold command [...] N m
 * published".  With a record path, what the node received and published is written there
 * as arrays at the stop (amsfe_sym.ros.cnode reads them into the rosbag2 of --record).
 */
#define _GNU_SOURCE
#include <errno.h>
#include <math.h>
#include <sched.h>
#include <signal.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/mman.h>
#include <time.h>
#include <unistd.h>

#include <rcl/graph.h>
#include <rcl/rcl.h>
#include <rcutils/error_handling.h>
#include <rmw/serialized_message.h>
#include <geometry_msgs/msg/point_stamped.h>
#include <sensor_msgs/msg/joint_state.h>
#include <std_msgs/msg/float64_multi_array.h>
#include <std_msgs/msg/string.h>

#include "amsfe_cdr.h"
#include "amsfe_rcl.h"
#include "amsfe_lifecycle.h"
#include "amsfe_live.h"
#include "amsfe_node_params.h"
#include "amsfe_watchdog.h"

/* the generated library's gravity g(q, theta) (casadi's calling convention) */
extern int gravity(const double **arg, double **res, long long *iw, double *w, int mem);
extern int gravity_work(long long *sz_arg, long long *sz_res, long long *sz_iw, long long *sz_w);

#define EXIT_HOLD 3
#define EXIT_BAD_INPUT 2
#define MAX_JOINTS 64
#define MSG_CAP 65536  /* bytes of one incoming message kept without a resize */
#define DIAG_CAP 8192



/* The kinds of tick the node's own latency is split by at the stop: which work falls on a
 * sample's way (a frame's update runs before its command; the diagnostics JSON, the record
 * and the standard deviations after it, delaying the next sample taken). */
enum lat_kind { LAT_FIRST, LAT_FRAME, LAT_AFTER_FRAME, LAT_AFTER_STD, LAT_OTHER, LAT_KINDS };
static const char *const LAT_KIND_NAME[LAT_KINDS] = {
    "first 10", "frame fused or refused", "after a frame tick", "after a std tick", "others"};

/* ------------------------------------------------------------------ the record */
/* What the node received and published, kept in arrays of `cap` ticks (allocated at
 * start) and written at the stop as sections "name type rows cols data". */
typedef struct {
  long cap, ticks;
  long long *ns, *sent;              /* each tick's stamp, its sample's source timestamp */
  double *z, *x, *std, *u;           /* [cap x 2n], [cap x N] x 2, [cap x n] */
  long cap_truth, n_truth;           /* every truth received: its source timestamp, x */
  long long *truth_sent;
  double *truth_x;
  long cap_eff, n_eff;
  long long *eff_ns;
  double *eff_u;
  long cap_fr, n_fr;
  long long *fr_ns, *fr_exp;  /* arrival (the tick's stamp), exposure */
  double *fr_z;
  live_frame rx[LIVE_MAX_FRAMES]; /* frames received, not yet recorded */
  int n_rx;
  long cap_diag, n_diag;
  long long *diag_ns;
  long *diag_at;
  char *diag_text;
  size_t diag_used, diag_bytes;
  int has_hold;
  long long hold_ns;
  double *hold_u;
  long lost; /* rows not kept (a full record) */
} record_t;

static void rec_section(FILE *f, const char *name, char type, long rows, long cols,
                        const void *data, size_t elem) {
  char head[16] = {0};
  strncpy(head, name, 14);
  head[15] = type;
  int64_t rc[2] = {rows, cols};
  fwrite(head, 1, 16, f);
  fwrite(rc, 8, 2, f);
  if (rows > 0 && cols > 0) fwrite(data, elem, (size_t)(rows * cols), f);
}

/* ------------------------------------------------------------------ the node */
typedef struct {
  params_file pf;
  live_loop L;
  int n, N, p, recording, std_every, hold_zero, effort_in_encoders, read_effort;
  long end_k;
  double T; /* [s] the library's (t_k = k T as the Python node prints it) */
  double encoder_timeout, subscriber_wait;
  const char *topic[16];
  const char *names[MAX_JOINTS];
  int idx[MAX_JOINTS];
  double *pos, *vel, *eff, *z, *u_hold, *hold_limit, *stdv, *theta_buf, *truth;
  /* rcl */
  rcl_context_t ctx;
  rcl_node_t node;
  rcl_subscription_t sub_enc, sub_cam, sub_eff, sub_truth;
  rcl_publisher_t pub_cmd, pub_est, pub_std, pub_theta, pub_diag;
  rcl_wait_set_t ws;
  rcl_wait_set_t ws_eff; /* the effort subscription alone (await_effort) */
  long eff_last;         /* the latest tick of an effort received (-1: none) */
  long eff_waits, eff_missed; /* samples that waited for the previous tick's effort; in vain */
  rcl_serialized_message_t in;
  amsfe_out m_cmd, m_est, m_std, m_theta, m_diag;
  char *diag;
  /* gravity */
  const double **g_arg;
  double **g_res;
  long long *g_iw;
  double *g_w;
  /* the run */
  double last_rx;
  int started, std_k, first_command;
  long last_k;
  long long last_ns;
  int have_last;
  double *last_x, *last_P_diag;
  const char *stop_reason;
  char stop_line[2048];
  int stop_code;
  double *lat;  /* [cap] sample received by the middleware -> command published [s] */
  unsigned char *lat_kind; /* [cap] each one's tick kind (enum lat_kind) */
  int prev_kind;           /* what the previous tick did after its command (LAT_AFTER_*) */
  long n_lat, cap_lat;
  long long cmd_wall; /* wall clock when the tick's command was published [ns] (0: none) */
  record_t rec;
  amsfe_watchdog *wd;  /* the watchdogs (amsfe_watchdog.h): their reasons are the holds */
  double *frame_nis;   /* [LIVE_MAX_FRAMES] NIS of the frames fused at the tick */
  int exit_code;       /* the process's, known at the stop */
  int managed, active; /* --managed: samples processed only while active (lifecycle) */
  node_lifecycle lc;
} node_t;

enum { T_ENC, T_CAM, T_EFF, T_TRUTH, T_EST, T_STD, T_THETA, T_DIAG, T_CMD, T_N };
static const char *const TOPIC_KEYS[T_N] = {
    "topic_encoders", "topic_camera", "topic_effort", "topic_truth", "topic_estimate",
    "topic_estimate_std", "topic_theta", "topic_diagnostics", "topic_commands"};

/* Read the parameter file into the node and its live loop. */
static void configure(node_t *s, const char *path) {
  params_file *pf = &s->pf;
  pf_open(pf, path);
  amsfe_dims d;
  amsfe_dims_get(&d);
  int dims[4];
  pf_ints(pf, "dims", dims, 4);
  if (dims[0] != d.n || dims[1] != d.N || dims[3] != d.ne) {
    char found[96];
    snprintf(found, sizeof found, "a library of n = %d, N = %d, ne = %d", d.n, d.N, d.ne);
    pf_fail(pf, "dims", "the sizes of the library the node was built with", found);
  }
  int n = s->n = d.n, N = s->N = d.N;
  s->p = N - 4 * n;
  live_loop *L = &s->L;
  L->n = n, L->N = N;
  L->T_ns = pf_long(pf, "T_ns");
  s->T = pf_double(pf, "T");
  L->tol = pf_double(pf, "grid_tolerance");
  L->max_gap = (int)pf_long(pf, "max_gap_steps");
  L->exposure_shift = pf_long(pf, "exposure_shift");
  L->controller = (int)pf_long(pf, "controller");
  s->end_k = (long)pf_long(pf, "end_k");
  s->std_every = (int)pf_long(pf, "std_every");
  s->hold_zero = strcmp(pf_string(pf, "hold"), "zero") == 0;
  s->encoder_timeout = pf_double(pf, "encoder_timeout");
  s->subscriber_wait = pf_double(pf, "subscriber_wait");
  s->effort_in_encoders = (int)pf_long(pf, "effort_in_encoders");
  s->read_effort = (int)pf_long(pf, "read_effort");
  s->managed = (int)pf_long(pf, "managed");
  s->active = !s->managed;
  for (int i = 0; i < T_N; ++i) s->topic[i] = pf_string(pf, TOPIC_KEYS[i]);
  if (n > MAX_JOINTS) pf_fail(pf, "joints", "at most 64 joints", "more");
  if (pf_tokens(pf, "joints", s->names, MAX_JOINTS, 0) != n)
    pf_fail(pf, "joints", "one name per joint of the library", "another count");
  /* the estimator's block */
  amsfe_params *ep = &L->ep;
  char const *t[16];
  if (pf_tokens(pf, "est", t, 16, 0) != 11) pf_fail(pf, "est", "11 values", "another count");
  int *ints[] = {&ep->estimator, &ep->buffer_steps, &ep->camera_iterations, &ep->camera_period,
                 &ep->camera_phase, &ep->camera_max_delay, &ep->max_frames_per_step};
  for (int i = 0; i < 7; ++i) *ints[i] = (int)pf_parse_long(pf, "est", t[i]);
  ep->gate_camera = pf_parse_double(pf, "est", t[7]);
  ep->gate_encoder = pf_parse_double(pf, "est", t[8]);
  ep->k0 = (long)pf_parse_long(pf, "est", t[9]);
  ep->backward_map = (int)pf_parse_long(pf, "est", t[10]);
  double *qw = ALLOC(double, d.nw), *re = ALLOC(double, d.ne), *rc = ALLOC(double, 2);
  double *x0 = ALLOC(double, N), *P0 = ALLOC(double, (size_t)N * N);
  pf_doubles(pf, "qw", qw, d.nw);
  pf_doubles(pf, "r_encoder", re, d.ne);
  pf_doubles(pf, "r_camera", rc, 2);
  pf_doubles(pf, "x0", x0, N);
  pf_doubles(pf, "P0", P0, N * N);
  ep->qw = qw, ep->r_encoder = re, ep->r_camera = rc, ep->x0 = x0, ep->P0 = P0;
  L->x0_from_encoders = (int)pf_long(pf, "x0_motor_from_encoders");
  L->inverse_tol = pf_double(pf, "inverse_tol");
  /* the controller's block */
  if (L->controller) {
    amsfe_ctrl_params *cp = &L->cp;
    if (pf_tokens(pf, "ctrl", t, 16, 0) != 16) pf_fail(pf, "ctrl", "16 values", "another count");
    cp->controller = (int)pf_parse_long(pf, "ctrl", t[0]);
    cp->T = pf_parse_double(pf, "ctrl", t[1]);
    cp->p = pf_parse_double(pf, "ctrl", t[2]);
    cp->qmd_next_hold = (int)pf_parse_long(pf, "ctrl", t[3]);
    cp->state_true = (int)pf_parse_long(pf, "ctrl", t[4]);
    cp->link_bandwidth = pf_parse_double(pf, "ctrl", t[5]);
    cp->motor_bandwidth = pf_parse_double(pf, "ctrl", t[6]);
    cp->startup_converged = (int)pf_parse_long(pf, "ctrl", t[7]);
    cp->ready_q_std = pf_parse_double(pf, "ctrl", t[8]);
    cp->ready_qd_std = pf_parse_double(pf, "ctrl", t[9]);
    cp->blend_accel = pf_parse_double(pf, "ctrl", t[10]);
    cp->blend_rate = pf_parse_double(pf, "ctrl", t[11]);
    cp->ready_nis = pf_parse_double(pf, "ctrl", t[12]);
    cp->ready_nis_window = pf_parse_double(pf, "ctrl", t[13]);
    cp->hold_motor = (int)pf_parse_long(pf, "ctrl", t[14]);
    cp->blend_wf = pf_parse_double(pf, "ctrl", t[15]);
    if (pf_tokens(pf, "ctrl2", t, 16, 0) != 2) pf_fail(pf, "ctrl2", "2 values", "another count");
    cp->headroom_tau = pf_parse_double(pf, "ctrl2", t[0]);
    cp->blend_lead = pf_parse_double(pf, "ctrl2", t[1]);
    static const char *const vec[] = {"h", "lam", "Lt", "eps", "phi", "wm", "tau_max", "wf",
                                      "vmax", "u_max", "Mm", "Fm", "Ks"};
    const double **dst[] = {&cp->h, &cp->lam, &cp->Lt, &cp->eps, &cp->phi, &cp->wm,
                            &cp->tau_max, &cp->wf, &cp->vmax, &cp->u_max, &cp->Mm, &cp->Fm,
                            &cp->Ks};
    for (int i = 0; i < 13; ++i) {
      double *v = ALLOC(double, n);
      pf_doubles(pf, vec[i], v, n);
      *dst[i] = v;
    }
    int *ks = ALLOC(int, n);
    pf_ints(pf, "ks_theta", ks, n);
    cp->ks_theta = ks;
    double *th = ALLOC(double, s->p + 1);
    pf_doubles(pf, "theta_initial", th, s->p);
    cp->theta_initial = th;
    /* the reference: K rows of 5n float64 in a binary file */
    const char *ref_tok[2];
    if (pf_tokens(pf, "ref_file", ref_tok, 2, 0) != 2)
      pf_fail(pf, "ref_file", "a path and a row count", "another count");
    L->K_ref = (long)pf_parse_long(pf, "ref_file", ref_tok[1]);
    double *ref = ALLOC(double, (size_t)L->K_ref * 5 * n);
    FILE *f = fopen(ref_tok[0], "rb");
    if (!f || fread(ref, sizeof(double) * 5 * (size_t)n, (size_t)L->K_ref, f) != (size_t)L->K_ref)
      pf_fail(pf, "ref_file", "K rows of 5n float64", "a shorter or unreadable file");
    fclose(f);
    L->ref = ref;
  }
  s->hold_limit = ALLOC(double, n);
  pf_doubles(pf, "hold_limit", s->hold_limit, n);
  /* the watchdogs: the [watchdog] keys of the spec, in amsfe_watchdog_config's order */
  double w[11];
  pf_doubles(pf, "watchdog", w, 11);
  amsfe_watchdog_config wc = {n, N, d.ne, s->T, w[0], w[1], (int)w[2], w[3], (int)w[4],
                              (int)w[5], w[6], w[7], L->max_gap, w[8], (int)w[9],
                              s->hold_limit /* u_max (inf: none) */, w[10]};
  size_t wsize = amsfe_watchdog_memory_size(&wc);
  void *wmem = NULL;
  if (!wsize || posix_memalign(&wmem, 64, wsize) != 0 ||
      amsfe_watchdog_init(&s->wd, &wc, wmem, wsize) != AMSFE_OK)
    pf_fail(pf, "watchdog", "bounds the watchdogs accept (amsfe_watchdog_init)", "a refusal");
  s->encoder_timeout = w[7];
  s->frame_nis = ALLOC(double, LIVE_MAX_FRAMES);
}

static void take_frames(node_t *s);
static void print_hold_list(const double *u, int n, char *out, size_t cap);
static void take_efforts(node_t *s);
static int await_effort(node_t *s, long long ns);
static void take_truth(node_t *s);

/* The joints' indices in a JointState's names (-1 and a stop line: one is missing). */
static int order(node_t *s, const char **names, int count) {
  int n = s->n;
  for (int j = 0; j < n; ++j) {
    s->idx[j] = -1;
    for (int i = 0; i < count && i < MAX_JOINTS; ++i)
      if (strcmp(names[i], s->names[j]) == 0) {
        if (s->idx[j] >= 0) s->idx[j] = -2; /* twice */
        else if (s->idx[j] == -1) s->idx[j] = i;
      }
    if (s->idx[j] < 0) {
      int len = snprintf(s->stop_line, sizeof s->stop_line,
                         "%s JointState names: expected JointState names including the "
                         "robot's [", s->topic[T_ENC]);
      for (int i = 0; i < n && len < (int)sizeof s->stop_line - 64; ++i)
        len += snprintf(s->stop_line + len, sizeof s->stop_line - (size_t)len, "%s'%s'",
                        i ? ", " : "", s->names[i]);
      snprintf(s->stop_line + len, sizeof s->stop_line - (size_t)len,
               "], found joint '%s' %s. Fix: map the log's joint names to the robot's in the "
               "topic spec's [joints] names",
               s->names[j], s->idx[j] == -1 ? "missing" : "more than once");
      s->stop_code = EXIT_BAD_INPUT;
      s->stop_reason = "bad input";
      return -1;
    }
  }
  return 0;
}

/* Parse a JointState in s->in: its stamp, the joints' values in q order (NaN where the
 * message has no such field).  0: ok; -1: malformed or a joint missing. */
static int read_joint_state(node_t *s, long long *ns, double *pos, double *vel, double *eff,
                            int *has_eff) {
  cdr_in r;
  cdr_in_init(&r, s->in.buffer, s->in.buffer_length);
  *ns = cdr_header(&r);
  uint32_t count = cdr_u32(&r);
  const char *names[MAX_JOINTS];
  if (count > MAX_JOINTS) count = 0, r.ok = 0;
  for (uint32_t i = 0; i < count && r.ok; ++i) names[i] = cdr_string(&r);
  int np, nv, ne;
  double *buf = s->theta_buf; /* MAX_JOINTS values of scratch */
  cdr_doubles(&r, buf, MAX_JOINTS, &np);
  for (int j = 0; j < s->n; ++j) pos[j] = 0.0;
  if (!r.ok) return -1;
  if (order(s, names, (int)count) < 0) return -1;
  int n = s->n;
  for (int j = 0; j < n; ++j) pos[j] = np == (int)count ? buf[s->idx[j]] : NAN;
  cdr_doubles(&r, buf, MAX_JOINTS, &nv);
  for (int j = 0; j < n; ++j) vel[j] = nv == (int)count ? buf[s->idx[j]] : NAN;
  cdr_doubles(&r, buf, MAX_JOINTS, &ne);
  for (int j = 0; j < n; ++j) eff[j] = ne == (int)count ? buf[s->idx[j]] : NAN;
  *has_eff = ne > 0;
  return r.ok ? 0 : -1;
}

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

static void record_tick(node_t *s, long long ns, const double *z, long long sent) {
  record_t *R = &s->rec;
  live_loop *L = &s->L;
  int n = s->n, N = s->N;
  if (L->k == 0) { /* frames sent before the first sample: skipped, not recorded */
    int keep = 0;
    for (int i = 0; i < R->n_rx; ++i)
      if (R->rx[i].sent > sent) R->rx[keep++] = R->rx[i];
    R->n_rx = keep;
  }
  int keep = 0;
  for (int i = 0; i < R->n_rx; ++i) {
    if (R->rx[i].sent <= sent) {
      if (R->n_fr < R->cap_fr) {
        R->fr_ns[R->n_fr] = ns, R->fr_exp[R->n_fr] = R->rx[i].exposure_ns;
        R->fr_z[2 * R->n_fr] = R->rx[i].z[0], R->fr_z[2 * R->n_fr + 1] = R->rx[i].z[1];
        ++R->n_fr;
      } else {
        ++R->lost;
      }
    } else {
      R->rx[keep++] = R->rx[i];
    }
  }
  R->n_rx = keep;
  if (R->ticks >= R->cap) {
    ++R->lost;
    return;
  }
  long t = R->ticks++;
  R->ns[t] = ns, R->sent[t] = sent;
  memcpy(R->z + t * 2 * n, z, sizeof(double) * 2 * (size_t)n);
  memcpy(R->x + t * N, L->x, sizeof(double) * (size_t)N);
  for (int i = 0; i < N; ++i) R->std[t * N + i] = sqrt(L->P_diag[i] > 0.0 ? L->P_diag[i] : 0.0);
  for (int j = 0; j < n; ++j) R->u[t * n + j] = L->controller ? L->u[j] : NAN;
}

static void record_effort(node_t *s, long long ns, const double *u) {
  record_t *R = &s->rec;
  if (!s->recording) return;
  if (R->n_eff >= R->cap_eff) {
    ++R->lost;
    return;
  }
  R->eff_ns[R->n_eff] = ns;
  memcpy(R->eff_u + R->n_eff * s->n, u, sizeof(double) * (size_t)s->n);
  ++R->n_eff;
}

static void record_diag(node_t *s, long long ns) {
  record_t *R = &s->rec;
  size_t len = strlen(s->diag) + 1;
  if (R->n_diag >= R->cap_diag || R->diag_used + len > R->diag_bytes) {
    ++R->lost;
    return;
  }
  R->diag_ns[R->n_diag] = ns;
  R->diag_at[R->n_diag++] = (long)R->diag_used;
  memcpy(R->diag_text + R->diag_used, s->diag, len);
  R->diag_used += len;
}

static void wait_subscriber(node_t *s) {
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
static void publish_tick(node_t *s, long long ns, const double *z, long long sent) {
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

/* One encoder sample in s->in (sent at `sent`, received by the middleware at `received`,
 * system clock [ns]). */
static void on_encoders(node_t *s, long long sent, long long received, double taken) {
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
  if (r == LIVE_BAD_STAMPS) { /* issue 37: held by the stamps' name, not as a stall */
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

/* What a node that has received no encoder sample for `seconds` prints (the Python node's
 * middleware.waiting_line, word for word): the topic it waits on, its type, and what the graph
 * shows for it: no publisher (and the topics of that type that have one), publishers of another
 * type (a type mismatch), or publishers of the right type delivering nothing.  Called every
 * 10 s before the first sample only (it allocates: never on the sample path). */
static void say_waiting(node_t *s, double seconds) {
  const char *want = "sensor_msgs/msg/JointState";
  const char *topic = rcl_subscription_get_topic_name(&s->sub_enc);
  if (topic == NULL) topic = s->topic[T_ENC];
  rcl_allocator_t alloc = rcl_get_default_allocator();
  rmw_topic_endpoint_info_array_t pubs = rmw_get_zero_initialized_topic_endpoint_info_array();
  if (rcl_get_publishers_info_by_topic(&s->node, &alloc, topic, false, &pubs) != RCL_RET_OK) {
    rcutils_reset_error();
    return;
  }
  char line[2048];
  int at = snprintf(line, sizeof line, "node: nothing on %s (%s) for %.0f s", topic, want, seconds);
  if (pubs.size == 0) {
    at += snprintf(line + at, sizeof line - (size_t)at, ": no publisher of %s on the graph", topic);
    rcl_names_and_types_t nt = rmw_get_zero_initialized_names_and_types();
    if (rcl_get_topic_names_and_types(&s->node, &alloc, false, &nt) == RCL_RET_OK) {
      int first = 1;
      for (size_t i = 0; i < nt.names.size && at < (int)sizeof line - 64; ++i) {
        int same = 0;
        for (size_t j = 0; j < nt.types[i].size; ++j)
          same |= strcmp(nt.types[i].data[j], want) == 0;
        if (!same || strcmp(nt.names.data[i], topic) == 0) continue;
        at += snprintf(line + at, sizeof line - (size_t)at, "%s'%s'",
                       first ? "; topics of that type: [" : ", ", nt.names.data[i]);
        first = 0;
      }
      if (!first) at += snprintf(line + at, sizeof line - (size_t)at, "]");
      rcl_names_and_types_fini(&nt);
    } else {
      rcutils_reset_error();
    }
    snprintf(line + at, sizeof line - (size_t)at, " (check -r / [topics])");
  } else {
    char wrong[1024] = "";
    int w = 0, n_wrong = 0;
    for (size_t i = 0; i < pubs.size; ++i) {
      const char *t = pubs.info_array[i].topic_type;
      if (t == NULL || strcmp(t, want) == 0 || strstr(wrong, t) != NULL) continue;
      w += snprintf(wrong + w, sizeof wrong - (size_t)w, "%s'%s'", n_wrong ? ", " : "", t);
      ++n_wrong;
    }
    if (n_wrong)
      snprintf(line + at, sizeof line - (size_t)at,
               ": %zu publisher(s) of type [%s], not %s: a type mismatch, no message can pass "
               "(publish the right type or remap)", pubs.size, wrong, want);
    else
      snprintf(line + at, sizeof line - (size_t)at,
               ": %zu publisher(s) of %s, none delivering (check QoS)", pubs.size, want);
  }
  rmw_topic_endpoint_info_array_fini(&pubs, &alloc);
  printf("%s\n", line);
  fflush(stdout);
}

static void take_frames(node_t *s) {
  rmw_message_info_t info;
  while (rcl_take_serialized_message(&s->sub_cam, &s->in, &info, NULL) == RCL_RET_OK) {
    cdr_in r;
    cdr_in_init(&r, s->in.buffer, s->in.buffer_length);
    long long exposure = cdr_header(&r);
    double z[2];
    z[0] = cdr_f64(&r), z[1] = cdr_f64(&r);
    (void)cdr_f64(&r);
    if (!r.ok || !s->active) continue;
    live_frame_in(&s->L, exposure, z, info.source_timestamp);
    if (s->recording && s->rec.n_rx < LIVE_MAX_FRAMES) {
      live_frame *f = &s->rec.rx[s->rec.n_rx++];
      f->exposure_ns = exposure, f->z[0] = z[0], f->z[1] = z[1], f->sent = info.source_timestamp;
    }
  }
}

/* The torque the arm applied over tick k-1 before sample k is estimated (docs/live-load.md,
 * "Torque and sample"): an arm publishes it on the effort topic just before sample k, DDS
 * does not order two topics, and without it the step k-1 -> k takes this node's command of
 * k-1, not the older one a free-running arm may have applied (a false innovation).  Waited
 * for, up to half a period (an estimator without a controller, whose wait delays no command:
 * up to 20 periods, as a log played at its pace needs on a loaded machine), when the effort
 * stream is live (the effort of k-2 came; at ticks 1 and 2 before any came: the topic has a
 * publisher) and that of k-1 did not yet; counted, and in vain counted too (the command, or
 * the last torque, is used then).
 * 1 when it waited. */
static int await_effort(node_t *s, long long ns) {
  live_loop *L = &s->L;
  int ok;
  long k = live_tick_of(L, ns, &ok);
  if (L->k < 0 || !ok || k != L->k + 1 || s->eff_last >= k - 1) return 0;
  if (s->eff_last < k - 2) { /* not live; at the start: live when the topic has a publisher */
    size_t pubs = 0;
    if (s->eff_last >= 0 || k > 2 ||
        rcl_subscription_get_publisher_count(&s->sub_eff, &pubs) != RCL_RET_OK || pubs < 1)
      return 0;
  }
  ++s->eff_waits;
  double until = amsfe_mono_s() + (L->controller ? 0.5 : 20.0) * s->T;
  while (s->eff_last < k - 1 && !amsfe_signal && s->stop_code < 0) {
    double left = until - amsfe_mono_s();
    if (left <= 0) {
      ++s->eff_missed;
      break;
    }
    if (rcl_wait_set_clear(&s->ws_eff) != RCL_RET_OK ||
        rcl_wait_set_add_subscription(&s->ws_eff, &s->sub_eff, NULL) != RCL_RET_OK) {
      rcutils_reset_error();
      break;
    }
    rcl_ret_t ret = rcl_wait(&s->ws_eff, (int64_t)(left * 1e9) + 1);
    if (ret != RCL_RET_OK && ret != RCL_RET_TIMEOUT) rcutils_reset_error();
    take_efforts(s);
  }
  return 1;
}

static void take_efforts(node_t *s) {
  rmw_message_info_t info;
  while (s->stop_code < 0 &&
         rcl_take_serialized_message(&s->sub_eff, &s->in, &info, NULL) == RCL_RET_OK) {
    long long ns;
    int has_eff;
    double *pos = s->stdv, *vel = s->stdv + s->n; /* scratch */
    if (!s->active || read_joint_state(s, &ns, pos, vel, s->eff, &has_eff) < 0) continue;
    int ok;
    long j = live_tick_of(&s->L, ns, &ok);
    if (ok && s->L.k >= 0 && j > s->eff_last) s->eff_last = j;
    live_applied(&s->L, ns, s->eff);
    record_effort(s, ns, s->eff);
  }
}

static void take_truth(node_t *s) {
  rmw_message_info_t info;
  record_t *R = &s->rec;
  while (rcl_take_serialized_message(&s->sub_truth, &s->in, &info, NULL) == RCL_RET_OK) {
    cdr_in r;
    cdr_in_init(&r, s->in.buffer, s->in.buffer_length);
    (void)cdr_u32(&r), (void)cdr_u32(&r); /* layout: no dims expected */
    int count;
    cdr_doubles(&r, s->truth, s->N, &count);
    if (!r.ok || count != s->N) continue;
    if (R->n_truth >= R->cap_truth) { /* matched to its tick when written (cnode.py) */
      ++R->lost;
      continue;
    }
    R->truth_sent[R->n_truth] = info.source_timestamp;
    memcpy(R->truth_x + R->n_truth * s->N, s->truth, sizeof(double) * (size_t)s->N);
    ++R->n_truth;
  }
}

/* The last estimate's std and theta if not out yet, then the hold command (with a
 * controller), acknowledged within 0.5 s; its list for the stop line into `held`. */
static void publish_hold(node_t *s, char *held, size_t cap) {
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

/* A lifecycle transition of a managed node (amsfe_lifecycle.h). */
static void on_lifecycle(void *ctx, int event) {
  node_t *s = ctx;
  char held[1024];
  if (event == LC_ACTIVATE) {
    amsfe_watchdog_reset(s->wd); /* its clock starts again at the next sample */
    s->active = 1, s->started = 0;
  } else if (event == LC_DEACTIVATE) {
    s->active = 0, s->started = 0;
    publish_hold(s, held, sizeof held);
  } else if (event == LC_SHUTDOWN) {
    s->active = 0;
    snprintf(s->stop_line, sizeof s->stop_line, "shut down by its lifecycle manager");
    s->stop_code = 0;
  }
}

static int cmp_double(const void *a, const void *b) {
  double x = *(const double *)a, y = *(const double *)b;
  return (x > y) - (x < y);
}

/* numpy's default percentile (linear between the two nearest ranks) of sorted v. */
static double percentile(const double *v, long n, double q) {
  double at = q * (double)(n - 1);
  long lo = (long)floor(at);
  long hi = lo + 1 < n ? lo + 1 : lo;
  return v[lo] + (at - (double)lo) * (v[hi] - v[lo]);
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

static void write_record(node_t *s, const char *path) {
  record_t *R = &s->rec;
  int n = s->n, N = s->N;
  char tmp[4096];
  snprintf(tmp, sizeof tmp, "%s.tmp", path);
  FILE *f = fopen(tmp, "wb");
  if (!f) {
    fprintf(stderr, "error: amsfe_node: cannot write the record %s: %s\n", path, strerror(errno));
    return;
  }
  long long hold_ns = R->hold_ns;
  rec_section(f, "ns", 'q', R->ticks, 1, R->ns, 8);
  rec_section(f, "z", 'd', R->ticks, 2 * n, R->z, 8);
  rec_section(f, "x", 'd', R->ticks, N, R->x, 8);
  rec_section(f, "std", 'd', R->ticks, N, R->std, 8);
  rec_section(f, "u", 'd', R->ticks, n, R->u, 8);
  rec_section(f, "sent", 'q', R->ticks, 1, R->sent, 8);
  rec_section(f, "truth_sent", 'q', R->n_truth, 1, R->truth_sent, 8);
  rec_section(f, "truth_x", 'd', R->n_truth, N, R->truth_x, 8);
  rec_section(f, "eff_ns", 'q', R->n_eff, 1, R->eff_ns, 8);
  rec_section(f, "eff_u", 'd', R->n_eff, n, R->eff_u, 8);
  rec_section(f, "fr_ns", 'q', R->n_fr, 1, R->fr_ns, 8);
  rec_section(f, "fr_exp", 'q', R->n_fr, 1, R->fr_exp, 8);
  rec_section(f, "fr_z", 'd', R->n_fr, 2, R->fr_z, 8);
  rec_section(f, "diag_ns", 'q', R->n_diag, 1, R->diag_ns, 8);
  rec_section(f, "diag_text", 'c', (long)R->diag_used, 1, R->diag_text, 1);
  rec_section(f, "hold_ns", 'q', R->has_hold, 1, &hold_ns, 8);
  rec_section(f, "hold_u", 'd', R->has_hold, n, R->hold_u, 8);
  int64_t lost = R->lost;
  rec_section(f, "lost", 'q', 1, 1, &lost, 8);
  /* how the node stopped: its line, exit code, the watchdog's reason ("" : none) */
  amsfe_watchdog_state ws;
  amsfe_watchdog_get_state(s->wd, &ws);
  const char *wd_name = ws.reason != AMSFE_WD_NONE ? amsfe_watchdog_reason_name(ws.reason) : "";
  int64_t code = s->exit_code;
  rec_section(f, "stop_line", 'c', (long)strlen(s->stop_line), 1, s->stop_line, 1);
  rec_section(f, "stop_code", 'q', 1, 1, &code, 8);
  rec_section(f, "stop_wd", 'c', (long)strlen(wd_name), 1, wd_name, 1);
  int bad = ferror(f);
  bad |= fclose(f) != 0;
  if (bad || rename(tmp, path) != 0)
    fprintf(stderr, "error: amsfe_node: cannot write the record %s\n", path);
}

/* --replay EVENTS: the live loop alone, without rcl, on messages from a text file, one a
 * line ("frame EXPOSURE_NS U V SENT", "applied STAMP_NS U1..Un", "enc STAMP_NS SENT Z1..Z2n";
 * stamps in ns); prints per encoder sample "tick K X1..XN U1..Un" (17 digits), "skip" or
 * "stop R", then "skipped REASON COUNT" and "counters APPLIED REJECTED ENC_REJECTED".
 * tests/test_cnode.py compares it with the Python LiveLoop on the same messages. */
static int replay(node_t *s, const char *path) {
  live_loop *L = &s->L;
  int n = s->n, N = s->N;
  FILE *f = fopen(path, "r");
  if (!f) return EXIT_BAD_INPUT;
  char line[8192];
  double v[3 * MAX_JOINTS + 8];
  while (fgets(line, sizeof line, f)) {
    char *tok = strtok(line, " \n");
    if (!tok) continue;
    int kind = strcmp(tok, "frame") == 0 ? 0 : strcmp(tok, "applied") == 0 ? 1 : 2;
    long long a = strtoll(strtok(NULL, " \n"), NULL, 10), b = 0;
    if (kind == 2) b = strtoll(strtok(NULL, " \n"), NULL, 10);
    int m = 0, cap = kind == 0 ? 2 : kind == 1 ? n : 2 * n;
    for (char *t; m < cap && (t = strtok(NULL, " \n"));) v[m++] = strtod(t, NULL);
    if (kind == 0) {
      char *t = strtok(NULL, " \n");
      live_frame_in(L, a, v, t ? strtoll(t, NULL, 10) : 0);
    } else if (kind == 1) {
      live_applied(L, a, v);
    } else {
      int r = live_encoders(L, a, v, b);
      if (r == 0) {
        printf("skip\n");
      } else if (r == LIVE_BAD_STAMPS) {
        char why[768];
        live_bad_stamp_line(L, why, sizeof why);
        printf("stop %d %s\n", r, why);
        break;
      } else if (r < 0) {
        printf("stop %d\n", r);
        break;
      } else {
        printf("tick %ld", L->k);
        for (int i = 0; i < N; ++i) printf(" %.17g", L->x[i]);
        for (int j = 0; j < n; ++j) printf(" %.17g", L->controller ? L->u[j] : NAN);
        printf("\n");
      }
    }
  }
  fclose(f);
  for (int i = 0; i < SKIP_REASONS; ++i)
    if (L->skipped[i]) printf("skipped %s|%ld\n", LIVE_SKIP_TEXT[i], L->skipped[i]);
  printf("counters %ld %ld %ld\n", L->c.frames_applied, L->c.frames_rejected,
         L->c.encoder_rejected);
  return 0;
}

int main(int argc, char **argv) {
  if (argc < 2 || argv[1][0] == '-') {
    fprintf(stderr, "usage: %s PARAMS [--ros-args ...]  (run by amsfe node --impl c)\n", argv[0]);
    return EXIT_BAD_INPUT;
  }
  static node_t S;
  amsfe_program_start("amsfe_node");
  node_t *s = &S;
  s->stop_code = -1;
  s->first_command = 1;
  s->std_k = -1;
  configure(s, argv[1]);
  live_loop *L = &s->L;
  int n = s->n, N = s->N;
  if (live_init(L) != AMSFE_OK) return 1;
  if (argc == 4 && strcmp(argv[2], "--replay") == 0) return replay(s, argv[3]);
  params_file *pf = &s->pf;
  const char *qos_tok[4];
  if (pf_tokens(pf, "qos", qos_tok, 4, 0) != 4)
    pf_fail(pf, "qos", "reliability, depth, encoder depth, camera depth", "another count");
  const char *reliability = qos_tok[0];
  int depth = (int)pf_parse_long(pf, "qos", qos_tok[1]);
  int depth_enc = (int)pf_parse_long(pf, "qos", qos_tok[2]);
  int depth_cam = (int)pf_parse_long(pf, "qos", qos_tok[3]);
  const char *rec_tok[2];
  int rec_n = pf_tokens(pf, "record", rec_tok, 2, 1);
  const char *record_path = rec_n == 2 ? rec_tok[0] : NULL;
  s->recording = record_path != NULL;
  int priority = (int)pf_long(pf, "sched_priority");
  /* ---- buffers of the run, allocated once */
  s->pos = ALLOC(double, MAX_JOINTS), s->vel = ALLOC(double, MAX_JOINTS);
  s->eff = ALLOC(double, MAX_JOINTS), s->z = ALLOC(double, 2 * n);
  s->u_hold = ALLOC(double, n), s->stdv = ALLOC(double, 2 * n + MAX_JOINTS);
  s->theta_buf = ALLOC(double, MAX_JOINTS > N ? MAX_JOINTS : N);
  s->truth = ALLOC(double, N), s->last_x = ALLOC(double, N), s->last_P_diag = ALLOC(double, N);
  s->diag = ALLOC(char, DIAG_CAP);
  long long sz_arg, sz_res, sz_iw, sz_w;
  gravity_work(&sz_arg, &sz_res, &sz_iw, &sz_w);
  s->g_arg = (const double **)ALLOC(double *, sz_arg + 2);
  s->g_res = ALLOC(double *, sz_res + 1);
  s->g_iw = ALLOC(long long, sz_iw + 1), s->g_w = ALLOC(double, sz_w + 1);
  long cap = s->end_k >= 0 ? s->end_k + 1 : (L->K_ref > 0 ? L->K_ref : 100000);
  s->cap_lat = cap, s->lat = ALLOC(double, cap), s->lat_kind = ALLOC(unsigned char, cap);
  s->prev_kind = LAT_OTHER;
  if (s->recording) {
    record_t *R = &s->rec;
    R->cap = cap;
    R->ns = ALLOC(long long, cap), R->z = ALLOC(double, cap * 2 * n);
    R->x = ALLOC(double, cap * N), R->std = ALLOC(double, cap * N);
    R->u = ALLOC(double, cap * n), R->sent = ALLOC(long long, cap);
    R->cap_truth = cap + 64, R->truth_sent = ALLOC(long long, R->cap_truth);
    R->truth_x = ALLOC(double, R->cap_truth * N);
    R->cap_eff = 2 * cap, R->eff_ns = ALLOC(long long, R->cap_eff);
    R->eff_u = ALLOC(double, R->cap_eff * n);
    R->cap_fr = cap, R->fr_ns = ALLOC(long long, cap), R->fr_exp = ALLOC(long long, cap);
    R->fr_z = ALLOC(double, 2 * cap);
    R->cap_diag = cap, R->diag_ns = ALLOC(long long, cap), R->diag_at = ALLOC(long, cap);
    R->diag_bytes = (size_t)cap * 256 + DIAG_CAP, R->diag_text = ALLOC(char, R->diag_bytes);
    R->hold_u = ALLOC(double, n);
  }
  /* ---- rcl: context, node, subscriptions, publishers, wait set */
  rcl_allocator_t alloc = amsfe_rcl_start(argc, argv, &s->ctx, &s->node, "amsfe_node", "node", priority);
  const amsfe_types ty = amsfe_message_types();
  const rosidl_message_type_support_t *ts_str = ROSIDL_GET_MSG_TYPE_SUPPORT(std_msgs, msg, String);
  rcl_subscription_options_t so = rcl_subscription_get_default_options();
  /* the camera first, as the Python node subscribes it */
  so.qos = amsfe_qos(reliability, depth_cam);
  s->sub_cam = rcl_get_zero_initialized_subscription();
  amsfe_rcl_check(rcl_subscription_init(&s->sub_cam, &s->node, ty.point_stamped, s->topic[T_CAM], &so), "camera subscription");
  so.qos = amsfe_qos(reliability, depth);
  s->sub_truth = rcl_get_zero_initialized_subscription();
  if (s->recording)
    amsfe_rcl_check(rcl_subscription_init(&s->sub_truth, &s->node, ty.f64_array, s->topic[T_TRUTH], &so), "truth subscription");
  so.qos = amsfe_qos(reliability, depth_enc);
  s->sub_eff = rcl_get_zero_initialized_subscription();
  int sub_eff = s->read_effort && !s->effort_in_encoders;
  if (sub_eff)
    amsfe_rcl_check(rcl_subscription_init(&s->sub_eff, &s->node, ty.joint_state, s->topic[T_EFF], &so), "effort subscription");
  s->sub_enc = rcl_get_zero_initialized_subscription();
  amsfe_rcl_check(rcl_subscription_init(&s->sub_enc, &s->node, ty.joint_state, s->topic[T_ENC], &so), "encoder subscription");
  rcl_publisher_options_t po = rcl_publisher_get_default_options();
  po.qos = amsfe_qos(reliability, depth);
  s->pub_est = rcl_get_zero_initialized_publisher();
  amsfe_rcl_check(rcl_publisher_init(&s->pub_est, &s->node, ty.joint_state, s->topic[T_EST], &po), "estimate publisher");
  s->pub_std = rcl_get_zero_initialized_publisher();
  amsfe_rcl_check(rcl_publisher_init(&s->pub_std, &s->node, ty.joint_state, s->topic[T_STD], &po), "estimate_std publisher");
  s->pub_theta = rcl_get_zero_initialized_publisher();
  amsfe_rcl_check(rcl_publisher_init(&s->pub_theta, &s->node, ty.f64_array, s->topic[T_THETA], &po), "theta publisher");
  s->pub_diag = rcl_get_zero_initialized_publisher();
  amsfe_rcl_check(rcl_publisher_init(&s->pub_diag, &s->node, ts_str, s->topic[T_DIAG], &po), "diagnostics publisher");
  s->pub_cmd = rcl_get_zero_initialized_publisher();
  if (L->controller)
    amsfe_rcl_check(rcl_publisher_init(&s->pub_cmd, &s->node, ty.f64_array, s->topic[T_CMD], &po), "command publisher");
  s->in = amsfe_message_buffer(MSG_CAP);
  int pos_vel[3] = {n, n, 0}; /* position and velocity, effort empty */
  amsfe_out_joint_state(&s->m_est, s->names, n, pos_vel);
  amsfe_out_joint_state(&s->m_std, s->names, n, pos_vel);
  amsfe_out_f64_array(&s->m_theta, s->p);
  amsfe_out_f64_array(&s->m_cmd, n);
  amsfe_out_alloc(&s->m_diag, DIAG_CAP + 64);
  s->ws = rcl_get_zero_initialized_wait_set();
  if (s->managed) amsfe_rcl_check(lifecycle_init(&s->lc, &s->node), "the lifecycle state machine");
  amsfe_rcl_check(rcl_wait_set_init(&s->ws, 4, 0, 0, 0, s->managed ? LIFECYCLE_SERVICES : 0, 0, &s->ctx,
                               alloc),
            "wait set");
  s->ws_eff = rcl_get_zero_initialized_wait_set();
  s->eff_last = -1;
  if (sub_eff) amsfe_rcl_check(rcl_wait_set_init(&s->ws_eff, 1, 0, 0, 0, 0, 0, &s->ctx, alloc), "wait set");
  printf("node: C node on rcl (%s), waiting for %s\n", s->topic[T_ENC],
         s->managed ? "configure and activate" : "encoders");
  fflush(stdout);
  /* ---- the loop: wait, take, tick, publish */
  double quiet_since = amsfe_mono_s(), said = 0.0; /* before the first sample: said every 10 s */
  while (s->stop_code < 0 && !amsfe_signal) {
    rcl_ret_t add = rcl_wait_set_clear(&s->ws);
    if (add == RCL_RET_OK) add = rcl_wait_set_add_subscription(&s->ws, &s->sub_enc, NULL);
    if (add == RCL_RET_OK) add = rcl_wait_set_add_subscription(&s->ws, &s->sub_cam, NULL);
    if (add == RCL_RET_OK && sub_eff) add = rcl_wait_set_add_subscription(&s->ws, &s->sub_eff, NULL);
    if (add == RCL_RET_OK && s->recording)
      add = rcl_wait_set_add_subscription(&s->ws, &s->sub_truth, NULL);
    if (add == RCL_RET_OK && s->managed) add = lifecycle_wait_add(&s->lc, &s->ws);
    amsfe_rcl_check(add, "the wait set");
    rcl_ret_t ret = rcl_wait(&s->ws, RCL_MS_TO_NS(50));
    if (ret != RCL_RET_OK && ret != RCL_RET_TIMEOUT) break;
    if (s->managed) /* a response kept for a second try may block 100 ms: not once samples flow */
      lifecycle_serve(&s->lc, !(s->active && s->started), on_lifecycle, s);
    take_frames(s);
    if (sub_eff) take_efforts(s);
    if (s->recording) take_truth(s);
    rmw_message_info_t info;
    long got = 0;
    /* every sample there, in their order: a late burst is caught up, not held */
    while (s->stop_code < 0 && !amsfe_signal &&
           rcl_take_serialized_message(&s->sub_enc, &s->in, &info, NULL) == RCL_RET_OK)
      on_encoders(s, info.source_timestamp, info.received_timestamp, amsfe_mono_s()), ++got;
    if (s->stop_code < 0 && !amsfe_signal && got == 0 && s->active && !s->started) {
      double silent = amsfe_mono_s() - quiet_since;
      if (silent > said + 10.0) {
        said = silent - fmod(silent, 10.0);
        say_waiting(s, silent);
      }
    }
    if (s->stop_code < 0 && !amsfe_signal && got == 0 && s->active && s->started) {
      /* no sample: the stall watchdogs */
      size_t publishers = 0;
      int known = rcl_subscription_get_publisher_count(&s->sub_enc, &publishers) == RCL_RET_OK;
      if (amsfe_watchdog_idle(s->wd, amsfe_mono_s(), known ? (int)publishers : -1) != AMSFE_WD_NONE) {
        amsfe_watchdog_format(s->wd, s->stop_line, sizeof s->stop_line); /* as the Python node */
        s->stop_code = EXIT_HOLD;
      }
    }
  }
  /* ---- the stop: the last estimate's std and theta, then the hold command */
  int code = s->stop_code;
  char held[1024] = "";
  publish_hold(s, held, sizeof held);
  if (amsfe_signal && code < 0) {
    printf("node: hold: interrupted%s\n", held);
    snprintf(s->stop_line, sizeof s->stop_line, "hold: interrupted");
    code = amsfe_signal == SIGTERM ? 143 : 130;
  } else if (code == EXIT_BAD_INPUT) {
    printf("node: stopped on bad input%s\n", held);
    fprintf(stderr, "error: %s\n", s->stop_line);
  } else if (code < 0) {
    printf("node: shutdown%s\n", held);
    snprintf(s->stop_line, sizeof s->stop_line, "shutdown");
    code = 0;
  } else {
    printf("node: %s%s\n", s->stop_line, held);
  }
  if (s->n_lat > 0) { /* the p99 of each kind of tick (bench --ros reads it), then the whole */
    double *by = ALLOC(double, s->n_lat);
    printf("node: latency p99 by tick [ms]:");
    for (int kind = 0, said = 0; kind < LAT_KINDS; ++kind) {
      long m = 0;
      for (long i = 0; i < s->n_lat; ++i)
        if (s->lat_kind[i] == kind) by[m++] = s->lat[i];
      qsort(by, (size_t)m, sizeof(double), cmp_double);
      if (m)
        printf("%s %s %.3f (%ld)", said++ ? "," : "", LAT_KIND_NAME[kind],
               1e3 * percentile(by, m, 0.99), m);
    }
    printf("\n");
    free(by);
  }
  if (s->n_lat > 0) { /* the node's own latency (the Python node's line: bench --ros reads it) */
    double *l = s->lat;
    qsort(l, (size_t)s->n_lat, sizeof(double), cmp_double); /* at the stop */
    printf("node: latency sample received -> command published p50 %.3f p99 %.3f max %.3f ms "
           "over %ld commands\n", 1e3 * percentile(l, s->n_lat, 0.5),
           1e3 * percentile(l, s->n_lat, 0.99), 1e3 * l[s->n_lat - 1], s->n_lat);
  }
  if (s->eff_waits > 0)
    printf("node: waited for the torque applied over the previous tick at %ld samples (%ld not "
           "within the wait: estimated without it)\n", s->eff_waits, s->eff_missed);
  int any_skip = 0; /* what the loop skipped, by reason (the diagnostics JSON's words) */
  for (int i = 0; i < SKIP_REASONS; ++i)
    if (L->skipped[i])
      printf("%s%s: %ld", any_skip++ ? ", " : "node: skipped: ", LIVE_SKIP_TEXT[i], L->skipped[i]);
  if (any_skip) printf("\n");
  fflush(stdout);
  s->exit_code = code;
  if (s->recording) take_truth(s); /* a last tick's truth can come after its sample */
  if (s->recording) write_record(s, record_path);
  if (s->managed) lifecycle_fini(&s->lc, &s->node);
  (void)rcl_wait_set_fini(&s->ws_eff); /* (zero-initialised without an effort topic) */
  rcl_publisher_t *const pubs[] = {&s->pub_cmd, &s->pub_est, &s->pub_std, &s->pub_theta,
                                   &s->pub_diag};
  rcl_subscription_t *const subs[] = {&s->sub_enc, &s->sub_cam, &s->sub_eff, &s->sub_truth};
  amsfe_rcl_stop(&s->ws, pubs, 5, subs, 4, &s->node, &s->ctx);
  return code;
}
