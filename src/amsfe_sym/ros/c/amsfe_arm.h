/* amsfe_arm.h: the C arm's state (arm_t) and the functions its files share (amsfe_arm.c:
 * the program; the others, one concept each).  Private to the arm: the node does not
 * include it. */
#ifndef AMSFE_ARM_H
#define AMSFE_ARM_H

#include <stddef.h>

#include <rcl/rcl.h>

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

/* amsfe_arm_config.c */
void configure(arm_t *s, const char *path);
void fail(arm_t *s, const char *line);

/* amsfe_arm_sensors.c */
int gcall(gfun *g, const double **in, int n_in, double **out, int n_out);
int camera_tick(arm_t *s, long k);
void encoders(arm_t *s, long k);

/* amsfe_arm_commands.c */
void warn_duplicate(arm_t *s);
int two_controllers(arm_t *s, const rmw_gid_t *gids);
void wait_messages(arm_t *s, long long timeout_ns);

#endif /* AMSFE_ARM_H */
