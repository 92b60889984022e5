/* amsfe_node_intake.c: what the C node takes from its subscriptions (amsfe_node.c):
 * the encoders' JointState read, the camera's frames, the applied torque (and the wait
 * for it), the truth when it records, and the line of a node that receives nothing. */
#define _GNU_SOURCE
#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <string.h>

#include <rcl/graph.h>
#include <rcutils/error_handling.h>

#include "amsfe_node.h"

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
int read_joint_state(node_t *s, long long *ns, double *pos, double *vel, double *eff,
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

/* What a node that has received no encoder sample for `seconds` prints (the Python node's
 * middleware.waiting_line, word for word): the topic it waits on, its type, and what the graph
 * shows for it: no publisher (and the topics of that type that have one), publishers of another
 * type (a type mismatch), or publishers of the right type delivering nothing.  Called every
 * 10 s before the first sample only (it allocates: never on the sample path). */
void say_waiting(node_t *s, double seconds) {
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

void take_frames(node_t *s) {
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
int await_effort(node_t *s, long long ns) {
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

void take_efforts(node_t *s) {
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

void take_truth(node_t *s) {
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
