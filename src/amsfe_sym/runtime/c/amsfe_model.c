/* amsfe_model.c: the rk4 transition step chained from one generated stage (part of every
 * rk4 library; see docs/explanation/codegen.md, "Structure kept through generation").
 *
 * transition_step_chain(x, u) -> (x_next, A, Gamma) computes exactly what the generated
 * `transition_step` of the rk4 model computes (m = AMSFE_MODEL_SUBSTEPS classical
 * Runge-Kutta steps of h = T / m of the continuous flexible-joint model over T with u held;
 * A = dF/dx by forward sensitivities; Gamma = dF/dw, eq. 4), but instead of one
 * straight-line expression of the whole step (four inlined stages per substep, their
 * jacobians and the dense products of the sensitivities) it calls the generated stage four
 * times a substep and chains the sensitivities in the loops below, from xp_0 = xp, B_0 = I0:
 *
 *   xp_i = xp_s + c_i h k_{i-1},  S_i = B_s + c_i h D_{i-1}          (c = 0, 1/2, 1/2, 1)
 *   (k_i, J_i) = stage(xp_i, u, theta),  D_i = J_i [S_i; E]           (4n x N)
 *   xp_{s+1} = xp_s + h/6 (k_1 + 2 k_2 + 2 k_3 + k_4),  B_{s+1} = B_s + h/6 (D_1 + 2 D_2 + ...)
 *   xp+ = xp_m,  A = [B_m; E],  Gamma = [A[:, qd] M(q)^-1,  A[:, qmd] / Mm,  [0; T I_p]]
 *
 * with I0 = [I_4n 0] and E = [0 I_p] (theta is constant).  The stage's dense solves with the
 * mass matrix are done here, in loops, not in the generated code (docs/explanation/codegen.md):
 * the generated `rk4_stage_rhs` (xp, u, theta) -> (kr, M) returns k with its qdd rows unsolved
 * (rhs = Ks (qm - q) - b) and M(q, theta); one LDL^T of M gives qdd = M^-1 rhs; the generated
 * `rk4_stage_jac` (xp, u, theta, qdd) -> Jr returns J with its qdd rows unsolved
 * (dtau = d(Ks (qm - q))/dz - dRNEA/dz at a = qdd, which needs qdd first: hence two
 * functions), and D_i = Jr_i [S_i; E] with its n qdd rows solved by the same factor
 * ((M^-1 dtau) [S; E] = M^-1 (dtau [S; E])).  Gamma's M(q)^-1 is the first stage's factor
 * (its point is x).  The sensitivities are held row-major (row r of S, B and D contiguous over
 * the N columns) and Jr's pattern is read by rows, so D_i is nnz(Jr) contiguous axpys of length
 * N and the solve n^2 more (the jacobian's identity and diagonal motor rows
 * are single-nonzero rows, i.e. copies and scalings of rows of S; measured in docs/explanation/codegen.md).
 *
 * It follows CasADi's calling convention and exports the symbols `casadi.external` needs
 * (the names and sparsity of the generated `transition_step`), so Python and C callers use
 * it like any generated function. */
/* small loops over n and N: optimise them fully whatever the library's flags (as the glue) */
#if defined(__GNUC__) && !defined(__clang__)
#pragma GCC optimize("O3")
#endif
#include <string.h>

#include "amsfe_internal.h"
#include "amsfe_model_config.h" /* written by the code generator: AMSFE_MODEL_N, _P, _T, _MM */

/* The row loops below are contiguous axpys of N: with an AVX2 CPU they run 4-wide (one clone
 * of the chain per target, chosen at load time by the dynamic linker, so the library stays
 * portable x86-64).  No FMA in the clone: a vector lane computes what the scalar code
 * computes, in the same order, so the result does not depend on the CPU. */
#if defined(__x86_64__) && defined(__GNUC__) && !defined(__clang__) && defined(__linux__)
#define CHAIN_CLONES __attribute__((target_clones("avx2", "default")))
#else
#define CHAIN_CLONES
#endif
#define INLINE static inline __attribute__((always_inline))

