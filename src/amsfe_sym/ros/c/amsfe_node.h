/* amsfe_node.h: the C node's state (node_t, its record record_t) and the functions its
 * files share (amsfe_node.c: the program; the others, one concept each).  Private to the
 * node: the arm (amsfe_arm*.c) does not include it. */
#ifndef AMSFE_NODE_H
#define AMSFE_NODE_H

#include <stddef.h>

#include <rcl/rcl.h>

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

/* amsfe_node_config.c */
void configure(node_t *s, const char *path);

/* amsfe_node_intake.c */
int read_joint_state(node_t *s, long long *ns, double *pos, double *vel, double *eff,
                     int *has_eff);
void say_waiting(node_t *s, double seconds);
void take_frames(node_t *s);
int await_effort(node_t *s, long long ns);
void take_efforts(node_t *s);
void take_truth(node_t *s);

/* amsfe_node_sample.c */
void on_encoders(node_t *s, long long sent, long long received, double taken);

/* amsfe_node_publish.c */
void wait_subscriber(node_t *s);
void publish_tick(node_t *s, long long ns, const double *z, long long sent);
void publish_hold(node_t *s, char *held, size_t cap);

/* amsfe_node_record.c */
void record_tick(node_t *s, long long ns, const double *z, long long sent);
void record_effort(node_t *s, long long ns, const double *u);
void record_diag(node_t *s, long long ns);
void write_record(node_t *s, const char *path);

#endif /* AMSFE_NODE_H */
