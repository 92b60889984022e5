/* amsfe_loop.c: the real-time tick and the closed-loop simulation in C (amsfe_loop.h,
 * docs/how-to/runtime-c.md; the controllers they call: amsfe_ctrl.c).
 *
 * Control flow and bookkeeping: every model number comes from the robot's generated
 * functions (plant_step, camera_measure) compiled into the same library; the only arithmetic
 * here is the sensors' noise and the NEES.  Each branch mirrors its Python reference, named in
 * the comments (sim/loop.py, sim/sensors.py); the tests run both and compare every recorded
 * signal.
 */
#include "amsfe_loop.h"

#include <math.h>
#include <string.h>

#include "amsfe_loop_internal.h"

/* ================================================================== the real-time tick */
static void sort_frames(amsfe_frame *f, int count) { /* insertion sort: stable, tiny counts */
  for (int i = 1; i < count; ++i) {
    amsfe_frame v = f[i];
    int j = i - 1;
    while (j >= 0 && f[j].exposure_step > v.exposure_step) f[j + 1] = f[j], --j;
    f[j + 1] = v;
  }
}

int amsfe_loop_tick(amsfe_est *est, amsfe_ctrl *ctrl, const double *z, amsfe_frame *frames,
                    int n_frames, int *frame_status, const double *ref, const double *x_true,
                    double *u, amsfe_ctrl_out *out) {
  if (!est || !ctrl || !u || (n_frames > 0 && !frames)) return AMSFE_ERR_INPUT;
  if (ctrl->ticks > 0) {
    int st = amsfe_est_tick(est, z, ctrl->u_prev);
    if (st < 0) return st;
    amsfe_diag diag;
    amsfe_est_diagnostics(est, &diag);
    amsfe_ctrl_observe_nis(ctrl, diag.encoder_nis); /* the start-up's consistency test */
    sort_frames(frames, n_frames);
    for (int i = 0; i < n_frames; ++i) {
      double nis;
      st = amsfe_est_camera_frame(est, frames[i].z, frames[i].exposure_step, &nis);
      if (st < 0) return st;
      if (frame_status) frame_status[i] = st;
    }
  }
  amsfe_est_state(est, ctrl->x, ctrl->P);
  amsfe_ctrl_observe(ctrl, ctrl->P);
  return amsfe_ctrl_torque(ctrl, ctrl->ticks, ref, ctrl->x, z, x_true, u, out);
}

/* ================================================================== the simulation */
typedef struct {
  long delivery, exposure;
  double z[2];
} pending;

struct amsfe_sim {
  amsfe_sim_params par;
  amsfe_dims d;
  amsfe_est *est;
  amsfe_ctrl *ctrl;
  amsfe_sim_state st;
  gwork g;
  long exposures, last_delivered_exposure;
  int have_last, in_flight;
  pending *queue;
  amsfe_frame *due;
  int *status;
  double *xp, *xp_next, *xt, *xh, *P, *err, *z, *u, *y, *J, *depth, *s, *bound;
};

static size_t sim_layout(amsfe_sim *s, const amsfe_sim_params *p, char *base) {
  const amsfe_dims d = dims_now();
  long n = d.n, N = d.N;
  amsfe_sim tmp;
  if (!s) s = &tmp; /* only measuring, as ctrl_layout */
  carver cv = carve_object(base, sizeof(amsfe_sim));
  s->queue = (pending *)carve(&cv, sizeof(pending) * (size_t)p->max_in_flight);
  s->due = (amsfe_frame *)carve(&cv, sizeof(amsfe_frame) * (size_t)p->max_in_flight);
  s->status = (int *)carve(&cv, sizeof(int) * (size_t)p->max_in_flight);
  s->xp = DBL(&cv, 4 * n), s->xp_next = DBL(&cv, 4 * n), s->xt = DBL(&cv, N);
  s->xh = DBL(&cv, N), s->P = DBL(&cv, N * N), s->err = DBL(&cv, N);
  s->z = DBL(&cv, 2 * n), s->u = DBL(&cv, n), s->y = DBL(&cv, 2), s->J = DBL(&cv, 2 * N);
  s->depth = DBL(&cv, 1), s->s = DBL(&cv, n), s->bound = DBL(&cv, n);
  carve_work(&cv, WORKS, sizeof(WORKS) / sizeof(WORKS[0]), &s->g);
  return cv.off + 16;
}