DECLARE(rk4_stage_rhs)
DECLARE(rk4_stage_jac)
DECLARE(transition_step)
const cint *rk4_stage_jac_sparsity_out(cint i);
const char *transition_step_name_in(cint i);
const char *transition_step_name_out(cint i);
const cint *transition_step_sparsity_out(cint i);

#define NN AMSFE_MODEL_N
#define NP AMSFE_MODEL_P
#define NX (4 * NN)      /* plant states [q, qd, qm, qmd] */
#define NS (4 * NN + NP) /* estimator states, N */

static const double MM[NN] = AMSFE_MODEL_MM;

/* Nonzeros of Jr in CasADi's compressed sparsity [nrow, ncol, colind[ncol + 1], row[nnz]]
 * (a dense pattern is compressed to [nrow, ncol, 1]). */
static cint stage_nnz(const cint *sp) {
  return (sp[2] == 1 && sp[1] > 0) ? sp[0] * sp[1] : sp[2 + sp[1]];
}

/* Scratch beyond the stage's own work.  Doubles: xs, xi, k, kacc (NX each), B, S, D, Bn
 * (NX x NS each, row-major: row r of the sensitivity is contiguous over the NS columns; Bn the next
 * substep's B), the
 * stage's Jr (nnz), M, its LDL^T factor L and the first stage's L0 (n x n each), the pivots
 * dl and dl0 (n each).  Integers: Jr's pattern by rows (row pointers, column and
 * value index of each nonzero). */
static cint scratch_doubles(void) {
  return 4 * NX + 4 * (cint)NX * NS + stage_nnz(rk4_stage_jac_sparsity_out(0)) + 3 * NN * NN +
         2 * NN;
}
static cint scratch_ints(void) { return 2 * NX + 1 + 2 * stage_nnz(rk4_stage_jac_sparsity_out(0)); }

/* The generated stages' own integer work (the chain's index arrays follow it in iw). */
static cint stage_iw(void) {
  cint a = 0, r = 0, iw = 0, w = 0, iw2 = 0;
  rk4_stage_rhs_work(&a, &r, &iw, &w);
  rk4_stage_jac_work(&a, &r, &iw2, &w);
  return iw > iw2 ? iw : iw2;
}

int transition_step_chain_work(cint *sz_arg, cint *sz_res, cint *sz_iw, cint *sz_w) {
  cint a = 0, r = 0, iw = 0, w = 0, a2 = 0, r2 = 0, iw2 = 0, w2 = 0;
  rk4_stage_rhs_work(&a, &r, &iw, &w);
  rk4_stage_jac_work(&a2, &r2, &iw2, &w2);
  if (sz_arg) *sz_arg = (a > a2 ? a : a2) + 3;
  if (sz_res) *sz_res = (r > r2 ? r : r2) + 3;
  if (sz_iw) *sz_iw = (iw > iw2 ? iw : iw2) + scratch_ints();
  if (sz_w) *sz_w = (w > w2 ? w : w2) + scratch_doubles();
  return 0;
}

/* Jr's pattern by rows, from CasADi's compressed columns: the nonzeros of row r are
 * e = rp[r] .. rp[r + 1] - 1, in column jc[e], with value Jr[jv[e]]; fill: NX ints. */
static void rows_of(const cint *sp, cint *rp, cint *jc, cint *jv, cint *fill) {
  cint nrow = sp[0], ncol = sp[1];
  int dense = sp[2] == 1 && ncol > 0;
  const cint *colind = sp + 2, *row = sp + 2 + ncol + 1;
  for (cint r = 0; r <= nrow; ++r) rp[r] = 0;
  for (cint j = 0; j < ncol; ++j) {
    if (dense) {
      for (cint r = 0; r < nrow; ++r) rp[r + 1]++;
    } else {
      for (cint e = colind[j]; e < colind[j + 1]; ++e) rp[row[e] + 1]++;
    }
  }
  for (cint r = 0; r < nrow; ++r) rp[r + 1] += rp[r];
  for (cint r = 0; r < nrow; ++r) fill[r] = rp[r];
  for (cint j = 0; j < ncol; ++j) {
    if (dense) {
      for (cint r = 0; r < nrow; ++r) jc[fill[r]] = j, jv[fill[r]++] = j * nrow + r;
    } else {
      for (cint e = colind[j]; e < colind[j + 1]; ++e) jc[fill[row[e]]] = j, jv[fill[row[e]]++] = e;
    }
  }
}

