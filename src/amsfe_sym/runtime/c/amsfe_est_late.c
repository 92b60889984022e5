/* amsfe_est_late.c: the compiled estimator's late (out-of-sequence) camera frames:
 * oosm's retrodiction (eqs. 18-24), the replay and the cloning of amsfe_params.method, and
 * amsfe_est_camera_frame (amsfe_est_tick.c: the steps they re-run; docs/how-to/runtime-c.md).
 * Each branch mirrors the Python reference in estimation/ (named per function). */
/* The glue is small: optimise it fully whatever the library's flags (-O1 by default, chosen
 * for the size of the generated files); O3 vectorises the kernels' axpy loops.  No
 * -ffast-math: sums keep their order, so results do not depend on the flags. */
#if defined(__GNUC__) && !defined(__clang__)
#pragma GCC optimize("O3")
#endif
#include <math.h>
#include <string.h>

#include "amsfe_est_internal.h"

/* ------------------------------------------------------------------ late frames */
/* oosm.backward_inverse (eqs. 22, 24): xr <- x_j = F^-1(x_{j+1}, u_j) for j = k-1 .. kappa
 * from x_{k} = xs, each step refused unless its residual converged (CompiledTransition.
 * inverse); Phi <- A(x_{k-1}) ... A(x_kappa), the backward map's jacobian being Phi^-1. */
static int oosm_backward_inverse(amsfe_est *e, long kappa) {
  long N = e->d.N, NN = N * N;
  cint n_out = transition_inverse_n_out();
  copy(e->xr, e->xs, N);
  memset(e->Phi, 0, sizeof(double) * (size_t)NN);
  for (long i = 0; i < N; ++i) e->Phi[i * (N + 1)] = 1.0;
  for (long j = e->k - 1; j >= kappa; --j) {
    const double *uj = e->u_buf + pmod(j, e->B) * e->d.n;
    double residual = NAN, scale = 1.0;
    for (long i = 0; i < N; ++i) scale = fmax(scale, fabs(e->xr[i])); /* max(1, |x_next|) */
    for (cint i = 2; i < n_out; ++i) e->g.res[i] = NULL;
    const double *ii[2] = {e->xr, uj};
    double *io[2] = {e->sv, &residual};
    gcall(&e->g, transition_inverse, ii, 2, io, 2);
    if (!(residual <= e->inv_tol * scale)) { /* NaN too */
      e->inv_residual = residual, e->inv_limit = e->inv_tol * scale;
      return AMSFE_REFUSED_NO_CONVERGENCE;
    }
    const double *si[2] = {e->sv, uj};
    double *so[3] = {NULL, e->A1, NULL};
    gcall(&e->g, STEP, si, 2, so, 3); /* A(x_j) */
    amsfe_matmul((int)N, e->Phi, e->A1, e->Phi2);
    copy(e->Phi, e->Phi2, NN);
    copy(e->xr, e->sv, N);
  }
  return AMSFE_OK;
}

/* oosm.a1_retrodict with the last update's joint-torque H (its nonzeros last_hval):
 * Q H^T, P_prior H^T and S = sym(H P_prior H^T) + R, then the kernel */
EFFORT_PATH static int retrodict_torque(amsfe_est *e) {
  int M = e->d.N, m = e->d.ne;
  double *QHt = e->RH, *PHt = QHt + (long)M * m, *S = PHt + (long)M * m, *T = S + m * m;
  for (int a = 0; a < m; ++a) {
    double *qa = QHt + (long)a * M, *pa = PHt + (long)a * M;
    for (int i = 0; i < M; ++i) qa[i] = pa[i] = 0.0;
    for (int v = e->ehrow[a]; v < e->ehrow[a + 1]; ++v) {
      const double *qc = e->Q + (long)e->ehcol[v] * M, *pc = e->last_Pprior + (long)e->ehcol[v] * M;
      double h = e->last_hval[v];
      for (int i = 0; i < M; ++i) qa[i] += qc[i] * h, pa[i] += pc[i] * h;
    }
  }
  for (int b = 0; b < m; ++b)
    for (int a = 0; a < m; ++a) {
      double t = 0.0;
      for (int v = e->ehrow[a]; v < e->ehrow[a + 1]; ++v)
        t += e->last_hval[v] * PHt[e->ehcol[v] + (long)b * M];
      T[a + b * m] = t;
    }
  for (int b = 0; b < m; ++b)
    for (int a = 0; a < m; ++a)
      S[a + b * m] = 0.5 * (T[a + b * m] + T[b + a * m]) + (a == b ? e->re[a] : 0.0);
  return amsfe_a1_retrodict_cols(M, m, S, QHt, PHt, e->x, e->P, e->Q, e->last_nu, e->xs, e->M,
                                 e->C, e->RW);
}

