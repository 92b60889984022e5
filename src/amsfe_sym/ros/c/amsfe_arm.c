/* amsfe_arm: the simulated arm of `amsfe sim-node --impl c` in C, on rcl (docs/live-load.md,
 * "The C arm").
 *
 *   amsfe_arm PARAMS [--ros-args ...]
 *
 * PARAMS is written by amsfe_sym.ros.carm: the plant's start, theta, and every noise stream
 * of the run drawn in Python by the builders of `amsfe simulate` (sim/compiled.py's
 * simulation_inputs: encoder noise and disturbance per tick, camera noise, drops and jitter
 * per exposure), so a seed gives the samples of the compiled loop and of the Python
 * sim-node bit for bit; the topics, joint names and QoS of the Python sim-node
 * (ros/sim_node.py); the faults (ros/faults.py).
 *
 * Tick k: /clock (t_k), the truth x_k, the camera frames delivered at k (stamped with their
 * exposure), the encoder sample k (stamped t_k; a fault changes it); then the command: in
 * lockstep the k-th command received (waited for, bounded), free running the newest one
 * received before the tick's end on the wall clock (clock_nanosleep TIMER_ABSTIME on
 * CLOCK_MONOTONIC, one tick every T / rate; none new: the previous one is applied again,
 * counted); the torque applied over [t_k, t_k+1] goes out on the effort topic stamped t_k,
 * and the plant (the library's RK4 plant_step with the tick's disturbance) advances.
 *
 * The camera and the encoders are amsfe_loop.c's (amsfe_sim_run's expose / camera_tick and
 * Encoders.measure), the plant the same generated function.  SCHED_FIFO and mlockall when
 * permitted (else one line); everything is allocated before tick 0, nothing after.
 *
 * Exit: 0 done; 4 a refusal (no node, a missing command, two controllers): its one line
 * goes to the error file of PARAMS (carm.py raises it); 130 / 143 signals.
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
#include <rcutils/types/string_array.h>
#include <rcutils/error_handling.h>
#include <rmw/serialized_message.h>
#include <rmw/topic_endpoint_info_array.h>
#include <geometry_msgs/msg/point_stamped.h>
#include <rosgraph_msgs/msg/clock.h>
#include <sensor_msgs/msg/joint_state.h>
#include <std_msgs/msg/float64_multi_array.h>

#include "amsfe_cdr.h"
#include "amsfe_rcl.h"
#include "amsfe_node_params.h"

/* the generated library's functions (casadi's calling convention) */
typedef int (*cfun)(const double **arg, double **res, long long *iw, double *w, int mem);
typedef int (*cwork)(long long *sz_arg, long long *sz_res, long long *sz_iw, long long *sz_w);
extern int plant_step(const double **arg, double **res, long long *iw, double *w, int mem);
extern int plant_step_work(long long *, long long *, long long *, long long *);
extern int camera_measure(const double **arg, double **res, long long *iw, double *w, int mem);
extern int camera_measure_work(long long *, long long *, long long *, long long *);

#define EXIT_REFUSED 4
#define MAX_JOINTS 64
#define MSG_CAP 65536



/* ------------------------------------------------------------------ a generated function */
typedef struct {
  cfun f;
  const double **arg;
  double **res;
  long long *iw;
  double *w;
} gfun;

static void gfun_init(gfun *g, cfun f, cwork work) {
  long long a, r, i, w;
  work(&a, &r, &i, &w);
  g->f = f;
  g->arg = (const double **)ALLOC(double *, a + 4);
  g->res = ALLOC(double *, r + 3);
  g->iw = ALLOC(long long, i + 1), g->w = ALLOC(double, w + 1);
}

static int gcall(gfun *g, const double **in, int n_in, double **out, int n_out) {
  for (int i = 0; i < n_in; ++i) g->arg[i] = in[i];
  for (int i = 0; i < n_out; ++i) g->res[i] = out[i];
  return g->f(g->arg, g->res, g->iw, g->w, 0);
}

