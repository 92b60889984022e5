/* amsfe_arm_commands.c: what the C arm takes from the node (amsfe_arm.c): the commands
 * (the newest valid one, counted), the estimates' latency, the wait for them, and the
 * refusal of two controllers on the command topic. */
#define _GNU_SOURCE
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include <rcl/graph.h>
#include <rcutils/types/string_array.h>
#include <rcutils/error_handling.h>
#include <rmw/topic_endpoint_info_array.h>

#include "amsfe_arm.h"

static void gid_text(const rmw_gid_t *g, char *out) {
  for (int i = 0; i < 8; ++i) sprintf(out + 2 * i, "%02x", g->data[i]);
}

/* The node names of the publishers of the command topic, " and "-joined, into out; with
 * gids, the names of those two publishers (their GIDs when not on the graph). */
static void publisher_names(arm_t *s, const rmw_gid_t *gids, char *out, size_t cap) {
  rcl_allocator_t a = rcl_get_default_allocator();
  rmw_topic_endpoint_info_array_t info = rmw_get_zero_initialized_topic_endpoint_info_array();
  const char *topic = rcl_subscription_get_topic_name(&s->sub_cmd); /* remapped, resolved */
  int ok = topic && rcl_get_publishers_info_by_topic(&s->node, &a, topic, false, &info) == RCL_RET_OK;
  if (!ok) rcutils_reset_error();
  out[0] = 0;
  size_t len = 0;
  int count = gids ? 2 : ok ? (int)info.size : 0;
  for (int i = 0; i < count; ++i) {
    char name[160] = "";
    if (gids) {
      for (size_t j = 0; ok && j < info.size; ++j)
        if (memcmp(info.info_array[j].endpoint_gid, gids[i].data, RMW_GID_STORAGE_SIZE) == 0)
          snprintf(name, sizeof name, "%s%s%s", info.info_array[j].node_namespace,
                   strcmp(info.info_array[j].node_namespace, "/") ? "/" : "",
                   info.info_array[j].node_name);
      if (!name[0]) {
        char hex[17];
        gid_text(&gids[i], hex);
        snprintf(name, sizeof name, "a publisher (GID %s...)", hex);
      }
    } else {
      snprintf(name, sizeof name, "%s%s%s", info.info_array[i].node_namespace,
               strcmp(info.info_array[i].node_namespace, "/") ? "/" : "",
               info.info_array[i].node_name);
    }
    len += (size_t)snprintf(out + len, len < cap ? cap - len : 0, "%s%s", i ? " and " : "", name);
  }
  if (ok) rmw_topic_endpoint_info_array_fini(&info, &a);
  if (!out[0]) snprintf(out, cap, "two publishers (the graph names neither)");
}

/* Warn (once) of another node with this one's name on the graph (graph.py's
 * duplicate_name_warning; asked at the start, at t = 1 s in lockstep and before a refusal:
 * the graph query allocates, so never on a free-running tick). */
static int g_warned = 0;
void warn_duplicate(arm_t *s) {
  if (g_warned) return;
  rcl_allocator_t a = rcl_get_default_allocator();
  rcutils_string_array_t names = rcutils_get_zero_initialized_string_array();
  rcutils_string_array_t spaces = rcutils_get_zero_initialized_string_array();
  if (rcl_get_node_names(&s->node, a, &names, &spaces) != RCL_RET_OK) {
    rcutils_reset_error();
    return;
  }
  const char *me = rcl_node_get_name(&s->node), *ns = rcl_node_get_namespace(&s->node);
  int same = 0;
  for (size_t i = 0; i < names.size; ++i)
    same += names.data[i] && spaces.data[i] && strcmp(names.data[i], me) == 0 &&
            strcmp(spaces.data[i], ns) == 0;
  if (same > 1) {
    g_warned = 1;
    printf("sim-node: warning: %d nodes named %s%s%s on this ROS_DOMAIN_ID: their parameters, "
           "services and logs mix; stop the other one or rename this one (--ros-args -r "
           "__node:=NAME)\n", same, ns, strcmp(ns, "/") ? "/" : "", me);
    fflush(stdout);
  }
  (void)rcutils_string_array_fini(&names);
  (void)rcutils_string_array_fini(&spaces);
}

