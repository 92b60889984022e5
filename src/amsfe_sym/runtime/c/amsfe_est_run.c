/* amsfe_est_run.c: the compiled estimator over a whole log (amsfe_est_run: the ticks, the
 * frames screened and handed over in order, the recorded rows; docs/how-to/runtime-c.md). */
/* The glue is small: optimise it fully whatever the library's flags (-O1 by default, chosen
 * for the size of the generated files); O3 vectorises the kernels' axpy loops.  No
 * -ffast-math: sums keep their order, so results do not depend on the flags. */
#if defined(__GNUC__) && !defined(__clang__)
#pragma GCC optimize("O3")
#endif
#include <math.h>
#include <string.h>

#include "amsfe_est_internal.h"

/* ------------------------------------------------------------------ a whole log */
/* NEES of the robot's Nm states against a truth row [Nm] (input states left out: their
 * marginal covariance P[:Nm, :Nm]); scratch A1, L1, x1, x2 (free between ticks) */
EFFORT_PATH static void nees_inputs(amsfe_est *e, const amsfe_est_log *log, long k,
                                    amsfe_est_log_out *out) {
  long M = e->d.N, N = e->Nm;
  const double *t = log->truth ? log->truth + k * N : NULL;
  if (!t || !all_finite(t, N)) return;
  for (long j = 0; j < N; ++j) copy(e->A1 + j * N, e->P + j * M, N);
  if (!amsfe_cholesky((int)N, e->A1, e->L1)) return;
  double *err = e->x1, *w = e->x2, acc = 0.0;
  for (long i = 0; i < N; ++i) err[i] = t[i] - e->x[i], w[i] = err[i];
  amsfe_chol_solve((int)N, e->L1, w);
  for (long i = 0; i < N; ++i) acc += err[i] * w[i];
  out->nees[k] = acc;
}

static void record_row(amsfe_est *e, const amsfe_est_log *log, long k, amsfe_est_log_out *out) {
  long N = e->d.N;
  copy(out->x_hat + k * N, e->x, N);
  for (long i = 0; i < N; ++i) out->P_diag[k * N + i] = e->P[i + i * N];
  if (!out->nees) return;
  out->nees[k] = NAN;
  if (e->ni) { /* the truth is the robot's state: NEES of P's N x N block */
    nees_inputs(e, log, k, out);
    return;
  }
  const double *t = log->truth ? log->truth + k * N : NULL;
  const double *L = t && all_finite(t, N) ? amsfe_est_factor(e) : NULL;
  if (!L) return;
  double *err = e->x1, *w = e->x2; /* scratch: both are written before they are read */
  for (long i = 0; i < N; ++i) err[i] = t[i] - e->x[i], w[i] = err[i];
  amsfe_chol_solve((int)N, L, w);
  double acc = 0.0;
  for (long i = 0; i < N; ++i) acc += err[i] * w[i];
  out->nees[k] = acc;
}

/* Estimator._screen_frames, then one amsfe_est_camera_frame per usable frame in increasing
 * exposure step; frames [first, last) arrive at the current step. */
#define FRAME_PENDING (-1000) /* screened as usable, not yet given to the estimator */
static int run_frames(amsfe_est *e, const amsfe_est_log *log, long first, long last,
                      amsfe_est_log_out *out) {
  long k = e->k, oldest = k - e->B > e->par.k0 ? k - e->B : e->par.k0, pending = 0;
  for (long f = first; f < last; ++f) {
    long kappa = log->frame_exposure[f];
    int st = FRAME_PENDING;
    out->frame_nis[f] = NAN;
    if (e->par.estimator == AMSFE_ENCODERS) st = AMSFE_IGNORED;
    else if (!all_finite(log->frame_z + 2 * f, 2)) st = AMSFE_REFUSED_NONFINITE;
    else if (kappa >= oldest && e->seen[pmod(kappa, e->B + 1)] == kappa)
      st = AMSFE_REFUSED_DUPLICATE;
    else if (kappa < oldest) st = AMSFE_REFUSED_TOO_OLD;
    else
      for (long g = first; g < f; ++g)
        if (out->frame_status[g] == FRAME_PENDING && log->frame_exposure[g] == kappa)
          st = AMSFE_REFUSED_DUPLICATE;
    pending += st == FRAME_PENDING;
    out->frame_status[f] = st;
  }
  for (; pending > 0; --pending) {
    long best = -1;
    for (long f = first; f < last; ++f)
      if (out->frame_status[f] == FRAME_PENDING &&
          (best < 0 || log->frame_exposure[f] < log->frame_exposure[best]))
        best = f;
    double nis = NAN;
    int st = amsfe_est_camera_frame(e, log->frame_z + 2 * best, log->frame_exposure[best], &nis);
    if (st < 0) return st;
    out->frame_status[best] = st;
    out->frame_nis[best] = st == AMSFE_OK || st == AMSFE_GATED ? nis : NAN;
  }
  return AMSFE_OK;
}

int amsfe_est_run(amsfe_est *e, const amsfe_est_log *log, long k_begin, long k_end,
                  amsfe_est_log_out *out) {
  if (!e || !log || !out || !log->u || !log->z || !out->x_hat || !out->P_diag ||
      !out->encoder_nis || !out->encoder_accepted || k_begin < 0 || k_end > log->K ||
      (log->n_frames > 0 && (!log->frame_exposure || !log->frame_arrival || !log->frame_z ||
                             !out->frame_nis || !out->frame_status)))
    return AMSFE_ERR_INPUT;
  long n = e->d.n, ne = e->d.ne;
  out->failed_step = -1;
  long lo = 0, hi = log->n_frames; /* the first frame arriving at or after k_begin */
  while (lo < hi) {
    long mid = lo + (hi - lo) / 2;
    if (log->frame_arrival[mid] < k_begin) lo = mid + 1;
    else hi = mid;
  }
  long f = lo;
  for (long k = k_begin; k < k_end; ++k) {
    long first = f;
    while (f < log->n_frames && log->frame_arrival[f] == k) ++f;
    if (k == 0) {
      out->encoder_nis[0] = NAN, out->encoder_accepted[0] = 0;
      record_row(e, log, 0, out);
      continue;
    }
    int st = amsfe_est_tick(e, log->z + k * ne, log->u + (k - 1) * n);
    if (st >= 0) st = run_frames(e, log, first, f, out);
    if (st < 0) {
      out->failed_step = k;
      return st;
    }
    /* after the frames: replay re-runs the current step's encoder update */
    out->encoder_nis[k] = e->diag.encoder_nis;
    out->encoder_accepted[k] = (unsigned char)e->diag.encoder_accepted;
    record_row(e, log, k, out);
  }
  return AMSFE_OK;
}