/* oosm.a1_correct on a state with input states (est_oosm_correct is the model's N): G = Hc
 * Phi^-1 at x_r = xr, Szz = sym(G M G^T) + R, W = C G^T Szz^-1, P+ = sym(P - W (C G^T)^T) */
EFFORT_PATH static int oosm_correct_inputs(amsfe_est *e, const double *z, double *nis) {
  long M = e->d.N;
  int n = e->d.n;
  double *G = e->OW, *GM = G + 2 * M, *Pxz = GM + 2 * M, *W = Pxz + 2 * M;
  /* scratch: Phi2 (Phi^T), A1 (P - W Pxz^T; oosm's predictions keep theirs in A_buf) */
  double Szz[4], Ls[4], nu[2], sn[2];
  if (!camera_h(e, e->xr)) return AMSFE_ERR_NONFINITE;
  for (int r = 0; r < 2; ++r) { /* row r of G: Phi^T g = Hc[r, :]^T */
    double *g = G + r * M;
    for (long i = 0; i < M; ++i) g[i] = 0.0;
    for (int j = 0; j < n; ++j) g[e->chcol[r * n + j]] = e->chval[r * n + j];
    for (long j = 0; j < M; ++j)
      for (long i = 0; i < M; ++i) e->Phi2[i + j * M] = e->Phi[j + i * M];
    if (!amsfe_lu_solve((int)M, e->Phi2, g)) return AMSFE_ERR_NONFINITE;
  }
  if (!all_finite(G, 2 * M)) return AMSFE_ERR_NONFINITE;
  for (int r = 0; r < 2; ++r) /* G M and C G^T (M, C: M x M) */
    for (long i = 0; i < M; ++i) {
      double gm = 0.0, pz = 0.0;
      for (long l = 0; l < M; ++l) {
        gm += G[r * M + l] * e->M[l + i * M];
        pz += e->C[i + l * M] * G[r * M + l];
      }
      GM[r * M + i] = gm, Pxz[i + r * M] = pz;
    }
  double T[4];
  for (int a = 0; a < 2; ++a)
    for (int b = 0; b < 2; ++b) {
      double t = 0.0;
      for (long i = 0; i < M; ++i) t += GM[a * M + i] * G[b * M + i];
      T[a + 2 * b] = t;
    }
  for (int a = 0; a < 2; ++a)
    for (int b = 0; b < 2; ++b)
      Szz[a + 2 * b] = 0.5 * (T[a + 2 * b] + T[b + 2 * a]) + (a == b ? e->rc[a] : 0.0);
  if (!amsfe_cholesky(2, Szz, Ls)) return AMSFE_REFUSED_INDEFINITE;
  for (int r = 0; r < 2; ++r) nu[r] = z[r] - e->cy[r], sn[r] = nu[r];
  amsfe_chol_solve(2, Ls, sn);
  e->nis = nu[0] * sn[0] + nu[1] * sn[1];
  if (nis) *nis = e->nis;
  if (!(e->nis <= e->par.gate_camera)) return AMSFE_GATED;
  for (long i = 0; i < M; ++i) { /* row i of W = Pxz Szz^-1 */
    double w2[2] = {Pxz[i], Pxz[i + M]};
    amsfe_chol_solve(2, Ls, w2);
    W[i] = w2[0], W[i + M] = w2[1];
  }
  for (long j = 0; j < M; ++j)
    for (long i = 0; i < M; ++i)
      e->A1[i + j * M] = e->P[i + j * M] - (W[i] * Pxz[j] + W[i + M] * Pxz[j + M]);
  for (long j = 0; j < M; ++j)
    for (long i = 0; i < M; ++i)
      e->P1[i + j * M] = 0.5 * (e->A1[i + j * M] + e->A1[j + i * M]);
  if (!amsfe_cholesky((int)M, e->P1, e->L1)) return AMSFE_REFUSED_INDEFINITE; /* P(k|kappa+) */
  for (long i = 0; i < M; ++i) e->x[i] += W[i] * nu[0] + W[i + M] * nu[1];
  swap_P(e, &e->P1);
  return AMSFE_OK;
}

