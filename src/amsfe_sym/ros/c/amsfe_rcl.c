/* amsfe_rcl.c: see amsfe_rcl.h. */
#define _GNU_SOURCE
#include "amsfe_rcl.h"

#include <errno.h>
#include <execinfo.h>
#include <fcntl.h>
#include <sched.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/mman.h>
#include <time.h>
#include <unistd.h>

#include <geometry_msgs/msg/point_stamped.h>
#include <rcutils/error_handling.h>
#include <sensor_msgs/msg/joint_state.h>
#include <std_msgs/msg/float64_multi_array.h>

const char *amsfe_program = "amsfe";
volatile sig_atomic_t amsfe_signal = 0;

static void on_signal(int sig) { amsfe_signal = sig; }

/* ------------------------------------------------------------ the report of a fatal signal */
static void put(const char *text) { /* write(2) only: async-signal-safe */
  size_t len = strlen(text);
  while (len > 0) {
    ssize_t w = write(STDERR_FILENO, text, len);
    if (w <= 0) return;
    text += w, len -= (size_t)w;
  }
}

static void put_hex(uintptr_t v) {
  char buf[2 + 2 * sizeof v + 1], *e = buf + sizeof buf - 1;
  *e = 0;
  do *--e = "0123456789abcdef"[v & 15u]; while (v >>= 4);
  *--e = 'x', *--e = '0';
  put(e);
}

/* One line naming the signal and the address, then the stack (backtrace_symbols_fd:
 * "file(function+offset) [address]"; `addr2line -f -e FILE OFFSET` names a static
 * function), then the signal again with its default action: the exit status and the core
 * dump stay the signal's. */
static void on_fatal(int sig, siginfo_t *info, void *context) {
  (void)context;
  static const char *const names[] = {[SIGSEGV] = "SIGSEGV", [SIGBUS] = "SIGBUS",
                                      [SIGILL] = "SIGILL", [SIGFPE] = "SIGFPE",
                                      [SIGABRT] = "SIGABRT"};
  put("error: "), put(amsfe_program), put(": killed by "), put(names[sig]);
  if (info->si_code > 0) put(" at address "), put_hex((uintptr_t)info->si_addr); /* kernel's */
  put("; its stack:\n");
  void *frames[64];
  backtrace_symbols_fd(frames, backtrace(frames, 64), STDERR_FILENO);
  raise(sig); /* SA_RESETHAND: the default action, delivered when this handler returns */
}

void amsfe_program_start(const char *name) {
  amsfe_program = name;
  setvbuf(stdout, NULL, _IOLBF, 0);
#if !defined(__SANITIZE_ADDRESS__) /* an AddressSanitizer build reports these itself */
  void *warm[1];
  backtrace(warm, 1); /* loads libgcc's unwinder now: the handler then allocates nothing */
  static char alt[64 * 1024]; /* a stack overflow is reported too */
  stack_t ss = {.ss_sp = alt, .ss_size = sizeof alt, .ss_flags = 0};
  sigaltstack(&ss, NULL);
  struct sigaction sa;
  memset(&sa, 0, sizeof sa);
  sa.sa_sigaction = on_fatal;
  sa.sa_flags = SA_SIGINFO | SA_RESETHAND | SA_ONSTACK;
  static const int fatal[] = {SIGSEGV, SIGBUS, SIGILL, SIGFPE, SIGABRT};
  for (size_t i = 0; i < sizeof fatal / sizeof fatal[0]; ++i) sigaction(fatal[i], &sa, NULL);
#endif
}

void *amsfe_must(void *p, const char *what) {
  if (!p) {
    fprintf(stderr, "error: %s: out of memory for %s\n", amsfe_program, what);
    exit(1);
  }
  return p;
}

static long long clock_ns(clockid_t id) {
  struct timespec t;
  clock_gettime(id, &t);
  return (long long)t.tv_sec * 1000000000LL + t.tv_nsec;
}

long long amsfe_mono_ns(void) { return clock_ns(CLOCK_MONOTONIC); }

double amsfe_mono_s(void) {
  struct timespec t;
  clock_gettime(CLOCK_MONOTONIC, &t);
  return (double)t.tv_sec + 1e-9 * (double)t.tv_nsec;
}

long long amsfe_wall_ns(void) { return clock_ns(CLOCK_REALTIME); }

void amsfe_rcl_check(rcl_ret_t ret, const char *what) {
  if (ret == RCL_RET_OK) return;
  fprintf(stderr, "error: %s: %s: %s\n", amsfe_program, what, rcutils_get_error_string().str);
  rcutils_reset_error();
  exit(1);
}

