/* amsfe_rcl.h: the rcl set-up the C programs of the toolkit share (the C node, amsfe_node*.c,
 * and the C arm, amsfe_arm*.c): the program's name in its error lines, allocation that stops
 * the program in one line, the two clocks, SIGINT / SIGTERM caught into amsfe_signal, the
 * context and the node from the command line's --ros-args, the live topics' QoS, a message
 * buffer, and the stop.  Everything here runs at start or at the stop, never per sample.
 * docs/live-control.md, "The build". */
#ifndef AMSFE_RCL_H
#define AMSFE_RCL_H

#include <signal.h>
#include <stddef.h>

#include <rcl/rcl.h>
#include <rmw/serialized_message.h>
#include <rosidl_runtime_c/message_type_support_struct.h>

#include "amsfe_cdr.h"

/* The program's name in its error lines ("amsfe_node", "amsfe_arm"); set it first. */
extern const char *amsfe_program;
/* The signal caught (SIGINT, SIGTERM; 0: none) since amsfe_rcl_start. */
extern volatile sig_atomic_t amsfe_signal;

/* The first call of a program's main: its name `name` in its error lines (amsfe_program);
 * stdout line-buffered (a pipe's block buffer lost every line after the start's when a
 * program died: a SIGSEGV in CI once said nothing of where; the sample path prints nothing);
 * SIGSEGV, SIGBUS, SIGILL, SIGFPE and SIGABRT reported on stderr with the stack, on an
 * alternate stack, before the signal's default action (its exit status and core dump). */
void amsfe_program_start(const char *name);
/* `p`, or "error: <program>: out of memory for <what>" and exit 1. */
void *amsfe_must(void *p, const char *what);
/* `count` zeroed elements of `type` (at least one), or the program stops (amsfe_must). */
#define ALLOC(type, count) \
  ((type *)amsfe_must(calloc((size_t)(count) != 0 ? (size_t)(count) : 1, sizeof(type)), #type))

/* CLOCK_MONOTONIC [ns] and [s]; CLOCK_REALTIME [ns] (the middleware's receive stamps'). */
long long amsfe_mono_ns(void);
double amsfe_mono_s(void);
long long amsfe_wall_ns(void);

/* An rcl call's result: RCL_RET_OK goes on, anything else prints
 * "error: <program>: <what>: <rcl's error>" and exits 1 (at start: nothing to hold yet). */
void amsfe_rcl_check(rcl_ret_t ret, const char *what);
/* The start of a program: SIGINT and SIGTERM set amsfe_signal (the loops end, the stop is
 * published); the real-time set-up (amsfe_rcl.c's realtime: SCHED_FIFO `priority`, mlockall,
 * /dev/cpu_dma_latency; `who` prefixes its line; priority <= 0: none) before rcl_init, so
 * the middleware's threads (Fast DDS's receive and event threads) inherit the policy and a
 * sample's way through the process is real-time too, not only its tick (reception threads at
 * normal priority beside CPU hogs delayed the commands by ms); then rcl_init from argc/argv
 * (their --ros-args: remaps, parameters) and the node `name`.  Returns rcl's default
 * allocator (the wait sets'). */
rcl_allocator_t amsfe_rcl_start(int argc, char **argv, rcl_context_t *ctx, rcl_node_t *node,
                                const char *name, const char *who, int priority);
/* A live topic's QoS: KEEP_LAST `depth`, "reliable" or best effort, volatile. */
rmw_qos_profile_t amsfe_qos(const char *reliability, int depth);
/* A serialized message buffer of `capacity` bytes (incoming messages taken into it). */
rcl_serialized_message_t amsfe_message_buffer(size_t capacity);
/* The message types both programs publish or take. */
typedef struct {
  const rosidl_message_type_support_t *joint_state, *point_stamped, *f64_array;
} amsfe_types;
amsfe_types amsfe_message_types(void);

/* An outgoing message laid out once at start: its bytes, and the payload offsets of its
 * float64[] fields (JointState: position, velocity, effort; Float64MultiArray: data;
 * PointStamped: point.x); per tick only the stamp and the numbers are written. */
typedef struct {
  rcl_serialized_message_t ser;
  size_t at[3];
} amsfe_out;

/* Publishes rcl refused (a context going down), counted by amsfe_publish. */
extern long amsfe_publish_failed;

/* A buffer of `cap` bytes for `m` (the program stops when there is none). */
void amsfe_out_alloc(amsfe_out *m, size_t cap);
/* A std_msgs/Header (stamp 0, `frame`) at the start of w. */
void amsfe_put_header(cdr_out *w, const char *frame);
/* JointState of `names` with `counts` [3] values in position, velocity, effort (0: empty,
 * as messages.joint_state leaves a field it is not given). */
void amsfe_out_joint_state(amsfe_out *m, const char *const *names, int n, const int *counts);
/* Float64MultiArray of n values (no layout dims). */
void amsfe_out_f64_array(amsfe_out *m, int n);
/* The header's stamp [ns]. */
void amsfe_out_stamp(amsfe_out *m, long long ns);
/* n values into float64[] field `field`. */
void amsfe_out_fill(amsfe_out *m, int field, const double *v, int n);
/* rcl_publish_serialized_message, a refusal counted (amsfe_publish_failed). */
void amsfe_publish(rcl_publisher_t *pub, amsfe_out *m);

/* The stop, in the reverse order of the start: the wait set, the n_pubs publishers and
 * n_subs subscriptions (zero-initialised ones are skipped by rcl), the node, then the context
 * shut down and finalised, so the middleware's participant is destroyed here rather than by
 * exit-time destructors (the process ends: errors are ignored). */
void amsfe_rcl_stop(rcl_wait_set_t *ws, rcl_publisher_t *const *pubs, int n_pubs,
                    rcl_subscription_t *const *subs, int n_subs, rcl_node_t *node,
                    rcl_context_t *ctx);

#endif /* AMSFE_RCL_H */
