/* A plain C program that uses a generated amsfe_sym library without Python:
 * it calls transition_step (x+, A, Gamma) and camera on inputs read from the command line
 * and prints every output with 17 significant digits.  Built and run by
 * tests/test_embed_c.py, which compares the numbers with the Python path. */
#include <stdio.h>
#include <stdlib.h>
#include AMSFE_HEADER

static void print(const char *name, const casadi_real *v, casadi_int count) {
  printf("%s", name);
  for (casadi_int i = 0; i < count; ++i) printf(" %.17g", v[i]);
  printf("\n");
}

/* Non-zeros of a CasADi sparsity pattern [nrow, ncol, colind..., row...]; a dense pattern is
 * stored compactly as [nrow, ncol, 1] (colind[0] is 0 for every other pattern). */
static casadi_int nnz_out(const casadi_int *sp) {
  return sp[2] == 1 ? sp[0] * sp[1] : sp[2 + sp[1]];
}

int main(int argc, char **argv) {
  casadi_int sz_arg, sz_res, sz_iw, sz_w;
  transition_step_work(&sz_arg, &sz_res, &sz_iw, &sz_w);
  casadi_int nx = transition_step_sparsity_in(0)[0];
  casadi_int nu = transition_step_sparsity_in(1)[0];
  if (argc != 1 + nx + nu) {
    fprintf(stderr, "expected %lld numbers (x then u), got %d\n", nx + nu, argc - 1);
    return 2;
  }
  casadi_real *x = malloc(sizeof(casadi_real) * nx), *u = malloc(sizeof(casadi_real) * nu);
  for (casadi_int i = 0; i < nx; ++i) x[i] = strtod(argv[1 + i], NULL);
  for (casadi_int i = 0; i < nu; ++i) u[i] = strtod(argv[1 + nx + i], NULL);

  casadi_int n_out = transition_step_n_out();
  casadi_real **res = calloc(sz_res, sizeof(casadi_real *));
  const casadi_real **arg = calloc(sz_arg, sizeof(casadi_real *));
  casadi_int *iw = malloc(sizeof(casadi_int) * (sz_iw + 1));
  casadi_real *w = malloc(sizeof(casadi_real) * (sz_w + 1));
  arg[0] = x;
  arg[1] = u;
  for (casadi_int k = 0; k < n_out; ++k)
    res[k] = malloc(sizeof(casadi_real) * nnz_out(transition_step_sparsity_out(k)));
  if (transition_step(arg, res, iw, w, 0)) return 1;
  print("x_next", res[0], nnz_out(transition_step_sparsity_out(0)));
  print("A", res[1], nnz_out(transition_step_sparsity_out(1)));
  print("Gamma", res[2], nnz_out(transition_step_sparsity_out(2)));

  /* camera(q, theta): q = x[0:n], theta = x[4n:] */
  casadi_int n = camera_sparsity_in(0)[0];
  const casadi_real *carg[2] = {x, x + 4 * n};
  casadi_real y[2];
  casadi_real *cres[1] = {y};
  casadi_int ciw[64];
  casadi_real cw[4096];
  casadi_int a, r, i2, w2;
  camera_work(&a, &r, &i2, &w2);
  if (i2 > 64 || w2 > 4096) return 3;
  if (camera(carg, cres, ciw, cw, 0)) return 1;
  print("y", y, 2);
  return 0;
}
