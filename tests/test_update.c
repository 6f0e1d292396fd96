/* Augmented updates (AMPS Steps 1-6) against CHOLMOD on the explicitly formed current system:
   long random sequences of stiffness changes, new DOFs, constraints and forces on random SPD and
   finite element matrices, node-duplicating cuts of FE meshes, bad input and singular updates. */
#define AMPS_IMPLEMENTATION
#define AMPS_COUNT_TOUCH
/* failure injection in the background re-factorization: phase t_bg_fault fails */
static int t_bg_fault = 0;
#define AMPS_TEST_BG_FAULT(phase) (t_bg_fault == (phase))
/* the fill bound of a kept ordering (lowered to force the fall-back to a fresh one) */
static double t_fill_bound = 1.2;
#define AMPS_REFACTOR_FILL_BOUND t_fill_bound
/* 1: every loop of the background factorization runs in parallel (its helper thread on small matrices) */
static int t_bg_par = 0;
#define AMPS_TEST_BG_PARALLEL t_bg_par
#include "amps.h"
#include "amps_test.h"
#include "fe_util.h"
#include "cholmod_ref.h"
#include <string.h>
#include <pthread.h>
#include <time.h>

/* ---- explicit current system: triplets (i <= j, summed on assembly) ---- */
typedef struct trip {
    int nz, cap;
    int *i, *j;
    double *x;
} trip;

static void trip_add(trip *T, int i, int j, double v) {
    if (T->nz == T->cap) {
        T->cap = T->cap * 2 + 1024;
        T->i = (int *)realloc(T->i, sizeof(int) * T->cap);
        T->j = (int *)realloc(T->j, sizeof(int) * T->cap);
        T->x = (double *)realloc(T->x, sizeof(double) * T->cap);
    }
    T->i[T->nz] = i < j ? i : j;
    T->j[T->nz] = i < j ? j : i;
    T->x[T->nz] = v;
    T->nz++;
}
static void trip_free(trip *T) {
    free(T->i);
    free(T->j);
    free(T->x);
    memset(T, 0, sizeof(*T));
}

/* Reference solution of K x = f with x_C = g (con[i] != 0) by CHOLMOD on the reduced system.
   Returns CHOLMOD's relative residual (reduced system), or -1 if it failed. */
static double ref_constrained(amps_ctx *ctx, const trip *T, int N, const int *con, const double *g, const double *f,
                              double *x) {
    int *map = (int *)malloc(sizeof(int) * (N + 1)), nf = 0, k, c;
    double *rhs, *xf, num = 0, den = 0, res;
    trip R = {0, 0, NULL, NULL, NULL};
    amps_csc *A;
    for (k = 0; k < N; k++) map[k] = con[k] ? -1 : nf++;
    rhs = (double *)calloc(nf + 1, sizeof(double));
    xf = (double *)calloc(nf + 1, sizeof(double));
    for (k = 0; k < N; k++)
        if (map[k] >= 0) rhs[map[k]] = f[k];
    for (k = 0; k < T->nz; k++) {
        int i = T->i[k], j = T->j[k];
        double v = T->x[k];
        if (map[i] >= 0 && map[j] >= 0) trip_add(&R, map[i], map[j], v);
        else if (map[i] >= 0) rhs[map[i]] -= v * g[j];
        else if (map[j] >= 0) rhs[map[j]] -= v * g[i];
    }
    A = amps_csc_from_triplets(ctx, nf, R.nz, R.i, R.j, R.x, AMPS_UPPER);
    res = -1;
    if (A && (nf == 0 || ref_solve(nf, A->p, A->i, A->x, NULL, 0, rhs, xf) == 0)) {
        double *y = (double *)calloc(nf + 1, sizeof(double));
        if (nf) amps_csc_symv(A, AMPS_UPPER, xf, y);
        for (k = 0; k < nf; k++) {
            num += (y[k] - rhs[k]) * (y[k] - rhs[k]);
            den += rhs[k] * rhs[k];
        }
        res = den > 0 ? sqrt(num / den) : sqrt(num);
        free(y);
        for (k = 0; k < N; k++) x[k] = map[k] >= 0 ? xf[map[k]] : g[k];
    }
    (void)c;
    amps_csc_free(ctx, A);
    trip_free(&R);
    free(map);
    free(rhs);
    free(xf);
    return res;
}

/* Relative residual of the reduced system for x, from the explicit triplets. */
static double explicit_residual(const trip *T, int N, const int *con, const double *g, const double *f,
                                const double *x) {
    double *y = (double *)calloc(N, sizeof(double)), *kg = (double *)calloc(N, sizeof(double)), num = 0, den = 0;
    int k;
    for (k = 0; k < T->nz; k++) {
        int i = T->i[k], j = T->j[k];
        double v = T->x[k];
        y[i] += v * x[j];
        if (i != j) y[j] += v * x[i];
        if (con[j]) kg[i] += v * g[j];
        if (i != j && con[i]) kg[j] += v * g[i];
    }
    for (k = 0; k < N; k++)
        if (!con[k]) {
            num += (y[k] - f[k]) * (y[k] - f[k]);
            den += (f[k] - kg[k]) * (f[k] - kg[k]);
        }
    free(y);
    free(kg);
    return den > 0 ? sqrt(num / den) : sqrt(num);
}

/* Reaction (K x - f)_i from the explicit triplets. */
static double explicit_reaction(const trip *T, const double *x, const double *f, int i0) {
    double s = -f[i0];
    int k;
    for (k = 0; k < T->nz; k++) {
        if (T->i[k] == i0) s += T->x[k] * x[T->j[k]];
        else if (T->j[k] == i0) s += T->x[k] * x[T->i[k]];
    }
    return s;
}

/* ---- the state a test keeps beside the engine ---- */
typedef struct model {
    amps_ctx ctx;
    amps_update *U;
    amps_factor *F;
    amps_csc *K;
    trip T;
    int N, cap;
    int *con;
    double *g, *f;
    double worst_err, worst_res, worst_ref;
    int steps, fails;
    int bgmode; /* 1: start, wait for and cancel re-factorizations at random steps */
    unsigned long long bgrng;
    int extra;     /* 1: also check the reactions-only and watched solves; 2: and the
                                   L entries the watched solve reads (engine made with refine = 0) */
    double res_ok; /* a residual at most this passes too (the guard's tolerance) */
    int kept[3];   /* bgmode 2: swaps by refactor_order_kept (fresh, order kept, analysis kept) */
    int reused;    /* bgmode 2: swaps whose factor took the retired base's storage for L */
    int nref_seen; /* bgmode 2: swaps counted in kept */
    int origins;   /* cut_sequence: 1 declares each copy's DOFs copies of the node's (amps_update_set_origin) */
} model;

static void model_grow(model *m, int N) {
    if (N > m->cap) {
        int c = N * 2;
        m->con = (int *)realloc(m->con, sizeof(int) * c);
        m->g = (double *)realloc(m->g, sizeof(double) * c);
        m->f = (double *)realloc(m->f, sizeof(double) * c);
        memset(m->con + m->cap, 0, sizeof(int) * (c - m->cap));
        memset(m->g + m->cap, 0, sizeof(double) * (c - m->cap));
        memset(m->f + m->cap, 0, sizeof(double) * (c - m->cap));
        m->cap = c;
    }
    m->N = N;
}

static int model_init(model *m, int n, int nz, const int *ti, const int *tj, const double *tx,
                      const amps_update_opts *o) {
    int k;
    memset(m, 0, sizeof(*m));
    amps_ctx_init(&m->ctx);
    m->K = amps_csc_from_triplets(&m->ctx, n, nz, ti, tj, tx, AMPS_UPPER);
    if (!m->K) return 1;
    m->F = amps_analyze(&m->ctx, m->K, AMPS_UPPER, NULL);
    if (!m->F || amps_factorize(&m->ctx, m->F, m->K)) return 1;
    m->U = amps_update_create(&m->ctx, m->K, AMPS_UPPER, m->F, o);
    if (!m->U) return 1;
    for (k = 0; k < nz; k++) trip_add(&m->T, ti[k], tj[k], tx[k]);
    model_grow(m, n);
    return 0;
}

static void model_free(model *m) {
    amps_update_free(&m->ctx, m->U);
    amps_factor_free(&m->ctx, m->F);
    amps_csc_free(&m->ctx, m->K);
    trip_free(&m->T);
    free(m->con);
    free(m->g);
    free(m->f);
}

/* Before the full solve: reactions from the dense system alone (into r1) and a watched solve
   of up to 12 indices (into wi, xw; returns their count); with extra == 2 the L entries it
   reads are at most those of the columns in closure_L(watched). */
