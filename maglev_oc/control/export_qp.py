"""The exported NMPC's QP solver: a dual active-set method (Goldfarb-Idnani) in plain C99.

The QP of the real-time iteration (:mod:`maglev_oc.control.nmpc.rti`), in its scaled variables
dz = (du_0, dx_1, du_1, ..., dx_N) (nz = 6 N):

    min 1/2 dz' H dz + g' dz   s.t.  the linearized dynamics (equalities, 4 rows per interval),
                                     lbx <= dz <= ubx,  lba <= D_j du_j <= uba (2 rows per interval)

Eliminating the dynamics leaves the condensed QP in the 2 N currents; its Hessian's inverse is
applied, without forming it, by one pass of the Riccati recursion that the preparation has
already factored (:func:`~maglev_oc.control.nmpc.riccati.riccati_factor`): for any vector v,
``P v = argmin 1/2 dz' H dz - v' dz`` under the homogeneous dynamics costs one backward and one
forward pass over the N intervals with the prepared gains (about 1400 multiply-adds for N = 20).

The method is Goldfarb and Idnani's dual active-set method (Math. Programming 27 (1983) 1-33) in
its range-space form: it starts at the unconstrained minimizer dz_lq (the Riccati step the
feedback has already computed, dual feasible with no active constraint), then repeatedly takes
the most violated inequality p and moves along the primal direction z = P (n_p - N r) and the
dual direction r = M^-1 N' P n_p (N the active constraints' normals, M = N' P N, kept as its
Cholesky factor L, updated by one row when a constraint is added and by Givens rotations when
one is dropped) until p is satisfied (a full step: p joins the active set) or an active
multiplier reaches zero first (a partial step: that constraint leaves). Every full step raises
the dual objective strictly and the active sets between two full steps shrink, so no active set
repeats: the method ends after finitely many steps in exact arithmetic (no cycling, unlike a
primal active-set method on a degenerate vertex). When no inequality is violated, the solution
is recomputed from the final active set A directly, ``dz = dz_lq + P N_A lambda`` with
``M lambda = b_A - N_A' dz_lq`` (round-off of the steps does not accumulate), and checked again.

Work per step: one or two Riccati passes and O(q^2) on the q active constraints (q <= 2 N),
no allocation (the work arrays are a fixed-size struct in the controller's memory). The number of
steps is bounded by a budget fixed at export time; when it runs out (or the QP is infeasible, or
its data are not finite) the solver returns NaN, which the step's solution check rejects: the
step applies the saturated Riccati step and says so in ``solver_ok`` and ``qp_status``
(:data:`STATUS_CODES`).
"""

from __future__ import annotations

from string import Template

from maglev_oc.control.nmpc.layout import N_POLYTOPE_ROWS, NU, NX
from maglev_oc.control.nmpc.riccati import FACTOR_STAGE

__all__ = ["STATUS_CODES", "dual_qp_sources", "dual_qp_work_bytes"]

STATUS_CODES = {
    0: "solved: the QP's exact solution on its final active set, every inequality satisfied",
    1: "the iteration budget ran out (fallback applied)",
    2: "the QP is infeasible (fallback applied)",
    3: "the QP's data or start are not finite (fallback applied)",
    4: "numerical failure: more active constraints than currents (fallback applied)",
}
"""``qp_status`` of the exported dual active-set solver (diagnostics row ``qp_status``)."""

FEASIBILITY_TOLERANCE = 1e-9
"""Largest violation of an inequality the solver accepts, in the QP's scaled units (mm, m/s,
A); the step's solution check accepts 1e-6 (:data:`~maglev_oc.control.nmpc.rti.SOLUTION_TOLERANCE`)."""
DEPENDENCE_TOLERANCE = 1e-10
"""A violated constraint whose normal is in the span of the active ones to this relative precision
(``n_p' z <= tol n_p' P n_p``) is treated as dependent (Goldfarb-Idnani's z = 0 case)."""
INFINITE_BOUND = 5e7
"""Bounds at or beyond this are no bound (the QP writes a missing bound as 1e8)."""