static void out_point_stamped(amsfe_out *m) { /* messages.point_stamped: frame "camera" */
  amsfe_out_alloc(m, 128);
  cdr_out w;
  cdr_out_init(&w, m->ser.buffer, 128);
  amsfe_put_header(&w, "camera");
  double zero = 0.0;
  cdr_put(&w, &zero, 8, 8);
  m->at[0] = w.pos - 8;
  cdr_put(&w, &zero, 8, 8), cdr_put(&w, &zero, 8, 8);
  if (!w.ok) amsfe_must(NULL, "a PointStamped");
  m->ser.buffer_length = cdr_out_size(&w);
}

static void out_clock(amsfe_out *m) {
  amsfe_out_alloc(m, 16);
  cdr_out w;
  cdr_out_init(&w, m->ser.buffer, 16);
  cdr_put_u32(&w, 0), cdr_put_u32(&w, 0);
  m->ser.buffer_length = cdr_out_size(&w);
}

/* ------------------------------------------------------------------ the arm */
typedef struct {
  long delivery, exposure;
  double z[2];
} pending;

typedef struct {
  params_file pf;
  int n, N, p, lockstep;
  long K;
  long long T_ns;
  double T, rate, start_timeout, command_timeout;
  const char *names[MAX_JOINTS];
  const char *t_enc, *t_cam, *t_eff, *t_truth, *t_cmd, *t_est, *t_clock;
  const char *error_file;
  /* the inputs (sim/compiled.py's simulation_inputs) */
  double *x, *x_next, *theta, *enc_noise, *tau_d, *cam_noise, *cam_uniform, *cam_jitter;
  double enc_resolution;
  int cam_period, cam_phase, cam_delay, round_to_pixel, max_in_flight;
  double cam_width, cam_height, pixel_std, drop_probability;
  long n_exposures, exposures;
  pending *queue, *due;
  int in_flight;
  /* the faults (ros/faults.py: from tick k on; -1 none) */
  long f_frozen, f_jump, f_torque;
  double jump;
  double *frozen, *z, *zs, *u, *applied, *xt, *y, *J, *depth;
  int have_frozen;
  gfun g_plant, g_cam;
  /* rcl */
  rcl_context_t ctx;
  rcl_node_t node;
  rcl_publisher_t pub_enc, pub_cam, pub_eff, pub_truth, pub_clock;
  rcl_subscription_t sub_cmd, sub_est;
  rcl_wait_set_t ws;
  rcl_serialized_message_t in;
  amsfe_out m_enc, m_cam, m_eff, m_truth, m_clock;
  /* the commands */
  long commands;           /* accepted so far */
  long received;           /* taken (accepted or not) */
  double *cmd_last;        /* [n] the newest accepted */
  long cmd_new;            /* accepted since the last tick took one */
  int have_controller, intruder;
  rmw_gid_t controller, other;
  /* latency (the i-th command / estimate answers the i-th sample) */
  long long *sent_at, *cmd_lat, *est_lat;
  long n_cmd_lat, n_est_lat;
} arm_t;

static void fail(arm_t *s, const char *line) { /* carm.py raises it: "error: LINE" */
  FILE *f = s->error_file ? fopen(s->error_file, "w") : NULL;
  if (f) fputs(line, f), fclose(f);
  else fprintf(stderr, "error: %s\n", line);
}