static int model_partial(model *m, double *r1, amps_int *wi, double *xw, const char *what) {
    int N = m->N, k, nw = 0;
    unsigned long long h = (unsigned long long)m->steps * 6364136223846793005ULL + 1442695040888963407ULL;
    amps_status s = amps_update_solve_reactions(&m->ctx, m->U);
    CHECK(s == AMPS_OK, "%s step %d: reactions-only solve: %s", what, m->steps, m->ctx.msg);
    for (k = 0; k < N; k++) r1[k] = m->con[k] ? amps_update_reaction(m->U, k) : 0.0;
    for (k = 0; k < 12; k++) {
        int i, t, dup = 0;
        h = h * 6364136223846793005ULL + 1442695040888963407ULL;
        i = (int)((h >> 33) % (unsigned long long)N);
        for (t = 0; t < nw; t++) dup |= wi[t] == i;
        if (!dup) wi[nw++] = i;
    }
    CHECK(amps_update_watch(&m->ctx, m->U, nw, wi) == AMPS_OK, "%s: watch: %s", what, m->ctx.msg);
    amps_touch_reset(m->F);
    s = amps_update_solve_watched(&m->ctx, m->U, xw);
    CHECK(s == AMPS_OK, "%s step %d: watched solve: %s", what, m->steps, m->ctx.msg);
    if (m->extra == 2) {
        amps_marker mk;
        amps_int *req = (amps_int *)malloc(sizeof(amps_int) * (m->F->n + 1));
        amps_int *clo = (amps_int *)malloc(sizeof(amps_int) * (m->F->n + 1)), nb = 0, ncl;
        double bound = 0;
        amps_marker_init(&m->ctx, &mk, m->F->n);
        for (k = 0; k < nw; k++)
            if (wi[k] < m->F->n) req[nb++] = m->F->iperm[wi[k]];
        ncl = amps_closure(m->F, nb, req, clo, &mk);
        for (k = 0; k < ncl; k++) bound += (double)(m->F->Lp[clo[k] + 1] - m->F->Lp[clo[k]]);
        CHECK(amps_touch_count(m->F) <= bound, "%s step %d: watched solve read %.0f entries of L, closure has %.0f",
              what, m->steps, amps_touch_count(m->F), bound);
        amps_marker_free(&m->ctx, &mk);
        free(req);
        free(clo);
    }
    { /* the two-phase job gives the same values */
        amps_update_job job;
        double *y = (double *)malloc(sizeof(double) * (amps_update_dim(m->U) + 1)), xj[12];
        CHECK(amps_update_set_force(&m->ctx, m->U, 0, NULL, NULL) == AMPS_OK, "empty force change");
        CHECK(amps_update_watched_begin(&m->ctx, m->U, &job, y, 0, xj) == AMPS_ERR_CAPACITY ||
                      amps_update_base_order(m->U) == 0,
              "short y accepted");
        s = amps_update_watched_begin(&m->ctx, m->U, &job, y, amps_update_dim(m->U), xj);
        CHECK(s == AMPS_OK, "%s step %d: job begin: %s", what, m->steps, m->ctx.msg);
        CHECK(amps_update_watch(&m->ctx, m->U, nw, wi) == AMPS_ERR_STATE, "watch set changed during a job");
        amps_update_watched_run(&job);
        amps_update_watched_end(m->U, &job);
        /* equal up to rounding (a re-factorization may have been swapped in by the job's commit) */
        for (k = 0; k < nw; k++)
            CHECK(fabs(xj[k] - xw[k]) <= 1e-12 * (t_norm(nw, xw) + 1e-300), "%s step %d: job x[%d] = %.17e vs %.17e",
                  what, m->steps, (int)wi[k], xj[k], xw[k]);
        free(y);
    }
    return nw;
}

/* Solves with the engine and compares with CHOLMOD; tolerance on the relative error. */
static void model_check(model *m, double tol_err, const char *what) {
    int N = m->N, k, nw = 0;
    double *x = (double *)malloc(sizeof(double) * N), *xr = (double *)malloc(sizeof(double) * N), err, res, rref, eres;
    double *r1 = (double *)malloc(sizeof(double) * N), xw[12];
    amps_int wi[12];
    amps_status s;
    if (m->bgmode) {
        int r;
        m->bgrng = m->bgrng * 6364136223846793005ULL + 1442695040888963407ULL;
        r = (int)((m->bgrng >> 33) % 20);
        if (r < 3) {
            s = amps_update_refactor_start(&m->ctx, m->U);
            CHECK(s == AMPS_OK || s == AMPS_WARN_NOOP, "%s: refactor start: %s", what, m->ctx.msg);
        } else if (r < 5) {
            s = amps_update_refactor_wait(&m->ctx, m->U);
            CHECK(s == AMPS_OK || s == AMPS_WARN_NOOP, "%s: refactor wait: %s", what, m->ctx.msg);
        } else if (r == 5) amps_update_refactor_cancel(&m->ctx, m->U);
        else if (r == 6) {
            s = amps_update_refactor(&m->ctx, m->U);
            CHECK(s == AMPS_OK, "%s: synchronous refactor: %s", what, m->ctx.msg);
        }
    }
    if (m->bgmode == 2) { /* started every 5 steps, swapped in 3 steps later (or by a commit before) */
        amps_update_stats st;
        if (m->steps % 5 == 0) {
            s = amps_update_refactor_start(&m->ctx, m->U);
            CHECK(s == AMPS_OK || s == AMPS_WARN_NOOP, "%s: refactor start: %s", what, m->ctx.msg);
        }
        if (m->steps % 5 == 3) {
            s = amps_update_refactor_wait(&m->ctx, m->U);
            CHECK(s == AMPS_OK || s == AMPS_WARN_NOOP, "%s: refactor wait: %s", what, m->ctx.msg);
        }
        amps_update_get_stats(m->U, &st);
        if ((int)st.nrefactor > m->nref_seen) { /* the last swap since the previous step */
            m->nref_seen = (int)st.nrefactor;
            if (st.refactor_order_kept >= 0 && st.refactor_order_kept <= 2) m->kept[st.refactor_order_kept]++;
            m->reused += st.refactor_reused;
            CHECK(st.refactor_order_kept != 1 || st.refactor_fill <= t_fill_bound * (1 + 1e-12),
                  "%s: kept ordering with fill x%.3f", what, st.refactor_fill);
        }
    }
    if (m->extra) nw = model_partial(m, r1, wi, xw, what);
    s = amps_update_solve(&m->ctx, m->U, x);
    m->steps++;
    CHECK(s == AMPS_OK, "%s step %d: solve failed: %s", what, m->steps, m->ctx.msg);
    if (s != AMPS_OK) {
        free(x);
        free(xr);
        free(r1);
        m->fails++;
        return;
    }
    CHECK(amps_update_dim(m->U) == N, "%s: dim %d vs %d", what, (int)amps_update_dim(m->U), N);
    rref = ref_constrained(&m->ctx, &m->T, N, m->con, m->g, m->f, xr);
    CHECK(rref >= 0, "%s step %d: CHOLMOD failed", what, m->steps);
    err = t_reldiff(N, x, xr);
    res = explicit_residual(&m->T, N, m->con, m->g, m->f, x);
    if (amps_update_residual(&m->ctx, m->U, &eres) != AMPS_OK) eres = -1;
    if (err > m->worst_err) m->worst_err = err;
    if (res > m->worst_res) m->worst_res = res;
    if (rref > m->worst_ref) m->worst_ref = rref;
    CHECK(err <= tol_err, "%s step %d: relative error %.3e > %.1e", what, m->steps, err, tol_err);
    CHECK(res <= 10 * rref + 1e-14 || res <= m->res_ok, "%s step %d: residual %.3e vs CHOLMOD %.3e", what, m->steps,
          res, rref);
    /* two evaluations of a rounding-level residual agree to a factor, or both meet the bound */
    CHECK(fabs(eres - res) <= 0.5 * (eres > res ? eres : res) + 1e-14 || eres <= 10 * rref + 1e-14 || eres <= m->res_ok,
          "%s step %d: engine residual %.3e vs explicit %.3e", what, m->steps, eres, res);
    for (k = 0; k < N; k++)
        if (m->con[k]) {
            double re = explicit_reaction(&m->T, x, m->f, k), ra = amps_update_reaction(m->U, k);
            CHECK(fabs(re - ra) <= 1e-8 * (1 + fabs(re)), "%s step %d: reaction at %d: %.6e vs %.6e", what, m->steps, k,
                  ra, re);
            if (m->extra)
                CHECK(fabs(r1[k] - ra) <= 1e-8 * (1 + fabs(ra)),
                      "%s step %d: reaction at %d from the dense system %.6e vs full solve %.6e", what, m->steps, k,
                      r1[k], ra);
        }
    {
        double xn = t_norm(N, x);
        for (k = 0; k < nw; k++)
            CHECK(fabs(xw[k] - x[wi[k]]) <= 1e-10 * xn, "%s step %d: watched x[%d] = %.6e vs full %.6e", what, m->steps,
                  (int)wi[k], xw[k], x[wi[k]]);
    }
    free(x);
    free(xr);
    free(r1);
}

/* m->T and the engine get the same symmetric change alpha v v^T on idx[0..k-1]; via set_rows
   when use_rows (current rows from the explicit triplets plus the change). */
static void change_term(model *m, int k, const int *idx, const double *v, double alpha, int use_rows) {
    int a, b, nz = 0;
    int r[64], c[64];
    double x[64];
    for (a = 0; a < k; a++)
        for (b = a; b < k; b++) {
            r[nz] = idx[a];
            c[nz] = idx[b];
            x[nz] = alpha * v[a] * v[b];
            nz++;
            trip_add(&m->T, idx[a], idx[b], alpha * v[a] * v[b]);
        }
    if (!use_rows) {
        CHECK(amps_update_add(&m->ctx, m->U, nz, r, c, x) == AMPS_OK, "add: %s", m->ctx.msg);
    } else {
        /* full new rows: sum the explicit triplets of each row */
        int *cp = (int *)calloc(k + 1, sizeof(int)), *ci, t, q, cnt = 0;
        double *cx, *dense = (double *)calloc(m->N, sizeof(double));
        ci = (int *)malloc(sizeof(int) * k * m->N);
        cx = (double *)malloc(sizeof(double) * k * m->N);
        for (a = 0; a < k; a++) {
            int i0 = idx[a];
            memset(dense, 0, sizeof(double) * m->N);
            for (t = 0; t < m->T.nz; t++) {
                if (m->T.i[t] == i0) dense[m->T.j[t]] += m->T.x[t];
                else if (m->T.j[t] == i0) dense[m->T.i[t]] += m->T.x[t];
            }
            for (q = 0; q < m->N; q++)
                if (dense[q] != 0.0) {
                    ci[cnt] = q;
                    cx[cnt] = dense[q];
                    cnt++;
                }
            cp[a + 1] = cnt;
        }
        CHECK(amps_update_set_rows(&m->ctx, m->U, k, idx, cp, ci, cx) == AMPS_OK, "set_rows: %s", m->ctx.msg);
        free(cp);
        free(ci);
        free(cx);
        free(dense);
    }
}

/* Random sequence on model m: stiffness terms added and removed, new DOFs joined by springs,
   constraints added, moved and released, sparse force changes. */
