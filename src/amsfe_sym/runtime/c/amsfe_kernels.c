/* amsfe_kernels.c: the robot-independent dense kernels of the compiled estimators.
 *
 * The EKF's covariance algebra of a tick and of a late frame, written once for any state
 * dimension and compiled apart from the generated robot code, at the flags that make them
 * fast (codegen/build.py: the generated files stay at -O1, this file gets -O3).  No
 * -ffast-math: every sum keeps its order.  Two kinds of loop:
 * - the matrix products run in register tiles (tiles_v4/tiles_v2 below: 2 vectors of rows x
 *   4 columns, accumulators loaded from and stored to the matrices directly); the AVX2 + FMA
 *   version is chosen once at run time, so an FMA CPU rounds these products differently
 *   (never in another order) than an SSE2 one;
 * - the column loops around them (Cholesky panels, triangular solves, the selection picks of
 *   the Joseph update) have an AVX2 clone without FMA (KERNEL_CLONES): same result on every
 *   x86-64 CPU.
 *
 * The structure they use (docs/how-to/runtime-c.md, "Cost"):
 * - P is symmetric: every symmetric result is computed on its lower triangle and mirrored;
 *   the prediction uses the Cholesky factor of P that the positive-definiteness check of the
 *   previous step computed anyway: A P A^T = (A L)(A L)^T, A L costs N^3/2 (L triangular)
 *   and the product N^3/2, against N^3 + N^3/2 for (A P) A^T;
 * - the encoders' H selects states (eq. 5): H P H^T, P H^T and (I - K H) are row and column
 *   picks, never products with H; the gain is K = P H^T S^-1 with S^-1 from S's Cholesky
 *   factor (m x m, m^3/2) and one tiled M x m x m product, and the Joseph form is evaluated as
 *   P + V K^T + K V^T with V = K S / 2 - P H^T (algebraically the Joseph form for any K,
 *   Bucy and Joseph 1968; no N x N x N product).
 *
 * Cost (callgrind, instructions per amsfe_est_tick of oosm on a recorded closed-loop run,
 * tick_timer.c; docs/how-to/runtime-c.md has the command): Panda N = 29, ne = 14: 222.5k, of which
 * the rk4 transition_step 121k (generated stages and amsfe_model.c's chain), these kernels ~98k
 * (A P A^T 35k, the encoder update 48k, the Cholesky check 15k);
 * paper_2link N = 9: 16.7k.  A late frame (eq. 23 over a 33-step lag on the Panda) 2.7M.
 */
#if defined(__GNUC__) && !defined(__clang__)
#pragma GCC optimize("O3")
#endif
#include <math.h>
#include <string.h>

#include "amsfe_internal.h"

#define AT(M, i, j, ld) (M)[(i) + (long)(j) * (ld)]
/* The column loops outside the tiles (Cholesky panels, solves, the Joseph update's picks) get
 * an AVX2 clone chosen at load time, as amsfe_model.c's chain: without FMA, so their results
 * are the same on every x86-64 CPU. */
#if defined(__x86_64__) && defined(__GNUC__) && !defined(__clang__) && defined(__linux__)
#define KERNEL_CLONES __attribute__((target_clones("avx2", "default")))
#else
#define KERNEL_CLONES
#endif
/* ---- register tiles: C[i, j] = init[i, j] + sum_{m0 <= m < m1} X[i + m N] Y[m sm + j sj]
 * for the rows i of [lo, N) and the columns j of [0, ncols): every matrix product below is one
 * of these (A L: Y = L with sm = 1, sj = N; B B^T: Y = B with sm = N, sj = 1).  Tiles of
 * 2 vectors of rows x 4 columns held in registers; the last row and column tiles overlap the
 * ones before (N, ncols >= the tile) and recompute the same sums in the same order, so a
 * shared entry gets the same value (init is read, never the output: overlap-safe).  With an
 * AVX2 + FMA CPU the 4-wide version runs (chosen once at run time, so the library stays
 * portable x86-64); otherwise 2-wide vectors (SSE2, NEON). */
