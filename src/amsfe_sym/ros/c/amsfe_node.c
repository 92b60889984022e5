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
 *
 * The node's state is one node_t (amsfe_node.h), shared by its files, one concept each:
 * this one the program (start, the loop, the stop, --replay); amsfe_node_config.c the
 * parameter file; amsfe_node_intake.c the messages taken; amsfe_node_sample.c the
 * per-sample path; amsfe_node_publish.c what it publishes; amsfe_node_record.c the record.
 */
#define _GNU_SOURCE
#include <math.h>
#include <signal.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include <std_msgs/msg/string.h>

#include "amsfe_node.h"

/* the names of enum lat_kind (amsfe_node.h), as the stop's latency line prints them */
static const char *const LAT_KIND_NAME[LAT_KINDS] = {
    "first 10", "frame fused or refused", "after a frame tick", "after a std tick", "others"};

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