static void random_sequence(model *m, int steps, unsigned long long seed, double tol, const char *what) {
    typedef struct term {
        int k;
        int idx[4];
        double v[4];
        double alpha;
    } term;
    term *terms = (term *)malloc(sizeof(term) * (steps + 1));
    int nterms = 0, st, scale_i;
    double scale = 0;
    t_seed(seed);
    for (scale_i = 0; scale_i < m->T.nz; scale_i++)
        if (m->T.i[scale_i] == m->T.j[scale_i]) scale += m->T.x[scale_i];
    scale /= m->N;
    for (st = 0; st < steps; st++) {
        int op = t_int(10), N = m->N;
        if (op <= 2) { /* add a stiffness term */
            term *t = terms + nterms++;
            int a;
            t->k = 2 + t_int(3);
            t->alpha = scale * (0.1 + t_unif());
            for (a = 0; a < t->k; a++) {
                int dup, b;
                do {
                    t->idx[a] = t_int(N);
                    dup = 0;
                    for (b = 0; b < a; b++) dup |= t->idx[b] == t->idx[a];
                } while (dup);
                t->v[a] = t_unif() - 0.5;
            }
            change_term(m, t->k, t->idx, t->v, t->alpha, t_int(3) == 0);
        } else if (op == 3 && nterms > 0) { /* remove one */
            int which = t_int(nterms);
            term t = terms[which];
            terms[which] = terms[--nterms];
            change_term(m, t.k, t.idx, t.v, -t.alpha, t_int(3) == 0);
        } else if (op == 4) { /* a new DOF hung on a spring */
            amps_int first;
            int i0 = t_int(N), idx[2];
            double v[2] = {1, -1};
            CHECK(amps_update_add_dofs(&m->ctx, m->U, 1, &first) == AMPS_OK, "add_dofs: %s", m->ctx.msg);
            CHECK(first == N, "new DOF index %d vs %d", (int)first, N);
            model_grow(m, N + 1);
            idx[0] = i0;
            idx[1] = N;
            change_term(m, 2, idx, v, scale * (0.5 + t_unif()), 0);
            if (t_int(2)) {
                double fv = t_unif() - 0.5;
                amps_int ii = N;
                m->f[N] = fv;
                amps_update_set_force(&m->ctx, m->U, 1, &ii, &fv);
            }
        } else if (op == 5) { /* constrain or move */
            amps_int i0 = t_int(N);
            double v = 0.1 * (t_unif() - 0.5);
            m->con[i0] = 1;
            m->g[i0] = v;
            CHECK(amps_update_constrain(&m->ctx, m->U, 1, &i0, &v) == AMPS_OK, "constrain: %s", m->ctx.msg);
        } else if (op == 6) { /* release a constrained index */
            amps_int i0, tries = 0;
            do { i0 = t_int(N); } while (!m->con[i0] && ++tries < 50);
            m->con[i0] = 0;
            m->g[i0] = 0;
            CHECK(amps_update_release(&m->ctx, m->U, 1, &i0) == AMPS_OK, "release: %s", m->ctx.msg);
        } else { /* sparse force change */
            int nf = 1 + t_int(4), a;
            amps_int idx[5];
            double v[5];
            for (a = 0; a < nf; a++) {
                int dup, b;
                do {
                    idx[a] = t_int(N);
                    dup = 0;
                    for (b = 0; b < a; b++) dup |= idx[b] == idx[a];
                } while (dup);
                v[a] = t_unif() - 0.5;
                m->f[idx[a]] = v[a];
            }
            CHECK(amps_update_set_force(&m->ctx, m->U, nf, idx, v) == AMPS_OK, "force: %s", m->ctx.msg);
        }
        if (t_int(4) != 0 || st == steps - 1) model_check(m, tol, what);
    }
    free(terms);
}

static void random_spd(int n, unsigned long long seed, int *nz, int **ti, int **tj, double **tx) {
    int k, cap = n * 13 + 8, c = 0;
    t_seed(seed);
    *ti = (int *)malloc(sizeof(int) * cap);
    *tj = (int *)malloc(sizeof(int) * cap);
    *tx = (double *)malloc(sizeof(double) * cap);
    for (k = 0; k < n; k++) {
        (*ti)[c] = k;
        (*tj)[c] = k;
        (*tx)[c] = 4.0 + t_unif();
        c++;
    }
    for (k = 0; k < 4 * n; k++) {
        int i = t_int(n), j = t_int(n);
        double v = 0.4 * (t_unif() - 0.5);
        if (i == j) continue;
        (*ti)[c] = i < j ? i : j;
        (*tj)[c] = i < j ? j : i;
        (*tx)[c] = v;
        c++;
        (*ti)[c] = i;
        (*tj)[c] = i;
        (*tx)[c] = fabs(v);
        c++;
        (*ti)[c] = j;
        (*tj)[c] = j;
        (*tx)[c] = fabs(v);
        c++;
    }
    *nz = c;
}

static void fe_model(model *m, fe_mesh *mesh, int fixed_axis_end, const amps_update_opts *o) {
    int *fixed = (int *)calloc(mesh->nn, sizeof(int)), *dof = (int *)malloc(sizeof(int) * 3 * mesh->nn), v, n, nz;
    int *ti, *tj;
    double *tx;
    (void)fixed_axis_end;
    for (v = 0; v < mesh->nn; v++) fixed[v] = mesh->xyz[3 * v + 2] < 1e-9;
    n = fe_number(mesh, fixed, dof);
    nz = fe_assemble(mesh, dof, 1000.0, 0.3, &ti, &tj, &tx);
    CHECK(model_init(m, n, nz, ti, tj, tx, o) == 0, "fe model init: %s", m->ctx.msg);
    free(fixed);
    free(dof);
    free(ti);
    free(tj);
    free(tx);
}

/* ---- node-duplicating cuts on an FE mesh, reference assembled from scratch ---- */
typedef struct cutmesh {
    fe_mesh m;
    int *dof;
    int nn, cap;
} cutmesh;

static void cut_sequence(model *md, fe_mesh *mesh0, int steps, unsigned long long seed, double tol) {
    cutmesh cm;
    int v, st, ncut = 0;
    double E = 1000.0, nu = 0.3;
    t_seed(seed);
    cm.cap = mesh0->nn + steps + 1;
    cm.m.nn = mesh0->nn;
    cm.m.nt = mesh0->nt;
    cm.m.xyz = (double *)malloc(sizeof(double) * 3 * cm.cap);
    memcpy(cm.m.xyz, mesh0->xyz, sizeof(double) * 3 * mesh0->nn);
    cm.m.tet = (int *)malloc(sizeof(int) * 4 * mesh0->nt);
    memcpy(cm.m.tet, mesh0->tet, sizeof(int) * 4 * mesh0->nt);
    cm.dof = (int *)malloc(sizeof(int) * 3 * cm.cap);
    {
        int *fixed = (int *)calloc(mesh0->nn, sizeof(int));
        for (v = 0; v < mesh0->nn; v++) fixed[v] = mesh0->xyz[3 * v + 2] < 1e-9;
        fe_number(mesh0, fixed, cm.dof);
        free(fixed);
    }
    /* pull the free end apart so cuts open */
    for (v = 0; v < mesh0->nn; v++)
        if (cm.dof[3 * v] >= 0 && mesh0->xyz[3 * v + 2] > 0) {
            amps_int i = cm.dof[3 * v];
            double fx = mesh0->xyz[3 * v] < 2 ? -1.0 : 1.0;
            if (t_int(4) == 0) {
                md->f[i] = fx;
                amps_update_set_force(&md->ctx, md->U, 1, &i, &fx);
            }
        }
    for (st = 0; st < steps; st++) {
        int t, a, b, nmoved = 0, vnew = cm.m.nn, *moved = (int *)malloc(sizeof(int) * cm.m.nt);
        double p[3], nrm[3], X[12], Ke[144];
        int nzd = 0, capd = 144 * 64;
        int *ri = (int *)malloc(sizeof(int) * capd), *ci = (int *)malloc(sizeof(int) * capd);
        double *vx = (double *)malloc(sizeof(double) * capd);
        v = t_int(mesh0->nn);
        if (cm.dof[3 * v] < 0) {
            free(moved);
            free(ri);
            free(ci);
            free(vx);
            continue;
        }
        for (a = 0; a < 3; a++) {
            p[a] = cm.m.xyz[3 * v + a];
            nrm[a] = t_unif() - 0.5;
        }
        for (t = 0; t < cm.m.nt; t++) {
            int has = 0;
            double c[3] = {0, 0, 0}, s = 0;
            for (a = 0; a < 4; a++) {
                has |= cm.m.tet[4 * t + a] == v;
                for (b = 0; b < 3; b++) c[b] += 0.25 * cm.m.xyz[3 * cm.m.tet[4 * t + a] + b];
            }
            if (!has) continue;
            for (b = 0; b < 3; b++) s += (c[b] - p[b]) * nrm[b];
            if (s < 0) moved[nmoved++] = t;
        }
        { /* no-op unless both sides keep a tet */
            int deg = 0;
            for (t = 0; t < cm.m.nt; t++)
                for (a = 0; a < 4; a++) deg += cm.m.tet[4 * t + a] == v;
            if (nmoved == 0 || nmoved == deg) {
                free(moved);
                free(ri);
                free(ci);
                free(vx);
                continue;
            }
        }
        { /* new node v' with 3 new DOFs */
            amps_int first;
            CHECK(amps_update_add_dofs(&md->ctx, md->U, 3, &first) == AMPS_OK, "cut add_dofs: %s", md->ctx.msg);
            model_grow(md, md->N + 3);
            for (b = 0; b < 3; b++) {
                cm.m.xyz[3 * vnew + b] = cm.m.xyz[3 * v + b];
                cm.dof[3 * vnew + b] = (int)first + b;
            }
            cm.m.nn++;
            if (md->origins) {
                amps_int id[3], og[3];
                for (b = 0; b < 3; b++) {
                    id[b] = first + b;
                    og[b] = cm.dof[3 * v + b];
                }
                CHECK(amps_update_set_origin(&md->ctx, md->U, 3, id, og) == AMPS_OK, "set_origin: %s", md->ctx.msg);
            }
        }
        /* delta = sum over moved tets of Ke(new numbering) - Ke(old numbering) */
        for (t = 0; t < nmoved; t++) {
            int e = moved[t], pass;
            for (a = 0; a < 4; a++)
                for (b = 0; b < 3; b++) X[3 * a + b] = cm.m.xyz[3 * cm.m.tet[4 * e + a] + b];
            fe_tet_K(X, E, nu, Ke);
            for (pass = 0; pass < 2; pass++) {
                double sg = pass == 0 ? -1.0 : 1.0;
                if (pass == 1)
                    for (a = 0; a < 4; a++)
                        if (cm.m.tet[4 * e + a] == v) cm.m.tet[4 * e + a] = vnew;
                for (a = 0; a < 12; a++)
                    for (b = 0; b < 12; b++) {
                        int r = cm.dof[3 * cm.m.tet[4 * e + a / 3] + a % 3],
                            c = cm.dof[3 * cm.m.tet[4 * e + b / 3] + b % 3], q, found = 0;
                        if (r < 0 || c < 0 || r > c) continue;
                        for (q = 0; q < nzd; q++)
                            if (ri[q] == r && ci[q] == c) {
                                vx[q] += sg * Ke[12 * a + b];
                                found = 1;
                                break;
                            }
                        if (!found) {
                            ri[nzd] = r;
                            ci[nzd] = c;
                            vx[nzd] = sg * Ke[12 * a + b];
                            nzd++;
                        }
                    }
            }
        }
        CHECK(amps_update_add(&md->ctx, md->U, nzd, ri, ci, vx) == AMPS_OK, "cut add: %s", md->ctx.msg);
        /* reference matrix: reassemble the cut mesh from scratch */
        {
            int *ti, *tj, nz, k;
            double *tx;
            nz = fe_assemble(&cm.m, cm.dof, E, nu, &ti, &tj, &tx);
            trip_free(&md->T);
            for (k = 0; k < nz; k++) trip_add(&md->T, ti[k], tj[k], tx[k]);
            free(ti);
            free(tj);
            free(tx);
        }
        ncut++;
        if (t_int(3) == 0) { /* pin a node (maybe the new copy) */
            amps_int i0 = cm.dof[3 * (t_int(2) ? vnew : v) + t_int(3)];
            double gv = 0.01 * (t_unif() - 0.5);
            md->con[i0] = 1;
            md->g[i0] = gv;
            CHECK(amps_update_constrain(&md->ctx, md->U, 1, &i0, &gv) == AMPS_OK, "pin: %s", md->ctx.msg);
        }
        model_check(md, tol, "fe cut");
        free(moved);
        free(ri);
        free(ci);
        free(vx);
    }
    CHECK(ncut > steps / 4, "only %d of %d cuts happened", ncut, steps);
    free(cm.m.xyz);
    free(cm.m.tet);
    free(cm.dof);
}

