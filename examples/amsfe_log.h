/* amsfe_log.h: what the two log-reading examples share (estimate_from_log.c and
 * control_from_log.c): a strict line reader, timing, and the estimator block of a log
 * (params, qw, r_encoder, r_camera, x0, P0; written by
 * amsfe_sym.runtime.compiled_estimator.estimator_log_lines), which creates the estimator.
 *
 * The reader stops at the first defect with one line on stderr, "LOG:LINE: what: expected
 * ..., found ...", and exit status 2: an unknown record, a number that does not parse (the
 * whole token: "1.5x" is refused), a vector of the wrong length (too few or too many
 * values), a record out of order or repeated, a NUL byte, and a last line without its end
 * of line (a truncated file).  Blank lines are skipped.  A runtime call that fails exits
 * with status 1 and its line number.  Nothing is skipped silently. */
#ifndef AMSFE_LOG_H
#define AMSFE_LOG_H

#include <errno.h>
#include <limits.h>
#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "amsfe_runtime.h"

/* Exit statuses: a malformed log, and a runtime call that refused it. */
#define LOG_EXIT_MALFORMED 2
#define LOG_EXIT_RUNTIME 1

/* The reader of one log file: the current line and where the next token starts. */
typedef struct {
  const char *path;
  FILE *f;
  long line;   /* number of the current line, from 1 */
  char *buf;   /* the current line */
  size_t cap;
  char *cur;   /* the rest of the current line */
  char key[32]; /* the current record's name */
} log_reader;

static void log_exit(const log_reader *r, int code, const char *fmt, ...)
    __attribute__((noreturn, format(printf, 3, 4)));
static void log_exit(const log_reader *r, int code, const char *fmt, ...) {
  va_list ap;
  va_start(ap, fmt);
  fprintf(stderr, "%s:%ld: ", r->path, r->line);
  vfprintf(stderr, fmt, ap);
  fprintf(stderr, "\n");
  va_end(ap);
  exit(code);
}

#define log_fail(r, ...) log_exit((r), LOG_EXIT_MALFORMED, __VA_ARGS__)

static void log_open(log_reader *r, const char *path) {
  memset(r, 0, sizeof(*r));
  r->path = path;
  r->f = fopen(path, "r");
  if (!r->f) {
    fprintf(stderr, "%s: cannot open: %s\n", path, strerror(errno));
    exit(LOG_EXIT_MALFORMED);
  }
}

/* The next whitespace-separated token of the current line, NULL at its end. */
static char *log_token(log_reader *r) {
  char *s = r->cur;
  while (*s == ' ' || *s == '\t' || *s == '\n' || *s == '\r') ++s;
  if (!*s) {
    r->cur = s;
    return NULL;
  }
  char *t = s;
  while (*s && *s != ' ' && *s != '\t' && *s != '\n' && *s != '\r') ++s;
  if (*s) *s++ = '\0';
  r->cur = s;
  return t;
}

/* Read the next record: 1 with r->key set, 0 at the end of the file. */
static int log_next(log_reader *r) {
  for (;;) {
    errno = 0;
    ssize_t got = getline(&r->buf, &r->cap, r->f);
    if (got < 0) {
      if (ferror(r->f)) log_fail(r, "read error after this line: %s", strerror(errno));
      return 0;
    }
    ++r->line;
    if ((size_t)got != strlen(r->buf))
      log_fail(r, "expected a text line, found a NUL byte (is this a log of amsfe?)");
    if (r->buf[got - 1] != '\n')
      log_fail(r, "expected a complete line, found a last line without its end of line "
                  "(the file is truncated: write the log again)");
    r->cur = r->buf;
    char *key = log_token(r);
    if (!key) continue; /* a blank line */
    if (strlen(key) >= sizeof(r->key)) log_fail(r, "unknown record '%.40s...'", key);
    strcpy(r->key, key);
    return 1;
  }
}

static double log_parse_double(const log_reader *r, const char *what, int i, const char *tok) {
  char *end;
  errno = 0;
  double v = strtod(tok, &end);
  if (end == tok || *end) log_fail(r, "%s value %d: expected a number, found '%.40s'", what, i + 1, tok);
  return v; /* overflow gives +-inf, "nan" NaN: the runtime refuses what it cannot use */
}

static long log_parse_long(const log_reader *r, const char *what, int i, const char *tok, long lo,
                           long hi) {
  char *end;
  errno = 0;
  long v = strtol(tok, &end, 10);
  if (end == tok || *end || errno == ERANGE || v < lo || v > hi)
    log_fail(r, "%s value %d: expected an integer in [%ld, %ld], found '%.40s'", what, i + 1, lo,
             hi, tok);
  return v;
}

