/* amsfe_internal.h: what the runtime's C files share inside a generated library (the
 * estimator's files also share amsfe_est_internal.h, the loop's amsfe_loop_internal.h).
 * Not part of the public API (not copied next to the library): the calling convention of
 * CasADi's generated functions, the carving of caller-owned memory blocks, and the dense
 * kernels (defined in amsfe_kernels.c, hidden from the library's exports). */
#ifndef AMSFE_INTERNAL_H
#define AMSFE_INTERNAL_H

#include <math.h>
#include <stddef.h>

typedef long long cint;
typedef int (*cfun)(const double **arg, double **res, cint *iw, double *w, int mem);
typedef int (*cwork)(cint *sz_arg, cint *sz_res, cint *sz_iw, cint *sz_w);

/* The symbols a generated function `f` exports. */
#define DECLARE(f)                                                        \
  int f(const double **arg, double **res, cint *iw, double *w, int mem); \
  int f##_work(cint *sz_arg, cint *sz_res, cint *sz_iw, cint *sz_w);    \
  cint f##_n_out(void);                                                   \
  const cint *f##_sparsity_in(cint i);

/* Work arrays of generated functions, sized for the largest of a set. */
typedef struct {
  const double **arg;
  double **res;
  cint *iw;
  double *w;
} gwork;

/* Carves 16-byte aligned pieces out of one block; with base NULL it only measures. */
typedef struct {
  char *base;
  size_t off;
} carver;

static inline void *carve(carver *c, size_t bytes) {
  size_t o = (c->off + 15) & ~(size_t)15;
  c->off = o + bytes;
  return c->base ? (void *)(c->base + o) : NULL;
}

#define DBL(c, count) ((double *)carve((c), sizeof(double) * (size_t)(count)))

/* The carver of an object's layout: the object itself (`head` bytes) is its block's first
 * piece, the arrays it points to follow. */
static inline carver carve_object(char *base, size_t head) {
  carver c = {base, 0};
  carve(&c, head);
  return c;
}

/* Carve the work arrays of the largest of `count` generated functions. */
static inline void carve_work(carver *c, const cwork *works, size_t count, gwork *g) {
  cint sa = 0, sr = 0, si = 0, sw = 0;
  for (size_t i = 0; i < count; ++i) {
    cint a, r, iw, w;
    works[i](&a, &r, &iw, &w);
    sa = a > sa ? a : sa, sr = r > sr ? r : sr, si = iw > si ? iw : si, sw = w > sw ? w : sw;
  }
  g->arg = (const double **)carve(c, sizeof(double *) * (size_t)(sa + 1));
  g->res = (double **)carve(c, sizeof(double *) * (size_t)(sr + 1));
  g->iw = (cint *)carve(c, sizeof(cint) * (size_t)(si + 1));
  g->w = DBL(c, sw + 1);
}

/* Call a generated function: inputs in[0..nin), outputs out[0..nout) (NULL: not wanted). */
static inline int gcall(const gwork *g, cfun f, const double *const *in, int nin,
                        double *const *out, int nout) {
  for (int i = 0; i < nin; ++i) g->arg[i] = in[i];
  for (int i = 0; i < nout; ++i) g->res[i] = out[i];
  return f(g->arg, g->res, g->iw, g->w, 0);
}

static inline int all_finite(const double *v, long count) {
  for (long i = 0; i < count; ++i)
    if (!isfinite(v[i])) return 0;
  return 1;
}

#if defined(__GNUC__)
#define AMSFE_HIDDEN __attribute__((visibility("hidden")))
#else
#define AMSFE_HIDDEN
#endif

/* The dense kernels of amsfe_kernels.c (column-major; symmetric results exactly symmetric). */
/* Lower Cholesky factor of the m x m S into L (its strict upper part set to 0); 1 when
 * every pivot is > 0 (a NaN pivot gives 0), as LAPACK potrf. */