static void report(const char *what, const model *m) {
    amps_update_stats st;
    amps_update_get_stats(m->U, &st);
    printf("  %-28s steps %4d  worst error %.2e  worst residual %.2e (CHOLMOD %.2e)  re-factorizations %d\n", what,
           m->steps, m->worst_err, m->worst_res, m->worst_ref, (int)st.nrefactor);
}

static void test_random_sequences(void) {
    int seed;
    for (seed = 1; seed <= 4; seed++) {
        model m;
        amps_update_opts o;
        int nz, *ti, *tj;
        double *tx;
        const char *what = seed == 3   ? "random spd (dual)"
                           : seed == 4 ? "random spd (refine 0, touch counts)"
                                       : "random spd";
        amps_update_opts_default(&o);
        o.grow = 1;
        o.cap_mod = 8;
        o.cap_new = 4;
        o.cap_pending = 8;
        o.formulation = seed == 3 ? AMPS_FORM_DUAL : AMPS_FORM_PRIMAL;
        if (seed == 4) o.refine = 0;
        random_spd(60 + 40 * seed, 100 + seed, &nz, &ti, &tj, &tx);
        CHECK(model_init(&m, 60 + 40 * seed, nz, ti, tj, tx, &o) == 0, "init: %s", m.ctx.msg);
        m.extra = seed == 4 ? 2 : 1;
        random_sequence(&m, 220, 1000 + seed, 1e-10, what);
        report(what, &m);
        model_free(&m);
        free(ti);
        free(tj);
        free(tx);
    }
}

static void test_fe_sequences(void) {
    int kind;
    for (kind = 0; kind < 2; kind++) {
        model m;
        amps_update_opts o;
        fe_mesh mesh = kind == 0 ? fe_beam(6) : fe_brick(3);
        amps_update_opts_default(&o);
        o.grow = 1;
        fe_model(&m, &mesh, 2, &o);
        random_sequence(&m, 200, 77 + kind, 1e-9, kind == 0 ? "beam 5x5x6 random" : "brick R=3 random");
        report(kind == 0 ? "beam 5x5x6 random" : "brick R=3 random", &m);
        model_free(&m);
        fe_free(&mesh);
    }
    for (kind = 0; kind < 3; kind++) {
        model m;
        amps_update_opts o;
        fe_mesh mesh = kind == 1 ? fe_brick(3) : fe_beam(8);
        amps_update_opts_default(&o);
        o.grow = 1;
        o.formulation = kind == 2 ? AMPS_FORM_DUAL : AMPS_FORM_PRIMAL;
        fe_model(&m, &mesh, 2, &o);
        m.extra = 1;
        cut_sequence(&m, &mesh, 60, 5 + kind, 1e-9);
        report(kind == 0 ? "beam 5x5x8 cuts" : kind == 1 ? "brick R=3 cuts" : "beam 5x5x8 cuts (dual)", &m);
        model_free(&m);
        fe_free(&mesh);
    }
}

/* A change that leaves K^ singular up to a relative 3e-14 (K^ + delta e_i e_i^T with
   1 + delta (K^-1)_ii = 3e-14: the dense system's pivot at the rounding level of a larger
   system) is not committed through the augmentation: the pivot test sends it to a
   re-factorization of K^ (stats.pivot_folds), whose own pivot test decides. A change 1e-6 from
   singular is committed through the augmentation. */
static void test_near_singular(void) {
    int k, trial;
    for (trial = 0; trial < 2; trial++) {
        model m;
        amps_update_opts o;
        amps_update_stats st;
        int nz, *ti, *tj;
        double *tx, e[40], x[40], delta;
        amps_int i = 7;
        amps_status s;
        amps_update_opts_default(&o);
        o.grow = 1;
        random_spd(40, 9, &nz, &ti, &tj, &tx);
        CHECK(model_init(&m, 40, nz, ti, tj, tx, &o) == 0, "near singular: init: %s", m.ctx.msg);
        for (k = 0; k < 40; k++) e[k] = k == i;
        CHECK(amps_update_solve_rhs(&m.ctx, m.U, e, x) == AMPS_OK, "near singular: solve: %s", m.ctx.msg);
        delta = -(1.0 - (trial ? 1e-6 : 3e-14)) / x[i];
        s = amps_update_add(&m.ctx, m.U, 1, &i, &i, &delta);
        if (s == AMPS_OK) s = amps_update_commit(&m.ctx, m.U);
        amps_update_get_stats(m.U, &st);
        if (trial == 0)
            CHECK((s == AMPS_OK || s == AMPS_ERR_SINGULAR_UPDATE) && st.pivot_folds == 1,
                  "a change singular to 3e-14: status %d, %ld re-factorizations", (int)s, (long)st.pivot_folds);
        else
            CHECK(s == AMPS_OK && st.pivot_folds == 0, "a change 1e-6 from singular: %s, %ld re-factorizations",
                  m.ctx.msg, (long)st.pivot_folds);
        model_free(&m);
        free(ti);
        free(tj);
        free(tx);
    }
}

