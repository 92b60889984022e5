/* amsfe_arm_config.c: the C arm's parameter file, read once at start (amsfe_arm.c):
 * the run's inputs drawn in Python, the faults, and the generated functions' work
 * space; a refusal's line. */
#define _GNU_SOURCE
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "amsfe_arm.h"

static void gfun_init(gfun *g, cfun f, cwork work) {
  long long a, r, i, w;
  work(&a, &r, &i, &w);
  g->f = f;
  g->arg = (const double **)ALLOC(double *, a + 4);
  g->res = ALLOC(double *, r + 3);
  g->iw = ALLOC(long long, i + 1), g->w = ALLOC(double, w + 1);
}

void fail(arm_t *s, const char *line) { /* carm.py raises it: "error: LINE" */
  FILE *f = s->error_file ? fopen(s->error_file, "w") : NULL;
  if (f) fputs(line, f), fclose(f);
  else fprintf(stderr, "error: %s\n", line);
}

void configure(arm_t *s, const char *path) {
  params_file *pf = &s->pf;
  pf_open(pf, path);
  int dims[3];
  pf_ints(pf, "dims", dims, 3);
  int n = s->n = dims[0], N = s->N = dims[1];
  s->p = dims[2];
  if (n < 1 || n > MAX_JOINTS || N != 4 * n + s->p) pf_fail(pf, "dims", "n, N = 4n + p, p", "others");
  s->T_ns = pf_long(pf, "T_ns");
  s->T = pf_double(pf, "T");
  s->K = (long)pf_long(pf, "K");
  s->lockstep = (int)pf_long(pf, "lockstep");
  s->rate = pf_double(pf, "rate");
  s->start_timeout = pf_double(pf, "start_timeout");
  s->command_timeout = pf_double(pf, "command_timeout");
  if (pf_tokens(pf, "joints", s->names, MAX_JOINTS, 0) != n)
    pf_fail(pf, "joints", "one name per joint", "another count");
  s->t_enc = pf_string(pf, "topic_encoders"), s->t_cam = pf_string(pf, "topic_camera");
  s->t_eff = pf_string(pf, "topic_effort"), s->t_truth = pf_string(pf, "topic_truth");
  s->t_cmd = pf_string(pf, "topic_commands"), s->t_est = pf_string(pf, "topic_estimate");
  s->t_clock = pf_string(pf, "topic_clock");
  s->error_file = pf_string(pf, "error_file");
  s->enc_resolution = pf_double(pf, "enc_resolution");
  const char *t[16];
  if (pf_tokens(pf, "camera", t, 16, 0) != 10) pf_fail(pf, "camera", "10 values", "another count");
  s->cam_period = (int)pf_parse_long(pf, "camera", t[0]);
  s->cam_phase = (int)pf_parse_long(pf, "camera", t[1]);
  s->cam_delay = (int)pf_parse_long(pf, "camera", t[2]);
  s->cam_width = pf_parse_double(pf, "camera", t[3]);
  s->cam_height = pf_parse_double(pf, "camera", t[4]);
  s->pixel_std = pf_parse_double(pf, "camera", t[5]);
  s->round_to_pixel = (int)pf_parse_long(pf, "camera", t[6]);
  s->drop_probability = pf_parse_double(pf, "camera", t[7]);
  s->n_exposures = (long)pf_parse_long(pf, "camera", t[8]);
  s->max_in_flight = (int)pf_parse_long(pf, "camera", t[9]);
  if (s->cam_period < 1 || s->max_in_flight < 1) pf_fail(pf, "camera", "period, queue >= 1", "less");
  if (pf_tokens(pf, "faults", t, 16, 0) != 4) pf_fail(pf, "faults", "4 values", "another count");
  s->f_frozen = (long)pf_parse_long(pf, "faults", t[0]);
  s->f_jump = (long)pf_parse_long(pf, "faults", t[1]);
  s->jump = pf_parse_double(pf, "faults", t[2]);
  s->f_torque = (long)pf_parse_long(pf, "faults", t[3]);
  /* the inputs: one file of float64, in this order */
  long K = s->K, E = s->n_exposures;
  s->x = ALLOC(double, 4 * n), s->x_next = ALLOC(double, 4 * n), s->theta = ALLOC(double, s->p + 1);
  s->enc_noise = ALLOC(double, K * 2 * n), s->tau_d = ALLOC(double, K * 2 * n);
  s->cam_noise = ALLOC(double, 2 * E), s->cam_uniform = ALLOC(double, E);
  s->cam_jitter = ALLOC(double, E);
  FILE *f = fopen(pf_string(pf, "inputs"), "rb");
  struct {
    double *v;
    long count;
  } parts[] = {{s->x, 4 * n},         {s->theta, s->p},      {s->enc_noise, K * 2 * n},
               {s->tau_d, K * 2 * n}, {s->cam_noise, 2 * E}, {s->cam_uniform, E},
               {s->cam_jitter, E}};
  for (size_t i = 0; i < sizeof parts / sizeof parts[0]; ++i)
    if (!f || fread(parts[i].v, sizeof(double), (size_t)parts[i].count, f) != (size_t)parts[i].count)
      pf_fail(pf, "inputs", "the run's arrays (carm.py)", "a shorter or unreadable file");
  fclose(f);
  s->queue = ALLOC(pending, s->max_in_flight), s->due = ALLOC(pending, s->max_in_flight);
  s->frozen = ALLOC(double, 2 * n), s->z = ALLOC(double, 2 * n), s->zs = ALLOC(double, 2 * n);
  s->u = ALLOC(double, n), s->applied = ALLOC(double, n), s->cmd_last = ALLOC(double, n);
  s->xt = ALLOC(double, N), s->y = ALLOC(double, 2), s->J = ALLOC(double, 2 * N);
  s->depth = ALLOC(double, 1);
  s->sent_at = ALLOC(long long, K), s->cmd_lat = ALLOC(long long, K);
  s->est_lat = ALLOC(long long, K);
  gfun_init(&s->g_plant, plant_step, plant_step_work);
  gfun_init(&s->g_cam, camera_measure, camera_measure_work);
}