static void configure(arm_t *s, const char *path) {
  params_file *pf = &s->pf;
  pf_open(pf, path);
  int dims[3];
  pf_ints(pf, "dims", dims, 3);
  int n = s->n = dims[0], N = s->N = dims[1];
  s->p = dims[2];
  if (n < 1 || n > MAX_JOINTS || N != 4 * n + s->p) pf_fail(pf, "dims", "n, N = 4n + p, p", "others");
  s->T_ns = pf_long(pf, "T_ns");
  s->T = pf_double(pf, "T");
  s->K = (long)pf_long(pf, "K");
  s->lockstep = (int)pf_long(pf, "lockstep");
  s->rate = pf_double(pf, "rate");
  s->start_timeout = pf_double(pf, "start_timeout");
  s->command_timeout = pf_double(pf, "command_timeout");
  if (pf_tokens(pf, "joints", s->names, MAX_JOINTS, 0) != n)
    pf_fail(pf, "joints", "one name per joint", "another count");
  s->t_enc = pf_string(pf, "topic_encoders"), s->t_cam = pf_string(pf, "topic_camera");
  s->t_eff = pf_string(pf, "topic_effort"), s->t_truth = pf_string(pf, "topic_truth");
  s->t_cmd = pf_string(pf, "topic_commands"), s->t_est = pf_string(pf, "topic_estimate");
  s->t_clock = pf_string(pf, "topic_clock");
  s->error_file = pf_string(pf, "error_file");
  s->enc_resolution = pf_double(pf, "enc_resolution");
  const char *t[16];
  if (pf_tokens(pf, "camera", t, 16, 0) != 10) pf_fail(pf, "camera", "10 values", "another count");
  s->cam_period = (int)pf_parse_long(pf, "camera", t[0]);
  s->cam_phase = (int)pf_parse_long(pf, "camera", t[1]);
  s->cam_delay = (int)pf_parse_long(pf, "camera", t[2]);
  s->cam_width = pf_parse_double(pf, "camera", t[3]);
  s->cam_height = pf_parse_double(pf, "camera", t[4]);
  s->pixel_std = pf_parse_double(pf, "camera", t[5]);
  s->round_to_pixel = (int)pf_parse_long(pf, "camera", t[6]);
  s->drop_probability = pf_parse_double(pf, "camera", t[7]);
  s->n_exposures = (long)pf_parse_long(pf, "camera", t[8]);
  s->max_in_flight = (int)pf_parse_long(pf, "camera", t[9]);
  if (s->cam_period < 1 || s->max_in_flight < 1) pf_fail(pf, "camera", "period, queue >= 1", "less");
  if (pf_tokens(pf, "faults", t, 16, 0) != 4) pf_fail(pf, "faults", "4 values", "another count");
  s->f_frozen = (long)pf_parse_long(pf, "faults", t[0]);
  s->f_jump = (long)pf_parse_long(pf, "faults", t[1]);
  s->jump = pf_parse_double(pf, "faults", t[2]);
  s->f_torque = (long)pf_parse_long(pf, "faults", t[3]);
  /* the inputs: one file of float64, in this order */
  long K = s->K, E = s->n_exposures;
  s->x = ALLOC(double, 4 * n), s->x_next = ALLOC(double, 4 * n), s->theta = ALLOC(double, s->p + 1);
  s->enc_noise = ALLOC(double, K * 2 * n), s->tau_d = ALLOC(double, K * 2 * n);
  s->cam_noise = ALLOC(double, 2 * E), s->cam_uniform = ALLOC(double, E);
  s->cam_jitter = ALLOC(double, E);
  FILE *f = fopen(pf_string(pf, "inputs"), "rb");
  struct {
    double *v;
    long count;
  } parts[] = {{s->x, 4 * n},         {s->theta, s->p},      {s->enc_noise, K * 2 * n},
               {s->tau_d, K * 2 * n}, {s->cam_noise, 2 * E}, {s->cam_uniform, E},
               {s->cam_jitter, E}};
  for (size_t i = 0; i < sizeof parts / sizeof parts[0]; ++i)
    if (!f || fread(parts[i].v, sizeof(double), (size_t)parts[i].count, f) != (size_t)parts[i].count)
      pf_fail(pf, "inputs", "the run's arrays (carm.py)", "a shorter or unreadable file");
  fclose(f);
  s->queue = ALLOC(pending, s->max_in_flight), s->due = ALLOC(pending, s->max_in_flight);
  s->frozen = ALLOC(double, 2 * n), s->z = ALLOC(double, 2 * n), s->zs = ALLOC(double, 2 * n);
  s->u = ALLOC(double, n), s->applied = ALLOC(double, n), s->cmd_last = ALLOC(double, n);
  s->xt = ALLOC(double, N), s->y = ALLOC(double, 2), s->J = ALLOC(double, 2 * N);
  s->depth = ALLOC(double, 1);
  s->sent_at = ALLOC(long long, K), s->cmd_lat = ALLOC(long long, K);
  s->est_lat = ALLOC(long long, K);
  gfun_init(&s->g_plant, plant_step, plant_step_work);
  gfun_init(&s->g_cam, camera_measure, camera_measure_work);
}