def dual_qp_work_bytes(horizon: int) -> int:
    """``sizeof`` the solver's work struct (doubles, then an even number of ints: no padding)."""
    nz, qmax, nc = (NX + NU) * horizon, NU * horizon, _constraints(horizon)
    doubles = 4 * nz + NU * horizon + qmax * qmax + 5 * qmax + nc
    ints = qmax + 2 * nc
    assert ints % 2 == 0
    return 8 * doubles + 4 * ints


def _constraints(horizon: int) -> int:
    """One-sided inequalities: lower and upper bound of every entry of dz, of every polytope row."""
    return 2 * (NX + NU) * horizon + 2 * N_POLYTOPE_ROWS * horizon


def dual_qp_sources(prefix: str, horizon: int) -> dict[str, str]:
    """``{file name: text}`` of the solver's header and source for an export with this prefix."""
    assert NX == 4 and NU == 2 and N_POLYTOPE_ROWS == 2 and FACTOR_STAGE == 40  # the C below
    fields = {
        "prefix": prefix,
        "PREFIX": prefix.upper(),
        "N": horizon,
        "FEAS": repr(FEASIBILITY_TOLERANCE),
        "DEP": repr(DEPENDENCE_TOLERANCE),
        "INF": repr(INFINITE_BOUND),
    }
    return {
        f"{prefix}_qp.h": Template(_HEADER).substitute(fields),
        f"{prefix}_qp.c": Template(_SOURCE).substitute(fields),
    }


_HEADER = """\
/* The exported NMPC's QP solver: Goldfarb-Idnani's dual active-set method on the QP condensed
   by the prepared Riccati factorization (see ${prefix}_qp.c). Plain C99, no allocation. */
#ifndef ${PREFIX}_QP_H
#define ${PREFIX}_QP_H

#define ${PREFIX}_QP_N ${N}                              /* shooting intervals */
#define ${PREFIX}_QP_NZ (6 * ${PREFIX}_QP_N)             /* variables dz */
#define ${PREFIX}_QP_NA (6 * ${PREFIX}_QP_N)             /* rows of A: dynamics (4), polytope (2) */
#define ${PREFIX}_QP_NC (2 * ${PREFIX}_QP_NZ + 4 * ${PREFIX}_QP_N) /* one-sided inequalities */
#define ${PREFIX}_QP_QMAX (2 * ${PREFIX}_QP_N)           /* active constraints at most (currents) */

/* qp_status */
#define ${PREFIX}_QP_SOLVED 0
#define ${PREFIX}_QP_BUDGET 1     /* the iteration budget ran out */
#define ${PREFIX}_QP_INFEASIBLE 2
#define ${PREFIX}_QP_NOT_FINITE 3 /* data or start not finite */
#define ${PREFIX}_QP_NUMERICAL 4  /* more independent active constraints than currents */

typedef struct {
  double x[${PREFIX}_QP_NZ];  /* the iterate */
  double z[${PREFIX}_QP_NZ];  /* its primal direction */
  double w[${PREFIX}_QP_NZ];  /* P n_p */
  double v[${PREFIX}_QP_NZ];  /* a gradient */
  double k[2 * ${PREFIX}_QP_N]; /* the feedforward terms of a Riccati pass */
  double L[${PREFIX}_QP_QMAX][${PREFIX}_QP_QMAX]; /* Cholesky factor of N' P N (active set) */
  double u[${PREFIX}_QP_QMAX];  /* multipliers of the active constraints (>= 0) */
  double r[${PREFIX}_QP_QMAX];  /* their direction */
  double l[${PREFIX}_QP_QMAX];  /* L^-1 N' w */
  double nw[${PREFIX}_QP_QMAX]; /* N' w, then a right-hand side */
  double lam[${PREFIX}_QP_QMAX];
  double b[${PREFIX}_QP_NC];       /* the constraints' right-hand sides (n_c' dz >= b_c) */
  int active[${PREFIX}_QP_QMAX];   /* the active constraints, in the order they joined */
  int is_active[${PREFIX}_QP_NC];
  int finite[${PREFIX}_QP_NC];     /* the constraints with a finite bound */
} ${prefix}_qp_work;

/* The QP's solution dz (nz) and its multipliers lam_x (nz), lam_a (na) in CasADi's convention
   (positive: upper bound active; the dynamics rows' multipliers are not computed: 0), from the
   prepared Riccati factorization `factor` (40 per interval), the bounds (the scaled QP's, nz and
   na: only the polytope rows of lba/uba are read) and the unconstrained minimizer `start`, in at
   most `budget` steps (each one or two Riccati passes). Returns the status (${PREFIX}_QP_*); on
   any status but ${PREFIX}_QP_SOLVED, dz is NaN. `iterations`: the steps taken. */
int ${prefix}_qp_solve(${prefix}_qp_work* ws, const double* factor, const double* lbx,
                       const double* ubx, const double* lba, const double* uba,
                       const double* start, int budget, double* dz, double* lam_x, double* lam_a,
                       int* iterations);

#endif
"""

