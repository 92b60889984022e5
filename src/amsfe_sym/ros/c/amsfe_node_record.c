/* amsfe_node_record.c: the C node's record (amsfe_node.c): what it received and
 * published, kept per tick in the arrays of record_t (amsfe_node.h) and written at the
 * stop as sections "name type rows cols data" (amsfe_sym.ros.cnode reads them). */
#define _GNU_SOURCE
#include <errno.h>
#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <string.h>

#include "amsfe_node.h"

static void rec_section(FILE *f, const char *name, char type, long rows, long cols,
                        const void *data, size_t elem) {
  char head[16] = {0};
  strncpy(head, name, 14);
  head[15] = type;
  int64_t rc[2] = {rows, cols};
  fwrite(head, 1, 16, f);
  fwrite(rc, 8, 2, f);
  if (rows > 0 && cols > 0) fwrite(data, elem, (size_t)(rows * cols), f);
}

void record_tick(node_t *s, long long ns, const double *z, long long sent) {
  record_t *R = &s->rec;
  live_loop *L = &s->L;
  int n = s->n, N = s->N;
  if (L->k == 0) { /* frames sent before the first sample: skipped, not recorded */
    int keep = 0;
    for (int i = 0; i < R->n_rx; ++i)
      if (R->rx[i].sent > sent) R->rx[keep++] = R->rx[i];
    R->n_rx = keep;
  }
  int keep = 0;
  for (int i = 0; i < R->n_rx; ++i) {
    if (R->rx[i].sent <= sent) {
      if (R->n_fr < R->cap_fr) {
        R->fr_ns[R->n_fr] = ns, R->fr_exp[R->n_fr] = R->rx[i].exposure_ns;
        R->fr_z[2 * R->n_fr] = R->rx[i].z[0], R->fr_z[2 * R->n_fr + 1] = R->rx[i].z[1];
        ++R->n_fr;
      } else {
        ++R->lost;
      }
    } else {
      R->rx[keep++] = R->rx[i];
    }
  }
  R->n_rx = keep;
  if (R->ticks >= R->cap) {
    ++R->lost;
    return;
  }
  long t = R->ticks++;
  R->ns[t] = ns, R->sent[t] = sent;
  memcpy(R->z + t * 2 * n, z, sizeof(double) * 2 * (size_t)n);
  memcpy(R->x + t * N, L->x, sizeof(double) * (size_t)N);
  for (int i = 0; i < N; ++i) R->std[t * N + i] = sqrt(L->P_diag[i] > 0.0 ? L->P_diag[i] : 0.0);
  for (int j = 0; j < n; ++j) R->u[t * n + j] = L->controller ? L->u[j] : NAN;
}

void record_effort(node_t *s, long long ns, const double *u) {
  record_t *R = &s->rec;
  if (!s->recording) return;
  if (R->n_eff >= R->cap_eff) {
    ++R->lost;
    return;
  }
  R->eff_ns[R->n_eff] = ns;
  memcpy(R->eff_u + R->n_eff * s->n, u, sizeof(double) * (size_t)s->n);
  ++R->n_eff;
}

void record_diag(node_t *s, long long ns) {
  record_t *R = &s->rec;
  size_t len = strlen(s->diag) + 1;
  if (R->n_diag >= R->cap_diag || R->diag_used + len > R->diag_bytes) {
    ++R->lost;
    return;
  }
  R->diag_ns[R->n_diag] = ns;
  R->diag_at[R->n_diag++] = (long)R->diag_used;
  memcpy(R->diag_text + R->diag_used, s->diag, len);
  R->diag_used += len;
}

void write_record(node_t *s, const char *path) {
  record_t *R = &s->rec;
  int n = s->n, N = s->N;
  char tmp[4096];
  snprintf(tmp, sizeof tmp, "%s.tmp", path);
  FILE *f = fopen(tmp, "wb");
  if (!f) {
    fprintf(stderr, "error: amsfe_node: cannot write the record %s: %s\n", path, strerror(errno));
    return;
  }
  long long hold_ns = R->hold_ns;
  rec_section(f, "ns", 'q', R->ticks, 1, R->ns, 8);
  rec_section(f, "z", 'd', R->ticks, 2 * n, R->z, 8);
  rec_section(f, "x", 'd', R->ticks, N, R->x, 8);
  rec_section(f, "std", 'd', R->ticks, N, R->std, 8);
  rec_section(f, "u", 'd', R->ticks, n, R->u, 8);
  rec_section(f, "sent", 'q', R->ticks, 1, R->sent, 8);
  rec_section(f, "truth_sent", 'q', R->n_truth, 1, R->truth_sent, 8);
  rec_section(f, "truth_x", 'd', R->n_truth, N, R->truth_x, 8);
  rec_section(f, "eff_ns", 'q', R->n_eff, 1, R->eff_ns, 8);
  rec_section(f, "eff_u", 'd', R->n_eff, n, R->eff_u, 8);
  rec_section(f, "fr_ns", 'q', R->n_fr, 1, R->fr_ns, 8);
  rec_section(f, "fr_exp", 'q', R->n_fr, 1, R->fr_exp, 8);
  rec_section(f, "fr_z", 'd', R->n_fr, 2, R->fr_z, 8);
  rec_section(f, "diag_ns", 'q', R->n_diag, 1, R->diag_ns, 8);
  rec_section(f, "diag_text", 'c', (long)R->diag_used, 1, R->diag_text, 1);
  rec_section(f, "hold_ns", 'q', R->has_hold, 1, &hold_ns, 8);
  rec_section(f, "hold_u", 'd', R->has_hold, n, R->hold_u, 8);
  int64_t lost = R->lost;
  rec_section(f, "lost", 'q', 1, 1, &lost, 8);
  /* how the node stopped: its line, exit code, the watchdog's reason ("" : none) */
  amsfe_watchdog_state ws;
  amsfe_watchdog_get_state(s->wd, &ws);
  const char *wd_name = ws.reason != AMSFE_WD_NONE ? amsfe_watchdog_reason_name(ws.reason) : "";
  int64_t code = s->exit_code;
  rec_section(f, "stop_line", 'c', (long)strlen(s->stop_line), 1, s->stop_line, 1);
  rec_section(f, "stop_code", 'q', 1, 1, &code, 8);
  rec_section(f, "stop_wd", 'c', (long)strlen(wd_name), 1, wd_name, 1);
  int bad = ferror(f);
  bad |= fclose(f) != 0;
  if (bad || rename(tmp, path) != 0)
    fprintf(stderr, "error: amsfe_node: cannot write the record %s\n", path);
}