#define TILE_BODY(V, VU, W, OP)                                                               \
  for (int j0 = 0;; j0 += 4) {                                                              \
    if (j0 > ncols - 4) j0 = ncols - 4;                                                     \
    int first = lower && j0 > lo ? j0 : lo, ms = tri && j0 > m0 ? j0 : m0;                  \
    for (int i0 = first < N - 2 * W ? first : N - 2 * W;; i0 += 2 * W) {                    \
      if (i0 > N - 2 * W) i0 = N - 2 * W;                                                   \
      V c00, c01, c10, c11, c20, c21, c30, c31;                                             \
      if (init) {                                                                           \
        const double *p = init + i0 + (long)j0 * N;                                         \
        c00 = *(const VU *)p, c01 = *(const VU *)(p + W), p += N;                           \
        c10 = *(const VU *)p, c11 = *(const VU *)(p + W), p += N;                           \
        c20 = *(const VU *)p, c21 = *(const VU *)(p + W), p += N;                           \
        c30 = *(const VU *)p, c31 = *(const VU *)(p + W);                                   \
      } else {                                                                              \
        c00 = c01 = c10 = c11 = c20 = c21 = c30 = c31 = (V){0};                             \
      }                                                                                     \
      const double *xm = X + (long)ms * N + i0, *ym = Y + ms * sm + j0 * sj;                \
      for (int m = ms; m < m1; ++m, xm += N, ym += sm) {                                    \
        V x0 = *(const VU *)xm, x1 = *(const VU *)(xm + W);                                 \
        double y0 = ym[0], y1 = ym[sj], y2 = ym[2 * sj], y3 = ym[3 * sj];                   \
        c00 OP x0 * y0, c01 OP x1 * y0, c10 OP x0 * y1, c11 OP x1 * y1;                     \
        c20 OP x0 * y2, c21 OP x1 * y2, c30 OP x0 * y3, c31 OP x1 * y3;                     \
      }                                                                                     \
      double *p = C + i0 + (long)j0 * N;                                                    \
      *(VU *)p = c00, *(VU *)(p + W) = c01, p += N;                                         \
      *(VU *)p = c10, *(VU *)(p + W) = c11, p += N;                                         \
      *(VU *)p = c20, *(VU *)(p + W) = c21, p += N;                                         \
      *(VU *)p = c30, *(VU *)(p + W) = c31;                                                 \
      if (i0 == N - 2 * W) break;                                                           \
    }                                                                                       \
    if (j0 == ncols - 4) break;                                                             \
  }

#define TILE_ARGS                                                                          \
  int N, int ncols, int lo, int lower, int tri, int m0, int m1, const double *restrict X,   \
      const double *restrict Y, long sm, long sj, const double *restrict init,             \
      double *restrict C

/* the vectors, and their unaligned, aliasing views for loads and stores */
typedef double v2d __attribute__((vector_size(16)));
typedef double v2du __attribute__((vector_size(16), aligned(8), may_alias));
static void tiles_v2(TILE_ARGS) { TILE_BODY(v2d, v2du, 2, +=) }
static void tiles_v2_sub(TILE_ARGS) { TILE_BODY(v2d, v2du, 2, -=) }

#if defined(__x86_64__) && defined(__GNUC__) && !defined(__clang__)
typedef double v4d __attribute__((vector_size(32)));
typedef double v4du __attribute__((vector_size(32), aligned(8), may_alias));
__attribute__((target("avx2,fma"))) static void tiles_v4(TILE_ARGS) {
  TILE_BODY(v4d, v4du, 4, +=)
}
__attribute__((target("avx2,fma"))) static void tiles_v4_sub(TILE_ARGS) {
  TILE_BODY(v4d, v4du, 4, -=)
}
static int have_avx2(void) {
  static int known = -1;
  if (known < 0) {
    __builtin_cpu_init();
    known = __builtin_cpu_supports("avx2") && __builtin_cpu_supports("fma");
  }
  return known;
}
#endif

/* Tiled when the shapes allow it, else the plain loops (same formula, other rounding order);
 * sub: C = init - X Y. */
static void tiles_op(int sub, TILE_ARGS) {
#if defined(__x86_64__) && defined(__GNUC__) && !defined(__clang__)
  if (have_avx2() && N >= 8 && ncols >= 4) {
    (sub ? tiles_v4_sub : tiles_v4)(N, ncols, lo, lower, tri, m0, m1, X, Y, sm, sj, init, C);
    return;
  }
#endif
  if (N >= 4 && ncols >= 4) {
    (sub ? tiles_v2_sub : tiles_v2)(N, ncols, lo, lower, tri, m0, m1, X, Y, sm, sj, init, C);
    return;
  }
  for (int j = 0; j < ncols; ++j)
    for (int i = lower && j > lo ? j : lo; i < N; ++i) {
      double v = init ? init[i + (long)j * N] : 0.0;
      for (int m = tri && j > m0 ? j : m0; m < m1; ++m) {
        double t = X[i + (long)m * N] * Y[m * sm + j * sj];
        v = sub ? v - t : v + t;
      }
      C[i + (long)j * N] = v;
    }
}
#define tiles(...) tiles_op(0, __VA_ARGS__)
#define tiles_sub(...) tiles_op(1, __VA_ARGS__)

