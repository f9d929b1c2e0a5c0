/*
 * Projected Newton method for   min f(u, p)   s.t.   lb <= u <= ub
 * (D. P. Bertsekas, "Projected Newton methods for optimization problems with simple
 * constraints", SIAM J. Control Optim. 20(2), 1982), the solver of moose.planner.mpc.projected_newton.
 *
 * This file is compiled after the CasADi-generated C of two functions of (u, p):
 *   pn_cost        -> f                  (a cost evaluation: one line-search trial)
 *   pn_derivatives -> f, grad f, hess f  (dense n x n, column-major)
 * and the definition of PN_N, the number of decision variables.
 *
 * One iteration at u with gradient g and Hessian H:
 *   1. w = || u - P(u - g) ||_inf (the first-order optimality measure); stop if w <= tol_opt.  This is
 *      the only convergence test: a short step is not one (see 5).
 *   2. epsilon-active set A: u_i within min(eps_active, w) of a bound with g_i pushing out of
 *      the box; the free set F is the rest.
 *   3. Direction: d_A = -g_A (the projection keeps those variables on their bound);
 *      d_F = -(H_FF + (c w + tau) I)^{-1} g_F.  c w is a regularisation that vanishes at a
 *      stationary point (regularised Newton, Ueda & Yamashita 2010): it bounds the step along
 *      flat directions far from the solution and keeps the local Newton step near it.  tau is
 *      the first of 0 (or beta - min diag), then doubling, for which the Cholesky factorisation
 *      succeeds (Nocedal & Wright, Numerical Optimization, 2nd ed., Alg. 3.3): the cost need not
 *      be convex.
 *   4. Armijo backtracking along the projection arc u(a) = P(u + a d), a = 1, rho, rho^2, ...:
 *      accept the first u(a) with f(u(a)) < f(u) and f(u(a)) <= f(u) + sigma g'(u(a) - u).
 *   5. Newton's direction has failed if the search accepts no point, or only one it had to
 *      shorten to a step ||u(a) - u||_inf < tol_step: H is then a poor model of f along d (a
 *      kink of the Hessian, e.g. the speed-floor penalty switching on, or a large shift tau).
 *      The iteration then searches along the projected gradient d = -g as in 4 (Bertsekas'
 *      safeguard: the arc P(u - a g) decreases f for small a wherever w > 0) and takes the
 *      lower of the two points.  If neither search accepts a point the iteration stops with
 *      PN_LINE_SEARCH, not converged.
 * Counting: every cost evaluation at a new point counts once against max_evals, the start
 * included; the derivatives at an accepted trial point are part of that point's evaluation
 * (as an objective that returns its gradient counts once in fmincon).
 */
#include <math.h>
#include <stdlib.h>

enum {
  PN_CONVERGED = 0,   /* first-order optimality measure below tol_opt */
  PN_MAX_ITER = 1,    /* iteration cap */
  PN_MAX_EVALS = 2,   /* evaluation cap */
  PN_LINE_SEARCH = 3, /* no decrease within max_ls backtracking steps, along Newton's direction nor -g */
  PN_NOT_FINITE = 4   /* cost or derivatives not finite at an accepted point */
};

/* Layout of the options vector. */
enum { OPT_MAX_ITER, OPT_MAX_EVALS, OPT_MAX_LS, OPT_RHO, OPT_SIGMA, OPT_EPS_ACTIVE, OPT_TOL_OPT,
       OPT_TOL_STEP, OPT_SHIFT, OPT_REGULARISATION, N_OPT };
/* Layout of the info vector. */
enum { INFO_F, INFO_F_START, INFO_ITER, INFO_EVALS, INFO_STATUS, INFO_OPTIMALITY, N_INFO };

int pn_n(void) { return PN_N; }
int pn_n_opt(void) { return N_OPT; }
int pn_n_info(void) { return N_INFO; }

typedef struct {
  const casadi_real **arg;
  casadi_real **res;
  casadi_int *iw;
  casadi_real *w;
} pn_work;

static int pn_finite(const double *x, int n) {
  for (int i = 0; i < n; ++i)
    if (!(x[i] - x[i] == 0.0)) return 0; /* NaN and +-inf give NaN */
  return 1;
}

static double pn_clip(double x, double lo, double hi) { return x < lo ? lo : (x > hi ? hi : x); }

static int pn_cost_at(pn_work *ws, const double *u, const double *p, double *f) {
  ws->arg[0] = u;
  ws->arg[1] = p;
  ws->res[0] = f;
  return pn_cost(ws->arg, ws->res, ws->iw, ws->w, 0) == 0 && pn_finite(f, 1);
}

static int pn_derivatives_at(pn_work *ws, const double *u, const double *p, double *f, double *g, double *H) {
  ws->arg[0] = u;
  ws->arg[1] = p;
  ws->res[0] = f;
  ws->res[1] = g;
  ws->res[2] = H;
  return pn_derivatives(ws->arg, ws->res, ws->iw, ws->w, 0) == 0 && pn_finite(f, 1) && pn_finite(g, PN_N) &&
         pn_finite(H, PN_N * PN_N);
}