static int sim_params_ok(const amsfe_sim_params *p) {
  if (!p || p->K < 1 || !p->x_plant0 || !p->theta_true || !p->ref || !p->enc_noise || !p->tau_d)
    return 0;
  if (p->cam_period < 1 || p->cam_phase < 0 || p->cam_phase >= p->cam_period ||
      p->cam_delay < 0 || p->max_in_flight < 1 || p->n_exposures < 0)
    return 0;
  if (p->n_exposures > 0 && (!p->cam_noise || !p->cam_uniform || !p->cam_jitter)) return 0;
  return p->enc_resolution >= 0 && p->diverged_error > 0;
}

size_t amsfe_sim_memory_size(const amsfe_sim_params *params) {
  if (!sim_params_ok(params)) return 0;
  return sim_layout(NULL, params, NULL);
}

int amsfe_sim_init(amsfe_sim **out, const amsfe_sim_params *p, amsfe_est *est, amsfe_ctrl *ctrl,
                   void *memory, size_t size) {
  if (!out || !memory || !est || !ctrl) return AMSFE_ERR_INPUT;
  if (!sim_params_ok(p)) return AMSFE_ERR_CONFIG;
  if (sim_layout(NULL, p, NULL) > size || ((size_t)memory & 15u)) return AMSFE_ERR_MEMORY;
  memset(memory, 0, size);
  amsfe_sim *s = (amsfe_sim *)memory;
  sim_layout(s, p, (char *)memory);
  amsfe_dims_get(&s->d);
  s->par = *p, s->est = est, s->ctrl = ctrl;
  memcpy(s->xp, p->x_plant0, sizeof(double) * (size_t)(4 * s->d.n));
  *out = s;
  return AMSFE_OK;
}

void amsfe_sim_get_state(const amsfe_sim *s, amsfe_sim_state *state) { *state = s->st; }

/* Camera._inside */
static int inside(const amsfe_sim *s, const double *y) {
  return isfinite(y[0]) && isfinite(y[1]) && y[0] >= 0.0 && y[0] < s->par.cam_width &&
         y[1] >= 0.0 && y[1] < s->par.cam_height;
}

/* Camera._expose at step k: project, draw (always), decide, queue. */
static int expose(amsfe_sim *s, long k, const double *q) {
  const amsfe_sim_params *p = &s->par;
  long e = s->exposures;
  if (e >= p->n_exposures) return AMSFE_ERR_INPUT; /* the caller drew too few */
  const double *in[2] = {q, p->theta_true};
  double *res[3] = {s->y, s->J, s->depth};
  if (gcall(&s->g, camera_measure, in, 2, res, 3)) return AMSFE_ERR_NONFINITE;
  if (!(s->depth[0] > 0)) s->y[0] = s->y[1] = NAN;
  s->exposures++;
  s->st.frames_exposed++;
  if (!inside(s, s->y)) {
    s->st.frames_out_of_image++, s->st.frames_out_of_image_true++;
    return AMSFE_OK;
  }
  double z[2];
  for (int i = 0; i < 2; ++i) {
    z[i] = s->y[i] + p->pixel_std * p->cam_noise[2 * e + i];
    if (p->round_to_pixel) z[i] = nearbyint(z[i]); /* np.round: half to even */
  }
  if (!inside(s, z)) {
    s->st.frames_out_of_image++;
    return AMSFE_OK;
  }
  if (p->cam_uniform[e] < p->drop_probability) {
    s->st.frames_dropped++;
    return AMSFE_OK;
  }
  if (s->in_flight >= p->max_in_flight) return AMSFE_ERR_MEMORY;
  pending *slot = &s->queue[s->in_flight++];
  slot->delivery = k + p->cam_delay + p->cam_jitter[e];
  slot->exposure = k;
  slot->z[0] = z[0], slot->z[1] = z[1];
  return AMSFE_OK;
}