void amsfe_mirror_lower(int m, double *restrict X) {
  for (int j = 0; j < m; ++j)
    for (int i = j + 1; i < m; ++i) AT(X, j, i, m) = AT(X, i, j, m);
}

/* Left-looking in panels of 4 columns: L[j0:, panel] = S[j0:, panel] - L[j0:, :j0] L[panel, :j0]^T
 * (one register-tiled product), then the panel column by column. */
KERNEL_CLONES int amsfe_cholesky(int m, const double *restrict S, double *restrict L) {
  for (int j0 = 0; j0 < m; j0 += 4) {
    int w = m - j0 < 4 ? m - j0 : 4;
    if (j0 == 0)
      for (long i = 0; i < (long)m * w; ++i) L[i] = S[i];
    else /* rows above j0 of the panel are recomputed too; zeroed below */
      tiles_sub(m, w, j0, 0, 0, 0, j0, L, L + j0, m, 1, S + (long)j0 * m, L + (long)j0 * m);
    for (int j = j0; j < j0 + w; ++j) {
      double *lj = L + (long)j * m;
      for (int k = j0; k < j; ++k) {
        const double *lk = L + (long)k * m;
        double c = lk[j];
        for (int i = j; i < m; ++i) lj[i] -= lk[i] * c;
      }
      double d = lj[j];
      if (!(d > 0)) return 0; /* also a NaN pivot */
      d = sqrt(d);
      lj[j] = d;
      for (int i = j + 1; i < m; ++i) lj[i] /= d;
    }
  }
  for (int j = 1; j < m; ++j) /* the strict upper part is zero */
    for (int i = 0; i < j; ++i) L[i + (long)j * m] = 0.0;
  return 1;
}

KERNEL_CLONES void amsfe_chol_solve(int m, const double *restrict L, double *restrict b) {
  for (int k = 0; k < m; ++k) { /* L y = b, column-oriented */
    double y = b[k] / AT(L, k, k, m);
    b[k] = y;
    const double *restrict lk = L + (long)k * m;
    for (int i = k + 1; i < m; ++i) b[i] -= lk[i] * y;
  }
  for (int i = m - 1; i >= 0; --i) { /* L^T x = y, row i of L^T is column i of L */
    const double *restrict li = L + (long)i * m;
    double v = b[i];
    for (int k = i + 1; k < m; ++k) v -= li[k] * b[k];
    b[i] = v / li[i];
  }
}

/* Li = L^-1 for L lower triangular m x m with a positive diagonal (column-major; Li's strict
 * upper part set to zero): column b of Li by forward substitution on e_b. */
KERNEL_CLONES void amsfe_tri_inverse(int m, const double *restrict L, double *restrict Li) {
  for (int b = 0; b < m; ++b) {
    double *restrict lb = Li + (long)b * m;
    for (int i = 0; i < m; ++i) lb[i] = i == b ? 1.0 : 0.0;
    for (int k = b; k < m; ++k) { /* column axpys: no dependent chain of divisions */
      const double *restrict lk = L + (long)k * m;
      double y = lb[k] / lk[k];
      lb[k] = y;
      for (int i = k + 1; i < m; ++i) lb[i] -= lk[i] * y;
    }
  }
}

/* out = A L L^T A^T + G diag(qw) G^T, exactly symmetric (eq. 14 with P = L L^T).
 * A: N x N, L: lower N x N (its strict upper part zero), G: N x nw; B: scratch of
 * AMSFE_PREDICT_WORK(N, nw) doubles. */