/* OosmEstimator._late_frame (A1 over the lag) */
static int oosm_late(amsfe_est *e, const double *z, long kappa, double *nis) {
  long N = e->d.N, NN = N * N, k = e->k;
  memset(e->Phi, 0, sizeof(double) * (size_t)NN);
  memset(e->Q, 0, sizeof(double) * (size_t)NN);
  memset(e->sv, 0, sizeof(double) * (size_t)N);
  for (long i = 0; i < N; ++i) e->Phi[i * (N + 1)] = 1.0;
  for (long j = kappa; j < k; ++j) { /* eq. (23) */
    long s = pmod(j, e->B);
    const double *Aj = e->A_buf + s * NN;
    amsfe_matmul((int)N, Aj, e->Phi, e->Phi2);
    amsfe_sandwich((int)N, e->d.nw, Aj, e->Q, e->G_buf + s * N * e->d.nw, e->qw, e->Qb, e->T1);
    copy(e->Phi, e->Phi2, NN);
    copy(e->Q, e->Qb, NN);
    /* the updates' corrections carried to k (oosm.backward_map): s <- A_j s + c_{j+1} */
    for (long i = 0; i < N; ++i) e->xr[i] = 0.0;
    for (long m = 0; m < N; ++m) {
      double c = e->sv[m];
      for (long i = 0; i < N; ++i) e->xr[i] += Aj[i + m * N] * c;
    }
    if (j + 1 < k) {
      const double *post = e->xpost_buf + pmod(j + 1, e->B) * N, *prior = e->xprior_buf + s * N;
      for (long i = 0; i < N; ++i) e->xr[i] += post[i] - prior[i];
    }
    copy(e->sv, e->xr, N);
  }
  if (e->has_last > 0.5 && e->jt) { /* the same with the joint torques' H */
    if (!retrodict_torque(e)) return AMSFE_ERR_S_NOT_PD;
  } else if (e->has_last > 0.5) { /* oosm.a1_retrodict (eqs. 24-27 corrected) */
    if (!amsfe_a1_retrodict((int)N, e->d.ne, e->enc_rows, e->re, e->x, e->P, e->Q, e->last_nu,
                            e->last_Pprior, e->xs, e->M, e->C, e->RW))
      return AMSFE_ERR_S_NOT_PD;
  } else { /* no encoder update at k: x_shift = x, M = C = P - Q */
    copy(e->xs, e->x, N);
    for (long i = 0; i < NN; ++i) e->M[i] = e->C[i] = e->P[i] - e->Q[i];
  }
  if (e->par.backward_map == AMSFE_BACKWARD_INVERSE) {
    int st = oosm_backward_inverse(e, kappa);
    if (st != AMSFE_OK) return st;
  } else { /* eq. (24): x(kappa|k) = F_{kappa,k}(x_shift) linearised about the stored
              * trajectory: x(kappa|kappa) + Phi^-1 (s + x_shift - x(k|k-1)) (oosm.backward_map) */
    const double *prior_k = e->xprior_buf + pmod(k - 1, e->B) * N;
    for (long i = 0; i < N; ++i) e->xr[i] = e->sv[i] + (e->xs[i] - prior_k[i]);
    copy(e->Phi2, e->Phi, NN);
    if (!amsfe_lu_solve((int)N, e->Phi2, e->xr)) return AMSFE_ERR_NONFINITE;
    const double *post_kappa = e->xpost_buf + pmod(kappa, e->B) * N;
    for (long i = 0; i < N; ++i) e->xr[i] += post_kappa[i];
  }
  if (!all_finite(e->xr, N)) return AMSFE_ERR_NONFINITE;
  if (e->ni) return oosm_correct_inputs(e, z, nis);
  const double *in[8] = {e->x, e->P, e->xr, e->M, e->C, e->Phi, z, e->rc};
  double *out[5] = {e->x1, e->P1, &e->nis, &e->s_ok, &e->chk};
  gcall(&e->g, est_oosm_correct, in, 8, out, 5);
  if (!isfinite(e->chk)) return AMSFE_ERR_NONFINITE;
  if (!(e->s_ok > 0.5)) return AMSFE_REFUSED_INDEFINITE;
  if (nis) *nis = e->nis;
  if (!(e->nis <= e->par.gate_camera)) return AMSFE_GATED;
  if (!amsfe_cholesky((int)N, e->P1, e->L1)) return AMSFE_REFUSED_INDEFINITE; /* P(k|kappa+) */
  copy(e->x, e->x1, N);
  swap_P(e, &e->P1);
  return AMSFE_OK;
}

/* ReplayEstimator: rewind to kappa, apply the frame there, re-filter up to now */
static int replay_frame(amsfe_est *e, const double *z, long kappa, double *nis) {
  long N = e->d.N, s = pmod(kappa, e->R), k = e->k;
  if (e->r_nf[s] >= e->F) return AMSFE_REFUSED_FULL;
  if (kappa < k) {
    copy(e->x, e->r_x + s * N, N);
    set_P(e, e->r_P + s * N * N);
  }
  int st = frame_now(e, z, nis);
  if (st < 0) return st;
  copy(e->r_fz + (s * e->F + e->r_nf[s]) * e->d.nc, z, e->d.nc);
  ++e->r_nf[s];
  replay_store(e, kappa);
  for (long j = kappa; j < k; ++j) {
    int st2 = replay_step(e, j, j + 1 == k);
    if (st2) return st2;
  }
  e->diag.replayed_steps = (int)(k - kappa);
  return st;
}

