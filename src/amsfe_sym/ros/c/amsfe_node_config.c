/* amsfe_node_config.c: the C node's configuration, read once at start from the
 * parameter file amsfe_sym.ros.cnode writes (amsfe_node_params.h; amsfe_node.c). */
#define _GNU_SOURCE
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "amsfe_node.h"

static const char *const TOPIC_KEYS[T_N] = {
    "topic_encoders", "topic_camera", "topic_effort", "topic_truth", "topic_estimate",
    "topic_estimate_std", "topic_theta", "topic_diagnostics", "topic_commands"};

/* Read the parameter file into the node and its live loop. */
void configure(node_t *s, const char *path) {
  params_file *pf = &s->pf;
  pf_open(pf, path);
  amsfe_dims d;
  amsfe_dims_get(&d);
  int dims[4];
  pf_ints(pf, "dims", dims, 4);
  if (dims[0] != d.n || dims[1] != d.N || dims[3] != d.ne) {
    char found[96];
    snprintf(found, sizeof found, "a library of n = %d, N = %d, ne = %d", d.n, d.N, d.ne);
    pf_fail(pf, "dims", "the sizes of the library the node was built with", found);
  }
  int n = s->n = d.n, N = s->N = d.N;
  s->p = N - 4 * n;
  live_loop *L = &s->L;
  L->n = n, L->N = N;
  L->T_ns = pf_long(pf, "T_ns");
  s->T = pf_double(pf, "T");
  L->tol = pf_double(pf, "grid_tolerance");
  L->max_gap = (int)pf_long(pf, "max_gap_steps");
  L->exposure_shift = pf_long(pf, "exposure_shift");
  L->controller = (int)pf_long(pf, "controller");
  s->end_k = (long)pf_long(pf, "end_k");
  s->std_every = (int)pf_long(pf, "std_every");
  s->hold_zero = strcmp(pf_string(pf, "hold"), "zero") == 0;
  s->encoder_timeout = pf_double(pf, "encoder_timeout");
  s->subscriber_wait = pf_double(pf, "subscriber_wait");
  s->effort_in_encoders = (int)pf_long(pf, "effort_in_encoders");
  s->read_effort = (int)pf_long(pf, "read_effort");
  s->managed = (int)pf_long(pf, "managed");
  s->active = !s->managed;
  for (int i = 0; i < T_N; ++i) s->topic[i] = pf_string(pf, TOPIC_KEYS[i]);
  if (n > MAX_JOINTS) pf_fail(pf, "joints", "at most 64 joints", "more");
  if (pf_tokens(pf, "joints", s->names, MAX_JOINTS, 0) != n)
    pf_fail(pf, "joints", "one name per joint of the library", "another count");
  /* the estimator's block */
  amsfe_params *ep = &L->ep;
  char const *t[16];
  if (pf_tokens(pf, "est", t, 16, 0) != 11) pf_fail(pf, "est", "11 values", "another count");
  int *ints[] = {&ep->estimator, &ep->buffer_steps, &ep->camera_iterations, &ep->camera_period,
                 &ep->camera_phase, &ep->camera_max_delay, &ep->max_frames_per_step};
  for (int i = 0; i < 7; ++i) *ints[i] = (int)pf_parse_long(pf, "est", t[i]);
  ep->gate_camera = pf_parse_double(pf, "est", t[7]);
  ep->gate_encoder = pf_parse_double(pf, "est", t[8]);
  ep->k0 = (long)pf_parse_long(pf, "est", t[9]);
  ep->backward_map = (int)pf_parse_long(pf, "est", t[10]);
  double *qw = ALLOC(double, d.nw), *re = ALLOC(double, d.ne), *rc = ALLOC(double, 2);
  double *x0 = ALLOC(double, N), *P0 = ALLOC(double, (size_t)N * N);
  pf_doubles(pf, "qw", qw, d.nw);
  pf_doubles(pf, "r_encoder", re, d.ne);
  pf_doubles(pf, "r_camera", rc, 2);
  pf_doubles(pf, "x0", x0, N);
  pf_doubles(pf, "P0", P0, N * N);
  ep->qw = qw, ep->r_encoder = re, ep->r_camera = rc, ep->x0 = x0, ep->P0 = P0;
  L->x0_from_encoders = (int)pf_long(pf, "x0_motor_from_encoders");
  L->inverse_tol = pf_double(pf, "inverse_tol");
  /* the controller's block */
  if (L->controller) {
    amsfe_ctrl_params *cp = &L->cp;
    if (pf_tokens(pf, "ctrl", t, 16, 0) != 16) pf_fail(pf, "ctrl", "16 values", "another count");
    cp->controller = (int)pf_parse_long(pf, "ctrl", t[0]);
    cp->T = pf_parse_double(pf, "ctrl", t[1]);
    cp->p = pf_parse_double(pf, "ctrl", t[2]);
    cp->qmd_next_hold = (int)pf_parse_long(pf, "ctrl", t[3]);
    cp->state_true = (int)pf_parse_long(pf, "ctrl", t[4]);
    cp->link_bandwidth = pf_parse_double(pf, "ctrl", t[5]);
    cp->motor_bandwidth = pf_parse_double(pf, "ctrl", t[6]);
    cp->startup_converged = (int)pf_parse_long(pf, "ctrl", t[7]);
    cp->ready_q_std = pf_parse_double(pf, "ctrl", t[8]);
    cp->ready_qd_std = pf_parse_double(pf, "ctrl", t[9]);
    cp->blend_accel = pf_parse_double(pf, "ctrl", t[10]);
    cp->blend_rate = pf_parse_double(pf, "ctrl", t[11]);
    cp->ready_nis = pf_parse_double(pf, "ctrl", t[12]);
    cp->ready_nis_window = pf_parse_double(pf, "ctrl", t[13]);
    cp->hold_motor = (int)pf_parse_long(pf, "ctrl", t[14]);
    cp->blend_wf = pf_parse_double(pf, "ctrl", t[15]);
    if (pf_tokens(pf, "ctrl2", t, 16, 0) != 2) pf_fail(pf, "ctrl2", "2 values", "another count");
    cp->headroom_tau = pf_parse_double(pf, "ctrl2", t[0]);
    cp->blend_lead = pf_parse_double(pf, "ctrl2", t[1]);
    static const char *const vec[] = {"h", "lam", "Lt", "eps", "phi", "wm", "tau_max", "wf",
                                      "vmax", "u_max", "Mm", "Fm", "Ks"};
    const double **dst[] = {&cp->h, &cp->lam, &cp->Lt, &cp->eps, &cp->phi, &cp->wm,
                            &cp->tau_max, &cp->wf, &cp->vmax, &cp->u_max, &cp->Mm, &cp->Fm,
                            &cp->Ks};
    for (int i = 0; i < 13; ++i) {
      double *v = ALLOC(double, n);
      pf_doubles(pf, vec[i], v, n);
      *dst[i] = v;
    }
    int *ks = ALLOC(int, n);
    pf_ints(pf, "ks_theta", ks, n);
    cp->ks_theta = ks;
    double *th = ALLOC(double, s->p + 1);
    pf_doubles(pf, "theta_initial", th, s->p);
    cp->theta_initial = th;
    /* the reference: K rows of 5n float64 in a binary file */
    const char *ref_tok[2];
    if (pf_tokens(pf, "ref_file", ref_tok, 2, 0) != 2)
      pf_fail(pf, "ref_file", "a path and a row count", "another count");
    L->K_ref = (long)pf_parse_long(pf, "ref_file", ref_tok[1]);
    double *ref = ALLOC(double, (size_t)L->K_ref * 5 * n);
    FILE *f = fopen(ref_tok[0], "rb");
    if (!f || fread(ref, sizeof(double) * 5 * (size_t)n, (size_t)L->K_ref, f) != (size_t)L->K_ref)
      pf_fail(pf, "ref_file", "K rows of 5n float64", "a shorter or unreadable file");
    fclose(f);
    L->ref = ref;
  }
  s->hold_limit = ALLOC(double, n);
  pf_doubles(pf, "hold_limit", s->hold_limit, n);
  /* the watchdogs: the [watchdog] keys of the spec, in amsfe_watchdog_config's order */
  double w[11];
  pf_doubles(pf, "watchdog", w, 11);
  amsfe_watchdog_config wc = {n, N, d.ne, s->T, w[0], w[1], (int)w[2], w[3], (int)w[4],
                              (int)w[5], w[6], w[7], L->max_gap, w[8], (int)w[9],
                              s->hold_limit /* u_max (inf: none) */, w[10]};
  size_t wsize = amsfe_watchdog_memory_size(&wc);
  void *wmem = NULL;
  if (!wsize || posix_memalign(&wmem, 64, wsize) != 0 ||
      amsfe_watchdog_init(&s->wd, &wc, wmem, wsize) != AMSFE_OK)
    pf_fail(pf, "watchdog", "bounds the watchdogs accept (amsfe_watchdog_init)", "a refusal");
  s->encoder_timeout = w[7];
  s->frame_nis = ALLOC(double, LIVE_MAX_FRAMES);
}