_SOURCE = """\
/* Goldfarb-Idnani's dual active-set method (Math. Programming 27 (1983) 1-33) in range-space form
   on the NMPC's QP, the dynamics eliminated by the prepared Riccati factorization; exported by
   maglev_oc (maglev_oc/control/export_qp.py has the derivation).

   Variables dz = (du_0, dx_1, du_1, ..., dx_N): du_j at 6 j, dx_j at 6 j - 4. Per interval j the
   factor holds B_j (4x2), Quu_j^-1 (2x2), K_j (2x4), A_j (4x4), D_j (2x2), column-major.
   Constraint c (one-sided, n_c' dz >= b_c): c < 2 nz: entry c / 2 of dz, lower bound if c is
   even, else upper (n = -e); else k = c - 2 nz: polytope row (k / 2) % 2 of interval k / 4,
   lower if k is even, else upper (n = -D row). */
#include <math.h>
#include <string.h>
#include "${prefix}_qp.h"

#define N ${PREFIX}_QP_N
#define NZ ${PREFIX}_QP_NZ
#define NA ${PREFIX}_QP_NA
#define NC ${PREFIX}_QP_NC
#define QMAX ${PREFIX}_QP_QMAX
#define FS 40 /* factor entries per interval */
#define U(j) (6 * (j))
#define X(j) (6 * (j) - 4)
#define FEAS_TOL ${FEAS}
#define DEP_TOL ${DEP}
#define INF_BOUND ${INF}

typedef struct {
  const double* factor;
  const double* lbx;
  const double* ubx;
  const double* lba;
  const double* uba;
} qp_data;

/* x = argmin 1/2 x' H x + g' x under the homogeneous dynamics (x = -P g): one Riccati pass; g is
   zero beyond interval `top` (its du_j, dx_j for j > top), so the backward pass starts there */
static void riccati_pass(const double* f, const double* g, int top, double* x, double* kv) {
  double p[4], pn[4], qu[2], dx[4], dxn[4], du[2];
  int j, a, b, c;
  for (a = 0; a < 4; ++a) p[a] = top >= N ? g[X(N) + a] : 0.0;
  for (j = N - 1; j > top; --j) kv[2 * j] = kv[2 * j + 1] = 0.0;
  for (j = top < N - 1 ? top : N - 1; j >= 0; --j) {
    const double* B = f + FS * j;
    const double* Qi = B + 8;
    const double* K = B + 12;
    const double* A = B + 20;
    for (c = 0; c < 2; ++c) {
      qu[c] = g[U(j) + c];
      for (a = 0; a < 4; ++a) qu[c] += B[a + 4 * c] * p[a];
    }
    kv[2 * j] = Qi[0] * qu[0] + Qi[2] * qu[1];
    kv[2 * j + 1] = Qi[1] * qu[0] + Qi[3] * qu[1];
    if (j == 0) break;
    for (a = 0; a < 4; ++a) {
      pn[a] = g[X(j) + a] - K[2 * a] * qu[0] - K[2 * a + 1] * qu[1];
      for (b = 0; b < 4; ++b) pn[a] += A[b + 4 * a] * p[b];
    }
    for (a = 0; a < 4; ++a) p[a] = pn[a];
  }
  for (j = 0; j < N; ++j) {
    const double* B = f + FS * j;
    const double* K = B + 12;
    const double* A = B + 20;
    for (c = 0; c < 2; ++c) {
      du[c] = -kv[2 * j + c];
      if (j > 0)
        for (a = 0; a < 4; ++a) du[c] -= K[c + 2 * a] * dx[a];
      x[U(j) + c] = du[c];
    }
    for (a = 0; a < 4; ++a) {
      dxn[a] = B[a] * du[0] + B[a + 4] * du[1];
      if (j > 0)
        for (b = 0; b < 4; ++b) dxn[a] += A[a + 4 * b] * dx[b];
    }
    for (a = 0; a < 4; ++a) dx[a] = x[X(j + 1) + a] = dxn[a];
  }
}

/* the interval of constraint c's variable (x_N: N) */
static int stage_of(int c) {
  if (c >= 2 * NZ) return (c - 2 * NZ) / 4;
  return (c / 2 + 4) / 6;
}

/* the polytope row of constraint c >= 2 nz: its first variable and its coefficients */
static const double* polytope_row(const qp_data* d, int c, int* var, int* arow) {
  int k = c - 2 * NZ, j = k / 4, row = (k / 2) % 2;
  *var = U(j);
  *arow = 6 * j + 4 + row;
  return d->factor + FS * j + 36 + row; /* D[row], D[row + 2] */
}

static double normal_dot(const qp_data* d, int c, const double* v) {
  int var, arow;
  const double* D;
  double s = (c & 1) ? -1.0 : 1.0;
  if (c < 2 * NZ) return s * v[c / 2];
  D = polytope_row(d, c, &var, &arow);
  return s * (D[0] * v[var] + D[2] * v[var + 1]);
}

static void normal_add(const qp_data* d, int c, double alpha, double* v) {
  int var, arow;
  const double* D;
  double s = (c & 1) ? -alpha : alpha;
  if (c < 2 * NZ) {
    v[c / 2] += s;
    return;
  }
  D = polytope_row(d, c, &var, &arow);
  v[var] += s * D[0];
  v[var + 1] += s * D[2];
}

static double bound_of(const qp_data* d, int c) {
  int var, arow;
  if (c < 2 * NZ) return (c & 1) ? -d->ubx[c / 2] : d->lbx[c / 2];
  polytope_row(d, c, &var, &arow);
  return (c & 1) ? -d->uba[arow] : d->lba[arow];
}

/* the most violated inequality not in the active set (-1: none beyond FEAS_TOL), among the
   n_bounds finite simple bounds, then the polytope rows, listed in ws->finite */
static int most_violated(const qp_data* d, const ${prefix}_qp_work* ws, int n_bounds, int n_finite,
                         const double* x) {
  int m, c, best = -1;
  double worst = -FEAS_TOL, s;
  for (m = 0; m < n_bounds; ++m) {
    c = ws->finite[m];
    s = ((c & 1) ? -x[c / 2] : x[c / 2]) - ws->b[c];
    if (s < worst && !ws->is_active[c]) {
      worst = s;
      best = c;
    }
  }
  for (; m < n_finite; ++m) {
    c = ws->finite[m];
    s = normal_dot(d, c, x) - ws->b[c];
    if (s < worst && !ws->is_active[c]) {
      worst = s;
      best = c;
    }
  }
  return best;
}

/* y = L^-1 b (forward), then y = L^-T y (backward), on the leading q x q block */
static void forward(const ${prefix}_qp_work* ws, int q, const double* b, double* y) {
  int i, k;
  for (i = 0; i < q; ++i) {
    double s = b[i];
    for (k = 0; k < i; ++k) s -= ws->L[i][k] * y[k];
    y[i] = s / ws->L[i][i];
  }
}

static void backward(const ${prefix}_qp_work* ws, int q, double* y) {
  int i, k;
  for (i = q - 1; i >= 0; --i) {
    double s = y[i];
    for (k = i + 1; k < q; ++k) s -= ws->L[k][i] * y[k];
    y[i] = s / ws->L[i][i];
  }
}

/* drop active constraint number kd: its row of L goes, Givens rotations restore the triangle */
static void drop(${prefix}_qp_work* ws, int q, int kd) {
  int i, k;
  ws->is_active[ws->active[kd]] = 0;
  for (i = kd; i < q - 1; ++i) {
    ws->active[i] = ws->active[i + 1];
    ws->u[i] = ws->u[i + 1];
    for (k = 0; k <= i + 1; ++k) ws->L[i][k] = ws->L[i + 1][k];
  }
  for (i = kd; i < q - 1; ++i) {
    double a = ws->L[i][i], b = ws->L[i][i + 1], h = sqrt(a * a + b * b), c, s;
    c = a / h;
    s = b / h;
    for (k = i; k < q - 1; ++k) {
      double x1 = ws->L[k][i], x2 = ws->L[k][i + 1];
      ws->L[k][i] = c * x1 + s * x2;
      ws->L[k][i + 1] = -s * x1 + c * x2;
    }
    ws->L[i][i + 1] = 0.0;
  }
}

/* the exact solution on the active set: lam = M^-1 (b_A - N' start), x = start + P N lam */
static void solve_on_active_set(const qp_data* d, ${prefix}_qp_work* ws, int q, const double* start) {
  int k, top = 0;
  if (q == 0) { /* the start itself */
    memcpy(ws->x, start, sizeof(ws->x));
    return;
  }
  for (k = 0; k < q; ++k) ws->nw[k] = ws->b[ws->active[k]] - normal_dot(d, ws->active[k], start);
  forward(ws, q, ws->nw, ws->lam);
  backward(ws, q, ws->lam);
  memset(ws->v, 0, sizeof(ws->v));
  for (k = 0; k < q; ++k) {
    normal_add(d, ws->active[k], -ws->lam[k], ws->v);
    if (stage_of(ws->active[k]) > top) top = stage_of(ws->active[k]);
  }
  riccati_pass(d->factor, ws->v, top, ws->x, ws->k);
  for (k = 0; k < NZ; ++k) ws->x[k] += start[k];
  for (k = 0; k < q; ++k) ws->u[k] = ws->lam[k] > 0.0 ? ws->lam[k] : 0.0; /* round-off: >= 0 */
}

int ${prefix}_qp_solve(${prefix}_qp_work* ws, const double* factor, const double* lbx,
                       const double* ubx, const double* lba, const double* uba,
                       const double* start, int budget, double* dz, double* lam_x, double* lam_a,
                       int* iterations) {
  qp_data d;
  int i, k, q = 0, it = 0, status = ${PREFIX}_QP_BUDGET, exact = 0, n_bounds = 0, n_finite = 0;
  double total = 0.0;
  d.factor = factor;
  d.lbx = lbx;
  d.ubx = ubx;
  d.lba = lba;
  d.uba = uba;
  memset(ws->is_active, 0, sizeof(ws->is_active));
  for (i = 0; i < NZ; ++i) total += fabs(start[i]) + fabs(lbx[i]) + fabs(ubx[i]);
  for (i = 0; i < NA; ++i) total += fabs(lba[i]) + fabs(uba[i]);
  for (i = 0; i < N * FS; ++i) total += fabs(factor[i]);
  if (!(total < 1e300)) {
    status = ${PREFIX}_QP_NOT_FINITE;
    goto done;
  }
  memcpy(ws->x, start, sizeof(ws->x));
  for (i = 0; i < NC; ++i) {
    ws->b[i] = bound_of(&d, i);
    if (fabs(ws->b[i]) < INF_BOUND) ws->finite[n_finite++] = i;
    if (i == 2 * NZ - 1) n_bounds = n_finite;
  }
  for (;;) {
    int p = most_violated(&d, ws, n_bounds, n_finite, ws->x);
    double up = 0.0, pw;
    if (p < 0) {
      if (exact) { /* every inequality holds at the exact solution of the active set */
        status = ${PREFIX}_QP_SOLVED;
        break;
      }
      if (it >= budget) break;
      ++it;
      solve_on_active_set(&d, ws, q, start);
      exact = 1;
      continue;
    }
    exact = 0;
    if (it >= budget) break;
    /* w = P n_p (P is the inverse of the condensed Hessian, by a Riccati pass) */
    memset(ws->v, 0, sizeof(ws->v));
    normal_add(&d, p, -1.0, ws->v);
    riccati_pass(factor, ws->v, stage_of(p), ws->w, ws->k);
    pw = normal_dot(&d, p, ws->w);
    for (;;) { /* steps toward satisfying p: partial ones drop a constraint, the full one adds p */
      double d2, t1 = HUGE_VAL, t2 = HUGE_VAL, t, lsq = 0.0;
      int kd = -1, full;
      ++it;
      for (k = 0; k < q; ++k) ws->nw[k] = normal_dot(&d, ws->active[k], ws->w);
      forward(ws, q, ws->nw, ws->l);
      for (k = 0; k < q; ++k) {
        ws->r[k] = ws->l[k];
        lsq += ws->l[k] * ws->l[k];
      }
      backward(ws, q, ws->r);
      d2 = pw - lsq; /* n_p' z, z = P (n_p - N r) */
      full = d2 > DEP_TOL * pw;
      for (k = 0; k < q; ++k) {
        if (ws->r[k] > 0.0 && ws->u[k] / ws->r[k] < t1) {
          t1 = ws->u[k] / ws->r[k];
          kd = k;
        }
      }
      if (!full && kd < 0) {
        status = ${PREFIX}_QP_INFEASIBLE;
        goto done;
      }
      if (full) {
        if (q == QMAX) {
          status = ${PREFIX}_QP_NUMERICAL;
          goto done;
        }
        t2 = -(normal_dot(&d, p, ws->x) - ws->b[p]) / d2;
        if (q == 0) { /* z = P n_p = w */
          memcpy(ws->z, ws->w, sizeof(ws->z));
        } else {
          int top = stage_of(p);
          memset(ws->v, 0, sizeof(ws->v));
          normal_add(&d, p, -1.0, ws->v);
          for (k = 0; k < q; ++k) {
            normal_add(&d, ws->active[k], ws->r[k], ws->v);
            if (stage_of(ws->active[k]) > top) top = stage_of(ws->active[k]);
          }
          riccati_pass(factor, ws->v, top, ws->z, ws->k);
        }
      }
      t = t1 < t2 ? t1 : t2;
      if (full)
        for (i = 0; i < NZ; ++i) ws->x[i] += t * ws->z[i];
      for (k = 0; k < q; ++k) ws->u[k] -= t * ws->r[k];
      up += t;
      if (full && t2 <= t1) { /* p joins the active set */
        for (k = 0; k < q; ++k) ws->L[q][k] = ws->l[k];
        ws->L[q][q] = sqrt(d2);
        ws->u[q] = up;
        ws->active[q] = p;
        ws->is_active[p] = 1;
        ++q;
        break;
      }
      drop(ws, q, kd); /* constraint kd's multiplier reached zero first */
      --q;
      if (it >= budget) goto done;
    }
  }
done:
  *iterations = it;
  memset(lam_x, 0, NZ * sizeof(double));
  memset(lam_a, 0, NA * sizeof(double));
  if (status != ${PREFIX}_QP_SOLVED) {
    for (i = 0; i < NZ; ++i) dz[i] = NAN;
    return status;
  }
  memcpy(dz, ws->x, sizeof(ws->x));
  for (k = 0; k < q; ++k) { /* CasADi's convention: a positive multiplier for an upper bound */
    int c = ws->active[k], var, arow;
    double lam = (c & 1) ? ws->u[k] : -ws->u[k];
    if (c < 2 * NZ) {
      lam_x[c / 2] += lam;
    } else {
      polytope_row(&d, c, &var, &arow);
      lam_a[arow] += lam;
    }
  }
  return status;
}
"""