/* Bad input and a singular update: each fails cleanly, the solution stays, a valid update works. */
static void test_errors(void) {
    model m;
    amps_update_opts o;
    int nz, *ti, *tj;
    double *tx, *x0, *x1;
    amps_int idx[2], first;
    double val[2];
    int N;
    amps_update_opts_default(&o);
    o.grow = 1;
    random_spd(40, 9, &nz, &ti, &tj, &tx);
    CHECK(model_init(&m, 40, nz, ti, tj, tx, &o) == 0, "init: %s", m.ctx.msg);
    N = 40;
    x0 = (double *)malloc(sizeof(double) * 64);
    x1 = (double *)malloc(sizeof(double) * 64);
    idx[0] = 3;
    val[0] = 1.0;
    m.f[3] = 1.0;
    amps_update_set_force(&m.ctx, m.U, 1, idx, val);
    model_check(&m, 1e-10, "errors");
    amps_update_solve(&m.ctx, m.U, x0);
    idx[0] = 40;
    CHECK(amps_update_constrain(&m.ctx, m.U, 1, idx, val) == AMPS_ERR_INDEX, "index out of range accepted");
    idx[0] = -1;
    CHECK(amps_update_set_force(&m.ctx, m.U, 1, idx, val) == AMPS_ERR_INDEX, "negative index accepted");
    idx[0] = 2;
    idx[1] = 2;
    val[1] = 0;
    CHECK(amps_update_constrain(&m.ctx, m.U, 2, idx, val) == AMPS_ERR_ARG, "duplicate index accepted");
    val[0] = NAN;
    CHECK(amps_update_set_force(&m.ctx, m.U, 1, idx, val) == AMPS_ERR_VALUE, "NaN accepted");
    val[0] = INFINITY;
    CHECK(amps_update_constrain(&m.ctx, m.U, 1, idx, val) == AMPS_ERR_VALUE, "Inf accepted");
    {
        amps_int r[2] = {1, 2}, c[2] = {2, 1};
        double v[2] = {0.1, 0.1};
        CHECK(amps_update_add(&m.ctx, m.U, 2, r, c, v) == AMPS_ERR_ARG, "duplicate pair accepted");
        v[0] = NAN;
        CHECK(amps_update_add(&m.ctx, m.U, 1, r, c, v) == AMPS_ERR_VALUE, "NaN change accepted");
        r[0] = 99;
        v[0] = 1;
        CHECK(amps_update_add(&m.ctx, m.U, 1, r, c, v) == AMPS_ERR_INDEX, "bad change index accepted");
    }
    CHECK(amps_update_add_dofs(&m.ctx, m.U, -1, &first) == AMPS_ERR_ARG, "negative DOF count accepted");
    amps_update_solve(&m.ctx, m.U, x1);
    CHECK(t_reldiff(N, x1, x0) == 0.0, "rejected calls changed the solution");
    /* singular: a new DOF with no stiffness */
    CHECK(amps_update_add_dofs(&m.ctx, m.U, 1, &first) == AMPS_OK, "add_dofs");
    CHECK(amps_update_solve(&m.ctx, m.U, x1) == AMPS_ERR_SINGULAR_UPDATE, "zero row not detected: %s", m.ctx.msg);
    CHECK(amps_update_dim(m.U) == N, "dimension not restored");
    amps_update_solve(&m.ctx, m.U, x1);
    CHECK(t_reldiff(N, x1, x0) < 1e-14, "singular update changed the solution");
    /* singular: remove all stiffness of a base index (set its row to zero) */
    {
        amps_int r0 = 5, cp[2] = {0, 0}, ci[1] = {0};
        double cx[1] = {0};
        CHECK(amps_update_set_rows(&m.ctx, m.U, 1, &r0, cp, ci, cx) == AMPS_OK, "set_rows zero");
        CHECK(amps_update_commit(&m.ctx, m.U) == AMPS_ERR_SINGULAR_UPDATE, "zeroed row not detected");
    }
    amps_update_solve(&m.ctx, m.U, x1);
    CHECK(t_reldiff(N, x1, x0) < 1e-14, "state changed after singular update");
    /* a valid update afterwards */
    {
        int idx2[2] = {4, 7};
        double v[2] = {1, -1};
        change_term(&m, 2, idx2, v, 2.0, 0);
    }
    model_check(&m, 1e-10, "after errors");
    /* capacity without growth */
    {
        model m2;
        amps_update_opts o2;
        amps_update_opts_default(&o2);
        o2.grow = 0;
        o2.cap_mod = 2;
        o2.cap_new = 0;
        CHECK(model_init(&m2, 40, nz, ti, tj, tx, &o2) == 0, "init2");
        CHECK(amps_update_add_dofs(&m2.ctx, m2.U, 1, &first) == AMPS_ERR_CAPACITY, "cap_new not enforced");
        {
            int idx2[3] = {4, 7, 9};
            double v[3] = {1, -1, 1};
            change_term(&m2, 3, idx2, v, 2.0, 0);
        }
        CHECK(amps_update_commit(&m2.ctx, m2.U) == AMPS_ERR_CAPACITY, "cap_mod not enforced: %s", m2.ctx.msg);
        { /* the failed commit restored the system and discarded the recorded changes */
            amps_update_stats st2;
            amps_update_get_stats(m2.U, &st2);
            CHECK(st2.nsys == 0 && st2.ncommit == 0 && amps_update_dim(m2.U) == 40, "failed commit changed the system");
            CHECK(amps_update_commit(&m2.ctx, m2.U) == AMPS_OK, "failed commit kept its changes: %s", m2.ctx.msg);
        }
        trip_free(&m2.T);
        {
            int k;
            for (k = 0; k < nz; k++) trip_add(&m2.T, ti[k], tj[k], tx[k]);
        }
        model_check(&m2, 1e-10, "after capacity error");
        model_free(&m2);
    }
    model_free(&m);
    free(ti);
    free(tj);
    free(tx);
    free(x0);
    free(x1);
}

/* The accuracy guard on an elongated, badly conditioned beam: residuals stay within 10x of
   CHOLMOD's or within the guard's tolerance, which is the guard's contract (checked by
   model_check; without threads no AUTO re-factorization keeps the residual at CHOLMOD's level),
   and the guard reports the residual it reached. */
static void test_guard(void) {
    model m;
    amps_update_opts o;
    fe_mesh mesh = fe_beam(96);
    amps_update_stats st;
    double res;
    amps_update_opts_default(&o);
    o.grow = 1;
    o.guard_tol = 1e-8;
    fe_model(&m, &mesh, 2, &o);
    m.res_ok = o.guard_tol;
    cut_sequence(&m, &mesh, 40, 17, 1e-7);
    amps_update_get_stats(m.U, &st);
    amps_update_residual(&m.ctx, m.U, &res);
    CHECK(st.relres >= 0 && fabs(st.relres - res) <= 0.5 * res + 1e-12, "guard residual %.3e vs %.3e", st.relres, res);
    CHECK(st.guard_result >= AMPS_GUARD_MET && st.guard_result <= AMPS_GUARD_REFACTORED && st.relres <= 1e-8,
          "guard: result %d, residual %.3e", (int)st.guard_result, st.relres);
    { /* an unreachable tolerance: refinement, a re-factorization, then the warning */
        amps_update *U = m.U;
        double *x = (double *)malloc(sizeof(double) * m.N);
        int idx = 0;
        double fv = 1.0;
        U->guard.tol = 1e-30;
        amps_update_set_force(&m.ctx, U, 1, &idx, &fv);
        CHECK(amps_update_solve(&m.ctx, U, x) == AMPS_WARN_INACCURATE, "unreachable guard tolerance not reported: %s",
              m.ctx.msg);
        amps_update_get_stats(U, &st);
        CHECK(st.guard_result == AMPS_GUARD_NOT_MET && st.nrefactor >= 1, "guard: result %d, re-factorizations %d",
              (int)st.guard_result, (int)st.nrefactor);
        U->guard.tol = 1e-8;
        free(x);
    }
    report("beam 5x5x96 cuts, guard", &m);
    model_free(&m);
    fe_free(&mesh);
}

/* The residual's paths on a model's current solution: the 3x3-block product (SSE2 or plain C)
   and the scalar one agree row by row within their rounding, |rho_j - rho'_j| <= 2 gamma_m
   (|K^||x| + |f^|)_j (m: the row's length + 1), so their mixed backward errors differ by at most
   2 gamma_m (largest m); the double-double residual of every row is f - K^ x
   rounded once (against __float128: within eps |rho_j| + 64 eps^2 (|K^||x|)_j); TwoProduct and
   TwoSum are exact. */
static void residual_paths(model *m) {
    amps_update *U = m->U;
    double r1 = -1, eps = 2.220446049250313e-16, rn, om1, om2, e1, e2;
    double *rb = (double *)malloc(sizeof(double) * (size_t)U->N);
    amps_int j, bad = 0, mmax = 0;
    CHECK(U->base.blk3 == 1, "a mesh's K is not seen as 3x3 blocks");
    CHECK(amps_update_residual(&m->ctx, U, &r1) == AMPS_OK, "residual: %s", m->ctx.msg);
    e1 = amps__backward_error(U, U->sol.x, U->work.resid, &rn, 0, &om1);
    memcpy(rb, U->work.resid, sizeof(double) * (size_t)U->N);
    U->base.blk3 = 0;
    e2 = amps__backward_error(U, U->sol.x, U->work.resid, &rn, 0, &om2);
    U->base.blk3 = 1;
    for (j = 0; j < U->N; j++) {
        amps_int len = j < U->n ? U->base.Kp[j + 1] - U->base.Kp[j] : 1, a = U->aug.pos[j];
        double ax, g, bound;
        if (a >= 0 && (U->aug.kind[a] & AMPS__UCON)) {
            if (rb[j] != 0 || U->work.resid[j] != 0) bad++;
            continue;
        }
        amps__resid_row(U, j, U->sol.x, 0, &ax);
        len += (a >= 0 ? U->delta.row_len[a] : 0) + 1;
        g = len * eps / (1 - len * eps);
        if (len > mmax) mmax = len;
        bound = 2 * g * (ax + fabs(U->force.f[j]));
        if (!(fabs(rb[j] - U->work.resid[j]) <= bound)) bad++;
    }
    CHECK(bad == 0, "blocked and scalar residuals: %ld rows differ beyond rounding", (long)bad);
    CHECK(fabs(om1 - om2) <= 2 * mmax * eps / (1 - mmax * eps) && e1 >= 0 && e2 >= 0,
          "backward errors blocked %.3e (omega %.3e), scalar %.3e (omega %.3e)", e1, om1, e2, om2);
    free(rb);
    bad = 0;
#ifdef __SIZEOF_FLOAT128__
    {
        __extension__ typedef __float128 quad;
        const double *x = U->sol.x;
        int k;
        t_seed(77);
        for (k = 0; k < 1000; k++) {
            double a = (t_unif() - 0.5) * pow(2.0, t_int(80) - 40), b = (t_unif() - 0.5) * pow(2.0, t_int(80) - 40), p,
                   e;
            amps__two_prod(a, b, &p, &e);
            if ((quad)p + (quad)e != (quad)a * (quad)b) bad++;
            amps__two_sum(a, b, &p, &e);
            if ((quad)p + (quad)e != (quad)a + (quad)b) bad++;
        }
        CHECK(bad == 0, "TwoProduct / TwoSum inexact %ld times", (long)bad);
        for (j = 0; j < U->N; j++) {
            amps_int a = U->aug.pos[j], p, q;
            quad r = U->force.f[j];
            double ax, rd = amps__resid_row(U, j, x, 1, &ax), rq;
            if (j < U->n)
                for (p = U->base.Kp[j]; p < U->base.Kp[j + 1]; p++) r -= (quad)U->base.Kx[p] * x[U->base.Ki[p]];
            else r -= (quad)U->sigma * x[j];
            for (q = 0; a >= 0 && q < U->delta.row_len[a]; q++)
                r -= (quad)U->delta.val[U->delta.row_start[a] + q] *
                     x[U->aug.idx[U->delta.col[U->delta.row_start[a] + q]]];
            rq = (double)r;
            if (!(fabs(rd - rq) <= eps * fabs(rq) + 64 * eps * eps * ax)) bad++;
        }
        CHECK(bad == 0, "double-double residual: %ld rows off", (long)bad);
    }
#endif
    (void)bad;
    (void)j;
}