/* The rest of the line as exactly `count` tokens (their strings in toks). */
static void log_fixed(log_reader *r, const char *what, char **toks, int count) {
  int found = 0;
  char *t;
  while ((t = log_token(r))) {
    if (found < count) toks[found] = t;
    ++found;
  }
  if (found != count) log_fail(r, "%s: expected %d values, found %d", what, count, found);
}

/* The rest of the line as exactly `count` numbers. */
static void log_vector(log_reader *r, const char *what, double *out, int count) {
  int found = 0;
  char *t;
  while ((t = log_token(r))) {
    if (found < count) out[found] = log_parse_double(r, what, found, t);
    ++found;
  }
  if (found != count) log_fail(r, "%s: expected %d numbers, found %d", what, count, found);
}

static double now_ns(void) {
  struct timespec t;
  clock_gettime(CLOCK_MONOTONIC, &t);
  return 1e9 * (double)t.tv_sec + (double)t.tv_nsec;
}

static int cmp_double(const void *a, const void *b) {
  double x = *(const double *)a, y = *(const double *)b;
  return (x > y) - (x < y);
}

/* The estimator block being read; `seen` has a bit per line of it. */
typedef struct {
  amsfe_params par;
  double *qw, *re, rc[2], *x0, *P0;
  unsigned seen;
} est_block;

static const char *const EST_KEYS[] = {"params", "qw", "r_encoder", "r_camera", "x0", "P0"};
enum { EST_NKEYS = 6 };

static void est_block_init(est_block *b, const amsfe_dims *d) {
  memset(b, 0, sizeof(*b));
  b->qw = malloc(sizeof(double) * d->nw), b->re = malloc(sizeof(double) * d->ne);
  b->x0 = malloc(sizeof(double) * d->N), b->P0 = malloc(sizeof(double) * d->N * d->N);
}

/* One line of the estimator block: 0 when r->key is not one of its records, else 1; the P0
 * line (the block's last) creates *est.  Any defect exits (log_fail). */
static int est_block_line(est_block *b, const amsfe_dims *d, log_reader *r, amsfe_est **est) {
  int which = -1;
  for (int i = 0; i < EST_NKEYS; ++i)
    if (strcmp(r->key, EST_KEYS[i]) == 0) which = i;
  if (which < 0) return 0;
  if (b->seen & (1u << which)) log_fail(r, "%s: expected one such line, found a second", r->key);
  amsfe_params *p = &b->par;
  if (which == 0) {
    char *t[10];
    log_fixed(r, "params", t, 10);
    int *ints[] = {&p->estimator,     &p->buffer_steps,     &p->camera_iterations,
                   &p->camera_period, &p->camera_phase,     &p->camera_max_delay,
                   &p->max_frames_per_step};
    for (int i = 0; i < 7; ++i) *ints[i] = (int)log_parse_long(r, "params", i, t[i], INT_MIN, INT_MAX);
    p->gate_camera = log_parse_double(r, "params", 7, t[7]);
    p->gate_encoder = log_parse_double(r, "params", 8, t[8]);
    p->k0 = log_parse_long(r, "params", 9, t[9], LONG_MIN, LONG_MAX);
  } else if (which == 1) {
    log_vector(r, "qw", b->qw, d->nw);
  } else if (which == 2) {
    log_vector(r, "r_encoder", b->re, d->ne);
  } else if (which == 3) {
    log_vector(r, "r_camera", b->rc, 2);
  } else if (which == 4) {
    log_vector(r, "x0", b->x0, d->N);
  } else {
    for (int i = 0; i < EST_NKEYS - 1; ++i)
      if (!(b->seen & (1u << i)))
        log_fail(r, "P0: expected the lines params, qw, r_encoder, r_camera, x0 before it, "
                    "found no %s line", EST_KEYS[i]);
    log_vector(r, "P0", b->P0, d->N * d->N);
    p->qw = b->qw, p->r_encoder = b->re, p->r_camera = b->rc, p->x0 = b->x0, p->P0 = b->P0;
    int status;
    *est = amsfe_est_create(p, &status);
    if (!*est) log_exit(r, LOG_EXIT_RUNTIME, "amsfe_est_create: %s", amsfe_status_string(status));
  }
  b->seen |= 1u << which;
  return 1;
}

#endif /* AMSFE_LOG_H */
