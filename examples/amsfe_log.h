/* amsfe_log.h: what the two log-reading examples share (estimate_from_log.c and
 * control_from_log.c): number parsing, timing, and the estimator block of a log
 * (params, qw, r_encoder, r_camera, x0, P0; written by
 * amsfe_sym.runtime.compiled_estimator.estimator_log_lines), which creates the estimator. */
#ifndef AMSFE_LOG_H
#define AMSFE_LOG_H

#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "amsfe_runtime.h"

/* Read `count` numbers from `rest` into `out`; 0 when there are fewer. */
static int read_numbers(char *rest, double *out, int count) {
  char *end = rest;
  for (int i = 0; i < count; ++i) {
    out[i] = strtod(end, &rest);
    if (rest == end) return 0;
    end = rest;
  }
  return 1;
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

/* The estimator block being read. */
typedef struct {
  amsfe_params par;
  double *qw, *re, rc[2], *x0, *P0;
} est_block;

static void est_block_init(est_block *b, const amsfe_dims *d) {
  memset(b, 0, sizeof(*b));
  b->qw = malloc(sizeof(double) * d->nw), b->re = malloc(sizeof(double) * d->ne);
  b->x0 = malloc(sizeof(double) * d->N), b->P0 = malloc(sizeof(double) * d->N * d->N);
}

/* One line of the estimator block: returns 0 when `key` is not one of its keys, else 1 with
 * *ok = 0 on a bad line; the P0 line (the block's last) creates *est (exit on failure). */
static int est_block_line(est_block *b, const amsfe_dims *d, const char *key, char *rest,
                          int *ok, amsfe_est **est) {
  amsfe_params *p = &b->par;
  if (strcmp(key, "params") == 0) {
    *ok = sscanf(rest, "%d %d %d %d %d %d %d %lf %lf %ld", &p->estimator, &p->buffer_steps,
                 &p->camera_iterations, &p->camera_period, &p->camera_phase,
                 &p->camera_max_delay, &p->max_frames_per_step, &p->gate_camera,
                 &p->gate_encoder, &p->k0) == 10;
  } else if (strcmp(key, "qw") == 0) {
    *ok = read_numbers(rest, b->qw, d->nw);
  } else if (strcmp(key, "r_encoder") == 0) {
    *ok = read_numbers(rest, b->re, d->ne);
  } else if (strcmp(key, "r_camera") == 0) {
    *ok = read_numbers(rest, b->rc, 2);
  } else if (strcmp(key, "x0") == 0) {
    *ok = read_numbers(rest, b->x0, d->N);
  } else if (strcmp(key, "P0") == 0) {
    *ok = read_numbers(rest, b->P0, d->N * d->N);
    p->qw = b->qw, p->r_encoder = b->re, p->r_camera = b->rc, p->x0 = b->x0, p->P0 = b->P0;
    int status;
    *est = amsfe_est_create(p, &status);
    if (!*est) {
      fprintf(stderr, "amsfe_est_create: %s\n", amsfe_status_string(status));
      exit(1);
    }
  } else {
    return 0;
  }
  return 1;
}

#endif /* AMSFE_LOG_H */