int two_controllers(arm_t *s, const rmw_gid_t *gids) {
  char names[1024], line[1600];
  /* the graph may know the endpoints before their nodes' names: up to 3 s for them */
  for (int i = 0; i < 30; ++i) {
    publisher_names(s, gids, names, sizeof names);
    if (!strstr(names, "_UNKNOWN_")) break;
    struct timespec ts = {0, 100000000};
    nanosleep(&ts, NULL);
  }
  warn_duplicate(s);
  snprintf(line, sizeof line,
           "sim-node --lockstep commands on %s: expected one controller (a lockstep arm applies "
           "the k-th command received at tick k), found commands from %s. Fix: stop all but one "
           "controller on this ROS_DOMAIN_ID (or give each arm its own topics or domain)",
           s->t_cmd, names);
  fail(s, line);
  return EXIT_REFUSED;
}

/* Take every command waiting: the newest valid one in cmd_last, counted. */
static void take_commands(arm_t *s) {
  rmw_message_info_t info;
  int n = s->n;
  double v[MAX_JOINTS];
  while (rcl_take_serialized_message(&s->sub_cmd, &s->in, &info, NULL) == RCL_RET_OK) {
    if (s->lockstep) {
      if (!s->have_controller) {
        s->controller = info.publisher_gid, s->have_controller = 1;
      } else if (memcmp(info.publisher_gid.data, s->controller.data, RMW_GID_STORAGE_SIZE) != 0) {
        if (!s->intruder) s->other = info.publisher_gid, s->intruder = 1;
        continue; /* not applied: the run stops at this tick */
      }
    }
    long seq = (long)info.publication_sequence_number;
    long i = seq >= 1 ? seq - 1 : s->received;
    if (i >= 0 && i < s->K && s->n_cmd_lat < s->K)
      s->cmd_lat[s->n_cmd_lat++] = info.received_timestamp - s->sent_at[i];
    s->received++;
    cdr_in r;
    cdr_in_init(&r, s->in.buffer, s->in.buffer_length);
    uint32_t dims = cdr_u32(&r);
    for (uint32_t d = 0; d < dims && r.ok; ++d) (void)cdr_string(&r), cdr_u32(&r), cdr_u32(&r);
    (void)cdr_u32(&r); /* data_offset */
    int count = 0;
    cdr_doubles(&r, v, MAX_JOINTS, &count);
    int ok = r.ok && count == n;
    for (int j = 0; ok && j < n; ++j) ok = isfinite(v[j]);
    if (!ok) {
      fprintf(stderr, "[WARN] [amsfe_sim]: command of %d values refused (need %d finite)\n",
              count, n);
      continue;
    }
    memcpy(s->cmd_last, v, sizeof(double) * (size_t)n);
    s->commands++, s->cmd_new++;
  }
}

static void take_estimates(arm_t *s) {
  rmw_message_info_t info;
  while (rcl_take_serialized_message(&s->sub_est, &s->in, &info, NULL) == RCL_RET_OK) {
    long seq = (long)info.publication_sequence_number;
    long i = seq >= 1 ? seq - 1 : s->n_est_lat;
    if (i >= 0 && i < s->K && s->n_est_lat < s->K)
      s->est_lat[s->n_est_lat++] = info.received_timestamp - s->sent_at[i];
  }
}

/* Wait up to timeout_ns for a command or an estimate; take them. */
void wait_messages(arm_t *s, long long timeout_ns) {
  rcl_ret_t add = rcl_wait_set_clear(&s->ws);
  if (add == RCL_RET_OK) add = rcl_wait_set_add_subscription(&s->ws, &s->sub_cmd, NULL);
  if (add == RCL_RET_OK) add = rcl_wait_set_add_subscription(&s->ws, &s->sub_est, NULL);
  amsfe_rcl_check(add, "the wait set");
  rcl_ret_t ret = rcl_wait(&s->ws, timeout_ns > 0 ? timeout_ns : 0);
  if (ret != RCL_RET_OK && ret != RCL_RET_TIMEOUT) rcutils_reset_error();
  take_commands(s);
  take_estimates(s);
}