/* ------------------------------------------------------------------ the sensors */
static int inside(const arm_t *s, const double *y) {
  return isfinite(y[0]) && isfinite(y[1]) && y[0] >= 0.0 && y[0] < s->cam_width && y[1] >= 0.0 &&
         y[1] < s->cam_height;
}

/* amsfe_loop.c's expose: project, draw (always), decide, queue.  0 or -1 (queue full or the
 * noise arrays too short: a refusal). */
static int expose(arm_t *s, long k) {
  long e = s->exposures;
  if (e >= s->n_exposures) return -1;
  const double *in[2] = {s->x, s->theta};
  double *res[3] = {s->y, s->J, s->depth};
  if (gcall(&s->g_cam, in, 2, res, 3)) s->y[0] = s->y[1] = NAN;
  if (!(s->depth[0] > 0)) s->y[0] = s->y[1] = NAN;
  s->exposures++;
  if (!inside(s, s->y)) return 0;
  double z[2];
  for (int i = 0; i < 2; ++i) {
    z[i] = s->y[i] + s->pixel_std * s->cam_noise[2 * e + i];
    if (s->round_to_pixel) z[i] = nearbyint(z[i]); /* np.round: half to even */
  }
  if (!inside(s, z) || s->cam_uniform[e] < s->drop_probability) return 0;
  if (s->in_flight >= s->max_in_flight) return -1;
  pending *slot = &s->queue[s->in_flight++];
  slot->delivery = k + s->cam_delay + (long)s->cam_jitter[e];
  slot->exposure = k;
  slot->z[0] = z[0], slot->z[1] = z[1];
  return 0;
}

/* amsfe_loop.c's camera_tick: the frames due at k into s->due sorted by exposure; count. */
static int camera_tick(arm_t *s, long k) {
  if (k % s->cam_period == s->cam_phase && expose(s, k) < 0) return -1;
  int count = 0, keep = 0;
  for (int i = 0; i < s->in_flight; ++i) {
    if (s->queue[i].delivery <= k) s->due[count++] = s->queue[i];
    else s->queue[keep++] = s->queue[i];
  }
  s->in_flight = keep;
  for (int i = 1; i < count; ++i) { /* insertion sort: stable, tiny counts */
    pending f = s->due[i];
    int j = i - 1;
    for (; j >= 0 && s->due[j].exposure > f.exposure; --j) s->due[j + 1] = s->due[j];
    s->due[j + 1] = f;
  }
  return count;
}

/* Encoders.measure at x (row k of the noise; row 0 made z0), then the faults' sample. */
static void encoders(arm_t *s, long k) {
  int n = s->n;
  const double *v = s->enc_noise + k * 2 * n;
  for (int j = 0; j < n; ++j) {
    double zq = s->x[2 * n + j] + v[j];
    if (s->enc_resolution > 0) zq = nearbyint(zq / s->enc_resolution) * s->enc_resolution;
    s->z[j] = zq;
    s->z[n + j] = s->x[3 * n + j] + v[n + j];
  }
  memcpy(s->zs, s->z, sizeof(double) * 2 * (size_t)n);
  if (s->f_frozen >= 0 && k >= s->f_frozen) {
    if (!s->have_frozen) memcpy(s->frozen, s->z, sizeof(double) * 2 * (size_t)n), s->have_frozen = 1;
    memcpy(s->zs, s->frozen, sizeof(double) * 2 * (size_t)n);
  }
  if (s->f_jump >= 0 && k >= s->f_jump)
    for (int j = 0; j < n; ++j) s->zs[j] += s->jump;
}