/* Lower Cholesky factor of A + tau I (m x m, row-major) into L; 0 if not positive definite. */
static int pn_cholesky(int m, const double *A, double tau, double *L) {
  for (int i = 0; i < m; ++i) {
    for (int j = 0; j <= i; ++j) {
      double s = A[i * m + j] + (i == j ? tau : 0.0);
      for (int k = 0; k < j; ++k) s -= L[i * m + k] * L[j * m + k];
      if (i == j) {
        if (!(s > 0.0)) return 0;
        L[i * m + i] = sqrt(s);
      } else {
        L[i * m + j] = s / L[j * m + j];
      }
    }
  }
  return 1;
}

/* x = -(L L')^{-1} b. */
static void pn_cholesky_solve(int m, const double *L, const double *b, double *x) {
  for (int i = 0; i < m; ++i) {
    double s = -b[i];
    for (int k = 0; k < i; ++k) s -= L[i * m + k] * x[k];
    x[i] = s / L[i * m + i];
  }
  for (int i = m - 1; i >= 0; --i) {
    double s = x[i];
    for (int k = i + 1; k < m; ++k) s -= L[k * m + i] * x[k];
    x[i] = s / L[i * m + i];
  }
}

/* -(A + (r + tau) I)^{-1} b with the tau of Alg. 3.3 on A + r I (beta = shift * max(1, max |a_ii + r|));
 * 0 if none found. */
static int pn_shifted_newton(int m, const double *A, const double *b, double r, double shift, double *L,
                             double *x) {
  double min_diag = A[0] + r, max_abs = 1.0;
  for (int i = 0; i < m; ++i) {
    double a = A[i * m + i] + r;
    if (a < min_diag) min_diag = a;
    if (fabs(a) > max_abs) max_abs = fabs(a);
  }
  double beta = shift * max_abs;
  double tau = min_diag > 0.0 ? 0.0 : beta - min_diag;
  for (int attempt = 0; attempt < 64; ++attempt) {
    if (pn_cholesky(m, A, r + tau, L)) {
      pn_cholesky_solve(m, L, b, x);
      return 1;
    }
    tau = 2.0 * tau > beta ? 2.0 * tau : beta;
  }
  return 0;
}

/* ||u - P(u - g)||_inf. */
static double pn_optimality(const double *u, const double *g, const double *lb, const double *ub) {
  double w = 0.0;
  for (int i = 0; i < PN_N; ++i) {
    double r = fabs(pn_clip(u[i] - g[i], lb[i], ub[i]) - u[i]);
    if (r > w) w = r;
  }
  return w;
}

/* Step 4: Armijo backtracking along the projection arc P(u + a d) from a = 1.  The accepted point goes to trial,
 * its cost to *f_trial and its a to *alpha.  Returns 1 if a point was accepted, 0 if none within max_ls backtracks,
 * -1 if the evaluation cap came first. */
static int pn_search(pn_work *ws, const double *p, const double *lb, const double *ub, const double *opt,
                     const double *u, double f, const double *g, const double *d, double *trial, double *f_trial,
                     double *alpha, int *evals) {
  const int max_evals = (int)opt[OPT_MAX_EVALS], max_ls = (int)opt[OPT_MAX_LS];
  double a = 1.0;
  for (int j = 0; j <= max_ls; ++j) {
    if (*evals >= max_evals) return -1;
    double slope = 0.0;
    for (int i = 0; i < PN_N; ++i) {
      trial[i] = pn_clip(u[i] + a * d[i], lb[i], ub[i]);
      slope += g[i] * (trial[i] - u[i]);
    }
    ++*evals;
    if (pn_cost_at(ws, trial, p, f_trial) && *f_trial < f && *f_trial <= f + opt[OPT_SIGMA] * slope) {
      *alpha = a;
      return 1;
    }
    a *= opt[OPT_RHO];
  }
  return 0;
}

static double pn_step(const double *u, const double *trial) {
  double step = 0.0;
  for (int i = 0; i < PN_N; ++i) {
    double s = fabs(trial[i] - u[i]);
    if (s > step) step = s;
  }
  return step;
}