/* D (NX x NS, row-major) = Jr [S; E] with S (NX x NS, row-major) and E = [0 I_p] (theta is
 * constant): row r of D is the sum over row r's nonzeros of Jr of J[r, j] times row j of S
 * (a theta column j = NX + t adds J[r, j] at column j), accumulated in NV vectors of 4 held
 * in registers and stored once: the same sums in the same order as axpys into D, without a
 * load and a store of D's row per nonzero.  Lanes past NS read the next row of S (or, for
 * the last row, the scratch that follows S: inside w) and are never stored. */
#define NV ((NS + 3) / 4)
typedef double v4d __attribute__((vector_size(32)));
typedef double v4du __attribute__((vector_size(32), aligned(8), may_alias));
INLINE void sparse_times(const cint *rp, const cint *jc, const cint *jv, const double *J,
                         const double *restrict S, double *restrict D) {
  for (cint r = 0; r < NX; ++r) {
    v4d acc[NV];
    cint e = rp[r], end = rp[r + 1];
    if (e < end && jc[e] < NX) { /* the first product initialises the row */
      double v = J[jv[e]];
      const double *Sj = S + jc[e] * NS;
#pragma GCC unroll 16
      for (int q = 0; q < NV; ++q) acc[q] = v * *(const v4du *)(Sj + 4 * q);
      ++e;
    } else {
#pragma GCC unroll 16
      for (int q = 0; q < NV; ++q) acc[q] = (v4d){0};
    }
    for (; e < end; ++e) {
      cint j = jc[e];
      double v = J[jv[e]];
      if (j < NX) {
        const double *Sj = S + j * NS;
#pragma GCC unroll 16
        for (int q = 0; q < NV; ++q) acc[q] += v * *(const v4du *)(Sj + 4 * q);
      } else {
        acc[j / 4][j % 4] += v;
      }
    }
    double *restrict Dr = D + r * NS;
#pragma GCC unroll 16
    for (int q = 0; q < NS / 4; ++q) *(v4du *)(Dr + 4 * q) = acc[q];
    for (int c = NS / 4 * 4; c < NS; ++c) Dr[c] = acc[c / 4][c % 4];
  }
}

/* M = L diag(dl) L^T, L unit lower triangular (L[i * NN + j], i > j), for the symmetric
 * positive definite mass matrix M (n x n, column-major; its lower triangle is read): the
 * LDL^T of symbolic/linalg.py in loops, no pivoting (a NaN state gives NaN, as the unrolled
 * solve did, not an error status). */
INLINE void ldl_factor(const double *M, double *L, double *dl) {
  for (cint j = 0; j < NN; ++j) {
    double dj = M[j * NN + j];
    for (cint k = 0; k < j; ++k) dj -= L[j * NN + k] * L[j * NN + k] * dl[k];
    dl[j] = dj;
    for (cint i = j + 1; i < NN; ++i) {
      double lij = M[j * NN + i];
      for (cint k = 0; k < j; ++k) lij -= L[i * NN + k] * L[j * NN + k] * dl[k];
      L[i * NN + j] = lij / dj;
    }
  }
}

/* b <- M^-1 b (n) with the factor of ldl_factor. */
INLINE void ldl_solve(const double *L, const double *dl, double *b) {
  for (cint i = 0; i < NN; ++i)
    for (cint k = 0; k < i; ++k) b[i] -= L[i * NN + k] * b[k];
  for (cint i = 0; i < NN; ++i) b[i] /= dl[i];
  for (cint i = NN - 1; i >= 0; --i)
    for (cint k = i + 1; k < NN; ++k) b[i] -= L[k * NN + i] * b[k];
}