static void catch_signals(void) {
  struct sigaction sa;
  memset(&sa, 0, sizeof sa);
  sa.sa_handler = on_signal;
  sigaction(SIGINT, &sa, NULL);
  sigaction(SIGTERM, &sa, NULL);
}

/* What a real-time process of the toolkit (the C node, the C arm) asks of the
 * machine before its loop, when permitted, each said in one line when not:
 *   - memory locked (mlockall: no page fault on the sample path);
 *   - SCHED_FIFO at `priority` (above every normal task: a CPU hog cannot delay a sample);
 *   - /dev/cpu_dma_latency held at 0 us for the process's life (the kernel's PM QoS: an idle
 *     core polls rather than halts, so a sample's wake-up does not pay the idle state's exit,
 *     which on a VM is a trip through the hypervisor; cyclictest does the same).  The file
 *     descriptor stays open until the process ends: closing it lifts the request.
 * docs/live-control.md, "Scheduling". */
/* `who` prefixes the line ("node", "sim-node"); priority <= 0: nothing asked, nothing said. */
static void realtime(const char *who, int priority) {
  if (priority <= 0) return;
  char why[384] = "";
  size_t len = 0;
#if defined(__SANITIZE_ADDRESS__)
  /* an AddressSanitizer build (tools/cnode_asan.py): its shadow memory is terabytes of
   * reserved address space that mlockall would try to populate */
  snprintf(why, sizeof why, "mlockall: skipped under AddressSanitizer");
#else
  if (mlockall(MCL_CURRENT | MCL_FUTURE) != 0)
    snprintf(why, sizeof why, "mlockall: %s", strerror(errno));
#endif
  struct sched_param sp = {.sched_priority = priority};
  if (sched_setscheduler(0, SCHED_FIFO, &sp) != 0) {
    len = strlen(why);
    snprintf(why + len, sizeof why - len, "%sSCHED_FIFO %d: %s", len ? "; " : "", priority,
             strerror(errno));
  }
  static int dma_fd = -1; /* kept open: the request lasts while it is */
  const int32_t zero = 0;
  dma_fd = open("/dev/cpu_dma_latency", O_WRONLY | O_CLOEXEC);
  if (dma_fd < 0 || write(dma_fd, &zero, sizeof zero) != (ssize_t)sizeof zero) {
    len = strlen(why);
    snprintf(why + len, sizeof why - len, "%s/dev/cpu_dma_latency: %s", len ? "; " : "",
             strerror(errno));
    if (dma_fd >= 0) close(dma_fd), dma_fd = -1;
  }
  if (why[0])
    printf("%s: real-time set-up not fully permitted (%s): running without it "
           "(docs/live-control.md, \"Scheduling\")\n", who, why);
  else
    printf("%s: SCHED_FIFO priority %d, memory locked, CPU wake-up latency held at 0 us\n", who,
           priority);
  fflush(stdout);
}

rcl_allocator_t amsfe_rcl_start(int argc, char **argv, rcl_context_t *ctx, rcl_node_t *node,
                                const char *name, const char *who, int priority) {
  catch_signals();
  realtime(who, priority);
  rcl_allocator_t alloc = rcl_get_default_allocator();
  rcl_init_options_t io = rcl_get_zero_initialized_init_options();
  amsfe_rcl_check(rcl_init_options_init(&io, alloc), "rcl_init_options_init");
  *ctx = rcl_get_zero_initialized_context();
  amsfe_rcl_check(rcl_init(argc, (const char *const *)argv, &io, ctx), "rcl_init (--ros-args)");
  *node = rcl_get_zero_initialized_node();
  rcl_node_options_t no = rcl_node_get_default_options();
  amsfe_rcl_check(rcl_node_init(node, name, "", ctx, &no), "rcl_node_init");
  return alloc;
}

rmw_qos_profile_t amsfe_qos(const char *reliability, int depth) {
  rmw_qos_profile_t q = rmw_qos_profile_default;
  q.history = RMW_QOS_POLICY_HISTORY_KEEP_LAST;
  q.depth = (size_t)depth;
  q.reliability = strcmp(reliability, "reliable") == 0 ? RMW_QOS_POLICY_RELIABILITY_RELIABLE
                                                        : RMW_QOS_POLICY_RELIABILITY_BEST_EFFORT;
  q.durability = RMW_QOS_POLICY_DURABILITY_VOLATILE;
  return q;
}