/* Camera.tick: expose if due, then hand out the frames due now, sorted by exposure. */
static int camera_tick(amsfe_sim *s, long k, const double *q, int *count) {
  const amsfe_sim_params *p = &s->par;
  *count = 0;
  if (k % p->cam_period == p->cam_phase) {
    int st = expose(s, k, q);
    if (st != AMSFE_OK) return st;
  }
  int keep = 0;
  for (int i = 0; i < s->in_flight; ++i) {
    pending *f = &s->queue[i];
    if (f->delivery <= k) {
      s->due[*count].exposure_step = f->exposure;
      s->due[*count].z[0] = f->z[0], s->due[*count].z[1] = f->z[1];
      ++*count;
    } else {
      s->queue[keep++] = *f;
    }
  }
  s->in_flight = keep;
  sort_frames(s->due, *count);
  for (int i = 0; i < *count; ++i) {
    long ex = s->due[i].exposure_step;
    if (s->have_last && ex < s->last_delivered_exposure) s->st.frames_out_of_order++;
    if (!s->have_last || ex > s->last_delivered_exposure) s->last_delivered_exposure = ex;
    s->have_last = 1;
  }
  s->st.frames_delivered += *count;
  return AMSFE_OK;
}

/* e^T P^-1 e with L the Cholesky factor of P (NaN when there is none: P not positive
 * definite); w: N of scratch. */
static double nees(int N, const double *L, const double *e, double *w) {
  if (!L) return NAN;
  memcpy(w, e, sizeof(double) * (size_t)N);
  amsfe_chol_solve(N, L, w);
  double acc = 0.0;
  for (int i = 0; i < N; ++i) acc += e[i] * w[i];
  return acc;
}

/* sim/loop.py's REFUSAL_KINDS, from the runtime's statuses (amsfe_loop.h). */
int amsfe_sim_count_frame(amsfe_sim_state *st, int status) {
  switch (status) {
    case AMSFE_OK: st->frames_applied++; return 1;
    case AMSFE_IGNORED: return 0;
    case AMSFE_GATED: st->refused_gated++; break;
    case AMSFE_REFUSED_NONFINITE: st->refused_nan++; break;
    case AMSFE_REFUSED_TOO_OLD:
    case AMSFE_REFUSED_NO_CLONE_LEFT: st->refused_too_late++; break;
    case AMSFE_REFUSED_INDEFINITE: st->refused_indefinite++; break;
    case AMSFE_REFUSED_NO_CLONE: st->refused_unscheduled++; break;
    case AMSFE_REFUSED_NO_CONVERGENCE: st->refused_no_convergence++; break;
    default: st->refused_other++;
  }
  st->frames_rejected++;
  return -1;
}