void amsfe_predict_cov(int N, int nw, const double *restrict A, const double *restrict L,
                       const double *restrict G, const double *restrict qw, double *restrict out,
                       double *restrict B) {
  tiles(N, N, 0, 0, 1, 0, N, A, L, 1, N, NULL, B); /* B = A L (L lower: m >= j) */
  double *restrict Qn = B + (long)N * N, *restrict Gq = Qn + (long)N * N;
  for (int m = 0; m < nw; ++m) /* G diag(qw) */
    for (int i = 0; i < N; ++i) Gq[i + (long)m * N] = G[i + (long)m * N] * qw[m];
  tiles(N, N, 0, 1, 0, 0, nw, G, Gq, N, 1, NULL, Qn); /* lower part of G diag(qw) G^T */
  tiles(N, N, 0, 1, 0, 0, N, B, B, N, 1, Qn, out);    /* + B B^T */
  amsfe_mirror_lower(N, out);
}

/* out = A X A^T + G diag(qw) G^T (X symmetric N x N; G: N x nw, may be NULL), exactly
 * symmetric; T: AMSFE_PREDICT_WORK(N, nw) doubles of scratch.  The eq. 23 accumulation (X need
 * not be definite there). */
void amsfe_sandwich(int N, int nw, const double *restrict A, const double *restrict X,
                    const double *restrict G, const double *restrict qw, double *restrict out,
                    double *restrict T) {
  double *restrict Qn = T + (long)N * N, *restrict Gq = Qn + (long)N * N;
  amsfe_matmul(N, A, X, T);
  if (G) {
    for (int m = 0; m < nw; ++m) /* G diag(qw) */
      for (int i = 0; i < N; ++i) Gq[i + (long)m * N] = G[i + (long)m * N] * qw[m];
    tiles(N, N, 0, 1, 0, 0, nw, G, Gq, N, 1, NULL, Qn); /* lower part of G diag(qw) G^T */
  }
  tiles(N, N, 0, 1, 0, 0, N, T, A, N, 1, G ? Qn : NULL, out); /* + lower part of T A^T */
  amsfe_mirror_lower(N, out);
}

void amsfe_matmul(int N, const double *restrict A, const double *restrict B, double *restrict C) {
  tiles(N, N, 0, 0, 0, 0, N, A, B, 1, N, NULL, C);
}

void amsfe_matmul_cols(int N, int ncols, const double *restrict A, const double *restrict B,
                       long ldb, double *restrict C) {
  if (ncols > 0) tiles(N, ncols, 0, 0, 0, 0, N, A, B, 1, ldb, NULL, C);
}

/* b <- A^-1 b by Gaussian elimination with partial pivoting (LAPACK gesv's algorithm; A is
 * overwritten by its factors).  Returns 0 when a pivot is 0 or not finite (A singular). */
int amsfe_lu_solve(int N, double *restrict A, double *restrict b) {
  for (int k = 0; k < N; ++k) {
    int p = k;
    double best = fabs(AT(A, k, k, N));
    for (int i = k + 1; i < N; ++i)
      if (fabs(AT(A, i, k, N)) > best) best = fabs(AT(A, i, k, N)), p = i;
    if (!(best > 0) || !isfinite(best)) return 0;
    if (p != k) {
      for (int j = 0; j < N; ++j) {
        double t = AT(A, k, j, N);
        AT(A, k, j, N) = AT(A, p, j, N), AT(A, p, j, N) = t;
      }
      double t = b[k];
      b[k] = b[p], b[p] = t;
    }
    double *restrict ak = A + (long)k * N;
    double d = ak[k];
    for (int i = k + 1; i < N; ++i) ak[i] /= d;
    for (int j = k + 1; j < N; ++j) {
      double *restrict aj = A + (long)j * N;
      double c = aj[k];
      for (int i = k + 1; i < N; ++i) aj[i] -= ak[i] * c;
    }
    for (int i = k + 1; i < N; ++i) b[i] -= ak[i] * b[k];
  }
  for (int k = N - 1; k >= 0; --k) {
    b[k] /= AT(A, k, k, N);
    const double *restrict ak = A + (long)k * N;
    for (int i = 0; i < k; ++i) b[i] -= ak[i] * b[k];
  }
  return 1;
}

/* The work block w of both Joseph-form updates (AMSFE_JOSEPH_WORK(M, m) doubles):
 * W = [V | K | V2] (M x 3m: [V | K] and [K | V2] are both contiguous column blocks), Pn (M x
 * m), then S, Sh, Ls (m x m) and sn [m].  The callers fill Pn and S, joseph_finish the rest. */
#define JOSEPH_PN(w, M, m) ((w) + 3L * (M) * (m))
#define JOSEPH_S(w, M, m) ((w) + 4L * (M) * (m))