rcl_serialized_message_t amsfe_message_buffer(size_t capacity) {
  rcl_allocator_t alloc = rcl_get_default_allocator();
  rcl_serialized_message_t m = rmw_get_zero_initialized_serialized_message();
  amsfe_rcl_check(rmw_serialized_message_init(&m, capacity, &alloc), "a message buffer");
  return m;
}

void amsfe_rcl_stop(rcl_wait_set_t *ws, rcl_publisher_t *const *pubs, int n_pubs,
                    rcl_subscription_t *const *subs, int n_subs, rcl_node_t *node,
                    rcl_context_t *ctx) {
  rcl_ret_t fini = rcl_wait_set_fini(ws);
  for (int i = 0; i < n_pubs; ++i) fini |= rcl_publisher_fini(pubs[i], node);
  for (int i = 0; i < n_subs; ++i) fini |= rcl_subscription_fini(subs[i], node);
  fini |= rcl_node_fini(node);
  fini |= rcl_shutdown(ctx);
  fini |= rcl_context_fini(ctx);
  (void)fini; /* the process ends: nothing left to release it for */
}

long amsfe_publish_failed = 0;

void amsfe_out_alloc(amsfe_out *m, size_t cap) {
  m->ser = rmw_get_zero_initialized_serialized_message();
  rcutils_allocator_t a = rcutils_get_default_allocator();
  if (rmw_serialized_message_init(&m->ser, cap, &a) != RMW_RET_OK) amsfe_must(NULL, "a message");
}

void amsfe_put_header(cdr_out *w, const char *frame) {
  cdr_put_u32(w, 0), cdr_put_u32(w, 0), cdr_put_string(w, frame);
}

void amsfe_out_joint_state(amsfe_out *m, const char *const *names, int n, const int *counts) {
  size_t cap = 256 + 8 * (size_t)(counts[0] + counts[1] + counts[2]) + 16;
  for (int j = 0; j < n; ++j) cap += strlen(names[j]) + 8;
  amsfe_out_alloc(m, cap);
  cdr_out w;
  cdr_out_init(&w, m->ser.buffer, cap);
  amsfe_put_header(&w, "");
  cdr_put_u32(&w, (uint32_t)n);
  for (int j = 0; j < n; ++j) cdr_put_string(&w, names[j]);
  for (int i = 0; i < 3; ++i) cdr_put_doubles(&w, NULL, counts[i], &m->at[i]);
  if (!w.ok) amsfe_must(NULL, "a JointState");
  m->ser.buffer_length = cdr_out_size(&w);
}

void amsfe_out_f64_array(amsfe_out *m, int n) {
  size_t cap = 64 + 8 * (size_t)n;
  amsfe_out_alloc(m, cap);
  cdr_out w;
  cdr_out_init(&w, m->ser.buffer, cap);
  cdr_put_u32(&w, 0), cdr_put_u32(&w, 0); /* layout: no dims, data_offset 0 */
  cdr_put_doubles(&w, NULL, n, &m->at[0]);
  if (!w.ok) amsfe_must(NULL, "a Float64MultiArray");
  m->ser.buffer_length = cdr_out_size(&w);
}

void amsfe_out_stamp(amsfe_out *m, long long ns) {
  int32_t sec = (int32_t)(ns / 1000000000LL);
  uint32_t nsec = (uint32_t)(ns % 1000000000LL);
  memcpy(m->ser.buffer + 4, &sec, 4);
  memcpy(m->ser.buffer + 8, &nsec, 4);
}

void amsfe_out_fill(amsfe_out *m, int field, const double *v, int n) {
  memcpy(m->ser.buffer + 4 + m->at[field], v, sizeof(double) * (size_t)n);
}

void amsfe_publish(rcl_publisher_t *pub, amsfe_out *m) {
  if (rcl_publish_serialized_message(pub, &m->ser, NULL) != RCL_RET_OK) {
    rcutils_reset_error();
    ++amsfe_publish_failed;
  }
}

amsfe_types amsfe_message_types(void) {
  amsfe_types t = {ROSIDL_GET_MSG_TYPE_SUPPORT(sensor_msgs, msg, JointState),
                   ROSIDL_GET_MSG_TYPE_SUPPORT(geometry_msgs, msg, PointStamped),
                   ROSIDL_GET_MSG_TYPE_SUPPORT(std_msgs, msg, Float64MultiArray)};
  return t;
}