/* CloningEstimator: update through the clone of kappa, then drop it */
static int cloning_frame(amsfe_est *e, const double *z, long kappa, double *nis) {
  int N = e->d.N, S = e->S, Na = (1 + S) * N, slot = -1;
  for (int s = 0; s < S; ++s)
    if (e->clone_on[s] && e->clone_k[s] == kappa) slot = s;
  if (slot < 0) return scheduled(e, kappa) ? AMSFE_REFUSED_NO_CLONE_LEFT : AMSFE_REFUSED_NO_CLONE;
  if (e->ni) { /* the generated update is the model's N: the clone's padded H, in C */
    int n = e->d.n, o = N * (1 + slot);
    if (!camera_h(e, e->xa + o)) return AMSFE_ERR_NONFINITE;
    for (int r = 0; r < 2; ++r) {
      e->cnu[r] = z[r] - e->cy[r];
      for (int j = 0; j < n; ++j) e->ccol[r * n + j] = o + j; /* the clone's q */
    }
    if (!amsfe_joseph_rows(Na, 2, e->chrow, e->ccol, e->chval, e->rc, e->xa, e->Pa, e->cnu,
                           e->xa2, e->Pa2, &e->nis, e->JW))
      return AMSFE_ERR_S_NOT_PD;
  } else {
    for (int s = 0; s < S; ++s) e->sel[s] = s == slot ? 1.0 : 0.0;
    copy(e->cl, e->xa + N * (1 + slot), N);
    const double *in[6] = {e->xa, e->Pa, e->cl, e->sel, z, e->rc};
    double *out[5] = {e->xa2, e->Pa2, &e->nis, &e->s_ok, &e->chk};
    gcall(&e->g, est_clone_camera, in, 6, out, 5);
    if (!isfinite(e->chk)) return AMSFE_ERR_NONFINITE;
    if (!(e->s_ok > 0.5)) return AMSFE_ERR_S_NOT_PD;
  }
  if (nis) *nis = e->nis;
  int st = e->nis <= e->par.gate_camera ? AMSFE_OK : AMSFE_GATED;
  if (st == AMSFE_OK) {
    copy(e->xa, e->xa2, Na);
    copy(e->Pa, e->Pa2, (long)Na * Na);
  }
  drop_clone(e, slot);
  sync_clone(e);
  int alive = 0;
  for (int s = 0; s < S; ++s) alive += e->clone_on[s] && e->k - e->clone_k[s] < e->max_delay;
  e->diag.clones = alive;
  return st;
}

int amsfe_est_camera_frame(amsfe_est *e, const double *z, long kappa, double *nis) {
  if (nis) *nis = NAN;
  if (!e || !z) return AMSFE_ERR_INPUT;
  if (e->failed) return AMSFE_ERR_FAILED;
  if (kappa > e->k) return AMSFE_REFUSED_FUTURE; /* the reference raises; nothing changed */
  int st;
  long oldest = e->k - e->B > e->par.k0 ? e->k - e->B : e->par.k0;
  e->diag.replayed_steps = 0;
  if (e->par.estimator == AMSFE_ENCODERS) st = AMSFE_IGNORED;
  else if (!all_finite(z, e->d.nc)) st = AMSFE_REFUSED_NONFINITE;
  else if (kappa < oldest) st = AMSFE_REFUSED_TOO_OLD;
  else if (e->seen[pmod(kappa, e->B + 1)] == kappa) st = AMSFE_REFUSED_DUPLICATE;
  else {
    switch (e->par.estimator) {
      case AMSFE_NAIVE: st = frame_now(e, z, nis); break;
      case AMSFE_OOSM:
        st = kappa == e->k ? frame_now(e, z, nis) : oosm_late(e, z, kappa, nis);
        break;
      case AMSFE_REPLAY:
        st = replay_frame(e, z, kappa, nis);
        break;
      default: st = cloning_frame(e, z, kappa, nis);
    }
    if (st < 0) return fail(e, st);
    if (!pd_state(e)) return fail(e, AMSFE_ERR_NOT_PD);
  }
  if (st == AMSFE_OK || st == AMSFE_GATED) e->seen[pmod(kappa, e->B + 1)] = kappa;
  if (st == AMSFE_OK) ++e->diag.frames_applied;
  else if (st == AMSFE_GATED) ++e->diag.frames_gated;
  else if (st == AMSFE_IGNORED) ++e->diag.frames_ignored;
  else ++e->diag.frames_refused;
  return st;
}