/* S = sym(X[rows, rows]) + diag(r) (m x m) for the selection H = I[rows, :] of an M x M X. */
static void select_cov(int M, int m, const int *restrict rows, const double *restrict r,
                       const double *restrict X, double *restrict S) {
  for (int b = 0; b < m; ++b) /* symmetrised as the reference does */
    for (int a = 0; a < m; ++a)
      AT(S, a, b, m) = 0.5 * (AT(X, rows[a], rows[b], M) + AT(X, rows[b], rows[a], M)) +
                       (a == b ? r[a] : 0.0);
}

/* The Joseph-form update once Pn = -P H^T and S = sym(H P H^T) + diag(r) stand in w: S's
 * Cholesky factor, *nis = nu^T S^-1 nu, x+ = x + P H^T S^-1 nu, and P+ = (I - K H) P (I -
 * K H)^T + K diag(r) K^T, evaluated as P + V K^T + K V^T with K = P H^T S^-1 and V = K S / 2
 * - P H^T (equal for any K).  Returns 0 when S is not positive definite (x2, P2 unwritten). */
KERNEL_CLONES static int joseph_finish(int M, int m, const double *restrict x,
                                       const double *restrict P, const double *restrict nu,
                                       double *restrict x2, double *restrict P2,
                                       double *restrict nis, double *restrict w) {
  double *restrict V = w, *restrict K = w + (long)M * m, *restrict V2 = K + (long)M * m;
  double *restrict Pn = JOSEPH_PN(w, M, m), *restrict S = JOSEPH_S(w, M, m);
  double *restrict Sh = S + m * m, *restrict Ls = Sh + m * m, *restrict sn = Ls + m * m;
  if (!amsfe_cholesky(m, S, Ls)) return 0;
  for (int a = 0; a < m; ++a) sn[a] = nu[a];
  amsfe_chol_solve(m, Ls, sn);
  double s = 0.0;
  for (int a = 0; a < m; ++a) s += nu[a] * sn[a];
  *nis = s;
  for (int i = 0; i < M; ++i) x2[i] = x[i]; /* x+ = x + P H^T S^-1 nu */
  for (int a = 0; a < m; ++a) {
    const double *restrict na = Pn + (long)a * M;
    double f = sn[a];
    for (int i = 0; i < M; ++i) x2[i] -= na[i] * f;
  }
  /* K = P H^T S^-1 as one register-tiled product with S^-1 = Li^T Li, Li = Ls^-1 (m^3/2
   * flops on m x m; column solves of K over M rows were 2/3 of this kernel's instructions).
   * Li goes where V will be, S^-1 where V2 will be: both are written only after K. */
  double *restrict Li = V, *restrict Si = V2;
  amsfe_tri_inverse(m, Ls, Li);
  for (int b = 0; b < m; ++b)
    for (int a = b; a < m; ++a) {
      double v = 0.0;
      for (int k = a; k < m; ++k) v += AT(Li, k, a, m) * AT(Li, k, b, m);
      AT(Si, a, b, m) = v, AT(Si, b, a, m) = v;
    }
  tiles_sub(M, m, 0, 0, 0, 0, m, Pn, Si, 1, m, NULL, K); /* K = -(-P H^T) S^-1 */
  for (int i = 0; i < m * m; ++i) Sh[i] = 0.5 * S[i];
  tiles(M, m, 0, 0, 0, 0, m, K, Sh, 1, m, Pn, V); /* V = K S / 2 - P H^T */
  memcpy(V2, V, sizeof(double) * (size_t)M * (size_t)m);
  tiles(M, M, 0, 1, 0, 0, 2 * m, V, K, M, 1, P, P2); /* lower of P + [V K] [K V]^T */
  amsfe_mirror_lower(M, P2);
  return 1;
}

/* The Joseph-form update (eqs. 15-17) of (x, P), M x M, with a measurement that selects the
 * states rows[0..m) with noise variances r[m] (ekf.joseph_update with H = I[rows, :]).
 * nu = z - x[rows]; S = P[rows, rows] + diag(r); K = P[:, rows] S^-1;
 * x+ = x + P[:, rows] S^-1 nu; P+ = (I - K H) P (I - K H)^T + K diag(r) K^T (joseph_finish).
 * Writes x2, P2 (exactly symmetric), *nis, nu[m]; returns 0 when S is not positive definite
 * (then only nu is written).  w: AMSFE_JOSEPH_WORK(M, m) doubles. */