int amsfe_sim_run(amsfe_sim *s, long ticks, const amsfe_sim_records *rec) {
  const amsfe_sim_params *p = &s->par;
  amsfe_sim_state *st = &s->st;
  long n = s->d.n, N = s->d.N, pth = N - 4 * n;
  if (!rec) return AMSFE_ERR_INPUT;
  if (st->status < 0) return st->status;
  long end = st->k + ticks < p->K ? st->k + ticks : p->K;
  if (st->diverged) end = st->k;
  amsfe_ctrl_out out = {s->s, s->bound, NULL, 0};
  for (long k = st->k; k < end; ++k) {
    const double *xp = s->xp;
    memcpy(s->xt, xp, sizeof(double) * (size_t)(4 * n));
    memcpy(s->xt + 4 * n, p->theta_true, sizeof(double) * (size_t)pth);
    /* 1. sensors at t_k (Encoders.measure; row 0 made z0) */
    if (!all_finite(xp, 4 * n)) {
      st->plant_nonfinite = 1;
      return st->status = AMSFE_ERR_NONFINITE;
    }
    const double *v = p->enc_noise + k * 2 * n;
    for (long j = 0; j < n; ++j) {
      double zq = xp[2 * n + j] + v[j];
      if (p->enc_resolution > 0) zq = nearbyint(zq / p->enc_resolution) * p->enc_resolution;
      s->z[j] = zq;
      s->z[n + j] = xp[3 * n + j] + v[n + j];
    }
    int nf;
    int cst = camera_tick(s, k, xp, &nf);
    if (cst != AMSFE_OK) return st->status = cst;
    if (rec->frames)
      for (int i = 0; i < nf; ++i) {
        if (st->frames_recorded >= rec->frames_capacity) return st->status = AMSFE_ERR_MEMORY;
        double *row = rec->frames + 4 * st->frames_recorded++;
        row[0] = (double)s->due[i].exposure_step, row[1] = (double)k;
        row[2] = s->due[i].z[0], row[3] = s->due[i].z[1];
      }
    /* 2.-3. estimator k-1 -> k, controller, actuator limit */
    int tst = amsfe_loop_tick(s->est, s->ctrl, s->z, s->due, nf, s->status, p->ref + k * 5 * n,
                              s->xt, s->u, &out);
    if (tst < 0) return st->status = tst;
    if (k > 0) {
      amsfe_diag dg;
      amsfe_est_diagnostics(s->est, &dg);
      for (int i = 0; i < nf; ++i) amsfe_sim_count_frame(st, s->status[i]);
      if (!dg.encoder_accepted) {
        st->encoder_rejected++;
        if (isnan(dg.encoder_nis)) st->refused_nan++; else st->refused_gated++;
      }
    }
    /* record */
    amsfe_est_state(s->est, s->xh, s->P);
    for (long i = 0; i < N; ++i) s->err[i] = s->xt[i] - s->xh[i];
    if (rec->x_true) memcpy(rec->x_true + k * N, s->xt, sizeof(double) * (size_t)N);
    if (rec->x_hat) memcpy(rec->x_hat + k * N, s->xh, sizeof(double) * (size_t)N);
    if (rec->P_diag)
      for (long i = 0; i < N; ++i) rec->P_diag[k * N + i] = s->P[i + i * N];
    /* the estimator's own factor of P: the one its next prediction uses (eq. 14) */
    if (rec->nees) rec->nees[k] = nees((int)N, amsfe_est_factor(s->est), s->err, s->J);
    if (rec->u) memcpy(rec->u + k * n, s->u, sizeof(double) * (size_t)n);
    if (rec->z_enc) memcpy(rec->z_enc + k * 2 * n, s->z, sizeof(double) * (size_t)(2 * n));
    if (rec->s) memcpy(rec->s + k * n, s->s, sizeof(double) * (size_t)n);
    if (rec->bound) memcpy(rec->bound + k * n, s->bound, sizeof(double) * (size_t)n);
    if (rec->saturated) rec->saturated[k] = (unsigned char)out.saturated;
    st->ticks_done = k + 1;
    st->k = k + 1;
    /* _diverged: not finite, or the link tracking error beyond the limit */
    int bad = !all_finite(xp, 4 * n) || !all_finite(s->u, n);
    for (long j = 0; j < n && !bad; ++j)
      bad = fabs(xp[j] - p->ref[k * 5 * n + j]) > p->diverged_error;
    if (bad) {
      st->diverged = 1;
      return AMSFE_OK;
    }
    /* 4. plant over [t_k, t_k + T] */
    if (k + 1 < p->K) {
      const double *in[4] = {s->xp, s->u, p->theta_true, p->tau_d + k * 2 * n};
      double *res[1] = {s->xp_next};
      if (gcall(&s->g, plant_step, in, 4, res, 1)) return st->status = AMSFE_ERR_NONFINITE;
      memcpy(s->xp, s->xp_next, sizeof(double) * (size_t)(4 * n));
    }
  }
  return AMSFE_OK;
}