/* ------------------------------------------------------------------ the commands */
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
static void warn_duplicate(arm_t *s) {
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

static int two_controllers(arm_t *s, const rmw_gid_t *gids) {
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
static void wait_messages(arm_t *s, long long timeout_ns) {
  rcl_ret_t add = rcl_wait_set_clear(&s->ws);
  if (add == RCL_RET_OK) add = rcl_wait_set_add_subscription(&s->ws, &s->sub_cmd, NULL);
  if (add == RCL_RET_OK) add = rcl_wait_set_add_subscription(&s->ws, &s->sub_est, NULL);
  amsfe_rcl_check(add, "the wait set");
  rcl_ret_t ret = rcl_wait(&s->ws, timeout_ns > 0 ? timeout_ns : 0);
  if (ret != RCL_RET_OK && ret != RCL_RET_TIMEOUT) rcutils_reset_error();
  take_commands(s);
  take_estimates(s);
}

static int all_finite_x(const arm_t *s) {
  for (int i = 0; i < 4 * s->n; ++i)
    if (!isfinite(s->x[i])) return 0;
  return 1;
}

static int cmp_ll(const void *a, const void *b) {
  long long x = *(const long long *)a, y = *(const long long *)b;
  return (x > y) - (x < y);
}

/* "encoder -> WHAT p50 .. p99 .. max .. ms" of the latencies [ns] (sorted in place). */
static int latency_part(char *out, size_t cap, const char *what, long long *lat, long count) {
  if (count <= 0) return 0;
  qsort(lat, (size_t)count, sizeof(long long), cmp_ll);
  /* numpy's percentile (linear interpolation) */
  double q[2] = {0.5, 0.99}, r[2];
  for (int i = 0; i < 2; ++i) {
    double pos = q[i] * (double)(count - 1);
    long lo = (long)floor(pos);
    long hi = lo + 1 < count ? lo + 1 : lo;
    r[i] = (double)lat[lo] + (pos - (double)lo) * (double)(lat[hi] - lat[lo]);
  }
  return snprintf(out, cap, "encoder -> %s p50 %.3f p99 %.3f max %.3f ms", what, r[0] * 1e-6,
                  r[1] * 1e-6, (double)lat[count - 1] * 1e-6);
}

/* ------------------------------------------------------------------ the run */
static int run(arm_t *s) {
  int n = s->n, N = s->N;
  long K = s->K;
  long late = 0, stale = 0;
  long long period = (long long)llround((double)s->T_ns / s->rate);
  long long epoch = 0, t_start = amsfe_mono_ns();
  long second = lround(1.0 / s->T);
  char line[1600];
  /* wait for a subscriber of the encoders (and, in lockstep, a publisher of the commands) */
  long long deadline = amsfe_mono_ns() + (long long)(s->start_timeout * 1e9);
  for (;;) {
    size_t subs = 0, pubs = 0;
    rcl_publisher_get_subscription_count(&s->pub_enc, &subs);
    rcl_subscription_get_publisher_count(&s->sub_cmd, &pubs);
    if (subs >= 1 && (!s->lockstep || pubs >= 1)) break;
    if (amsfe_signal) return 0;
    if (amsfe_mono_ns() > deadline) {
      snprintf(line, sizeof line,
               "sim-node start: expected a subscriber of %s%s%s, found none within %g s. Fix: "
               "start `amsfe node SCENARIO` on the same ROS_DOMAIN_ID",
               s->t_enc, s->lockstep ? " and a publisher of " : "", s->lockstep ? s->t_cmd : "",
               s->start_timeout);
      fail(s, line);
      return EXIT_REFUSED;
    }
    wait_messages(s, 50000000LL);
  }
  warn_duplicate(s);
  if (s->lockstep) {
    size_t pubs = 0;
    rcl_subscription_get_publisher_count(&s->sub_cmd, &pubs);
    if (pubs > 1) return two_controllers(s, NULL);
  }
  long long t0 = amsfe_mono_ns();
  for (long k = 0; k < K && !amsfe_signal; ++k) {
    long long ns = k * s->T_ns;
    for (int i = 0; i < 3; ++i) {
      long at = i == 0 ? s->f_frozen : i == 1 ? s->f_jump : s->f_torque;
      if (at == k) {
        printf("sim-node: fault %s at t = %.3f s (tick %ld)\n",
               i == 0 ? "encoder_frozen" : i == 1 ? "encoder_jump" : "torque_loss",
               (double)k * s->T, k);
        fflush(stdout);
      }
    }
    /* 1. the sensors at x_k, published: clock, truth, frames, encoders */
    if (!all_finite_x(s)) {
      snprintf(line, sizeof line, "sim-node tick %ld: expected a finite plant state, found NaN "
               "or inf. Fix: check the commands the node sent", k);
      fail(s, line);
      return EXIT_REFUSED;
    }
    amsfe_out_stamp(&s->m_clock, ns);
    amsfe_publish(&s->pub_clock, &s->m_clock);
    memcpy(s->xt, s->x, sizeof(double) * 4 * (size_t)n);
    memcpy(s->xt + 4 * n, s->theta, sizeof(double) * (size_t)s->p);
    amsfe_out_fill(&s->m_truth, 0, s->xt, N);
    amsfe_publish(&s->pub_truth, &s->m_truth);
    int nf = camera_tick(s, k);
    if (nf < 0) {
      fail(s, "sim-node camera: expected the run's camera draws, found too few (or a full "
              "delivery queue). Fix: report it (carm.py draws them)");
      return EXIT_REFUSED;
    }
    for (int i = 0; i < nf; ++i) {
      amsfe_out_stamp(&s->m_cam, s->due[i].exposure * s->T_ns);
      amsfe_out_fill(&s->m_cam, 0, s->due[i].z, 2);
      amsfe_publish(&s->pub_cam, &s->m_cam);
    }
    if (s->lockstep && nf > 0 &&
        rcl_publisher_wait_for_all_acked(&s->pub_cam, (long long)(s->command_timeout * 1e9)) !=
            RCL_RET_OK) {
      rcutils_reset_error();
      fprintf(stderr, "[WARN] [amsfe_sim]: tick %ld: a camera frame not acknowledged within "
              "%g s: the node may fuse it a tick late\n", k, s->command_timeout);
    }
    encoders(s, k);
    s->sent_at[k] = amsfe_wall_ns();
    amsfe_out_stamp(&s->m_enc, ns);
    amsfe_out_fill(&s->m_enc, 0, s->zs, n);
    amsfe_out_fill(&s->m_enc, 1, s->zs + n, n);
    amsfe_publish(&s->pub_enc, &s->m_enc);
    if (k && k % second == 0) {
      printf("sim-node: t = %.1f s\n", (double)k * s->T);
      fflush(stdout);
      if (s->lockstep) warn_duplicate(s);
    }
    /* 2. the command applied over [t_k, t_k+1] */
    if (s->lockstep || k == 0) {
      long long until = amsfe_mono_ns() + (long long)(s->command_timeout * 1e9);
      while (s->commands <= k && !amsfe_signal && !s->intruder) {
        long long left = until - amsfe_mono_ns();
        if (left <= 0) {
          snprintf(line, sizeof line,
                   "sim-node tick %ld (t = %.3f s): expected its command on %s, found none "
                   "within %g s. Fix: start `amsfe node SCENARIO --controller amsfe` on the same "
                   "ROS_DOMAIN_ID, or run without --lockstep",
                   k, (double)k * s->T, s->t_cmd, s->command_timeout);
          fail(s, line);
          return EXIT_REFUSED;
        }
        wait_messages(s, left < 50000000LL ? left : 50000000LL);
      }
      if (amsfe_signal) break;
      if (s->intruder) {
        rmw_gid_t both[2] = {s->controller, s->other};
        return two_controllers(s, both);
      }
      memcpy(s->u, s->cmd_last, sizeof(double) * (size_t)n);
      s->cmd_new = 0;
      if (k == 0) {
        t0 = amsfe_mono_ns();
        epoch = t0 - period; /* tick 0 ends now: tick k ends at epoch + (k + 1) period */
        if (!s->lockstep) {
          printf("sim-node: tick 0 at wall clock %.6f s\n",
                 (double)(amsfe_wall_ns() - (amsfe_mono_ns() - epoch)) * 1e-9);
          fflush(stdout);
        }
      }
    } else {
      long long end = epoch + (k + 1) * period;
      if (amsfe_mono_ns() > end) late++;
      struct timespec ts = {(time_t)(end / 1000000000LL), (long)(end % 1000000000LL)};
      while (!amsfe_signal && clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME, &ts, NULL) == EINTR) {
      }
      wait_messages(s, 0); /* every command received before the tick's end */
      if (s->cmd_new == 0) stale++;
      else memcpy(s->u, s->cmd_last, sizeof(double) * (size_t)n);
      s->cmd_new = 0;
    }
    /* 3. the torque applied (a fault: zero), published; the plant advances */
    int lost = s->f_torque >= 0 && k >= s->f_torque;
    for (int j = 0; j < n; ++j) s->applied[j] = lost ? 0.0 : s->u[j];
    amsfe_out_stamp(&s->m_eff, ns);
    amsfe_out_fill(&s->m_eff, 2, s->applied, n);
    amsfe_publish(&s->pub_eff, &s->m_eff);
    if (k + 1 < K) {
      const double *in[4] = {s->x, s->applied, s->theta, s->tau_d + k * 2 * n};
      double *res[1] = {s->x_next};
      if (gcall(&s->g_plant, in, 4, res, 1)) memset(s->x_next, 0xff, sizeof(double) * 4 * (size_t)n);
      memcpy(s->x, s->x_next, sizeof(double) * 4 * (size_t)n);
    }
  }
  double wall = (double)(amsfe_mono_ns() - t0) * 1e-9;
  (void)t_start;
  if (rcl_publisher_wait_for_all_acked(&s->pub_eff, 1000000000LL) != RCL_RET_OK)
    rcutils_reset_error();
  wait_messages(s, 50000000LL); /* the last tick's estimate */
  if (amsfe_signal) return amsfe_signal == SIGTERM ? 143 : 130;
  printf("sim-node: %ld ticks in %.2f s wall, %ld commands", K, wall, s->commands);
  if (!s->lockstep) printf(", %ld late ticks, %ld without a new command", late, stale);
  printf("\n");
  char lat[512] = "";
  int len = latency_part(lat, sizeof lat, "estimate", s->est_lat, s->n_est_lat);
  if (len && s->n_cmd_lat) len += snprintf(lat + len, sizeof lat - (size_t)len, "; ");
  len += latency_part(lat + len, sizeof lat - (size_t)len, "command", s->cmd_lat, s->n_cmd_lat);
  printf("sim-node: %s\n", len ? lat : "no latency measured");
  if (amsfe_publish_failed) printf("sim-node: %ld publishes refused by rcl\n", amsfe_publish_failed);
  fflush(stdout);
  return 0;
}

int main(int argc, char **argv) {
  if (argc < 2 || argv[1][0] == '-') {
    fprintf(stderr, "usage: %s PARAMS [--ros-args ...]  (run by amsfe sim-node --impl c)\n",
            argv[0]);
    return 2;
  }
  static arm_t S;
  amsfe_program_start("amsfe_arm");
  arm_t *s = &S;
  configure(s, argv[1]);
  params_file *pf = &s->pf;
  const char *qt[3];
  if (pf_tokens(pf, "qos", qt, 3, 0) != 3) pf_fail(pf, "qos", "reliability depth out_depth", "other");
  const char *reliability = qt[0];
  int depth = (int)pf_parse_long(pf, "qos", qt[1]), out_depth = (int)pf_parse_long(pf, "qos", qt[2]);
  int priority = (int)pf_long(pf, "sched_priority");
  rcl_allocator_t alloc = amsfe_rcl_start(argc, argv, &s->ctx, &s->node, "amsfe_sim", "sim-node", priority);
  const amsfe_types ty = amsfe_message_types();
  const rosidl_message_type_support_t *ts_clk = ROSIDL_GET_MSG_TYPE_SUPPORT(rosgraph_msgs, msg, Clock);
  rcl_publisher_options_t po = rcl_publisher_get_default_options();
  po.qos = amsfe_qos(reliability, out_depth);
  struct {
    rcl_publisher_t *pub;
    const rosidl_message_type_support_t *ts;
    const char *topic;
  } pubs[] = {{&s->pub_enc, ty.joint_state, s->t_enc},
              {&s->pub_cam, ty.point_stamped, s->t_cam},
              {&s->pub_eff, ty.joint_state, s->t_eff},
              {&s->pub_truth, ty.f64_array, s->t_truth}};
  for (size_t i = 0; i < sizeof pubs / sizeof pubs[0]; ++i) {
    *pubs[i].pub = rcl_get_zero_initialized_publisher();
    amsfe_rcl_check(rcl_publisher_init(pubs[i].pub, &s->node, pubs[i].ts, pubs[i].topic, &po), pubs[i].topic);
  }
  po.qos = amsfe_qos(reliability, 1);
  s->pub_clock = rcl_get_zero_initialized_publisher();
  amsfe_rcl_check(rcl_publisher_init(&s->pub_clock, &s->node, ts_clk, s->t_clock, &po), "clock publisher");
  rcl_subscription_options_t so = rcl_subscription_get_default_options();
  so.qos = amsfe_qos(reliability, depth);
  s->sub_cmd = rcl_get_zero_initialized_subscription();
  amsfe_rcl_check(rcl_subscription_init(&s->sub_cmd, &s->node, ty.f64_array, s->t_cmd, &so), "command subscription");
  s->sub_est = rcl_get_zero_initialized_subscription();
  amsfe_rcl_check(rcl_subscription_init(&s->sub_est, &s->node, ty.joint_state, s->t_est, &so), "estimate subscription");
  s->in = amsfe_message_buffer(MSG_CAP);
  int n = s->n;
  int enc_counts[3] = {n, n, 0}, eff_counts[3] = {0, 0, n};
  amsfe_out_joint_state(&s->m_enc, s->names, n, enc_counts);
  amsfe_out_joint_state(&s->m_eff, s->names, n, eff_counts);
  out_point_stamped(&s->m_cam);
  amsfe_out_f64_array(&s->m_truth, s->N);
  out_clock(&s->m_clock);
  s->ws = rcl_get_zero_initialized_wait_set();
  amsfe_rcl_check(rcl_wait_set_init(&s->ws, 2, 0, 0, 0, 0, 0, &s->ctx, alloc), "wait set");
  int code = run(s);
  rcl_publisher_t *const all_pubs[] = {&s->pub_enc, &s->pub_cam, &s->pub_eff, &s->pub_truth,
                                       &s->pub_clock};
  rcl_subscription_t *const subs[] = {&s->sub_cmd, &s->sub_est};
  amsfe_rcl_stop(&s->ws, all_pubs, 5, subs, 2, &s->node, &s->ctx);
  return code;
}
