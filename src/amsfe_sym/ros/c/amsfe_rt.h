/* amsfe_rt.h: what a real-time process of the toolkit (the C node, the C arm) asks of the
 * machine before its loop, when permitted, each said in one line when not:
 *   - memory locked (mlockall: no page fault on the sample path);
 *   - SCHED_FIFO at `priority` (above every normal task: a CPU hog cannot delay a sample);
 *   - /dev/cpu_dma_latency held at 0 us for the process's life (the kernel's PM QoS: an idle
 *     core polls rather than halts, so a sample's wake-up does not pay the idle state's exit,
 *     which on a VM is a trip through the hypervisor; cyclictest does the same).  The file
 *     descriptor stays open until the process ends: closing it lifts the request.
 * docs/live-control.md, "Scheduling". */
#ifndef AMSFE_RT_H
#define AMSFE_RT_H

#include <errno.h>
#include <fcntl.h>
#include <sched.h>
#include <stdint.h>
#include <stdio.h>
#include <string.h>
#include <sys/mman.h>
#include <unistd.h>

/* `who` prefixes the line ("node", "sim-node"); priority <= 0: nothing asked, nothing said. */
static inline void amsfe_realtime(const char *who, int priority) {
  if (priority <= 0) return;
  char why[384] = "";
  size_t len = 0;
  if (mlockall(MCL_CURRENT | MCL_FUTURE) != 0)
    snprintf(why, sizeof why, "mlockall: %s", strerror(errno));
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

#endif /* AMSFE_RT_H */