AMSFE_HIDDEN int amsfe_cholesky(int m, const double *S, double *L);
/* b <- S^-1 b with S = L L^T (m x m, leading dimension m). */
AMSFE_HIDDEN void amsfe_chol_solve(int m, const double *L, double *b);
/* Li = L^-1 (m x m lower triangular, positive diagonal; Li lower triangular). */
AMSFE_HIDDEN void amsfe_tri_inverse(int m, const double *L, double *Li);
/* Upper triangle of the m x m X <- its lower triangle. */
AMSFE_HIDDEN void amsfe_mirror_lower(int m, double *X);
/* C = A B (N x N). */
AMSFE_HIDDEN void amsfe_matmul(int N, const double *A, const double *B, double *C);
/* C (N x ncols, leading dimension N) = A (N x N) B (N x ncols, leading dimension ldb). */
AMSFE_HIDDEN void amsfe_matmul_cols(int N, int ncols, const double *A, const double *B, long ldb,
                                    double *C);
/* out = A L L^T A^T + G diag(qw) G^T (eq. 14 with P = L L^T; G: N x nw); B: scratch of
 * AMSFE_PREDICT_WORK(N, nw) doubles. */
AMSFE_HIDDEN void amsfe_predict_cov(int N, int nw, const double *A, const double *L,
                                    const double *G, const double *qw, double *out, double *B);
/* out = A X A^T + G diag(qw) G^T (G may be NULL); T: AMSFE_PREDICT_WORK(N, nw) doubles of
 * scratch (eq. 23). */
AMSFE_HIDDEN void amsfe_sandwich(int N, int nw, const double *A, const double *X, const double *G,
                                 const double *qw, double *out, double *T);
/* b <- A^-1 b (LU with partial pivoting, A overwritten); 0 when A is singular. */
AMSFE_HIDDEN int amsfe_lu_solve(int N, double *A, double *b);
/* Joseph-form update of (x, P) (M states) by a measurement of the states rows[0..m) with
 * variances r (eqs. 15-17); 0 when S is not PD.  w: AMSFE_JOSEPH_WORK(M, m) doubles. */
AMSFE_HIDDEN int amsfe_joseph_select(int M, int m, const int *rows, const double *r,
                                     const double *x, const double *P, const double *z,
                                     double *x2, double *P2, double *nis, double *nu, double *w);
/* amsfe_joseph_select for an H given by its rows' nonzeros (hrow [m + 1], hcol, hval) and a
 * given innovation nu [m]; 0 when S is not PD.  w: AMSFE_JOSEPH_WORK(M, m) doubles. */
AMSFE_HIDDEN int amsfe_joseph_rows(int M, int m, const int *hrow, const int *hcol,
                                   const double *hval, const double *r, const double *x,
                                   const double *P, const double *nu, double *x2, double *P2,
                                   double *nis, double *w);
/* amsfe_a1_retrodict for any encoder H: QHt = Q H^T, PpHt = P_prior H^T (M x m), S =
 * sym(H P_prior H^T) + diag(r); 0 when S is not PD.  w: AMSFE_RETRO_WORK(M, m) doubles. */
AMSFE_HIDDEN int amsfe_a1_retrodict_cols(int M, int m, const double *S, const double *QHt,
                                         const double *PpHt, const double *x, const double *P,
                                         const double *Q, const double *nu, double *xs,
                                         double *Mo, double *C, double *w);
/* oosm.a1_retrodict with the encoders' H = I[rows, :] (x_shift, M, C); 0 when S is not PD. */
AMSFE_HIDDEN int amsfe_a1_retrodict(int M, int m, const int *rows, const double *r,
                                    const double *x, const double *P, const double *Q,
                                    const double *nu, const double *Pp, double *xs, double *Mo,
                                    double *C, double *w);
/* The lower Cholesky factor (N x N, column-major) of the estimator's current P, computed
 * now if it is stale (the next prediction then reuses it, as it reuses the factor of the
 * step's own check); NULL when P is not positive definite.  amsfe_runtime.c. */
struct amsfe_est;
AMSFE_HIDDEN const double *amsfe_est_factor(struct amsfe_est *e);
#define AMSFE_RETRO_WORK(M, m) (5L * (M) * (m) + (long)(M) * (M) + 2L * (m) * (m))
#define AMSFE_PREDICT_WORK(N, nw) (2L * (N) * (N) + (long)(N) * (nw))
#define AMSFE_JOSEPH_WORK(M, m) (4L * (M) * (m) + 3L * (m) * (m) + (m))

#endif /* AMSFE_INTERNAL_H */