/* The default accuracy (opts.refine_tol) on the same beam, no option set: every step's residual
   within 10x of CHOLMOD's (model_check), the backward error reported is the one reached (at most
   64 refine_tol: refinement stops when it stagnates), and with refine_tol = 0 nothing is
   measured or refined. */
/* A well-conditioned brick cut 40 times with the default options: solves whose Step 6 cancels
   little (stats.cancel_ratio <= 4) skip the product with K^, and every step still meets the
   residual contract against CHOLMOD (cut_sequence checks each one). */
static void test_check_skipped(void) {
    model m;
    amps_update_opts o;
    fe_mesh mesh = fe_brick(4);
    amps_update_stats st;
    amps_update_opts_default(&o);
    o.grow = 1;
    o.refactor = AMPS_REFACTOR_OFF;
    fe_model(&m, &mesh, 2, &o);
    cut_sequence(&m, &mesh, 40, 23, 1e-7);
    amps_update_get_stats(m.U, &st);
    CHECK(st.checks_skipped > 0 && st.checks_skipped <= st.nsolve, "brick: %d of %d solves skipped the check",
          (int)st.checks_skipped, (int)st.nsolve);
    CHECK(st.cancel_ratio >= 0, "brick: cancellation ratio %.3e after a full solve", st.cancel_ratio);
    CHECK(st.backward_error == -1 || st.cancel_ratio > 4, "brick: backward error %.3e with ratio %.3e",
          st.backward_error, st.cancel_ratio);
    printf("  brick R=4, 40 cuts: %d of %d solves skipped the check (last ratio %.2f)\n", (int)st.checks_skipped,
           (int)st.nsolve, st.cancel_ratio);
    report("brick R=4 cuts, default (check skipped where mu <= 4)", &m);
    model_free(&m);
    fe_free(&mesh);
}

static void test_default_accuracy(void) {
    int off;
    for (off = 0; off <= 1; off++) {
        model m;
        amps_update_opts o;
        fe_mesh mesh = fe_beam(96);
        amps_update_stats st;
        amps_update_opts_default(&o);
        CHECK(o.refine_tol > 0 && o.refine_tol <= 4.5e-16, "default refine_tol %.3e", o.refine_tol);
        o.grow = 1;
        o.refactor = AMPS_REFACTOR_OFF; /* the augmentation grows: the refinement is what keeps the contract */
        if (off) o.refine_tol = 0;
        fe_model(&m, &mesh, 2, &o);
        if (off) m.res_ok = 1e-6; /* no contract without the refinement */
        cut_sequence(&m, &mesh, 40, 17, 1e-7);
        amps_update_get_stats(m.U, &st);
        if (off)
            CHECK(st.backward_error == -1 && st.refine_solves == 0,
                  "refine_tol 0: backward error %.3e, %d refinement steps", st.backward_error, (int)st.refine_solves);
        else
            CHECK(st.backward_error >= 0 && st.backward_error <= 64 * o.refine_tol && st.relres == -1 &&
                          st.guard_result == AMPS_GUARD_MET,
                  "default: backward error %.3e, relres %.3e, guard result %d", st.backward_error, st.relres,
                  (int)st.guard_result);
        printf("  refine_tol %.1e: %d refinement steps over %d solves, last backward error %.2e\n", o.refine_tol,
               (int)st.refine_solves, (int)st.nsolve, st.backward_error);
        if (!off) residual_paths(&m);
        report(off ? "beam 5x5x96 cuts, refine_tol 0" : "beam 5x5x96 cuts, default", &m);
        model_free(&m);
        fe_free(&mesh);
    }
}

/* Re-factorizations started, awaited and cancelled at random steps of random and cut sequences
   (several in flight over a sequence, swaps between any kinds of change): every step agrees
   with CHOLMOD. Injected failures in each phase leave the engine on its old factors. */
static void test_refactor(void) {
    int seed, ph;
    for (seed = 1; seed <= 3; seed++) {
        model m;
        amps_update_opts o;
        int nz, *ti, *tj;
        double *tx;
        amps_update_stats st;
        const char *what = seed == 2 ? "refactor: random spd (dual)" : "refactor: random spd";
        amps_update_opts_default(&o);
        o.grow = 1;
        o.cap_mod = 8;
        o.cap_new = 4;
        o.cap_pending = 8;
        o.refactor = seed == 3 ? AMPS_REFACTOR_AUTO : AMPS_REFACTOR_MANUAL;
        o.formulation = seed == 2 ? AMPS_FORM_DUAL : AMPS_FORM_PRIMAL;
        random_spd(80, 300 + seed, &nz, &ti, &tj, &tx);
        CHECK(model_init(&m, 80, nz, ti, tj, tx, &o) == 0, "init: %s", m.ctx.msg);
        m.bgmode = 1;
        m.bgrng = (unsigned long long)seed;
        m.extra = 1;
        random_sequence(&m, 200, 2000 + seed, 1e-10, what);
        amps_update_get_stats(m.U, &st);
        CHECK(st.nrefactor >= 5, "%s: only %d re-factorizations swapped in", what, (int)st.nrefactor);
        report(what, &m);
        model_free(&m);
        free(ti);
        free(tj);
        free(tx);
    }
    for (ph = 0; ph < 2; ph++) {
        /* ph 1: node blocks given, so the new bases also drop the couplings cuts cancelled */
        model m;
        amps_update_opts o;
        fe_mesh mesh = fe_brick(3);
        amps_update_opts_default(&o);
        o.grow = 1;
        o.refactor = AMPS_REFACTOR_MANUAL;
        if (ph) {
            o.refactor_order.block = 3;
            o.refactor_order.method = AMPS_ORDER_AMD;
        }
        fe_model(&m, &mesh, 2, &o);
        m.bgmode = 1;
        m.bgrng = 7 + (unsigned long long)ph;
        m.extra = 1;
        cut_sequence(&m, &mesh, 60, 99, 1e-9);
        report(ph ? "refactor: brick R=3 cuts, node blocks" : "refactor: brick R=3 cuts", &m);
        model_free(&m);
        fe_free(&mesh);
    }
    for (ph = 1; ph <= 3; ph++) {
        model m;
        amps_update_opts o;
        int nz, *ti, *tj;
        double *tx, *x0, *x1;
        amps_update_stats st;
        amps_status s;
        int idx[3] = {3, 9, 17};
        double v[3] = {1, -1, 2};
        amps_update_opts_default(&o);
        o.grow = 1;
        o.refactor = AMPS_REFACTOR_MANUAL;
        random_spd(60, 400 + ph, &nz, &ti, &tj, &tx);
        CHECK(model_init(&m, 60, nz, ti, tj, tx, &o) == 0, "init: %s", m.ctx.msg);
        x0 = (double *)malloc(sizeof(double) * 60);
        x1 = (double *)malloc(sizeof(double) * 60);
        change_term(&m, 3, idx, v, 3.0, 0);
        model_check(&m, 1e-10, "fault");
        amps_update_solve(&m.ctx, m.U, x0);
        t_bg_fault = ph;
        CHECK(amps_update_refactor_start(&m.ctx, m.U) == AMPS_OK, "start: %s", m.ctx.msg);
        if (ph == 3) { /* a catch-up needs a log: changes while it runs */
            int k;
            for (k = 0; k < 40; k++) {
                int i2[2] = {k % 60, (k * 7 + 1) % 60};
                double v2[2] = {0.5, -0.5};
                change_term(&m, 2, i2, v2, 0.1, 0);
                amps_update_commit(&m.ctx, m.U);
            }
        }
        s = amps_update_refactor_wait(&m.ctx, m.U);
        t_bg_fault = 0;
        if (ph < 3) CHECK(s != AMPS_OK && s != AMPS_WARN_NOOP, "phase %d: injected failure not reported", ph);
        amps_update_get_stats(m.U, &st);
        CHECK(ph == 3 || (st.nrefactor == 0 && st.refactor_failed == 1 && !st.refactor_running),
              "phase %d: stats after a failure", ph);
        model_check(&m, 1e-10, "after an injected failure");
        if (ph < 3) {
            amps_update_solve(&m.ctx, m.U, x1);
            CHECK(t_reldiff(60, x0, x1) < 1e-14, "phase %d: solution changed by a failed re-factorization", ph);
        }
        CHECK(amps_update_refactor(&m.ctx, m.U) == AMPS_OK, "phase %d: re-factorization after a failure: %s", ph,
              m.ctx.msg);
        model_check(&m, 1e-10, "after a re-factorization");
        model_free(&m);
        free(ti);
        free(tj);
        free(tx);
        free(x0);
        free(x1);
    }
    { /* OFF: explicit calls are refused */
        model m;
        amps_update_opts o;
        int nz, *ti, *tj;
        double *tx;
        amps_update_opts_default(&o);
        o.refactor = AMPS_REFACTOR_OFF;
        random_spd(30, 9, &nz, &ti, &tj, &tx);
        CHECK(model_init(&m, 30, nz, ti, tj, tx, &o) == 0, "init: %s", m.ctx.msg);
        CHECK(amps_update_refactor_start(&m.ctx, m.U) == AMPS_ERR_STATE, "refactor with policy OFF accepted");
        CHECK(amps_update_refactor_wait(&m.ctx, m.U) == AMPS_WARN_NOOP, "wait with nothing running");
        model_free(&m);
        free(ti);
        free(tj);
        free(tx);
    }
}