/* Y <- M^-1 Y for Y the n rows of m (row-major, row i at Y + i m): ldl_solve on every
 * column at once, each step a contiguous row axpy. */
INLINE void ldl_solve_rows(const double *L, const double *dl, cint m, double *restrict Y) {
  for (cint i = 0; i < NN; ++i)
    for (cint k = 0; k < i; ++k) {
      double f = L[i * NN + k];
      double *restrict yi = Y + i * m;
      const double *restrict yk = Y + k * m;
      for (cint c = 0; c < m; ++c) yi[c] -= f * yk[c];
    }
  for (cint i = 0; i < NN; ++i) {
    double *restrict yi = Y + i * m;
    for (cint c = 0; c < m; ++c) yi[c] /= dl[i];
  }
  for (cint i = NN - 1; i >= 0; --i)
    for (cint k = i + 1; k < NN; ++k) {
      double f = L[k * NN + i];
      double *restrict yi = Y + i * m;
      const double *restrict yk = Y + k * m;
      for (cint c = 0; c < m; ++c) yi[c] -= f * yk[c];
    }
}

CHAIN_CLONES int transition_step_chain(const double **arg, double **res, cint *iw, double *w, int mem) {
  (void)mem;
  static const double c[4] = {0.0, 0.5, 0.5, 1.0}, wt[4] = {1.0, 2.0, 2.0, 1.0};
  const double T = AMSFE_MODEL_T, h = AMSFE_MODEL_T / AMSFE_MODEL_SUBSTEPS;
  const double *x = arg[0], *u = arg[1], *th = x + NX;
  double *xn = res[0], *A = res[1], *G = res[2];
  const cint *sp = rk4_stage_jac_sparsity_out(0);
  cint nnz = stage_nnz(sp);
  const cint NXS = (cint)NX * NS;
  /* the tail of the argument/result pointer arrays and of w and iw is ours; the stages get
   * the rest */
  const double **sarg = arg + 3;
  double **sres = res + 3;
  cint *rp = iw + stage_iw(), *jc = rp + NX + 1, *jv = jc + nnz, *fill = jv + nnz;
  double *xs = w, *xi = xs + NX, *k = xi + NX, *kacc = k + NX, *B = kacc + NX;
  double *S = B + NXS, *D = S + NXS, *Bn = D + NXS;
  double *J = Bn + NXS, *M = J + nnz, *L = M + NN * NN, *L0 = L + NN * NN;
  double *dl = L0 + NN * NN, *dl0 = dl + NN;
  double *sw_ = dl0 + NN;

  rows_of(sp, rp, jc, jv, fill);
  /* xs, B: the state and its sensitivity d xs / d x at the start of each substep */
  for (cint r = 0; r < NX; ++r) xs[r] = x[r];
  memset(B, 0, sizeof(double) * (size_t)NXS);
  for (cint r = 0; r < NX; ++r) B[r * NS + r] = 1.0;
  for (int s = 0; s < AMSFE_MODEL_SUBSTEPS; ++s) {
    /* Bn accumulates B_{s+1} = B + h/6 sum_i wt_i D_i; S_{i+1} = B + c_{i+1} h D_i is written
     * in the same pass over D */
    memset(kacc, 0, sizeof(double) * NX);
    memcpy(Bn, B, sizeof(double) * (size_t)NXS);
    const double *Si = B;
    for (int i = 0; i < 4; ++i) {
      for (cint r = 0; r < NX; ++r) xi[r] = xs[r] + (i ? c[i] * h * k[r] : 0.0);
      /* k with its qdd rows unsolved (rhs) and M; qdd = M^-1 rhs */
      sarg[0] = xi, sarg[1] = u, sarg[2] = th;
      sres[0] = k, sres[1] = M;
      int status = rk4_stage_rhs(sarg, sres, iw, sw_, 0);
      if (status) return status;
      ldl_factor(M, L, dl);
      ldl_solve(L, dl, k + NN);
      if (s == 0 && i == 0) { /* M(q) at x, for Gamma */
        memcpy(L0, L, sizeof(double) * NN * NN);
        memcpy(dl0, dl, sizeof(double) * NN);
      }
      /* Jr (dtau unsolved in the qdd rows) at a = qdd; D = M^-1 rows of Jr [S; E] */
      sarg[0] = xi, sarg[1] = u, sarg[2] = th, sarg[3] = k + NN;
      sres[0] = J;
      status = rk4_stage_jac(sarg, sres, iw, sw_, 0);
      if (status) return status;
      sparse_times(rp, jc, jv, J, Si, D);
      ldl_solve_rows(L, dl, NS, D + NN * NS);
      for (cint r = 0; r < NX; ++r) kacc[r] += wt[i] * k[r];
      double a = (h / 6.0) * wt[i];
      if (i < 3) {
        double f = c[i + 1] * h;
        for (cint e = 0; e < NXS; ++e) {
          Bn[e] += a * D[e];
          S[e] = B[e] + f * D[e];
        }
        Si = S;
      } else {
        for (cint e = 0; e < NXS; ++e) Bn[e] += a * D[e];
      }
    }
    for (cint r = 0; r < NX; ++r) xs[r] += (h / 6.0) * kacc[r];
    double *t = B;
    B = Bn, Bn = t;
  }
  if (xn) {
    for (cint r = 0; r < NX; ++r) xn[r] = xs[r];
    for (cint r = NX; r < NS; ++r) xn[r] = x[r];
  }
  /* A (NS x NS, column-major): the plant rows from the sensitivities B, the theta rows E */
  if (A) {
    for (cint col = 0; col < NS; ++col) {
      for (cint r = 0; r < NX; ++r) A[col * NS + r] = B[r * NS + col];
      for (cint r = NX; r < NS; ++r) A[col * NS + r] = (r == col ? 1.0 : 0.0);
    }
  }
  if (G) {
    /* Gamma (NS x (2n + p)), eq. (4): A[:, qd] M(q)^-1 (row by row: M^-1 of a row's qd
     * entries, M symmetric, with the first stage's factor), A[:, qmd] / Mm, [0; T I_p];
     * the theta rows of A[:, qd] are zero */
    memset(G, 0, sizeof(double) * (size_t)NS * (2 * NN + NP));
    double *Y = D; /* free now: Y (n x NX, row-major) = B[:, qd]^T, then M^-1 Y */
    for (cint r = 0; r < NX; ++r)
      for (cint l = 0; l < NN; ++l) Y[l * NX + r] = B[r * NS + NN + l];
    ldl_solve_rows(L0, dl0, NX, Y);
    for (cint j = 0; j < NN; ++j)
      for (cint r = 0; r < NX; ++r) G[j * NS + r] = Y[j * NX + r];
    for (cint j = 0; j < NN; ++j) {
      double *Gm = G + (NN + j) * NS;
      for (cint r = 0; r < NX; ++r) Gm[r] = B[r * NS + 3 * NN + j] / MM[j];
    }
    for (cint t = 0; t < NP; ++t) G[(2 * NN + t) * NS + NX + t] = T;
  }
  return 0;
}

/* The rest of CasADi's external-function API, as the generated transition_step's. */
cint transition_step_chain_n_in(void) { return 2; }
cint transition_step_chain_n_out(void) { return 3; }
const char *transition_step_chain_name_in(cint i) { return transition_step_name_in(i); }
const char *transition_step_chain_name_out(cint i) { return transition_step_name_out(i); }
const cint *transition_step_chain_sparsity_in(cint i) { return transition_step_sparsity_in(i); }
const cint *transition_step_chain_sparsity_out(cint i) { return transition_step_sparsity_out(i); }
int transition_step_chain_checkout(void) { return 0; }
void transition_step_chain_release(int mem) { (void)mem; }
void transition_step_chain_incref(void) {}
void transition_step_chain_decref(void) {}