KERNEL_CLONES int amsfe_joseph_select(int M, int m, const int *restrict rows,
                                      const double *restrict r, const double *restrict x,
                                      const double *restrict P, const double *restrict z,
                                      double *restrict x2, double *restrict P2,
                                      double *restrict nis, double *restrict nu,
                                      double *restrict w) {
  double *restrict Pn = JOSEPH_PN(w, M, m);
  for (int a = 0; a < m; ++a) nu[a] = z[a] - x[rows[a]];
  for (int a = 0; a < m; ++a) { /* Pn = -P H^T = -P[:, rows] */
    const double *restrict pa = P + (long)rows[a] * M;
    double *restrict na = Pn + (long)a * M;
    for (int i = 0; i < M; ++i) na[i] = -pa[i];
  }
  select_cov(M, m, rows, r, P, JOSEPH_S(w, M, m));
  return joseph_finish(M, m, x, P, nu, x2, P2, nis, w);
}

/* oosm.a1_retrodict with the encoders' selection H (eqs. 24-27 corrected), M states:
 * W = S^-1 H Q with S = P_prior[rows, rows] + diag(r) (the last encoder update's),
 * x_shift = x - Q H^T S^-1 nu, Pvv = Q - Q H^T W, Pxv = Q - P_prior H^T W,
 * Mo = sym(P + Pvv - Pxv - Pxv^T) = P - Q + U Wt^T + Wt U^T with Wt = W^T, U = P_prior H^T -
 * Q H^T / 2, and C = P - Pxv = P - Q + P_prior H^T Wt^T.  Q must be exactly symmetric.  Returns
 * 0 when S is not positive definite.  w: AMSFE_RETRO_WORK(M, m) doubles. */
KERNEL_CLONES int amsfe_a1_retrodict(int M, int m, const int *restrict rows,
                                     const double *restrict r, const double *restrict x,
                                     const double *restrict P, const double *restrict Q,
                                     const double *restrict nu, const double *restrict Pp,
                                     double *restrict xs, double *restrict Mo,
                                     double *restrict C, double *restrict w) {
  /* the selection's Q H^T = Q[:, rows], P_prior H^T = P_prior[:, rows] and S, then the
   * formulas of amsfe_a1_retrodict_cols (the same values: bit-identical results) */
  double *restrict QHt = w, *restrict PpHt = w + (long)M * m, *restrict S = PpHt + (long)M * m;
  for (int a = 0; a < m; ++a) {
    memcpy(QHt + (long)a * M, Q + (long)rows[a] * M, sizeof(double) * (size_t)M);
    memcpy(PpHt + (long)a * M, Pp + (long)rows[a] * M, sizeof(double) * (size_t)M);
  }
  select_cov(M, m, rows, r, Pp, S);
  return amsfe_a1_retrodict_cols(M, m, S, QHt, PpHt, x, P, Q, nu, xs, Mo, C, S + m * m);
}

/* The Joseph-form update of amsfe_joseph_select for a measurement whose jacobian H (m x M) is
 * given by its rows' nonzeros: row a holds hval[e] at column hcol[e], hrow[a] <= e <
 * hrow[a + 1] (ekf.joseph_update with that H; the joint torque sensors' Ks (qm - q) and the
 * camera of a state with input states, docs/explanation/effort.md).  The innovation nu [m] is given:
 * PHt = P H^T, S = sym(H PHt) + diag(r), x+ = x + PHt S^-1 nu, P+ the Joseph form evaluated as
 * amsfe_joseph_select does.  Returns 0 when S is not positive definite.  w:
 * AMSFE_JOSEPH_WORK(M, m) doubles. */