/* Re-factorizations that keep the base's ordering (opts.refactor_reuse): started every 5 steps
   and swapped in 3 steps later (a catch-up of the changes made meanwhile), on cut sequences
   (copies placed after their origin, declared or taken from the pattern, pins) and random
   sequences (pins, releases, new DOFs; steps without a pattern change keep the analysis): every
   step agrees with CHOLMOD to 1e-12 where a fresh factorization does. A fill bound below 1
   forces the fall-back to a fresh ordering; every 16th is fresh anyway. */
static void test_refactor_kept(void) {
    int ph;
    for (ph = 0; ph < 3; ph++) {
        model m;
        amps_update_opts o;
        fe_mesh mesh = fe_brick(3);
        const char *what = ph == 0   ? "kept order: cuts, origins declared"
                           : ph == 1 ? "kept order: cuts, node blocks"
                                     : "kept order: cuts, fill bound 0.5";
        amps_update_opts_default(&o);
        o.grow = 1;
        o.refactor = AMPS_REFACTOR_MANUAL;
        if (ph == 1) o.refactor_order.block = 3;
        fe_model(&m, &mesh, 2, &o);
        m.bgmode = 2;
        m.origins = ph != 1;
        if (ph == 2) t_fill_bound = 0.5;
        CHECK(amps_update_refactor(&m.ctx, m.U) == AMPS_OK, "%s: first (fresh) re-factorization: %s", what, m.ctx.msg);
        cut_sequence(&m, &mesh, 60, 123 + (unsigned long long)ph, 1e-12);
        t_fill_bound = 1.2;
        printf("  %-36s swaps: fresh %d, order kept %d, analysis kept %d; L's storage reused %d\n", what, m.kept[0],
               m.kept[1], m.kept[2], m.reused);
        /* how many swaps keep the order depends on where each job is swapped in (a commit takes a
           finished one), so on timing: 4-6 on an idle machine, 2 seen under load */
        if (ph < 2) CHECK(m.kept[1] >= 1, "%s: the ordering was never kept", what);
        else CHECK(m.kept[1] == 0 && m.kept[0] >= 4, "%s: no fall-back to a fresh ordering", what);
        /* from the third swap on, a retired base's storage is there (the first base is the caller's) */
        CHECK(m.reused >= m.kept[0] + m.kept[1] + m.kept[2] - 2, "%s: L's storage reused only %d times", what,
              m.reused);
        report(what, &m);
        model_free(&m);
        fe_free(&mesh);
    }
    {
        model m;
        amps_update_opts o;
        int nz, *ti, *tj, k;
        double *tx;
        amps_update_stats st;
        const char *what = "kept order: random spd";
        amps_update_opts_default(&o);
        o.grow = 1;
        o.refactor = AMPS_REFACTOR_MANUAL;
        random_spd(80, 77, &nz, &ti, &tj, &tx);
        CHECK(model_init(&m, 80, nz, ti, tj, tx, &o) == 0, "init: %s", m.ctx.msg);
        m.bgmode = 2;
        CHECK(amps_update_refactor(&m.ctx, m.U) == AMPS_OK, "%s: first re-factorization: %s", what, m.ctx.msg);
        random_sequence(&m, 120, 4321, 1e-12, what);
        printf("  %-36s swaps: fresh %d, order kept %d, analysis kept %d\n", what, m.kept[0], m.kept[1], m.kept[2]);
        CHECK(m.kept[1] + m.kept[2] >= 10, "%s: the ordering was kept only %d times", what, m.kept[1] + m.kept[2]);
        report(what, &m);
        /* pins and forces only: the analysis is kept; the 16th in a row orders afresh */
        m.bgmode = 0;
        for (k = 0; k < 17; k++) {
            amps_int i = (amps_int)(k % 7);
            double gv = 0.01 * k;
            if (k % 2) {
                m.con[i] = 1;
                m.g[i] = gv;
                CHECK(amps_update_constrain(&m.ctx, m.U, 1, &i, &gv) == AMPS_OK, "pin: %s", m.ctx.msg);
            } else {
                m.con[i] = 0;
                CHECK(amps_update_release(&m.ctx, m.U, 1, &i) == AMPS_OK, "release: %s", m.ctx.msg);
            }
            CHECK(amps_update_commit(&m.ctx, m.U) == AMPS_OK, "commit: %s", m.ctx.msg);
            CHECK(amps_update_refactor_start(&m.ctx, m.U) == AMPS_OK &&
                          amps_update_refactor_wait(&m.ctx, m.U) == AMPS_OK,
                  "%s: refactor: %s", what, m.ctx.msg);
            amps_update_get_stats(m.U, &st);
            if (k == 0) {
                /* the pattern may have changed in the sequence: after one swap it is the base's */
            } else if (st.refactor_order_kept == 0) break;
            else
                CHECK(st.refactor_order_kept == 2, "%s: pins only, analysis not kept (%d)", what,
                      st.refactor_order_kept);
            model_check(&m, 1e-12, what);
        }
        CHECK(k < 17 && st.refactor_order_kept == 0, "%s: no fresh ordering after 15 kept ones", what);
        CHECK(amps_update_set_origin(&m.ctx, m.U, 1, &k, &k) == AMPS_ERR_INDEX, "set_origin of a base index accepted");
        model_free(&m);
        free(ti);
        free(tj);
        free(tx);
    }
}

/* A host back end of two participants that runs every item at once (the engine's kernels). */
static void *t_inline_enqueue(amps_task_fn *task, amps_int n, amps_int min_range, void *task_ctx, void *user) {
    (void)min_range;
    (void)user;
    task(0, n, 0, task_ctx);
    return NULL;
}
static void t_inline_finish(void *h, void *user) {
    (void)h;
    (void)user;
}

/* The background factorization on the worker and its helper thread (every loop parallel): kept
   orderings on a cut sequence agree with CHOLMOD, and the last base factor is bitwise the serial
   factorization of its matrix. */
static void test_refactor_helper(void) {
    model m;
    amps_update_opts o;
    fe_mesh mesh = fe_brick(3);
    amps_ctx c1;
    const amps_factor *F;
    amps_factor *G;
    amps_order_opts go;
    amps_update_opts_default(&o);
    o.grow = 1;
    o.refactor = AMPS_REFACTOR_MANUAL;
    fe_model(&m, &mesh, 2, &o);
    amps_update_free(&m.ctx, m.U); /* again, on the two-participant back end */
    m.ctx.enqueue_task = t_inline_enqueue;
    m.ctx.finish_task = t_inline_finish;
    m.ctx.worker_count = 1;
    m.U = amps_update_create(&m.ctx, m.K, AMPS_UPPER, m.F, &o);
    CHECK(m.U != NULL, "helper: create: %s", m.ctx.msg);
    t_bg_par = 1;
    m.bgmode = 2;
    m.origins = 1;
    CHECK(amps_update_refactor(&m.ctx, m.U) == AMPS_OK, "helper: first re-factorization: %s", m.ctx.msg);
    cut_sequence(&m, &mesh, 30, 555, 1e-12);
    CHECK(amps_update_refactor_start(&m.ctx, m.U) == AMPS_OK && amps_update_refactor_wait(&m.ctx, m.U) == AMPS_OK,
          "helper: last re-factorization: %s", m.ctx.msg);
    t_bg_par = 0;
    report("refactor: helper thread", &m);
    F = amps_update_factor(m.U);
    amps_ctx_init(&c1);
    c1.nthreads = 1;
    go.method = AMPS_ORDER_GIVEN;
    go.perm = F->perm;
    go.block = 1;
    go.coords = NULL;
    G = amps_analyze(&c1, m.U->refac.K_own, AMPS_UPPER, &go);
    CHECK(G && amps_factorize(&c1, G, m.U->refac.K_own) == AMPS_OK, "helper: serial factorization: %s", c1.msg);
    if (G)
        CHECK(G->Lp[G->n] == F->Lp[F->n] && !memcmp(G->Lx, F->Lx, sizeof(double) * (size_t)F->Lp[F->n]) &&
                      !memcmp(G->D, F->D, sizeof(double) * (size_t)F->n),
              "helper: the background factor differs from the serial one");
    amps_factor_free(&c1, G);
    model_free(&m);
    fe_free(&mesh);
}

/* Column removal (amps__lu_drop): without re-factorizations the changed dense columns of long
   cut and random sequences move to the end of the dense factor by row transforms, some commits
   fall back to refactoring; every step agrees with CHOLMOD. */
static void test_lu_drop(void) {
    int ph;
    for (ph = 0; ph < 2; ph++) {
        model m;
        amps_update_opts o;
        amps_update_stats st;
        const char *what = ph ? "column removal: random spd" : "column removal: brick R=3 cuts";
        amps_update_opts_default(&o);
        o.grow = 1;
        o.refactor = AMPS_REFACTOR_OFF;
        if (ph == 0) {
            fe_mesh mesh = fe_brick(3);
            fe_model(&m, &mesh, 2, &o);
            cut_sequence(&m, &mesh, 80, 6, 1e-9);
            fe_free(&mesh);
        } else {
            int nz, *ti, *tj;
            double *tx;
            random_spd(120, 77, &nz, &ti, &tj, &tx);
            CHECK(model_init(&m, 120, nz, ti, tj, tx, &o) == 0, "init: %s", m.ctx.msg);
            random_sequence(&m, 150, 4242, 1e-10, what);
            free(ti);
            free(tj);
            free(tx);
        }
        amps_update_get_stats(m.U, &st);
        printf("  %s: %d commits, %d with column removal, %d of them fell back\n", what, (int)st.ncommit,
               (int)st.lu_drops, (int)st.lu_drop_fails);
        CHECK(st.lu_drops > 10 && st.lu_drop_fails < st.lu_drops, "%s: column removal used %d times, %d fell back",
              what, (int)st.lu_drops, (int)st.lu_drop_fails);
        report(what, &m);
        model_free(&m);
    }
}