static int pn_iterate(pn_work *ws, const double *p, const double *lb, const double *ub, const double *opt,
                      double *u, double *info, double *g, double *H, double *d, double *trial, double *trial_g,
                      double *Hf, double *L, double *gf, double *df, int *free_idx) {
  const int max_iter = (int)opt[OPT_MAX_ITER];
  double f = 0.0, w = 0.0;
  int iter = 0, evals = 1, capped = 0;
  info[INFO_ITER] = 0;
  info[INFO_EVALS] = 1;
  info[INFO_OPTIMALITY] = INFINITY;
  if (!pn_derivatives_at(ws, u, p, &f, g, H)) {
    info[INFO_F] = info[INFO_F_START] = INFINITY;
    return PN_NOT_FINITE;
  }
  info[INFO_F_START] = f;
  int status;
  for (;;) {
    w = pn_optimality(u, g, lb, ub);
    if (w <= opt[OPT_TOL_OPT]) { status = PN_CONVERGED; break; }
    if (iter >= max_iter) { status = PN_MAX_ITER; break; }
    if (capped) { status = PN_MAX_EVALS; break; }
    /* epsilon-active set and direction */
    double eps = w < opt[OPT_EPS_ACTIVE] ? w : opt[OPT_EPS_ACTIVE];
    int m = 0;
    for (int i = 0; i < PN_N; ++i) {
      int active = (u[i] <= lb[i] + eps && g[i] > 0.0) || (u[i] >= ub[i] - eps && g[i] < 0.0);
      d[i] = -g[i];
      if (!active) free_idx[m++] = i;
    }
    if (m > 0) {
      for (int a = 0; a < m; ++a) {
        gf[a] = g[free_idx[a]];
        for (int b = 0; b < m; ++b) Hf[a * m + b] = H[free_idx[b] * PN_N + free_idx[a]];
      }
      if (pn_shifted_newton(m, Hf, gf, opt[OPT_REGULARISATION] * w, opt[OPT_SHIFT], L, df))
        for (int a = 0; a < m; ++a) d[free_idx[a]] = df[a];
    }
    double f_newton = INFINITY, f_gradient = INFINITY, alpha = 1.0;
    int newton = pn_search(ws, p, lb, ub, opt, u, f, g, d, trial, &f_newton, &alpha, &evals);
    const double *next = newton == 1 ? trial : NULL;
    double f_next = f_newton;
    if (newton == 0 || (newton == 1 && alpha < 1.0 && pn_step(u, trial) < opt[OPT_TOL_STEP])) {
      /* step 5: Newton's direction failed; the projected gradient */
      for (int i = 0; i < PN_N; ++i) d[i] = -g[i];
      int gradient = pn_search(ws, p, lb, ub, opt, u, f, g, d, trial_g, &f_gradient, &alpha, &evals);
      if (gradient == 1 && f_gradient < f_next) {
        next = trial_g;
        f_next = f_gradient;
      }
      capped = gradient < 0;
    } else {
      capped = newton < 0;
    }
    if (next == NULL) { status = capped ? PN_MAX_EVALS : PN_LINE_SEARCH; break; }
    for (int i = 0; i < PN_N; ++i) u[i] = next[i];
    f = f_next;
    ++iter;
    if (!pn_derivatives_at(ws, u, p, &f, g, H)) { status = PN_NOT_FINITE; break; }
  }
  info[INFO_F] = f;
  info[INFO_ITER] = iter;
  info[INFO_EVALS] = evals;
  info[INFO_OPTIMALITY] = w;
  return status;
}

/*
 * Solve from u0 (clipped into the box).  u: the result (n); opt: N_OPT options; info: N_INFO
 * results.  Returns the status (PN_*), or -1 if the work space could not be allocated.
 */
int pn_solve(const double *u0, const double *p, const double *lb, const double *ub, const double *opt,
             double *u, double *info) {
  casadi_int sz_arg, sz_res, sz_iw, sz_w, a2, r2, iw2, w2;
  pn_cost_work(&sz_arg, &sz_res, &sz_iw, &sz_w);
  pn_derivatives_work(&a2, &r2, &iw2, &w2);
  if (a2 > sz_arg) sz_arg = a2;
  if (r2 > sz_res) sz_res = r2;
  if (iw2 > sz_iw) sz_iw = iw2;
  if (w2 > sz_w) sz_w = w2;
  const int n = PN_N;
  pn_work ws;
  ws.arg = malloc(sizeof(*ws.arg) * (size_t)(sz_arg > 0 ? sz_arg : 1));
  ws.res = malloc(sizeof(*ws.res) * (size_t)(sz_res > 0 ? sz_res : 1));
  ws.iw = malloc(sizeof(*ws.iw) * (size_t)(sz_iw > 0 ? sz_iw : 1));
  double *buffer = malloc(sizeof(double) * (size_t)((sz_w > 0 ? sz_w : 1) + 3 * n * n + 6 * n));
  int *free_idx = malloc(sizeof(int) * (size_t)n);
  int status = -1;
  if (ws.arg && ws.res && ws.iw && buffer && free_idx) {
    ws.w = buffer;
    double *H = buffer + (sz_w > 0 ? sz_w : 1), *Hf = H + n * n, *L = Hf + n * n;
    double *g = L + n * n, *d = g + n, *trial = d + n, *trial_g = trial + n, *gf = trial_g + n, *df = gf + n;
    for (int i = 0; i < n; ++i) u[i] = pn_clip(u0[i], lb[i], ub[i]);
    status = pn_iterate(&ws, p, lb, ub, opt, u, info, g, H, d, trial, trial_g, Hf, L, gf, df, free_idx);
    info[INFO_STATUS] = status;
  }
  free(free_idx);
  free(buffer);
  free(ws.iw);
  free(ws.res);
  free(ws.arg);
  return status;
}