KERNEL_CLONES int amsfe_joseph_rows(int M, int m, const int *restrict hrow,
                                    const int *restrict hcol, const double *restrict hval,
                                    const double *restrict r, const double *restrict x,
                                    const double *restrict P, const double *restrict nu,
                                    double *restrict x2, double *restrict P2,
                                    double *restrict nis, double *restrict w) {
  double *restrict Pn = JOSEPH_PN(w, M, m), *restrict S = JOSEPH_S(w, M, m);
  double *restrict T = S + m * m; /* T = H P H^T, where joseph_finish's Sh goes */
  for (int a = 0; a < m; ++a) { /* Pn = -P H^T, column a from the nonzeros of row a */
    double *restrict na = Pn + (long)a * M;
    for (int i = 0; i < M; ++i) na[i] = 0.0;
    for (int e = hrow[a]; e < hrow[a + 1]; ++e) {
      const double *restrict pc = P + (long)hcol[e] * M;
      double v = hval[e];
      for (int i = 0; i < M; ++i) na[i] += pc[i] * v;
    }
    for (int i = 0; i < M; ++i) na[i] = -na[i];
  }
  for (int b = 0; b < m; ++b)
    for (int a = 0; a < m; ++a) {
      double v = 0.0;
      for (int e = hrow[a]; e < hrow[a + 1]; ++e) v -= hval[e] * Pn[hcol[e] + (long)b * M];
      AT(T, a, b, m) = v;
    }
  for (int b = 0; b < m; ++b) /* S = sym(H P H^T) + R, as the reference symmetrises it */
    for (int a = 0; a < m; ++a)
      AT(S, a, b, m) = 0.5 * (AT(T, a, b, m) + AT(T, b, a, m)) + (a == b ? r[a] : 0.0);
  return joseph_finish(M, m, x, P, nu, x2, P2, nis, w);
}

/* amsfe_a1_retrodict for any encoder H, given through QHt = Q H^T, PpHt = P_prior H^T (M x m
 * each) and S = sym(H P_prior H^T) + diag(r) (m x m): the same formulas.  Returns 0 when S is
 * not positive definite.  w: AMSFE_RETRO_WORK(M, m) doubles. */
KERNEL_CLONES int amsfe_a1_retrodict_cols(int M, int m, const double *restrict S,
                                          const double *restrict QHt,
                                          const double *restrict PpHt,
                                          const double *restrict x, const double *restrict P,
                                          const double *restrict Q,
                                          const double *restrict nu, double *restrict xs,
                                          double *restrict Mo, double *restrict C,
                                          double *restrict w) {
  double *U = w, *Wt = w + (long)M * m, *U2 = Wt + (long)M * m;
  double *restrict D = U2 + (long)M * m, *restrict Ls = D + (long)M * M;
  if (!amsfe_cholesky(m, S, Ls)) return 0;
  for (long c = 0; c < m; ++c) { /* Wt = Q H^T S^-1 */
    double *wc = Wt + c * M;
    const double *restrict qc = QHt + c * M;
    for (int i = 0; i < M; ++i) wc[i] = qc[i];
    for (long a = 0; a < c; ++a) {
      const double *wa = Wt + a * M;
      double f = AT(Ls, c, a, m);
      for (int i = 0; i < M; ++i) wc[i] -= wa[i] * f;
    }
    double d = AT(Ls, c, c, m);
    for (int i = 0; i < M; ++i) wc[i] /= d;
  }
  for (long c = m - 1; c >= 0; --c) {
    double *wc = Wt + c * M;
    for (long a = c + 1; a < m; ++a) {
      const double *wa = Wt + a * M;
      double f = AT(Ls, a, c, m);
      for (int i = 0; i < M; ++i) wc[i] -= wa[i] * f;
    }
    double d = AT(Ls, c, c, m);
    for (int i = 0; i < M; ++i) wc[i] /= d;
  }
  for (int i = 0; i < M; ++i) xs[i] = x[i]; /* x_shift = x - Wt nu */
  for (int a = 0; a < m; ++a) {
    const double *restrict wa = Wt + (long)a * M;
    const double *restrict pa = PpHt + (long)a * M, *restrict qa = QHt + (long)a * M;
    double *restrict ua = U + (long)a * M;
    double f = nu[a];
    for (int i = 0; i < M; ++i) {
      xs[i] -= wa[i] * f;
      ua[i] = pa[i] - 0.5 * qa[i];
    }
  }
  memcpy(U2, U, sizeof(double) * (size_t)M * (size_t)m);
  for (long i = 0; i < (long)M * M; ++i) D[i] = P[i] - Q[i];
  tiles(M, M, 0, 1, 0, 0, 2 * m, U, Wt, M, 1, D, Mo); /* lower of D + [U Wt] [Wt U]^T */
  amsfe_mirror_lower(M, Mo);
  tiles(M, M, 0, 0, 0, 0, m, PpHt, Wt, M, 1, D, C); /* C = D + P_prior H^T Wt^T */
  return 1;
}