/* 1 and 2 threads give the same results. */
static void test_threads(void) {
#ifdef _OPENMP
    double *x[2];
    int th, N = 0;
    for (th = 1; th <= 2; th++) {
        model m;
        amps_update_opts o;
        fe_mesh mesh = fe_beam(8);
        amps_update_opts_default(&o);
        o.grow = 1;
        o.refactor = AMPS_REFACTOR_MANUAL;
        omp_set_num_threads(th);
        fe_model(&m, &mesh, 2, &o);
        cut_sequence(&m, &mesh, 30, 42, 1e-9);
        N = m.N;
        x[th - 1] = (double *)malloc(sizeof(double) * N);
        amps_update_solve(&m.ctx, m.U, x[th - 1]);
        model_free(&m);
        fe_free(&mesh);
    }
    CHECK(t_reldiff(N, x[0], x[1]) <= 1e-14, "1 vs 2 threads differ: %.3e", t_reldiff(N, x[0], x[1]));
    free(x[0]);
    free(x[1]);
    omp_set_num_threads(2);
#endif
}

/* The version macros and string; ctx->log: warnings, guard steps and a failed background
   re-factorization reach it, on the caller's thread, at the next engine call. */
typedef struct t_logrec {
    int n, nwarn, nfail, nguard, other_thread;
    pthread_t self;
    char last[256];
} t_logrec;
static void t_log(void *user, amps_status s, const char *msg) {
    t_logrec *r = (t_logrec *)user;
    r->n++;
    if (!pthread_equal(pthread_self(), r->self)) r->other_thread++;
    if (s > 0) r->nwarn++;
    if (s < 0 && strstr(msg, "re-factorization failed")) r->nfail++;
    if (s == AMPS_OK && strstr(msg, "guard")) r->nguard++;
    snprintf(r->last, sizeof(r->last), "%s", msg);
}
static void test_log(void) {
    char v[32];
    snprintf(v, sizeof(v), "%d.%d.%d", AMPS_VERSION_MAJOR, AMPS_VERSION_MINOR, AMPS_VERSION_PATCH);
    CHECK(!strcmp(amps_version(), AMPS_VERSION_STRING) && !strcmp(v, AMPS_VERSION_STRING) &&
                  !strcmp(amps_version(), "0.3.0"),
          "version %s / %s / %s", amps_version(), AMPS_VERSION_STRING, v);
    {
        model m;
        amps_update_opts o;
        int nz, *ti, *tj, k, idx[3] = {3, 9, 17};
        double *tx, val[3] = {1, -1, 2}, fv = 1.0, x[60];
        t_logrec r;
        amps_update_stats st;
        memset(&r, 0, sizeof(r));
        r.self = pthread_self();
        amps_update_opts_default(&o);
        o.grow = 1;
        o.refactor = AMPS_REFACTOR_MANUAL;
        random_spd(60, 77, &nz, &ti, &tj, &tx);
        CHECK(model_init(&m, 60, nz, ti, tj, tx, &o) == 0, "init: %s", m.ctx.msg);
        m.ctx.log = t_log;
        m.ctx.log_user = &r;
        change_term(&m, 3, idx, val, 3.0, 0);
        CHECK(amps_update_solve(&m.ctx, m.U, x) == AMPS_OK && r.n == 0, "log called %d times on a plain solve", r.n);
        /* an unreachable guard tolerance: a re-factorization, refinement steps, the warning */
        m.U->guard.tol = 1e-30;
        change_term(&m, 3, idx, val, 0.5, 0);
        m.f[idx[0]] = fv;
        amps_update_set_force(&m.ctx, m.U, 1, idx, &fv);
        CHECK(amps_update_solve(&m.ctx, m.U, x) == AMPS_WARN_INACCURATE, "guard warning: %s", m.ctx.msg);
        CHECK(r.nwarn == 1 && !strcmp(r.last, m.ctx.msg), "warnings logged %d, last '%s'", r.nwarn, r.last);
        CHECK(r.nguard >= 1, "guard remarks logged %d", r.nguard);
        m.U->guard.tol = 0;
        /* an injected failure of a background re-factorization: reported at a later commit */
        r.n = r.nfail = 0;
        t_bg_fault = 2;
        CHECK(amps_update_refactor_start(&m.ctx, m.U) == AMPS_OK, "start: %s", m.ctx.msg);
        for (k = 0; k < 2000; k++) {
            struct timespec ts = {0, 1000000L};
            int i2[2] = {k % 60, (k * 7 + 1) % 60};
            double v2[2] = {0.5, -0.5};
            change_term(&m, 2, i2, v2, 0.01, 0);
            amps_update_commit(&m.ctx, m.U);
            amps_update_get_stats(m.U, &st);
            if (!st.refactor_running) break;
            nanosleep(&ts, NULL);
        }
        t_bg_fault = 0;
        CHECK(!st.refactor_running && st.refactor_failed == 1, "failed job not dropped (running %d, failed %d)",
              (int)st.refactor_running, (int)st.refactor_failed);
        CHECK(r.nfail == 1 && r.other_thread == 0, "background failure logged %d times (%d on another thread): '%s'",
              r.nfail, r.other_thread, r.last);
        model_check(&m, 1e-10, "log: after the failure");
        model_free(&m);
        free(ti);
        free(tj);
        free(tx);
    }
}


/* A change set too large for the augmentation (hundreds of new indices, DOFs, constraints and
   releases at once) is committed by a re-factorization with the changes applied (AUTO, COUNT) or
   through the augmentation (MANUAL, OFF): the same solution as CHOLMOD either way, and the next
   small commit goes through the augmentation of the new base. */
static void test_commit_fold(void) {
    static const amps_refactor_policy pol[4] = {AMPS_REFACTOR_AUTO, AMPS_REFACTOR_COUNT, AMPS_REFACTOR_MANUAL,
                                                AMPS_REFACTOR_OFF};
    int p;
    for (p = 0; p < 4; p++) {
        model m;
        amps_update_opts o;
        amps_update_stats st;
        int n = 600, nz, *ti, *tj, k, a;
        double *tx, scale = 4.5;
        char what[64];
        snprintf(what, sizeof what, "commit fold (policy %d)", (int)pol[p]);
        random_spd(n, 77 + (unsigned long long)p, &nz, &ti, &tj, &tx);
        amps_update_opts_default(&o);
        o.refactor = pol[p];
        o.refactor_every = 1000;
        o.grow = 1;
        if (model_init(&m, n, nz, ti, tj, tx, &o)) {
            CHECK(0, "%s: setup: %s", what, m.ctx.msg);
            return;
        }
        t_seed(900 + (unsigned long long)p);
        for (k = 0; k < 20; k++) { /* a first constrained set, committed as usual */
            amps_int i0 = t_int(n);
            double v = 0.1 * (t_unif() - 0.5);
            m.con[i0] = 1;
            m.g[i0] = v;
            CHECK(amps_update_constrain(&m.ctx, m.U, 1, &i0, &v) == AMPS_OK, "%s: constrain: %s", what, m.ctx.msg);
        }
        model_check(&m, 1e-9, what);
        for (k = 0; k < 200; k++) { /* the large set: terms on 600 rows, 6 DOFs, pins and releases */
            int idx[3];
            double v[3];
            for (a = 0; a < 3; a++) {
                idx[a] = (3 * k + a) % n;
                v[a] = t_unif() - 0.5;
            }
            change_term(&m, 3, idx, v, scale * (0.1 + t_unif()), 0);
        }
        for (k = 0; k < 6; k++) {
            amps_int first;
            int idx[2];
            double v[2] = {1, -1}, fv = t_unif() - 0.5;
            CHECK(amps_update_add_dofs(&m.ctx, m.U, 1, &first) == AMPS_OK, "%s: add_dofs: %s", what, m.ctx.msg);
            model_grow(&m, m.N + 1);
            idx[0] = t_int(n);
            idx[1] = (int)first;
            change_term(&m, 2, idx, v, scale, 0);
            m.f[first] = fv;
            CHECK(amps_update_set_force(&m.ctx, m.U, 1, &first, &fv) == AMPS_OK, "%s: force: %s", what, m.ctx.msg);
        }
        for (k = 0; k < 80; k++) {
            amps_int i0 = t_int(m.N);
            double v = 0.1 * (t_unif() - 0.5);
            if (m.con[i0] && t_int(2)) {
                m.con[i0] = 0;
                m.g[i0] = 0;
                CHECK(amps_update_release(&m.ctx, m.U, 1, &i0) == AMPS_OK, "%s: release: %s", what, m.ctx.msg);
            } else {
                m.con[i0] = 1;
                m.g[i0] = v;
                CHECK(amps_update_constrain(&m.ctx, m.U, 1, &i0, &v) == AMPS_OK, "%s: constrain: %s", what, m.ctx.msg);
            }
        }
        model_check(&m, 1e-9, what);
        amps_update_get_stats(m.U, &st);
        CHECK(st.commit_folds == (pol[p] == AMPS_REFACTOR_AUTO || pol[p] == AMPS_REFACTOR_COUNT),
              "%s: %d commits by re-factorization", what, (int)st.commit_folds);
        if (st.commit_folds)
            CHECK(st.nsys == st.ncon, "%s: dense system %d after the re-factorization (%d constrained)", what,
                  (int)st.nsys, (int)st.ncon);
        random_sequence(&m, 30, 31 + (unsigned long long)p, 1e-9, what); /* small commits on the new base */
        amps_update_get_stats(m.U, &st);
        CHECK(st.commit_folds <= 1, "%s: small commits folded (%d)", what, (int)st.commit_folds);
        model_free(&m);
        free(ti);
        free(tj);
        free(tx);
    }
}

int main(void) {
    test_log();
    test_errors();
    test_near_singular();
    test_random_sequences();
    test_fe_sequences();
    test_guard();
    test_default_accuracy();
    test_check_skipped();
    test_refactor();
    test_refactor_kept();
    test_commit_fold();
    test_refactor_helper();
    test_lu_drop();
    test_threads();
    return amps_t_end("test_update");
}
