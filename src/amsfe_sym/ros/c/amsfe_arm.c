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
 *
 * Its state is one arm_t (amsfe_arm.h), shared by its files, one concept each: this one
 * the program (start, the run's ticks, the stop); amsfe_arm_config.c the parameter file;
 * amsfe_arm_sensors.c the camera and the encoders; amsfe_arm_commands.c the commands
 * taken.
 */
#define _GNU_SOURCE
#include <math.h>
#include <signal.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include <rcutils/error_handling.h>
#include <rosgraph_msgs/msg/clock.h>

#include "amsfe_arm.h"

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
