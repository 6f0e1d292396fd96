/* bench/harness: every solver over the same step sequence, time against error, side by side.

   usage: harness <mesh> <cut|deform> <steps> <every> <out.csv>
     mesh: beam:<h> | brick:<R> | TetGen .node / .msh / .mesh (see bench.h for the scenario)
     every: the sampled steps are 1, every k-th and the last; the reference solution, CHOLMOD
            refactorization, PCG and GMRES run at sampled steps only; amps.h and CHOLMOD
            update/downdate (stateful) run at every step.
   environment: BENCH_AMPS (amps configurations, default "p2,p1,d2,d1,p1o": primal/dual, threads),
     BENCH_CG_MAXIT (default 2000), BENCH_GM_MAXIT (default 600), BENCH_GM_RESTART (default 150),
     BENCH_SIMPL_MAXN (CHOLMOD simplicial refactor at the first and last sampled steps when the
     system has at most this many equations; default 60000), BENCH_ITER=0 (no CG / GMRES),
     BENCH_GUARD (opts.update.guard_tol of the amps.h scenes), BENCH_REFACTOR (auto: background
     re-factorization on; default off), BENCH_TMAX (seconds: no new
     step after this much wall time; the run then ends early, its last step a sampled one only if
     it happened to be).
   Writes one row per (step, method, tolerance) to out.csv:
     step,method,tol,time,iters,relres,relerr,conv,dim,nsys,t1,t2,t3,t4,t5,t6
   (relerr -1 where no reference was computed) and one row to <out>_meta.csv (sizes, setup times).

   Methods (the time of a step is wall clock of the change plus the solve; building the explicit
   matrix used by CG, GMRES and the reference is not counted):
   amps_<p|d><threads>  amps_scene_cut / amps_scene_pin + amps_scene_solve, primal or dual
                        formulation (opts.update.formulation), ctx.nthreads = 1 or 2; a trailing
                        o (amps_p1o) turns the default refinement off (opts.update.refine_tol = 0:
                        the default before it, beside it in the tables). BENCH_AMPS lists the
                        configurations (default p2,p1,d2,d1,p1o).
   chol_refactor        CHOLMOD analyze + factorize (supernodal LL', OpenBLAS) + solve on the
                        explicitly assembled reduced system; chol_solve: a second plain solve.
   chol_refactor_simpl  the same with CHOLMOD's simplicial LDL'.
   chol_updown          one CHOLMOD factorization of the initial system padded with identity rows
                        for the DOFs cuts will add, then per step rank updates (cholmod_updown)
                        and row deletions (cholmod_rowdel); see updown_* below.
   cg_<none|jacobi>     our CG on K_FF x_F = b_F, warm-started from the previous step's solution.
   gmres_<none|D|tri>   [Interactive cutting] (Yeung, Crouch, Pothen, "Interactively cutting and
                        constraining vertices in meshes using augmented matrices"):
                        unsymmetric augmented system, implicit Schur complement,
                        restarted GMRES; see gm_* below.
   The iterative methods run once per step to the tightest tolerance; the time and iterate at
   which each looser tolerance is first met are recorded (a run stopped there would do exactly
   the same work). Reference: CHOLMOD's solution improved by refinement steps with the residual
   in quad precision (__float128). Errors and residuals are those of the reduced system (bench.h).
   Build: see bench/run.sh. */
#define AMPS_IMPLEMENTATION
#include "../amps.h"
#include "bench.h"
#include "bench_solve.h"
#include <umfpack.h>

#define NTOL BENCH_NTOL
#define tols bench_tols

static FILE *csv;
static int cur_step;

static void put(const char *method, double tol, double t, int iters, double res, double err, int conv, long dim,
                long nsys, const double *ts) {
    static const double z[AMPS_STEP_COUNT] = {0};
    if (!ts) ts = z;
    fprintf(csv, "%d,%s,%g,%.6e,%d,%.3e,%.3e,%d,%ld,%ld,%.4e,%.4e,%.4e,%.4e,%.4e,%.4e\n", cur_step, method, tol, t,
            iters, res, err, conv, dim, nsys, ts[AMPS_STEP_WCOLS], ts[AMPS_STEP_GRAM], ts[AMPS_STEP_DCOLS],
            ts[AMPS_STEP_RHS], ts[AMPS_STEP_DENSE], ts[AMPS_STEP_SOLVE]);
}

static int envi(const char *name, int def) {
    const char *s = getenv(name);
    return s ? atoi(s) : def;
}

/* ======================= CHOLMOD on the explicit reduced system ======================= */

/* CHOLMOD refactor + solve (timed), a second solve (timed), then xref by refinement steps whose
   residual is summed in quad precision (x kept in quad too; until a correction is below 1e-3 eps
   ||x||, at most 20 steps): exact to working precision for cond < 1 / eps, so the errors of
   CHOLMOD and amps.h are measured, not the reference's. With simpl, also the simplicial LDL'
   refactor. Writes the rows of chol_refactor(_simpl), chol_solve. */
static void reference(const bench_sys *S, double *xref, double *work, int simpl) {
    cholmod_common c;
    cholmod_sparse *A;
    cholmod_dense *B, *X, *X2;
    cholmod_factor *L;
    int *fmap = (int *)bench_alloc(sizeof(int) * (size_t)S->n);
    double t0, t_ref, t_sol, *x0 = (double *)bench_alloc(sizeof(double) * (size_t)S->n);
    cholmod_start(&c);
    c.supernodal = CHOLMOD_SUPERNODAL;
    A = bench_reduced(S, fmap, &B, &c);
    t0 = amps_now();
    L = cholmod_analyze(A, &c);
    cholmod_factorize(A, L, &c);
    X = cholmod_solve(CHOLMOD_A, L, B, &c);
    t_ref = amps_now() - t0;
    t0 = amps_now();
    X2 = cholmod_solve(CHOLMOD_A, L, B, &c);
    t_sol = amps_now() - t0;
    if (!X || !X2 || c.status != CHOLMOD_OK) bench_die("cholmod", "reference factorization failed");
    bench_expand(S, fmap, (double *)X->x, x0);
    bench_refine(A, L, B, X2, 20, &c);
    bench_expand(S, fmap, (double *)X2->x, xref);
    put("chol_refactor", 0, t_ref, 0, bench_sys_relres(S, x0, work), bench_sys_relerr(S, x0, xref), 1, S->n, 0, NULL);
    put("chol_solve", 0, t_sol, 0, bench_sys_relres(S, x0, work), bench_sys_relerr(S, x0, xref), 1, S->n, 0, NULL);
    cholmod_free_dense(&X, &c);
    cholmod_free_dense(&X2, &c);
    cholmod_free_factor(&L, &c);
    if (simpl) {
        c.supernodal = CHOLMOD_SIMPLICIAL;
        c.final_ll = 0;
        t0 = amps_now();
        L = cholmod_analyze(A, &c);
        cholmod_factorize(A, L, &c);
        X = cholmod_solve(CHOLMOD_A, L, B, &c);
        t_ref = amps_now() - t0;
        bench_expand(S, fmap, (double *)X->x, x0);
        put("chol_refactor_simpl", 0, t_ref, 0, bench_sys_relres(S, x0, work), bench_sys_relerr(S, x0, xref), 1, S->n,
            0, NULL);
        cholmod_free_dense(&X, &c);
        cholmod_free_factor(&L, &c);
    }
    cholmod_free_dense(&B, &c);
    cholmod_free_sparse(&A, &c);
    cholmod_finish(&c);
    free(fmap);
    free(x0);
}

/* ============================ CHOLMOD update / downdate ============================
   CHOLMOD cannot change the order of a factorization, so it factors once the padded matrix
       A = [K0 0; 0 I_r],  r = 3 * (steps + 1) reserved equations,
   with the numbering of bench_sys (a cut's copy v' gets equations n0 + 3 j .. n0 + 3 j + 2, which
   are reserved rows until then; unused reserved rows keep x = 0). The analysis and the
   supernodal factorization with OpenBLAS are converted to a simplicial LDL' once (setup, not
   timed); every step then modifies that LDL' in place:
   - cut of v (copy v', moved tets T): with Ke(t) = W_t W_t^T, W_t = sqrt(V) B^T chol(C) (12 x 6,
     rank 6; B the strain-displacement matrix, C the elasticity matrix),
         K_new = K_old + sum_{t in T} P_new W_t W_t^T P_new^T - sum_{t in T} P_old W_t W_t^T P_old^T,
     P_old / P_new scatter the tet's 12 DOFs to equations with v / with v' (fixed DOFs dropped).
     In the padded matrix the rows of v' also drop their identity: A_new = A + C+ C+^T - C- C-^T,
     C+ = [P_new W_t]_t (6|T| columns), C- = [P_old W_t]_t plus e_{v'_x}, e_{v'_y}, e_{v'_z}.
     cholmod_updown(update, C+) first, then cholmod_updown(downdate, C-), so every
     intermediate matrix stays positive definite. Rows of C are permuted by L->Perm.
   - pin of equation e (value g_e): cholmod_rowdel turns row/column e of A (and of L) into the
     identity; the right-hand side gets b_F -= K_Fe g_e and b_e = g_e, so x_e = g_e.
   A step's time: building C (or the RHS change), the modification and one cholmod_solve. */
typedef struct updown {
    cholmod_common c;
    cholmod_factor *L;
    cholmod_dense *B;
    int N, n0, *iperm;
    double t_setup, lnz0;
} updown;

static void updown_init(updown *u, const bench_sys *S0, int reserve) {
    cholmod_sparse *A;
    int j, p, nz = 0, n0 = S0->n;
    double t0 = amps_now();
    cholmod_start(&u->c);
    u->n0 = n0;
    u->N = n0 + reserve;
    A = cholmod_allocate_sparse((size_t)u->N, (size_t)u->N, (size_t)(S0->K->p[n0] + reserve), 1, 1, 1, CHOLMOD_REAL,
                                &u->c);
    for (j = 0; j < u->N; j++) {
        ((int *)A->p)[j] = nz;
        if (j < n0)
            for (p = S0->K->p[j]; p < S0->K->p[j + 1]; p++) {
                ((int *)A->i)[nz] = S0->K->i[p];
                ((double *)A->x)[nz++] = S0->K->x[p];
            }
        else {
            ((int *)A->i)[nz] = j;
            ((double *)A->x)[nz++] = 1.0;
        }
    }
    ((int *)A->p)[u->N] = nz;
    u->L = cholmod_analyze(A, &u->c);
    cholmod_factorize(A, u->L, &u->c);
    if (u->c.status != CHOLMOD_OK) bench_die("cholmod", "updown initial factorization failed");
    cholmod_change_factor(CHOLMOD_REAL, 0, 0, 1, 1, u->L, &u->c);
    u->iperm = (int *)bench_alloc(sizeof(int) * (size_t)u->N);
    for (j = 0; j < u->N; j++) u->iperm[((int *)u->L->Perm)[j]] = j;
    u->lnz0 = 0;
    for (j = 0; j < u->N; j++) u->lnz0 += ((int *)u->L->nz)[j];
    u->B = cholmod_zeros((size_t)u->N, 1, CHOLMOD_REAL, &u->c);
    memcpy(u->B->x, S0->b, sizeof(double) * (size_t)n0);
    cholmod_free_sparse(&A, &u->c);
    u->t_setup = amps_now() - t0;
}

static void updown_free(updown *u) {
    cholmod_free_factor(&u->L, &u->c);
    cholmod_free_dense(&u->B, &u->c);
    cholmod_finish(&u->c);
    free(u->iperm);
}

/* W = sqrt(V) B^T chol(C) of tet t (12 x 6, row-major), Ke = W W^T */
static void tet_w(const amps_mesh *m, amps_int t, double W[72]) {
    double X[12], G[12], Bm[72], C[36], Lc[36] = {0}, V;
    int a, b, k, q;
    amps_mesh_tet_coords(m, t, X);
    V = fabs(amps_tet_gradients(X, G));
    amps_tet_B(G, Bm);
    amps_elasticity(m->E[t], m->nu[t], C);
    for (a = 0; a < 6; a++) /* Cholesky C = Lc Lc^T */
        for (b = 0; b <= a; b++) {
            double s = C[6 * a + b];
            for (k = 0; k < b; k++) s -= Lc[6 * a + k] * Lc[6 * b + k];
            Lc[6 * a + b] = a == b ? sqrt(s) : s / Lc[6 * b + b];
        }
    for (a = 0; a < 12; a++)
        for (q = 0; q < 6; q++) {
            double s = 0;
            for (k = q; k < 6; k++) s += Bm[12 * k + a] * Lc[6 * k + q];
            W[6 * a + q] = sqrt(V) * s;
        }
}

/* C = [P W_t]_t with v' replaced by `as` in the tets' node lists, plus identity columns of v'
   when ident; rows permuted and sorted */
static cholmod_sparse *updown_c(updown *u, const amps_mesh *M, const amps_int *ndof, const bench_step *s, int as,
                                int ident) {
    int ncol = 6 * s->nmoved + (ident ? 3 : 0), k, a, q, d, col = 0, nz = 0;
    cholmod_sparse *C =
            cholmod_allocate_sparse((size_t)u->N, (size_t)ncol, (size_t)(12 * ncol), 1, 1, 0, CHOLMOD_REAL, &u->c);
    int *Cp = (int *)C->p, *Ci = (int *)C->i;
    double *Cx = (double *)C->x, W[72];
    for (k = 0; k < s->nmoved; k++) {
        amps_int t = s->moved[k];
        tet_w(M, t, W);
        for (q = 0; q < 6; q++, col++) {
            int start = nz, i, j;
            Cp[col] = nz;
            for (a = 0; a < 4; a++) {
                int v = (int)M->tet[4 * t + a];
                if (v == s->vc) v = as;
                for (d = 0; d < 3; d++)
                    if (ndof[3 * v + d] >= 0) {
                        Ci[nz] = u->iperm[ndof[3 * v + d]];
                        Cx[nz++] = W[6 * (3 * a + d) + q];
                    }
            }
            for (i = start + 1; i < nz; i++) /* insertion sort of the column */
                for (j = i; j > start && Ci[j - 1] > Ci[j]; j--) {
                    int ti = Ci[j];
                    double tx = Cx[j];
                    Ci[j] = Ci[j - 1];
                    Cx[j] = Cx[j - 1];
                    Ci[j - 1] = ti;
                    Cx[j - 1] = tx;
                }
        }
    }
    if (ident)
        for (d = 0; d < 3; d++, col++) {
            Cp[col] = nz;
            Ci[nz] = u->iperm[ndof[3 * s->vc + d]];
            Cx[nz++] = 1.0;
        }
    Cp[col] = nz;
    return C;
}

/* one step; x (N) receives the solution. Kf0: the initial full K (pins only happen without cuts) */
static double updown_step(updown *u, const amps_mesh *M, const amps_int *ndof, const bench_step *s,
                          const bench_scen *sc, const amps_csc *Kf0, unsigned char *con, double *x) {
    double t0 = amps_now(), *b = (double *)u->B->x;
    cholmod_dense *X;
    int d;
    if (sc->cut) {
        cholmod_sparse *Cp = updown_c(u, M, ndof, s, s->vc, 0), *Cm = updown_c(u, M, ndof, s, s->node, 1);
        cholmod_updown(1, Cp, u->L, &u->c);
        cholmod_updown(0, Cm, u->L, &u->c);
        cholmod_free_sparse(&Cp, &u->c);
        cholmod_free_sparse(&Cm, &u->c);
    } else {
        for (d = 0; d < 3; d++) {
            int e = (int)ndof[3 * s->node + d], p;
            if (e < 0) continue;
            cholmod_rowdel((size_t)u->iperm[e], NULL, u->L, &u->c);
            con[e] = 1;
            for (p = Kf0->p[e]; p < Kf0->p[e + 1]; p++)
                if (!con[Kf0->i[p]]) b[Kf0->i[p]] -= Kf0->x[p] * s->u[d];
            b[e] = s->u[d];
        }
    }
    X = cholmod_solve(CHOLMOD_A, u->L, u->B, &u->c);
    if (!X || u->c.status < 0) bench_die("cholmod", "updown solve failed");
    memcpy(x, X->x, sizeof(double) * (size_t)u->N);
    cholmod_free_dense(&X, &u->c);
    return amps_now() - t0;
}

/* ================= [Interactive cutting]: augmented system + GMRES =================
   R = [K0 0; 0 I] (K0 = LDL^T, amps.h's factor of the initial system; padded identity for the
   equations cuts append), Lset = the equations whose column differs from R's (every DOF of a
   cut node, of its copy and of the moved tets' nodes, accumulated) and the constrained ones,
   J (n x m): column k = current K column Lset_k, or e_{Lset_k} if constrained (Eq. 5);
   H = rows Lset of I (Eq. 6); fhat = f - K g (Eq. 11). Eq. 13-17:
       [R J; H 0] [a1; a2] = [fhat; 0],   (H R^{-1} J) a2 = H R^{-1} fhat,   a1 = R^{-1}(fhat - J a2),
   and the solution is a1 off Lset, a2 at unconstrained Lset (at constrained ones a2 = -reaction).
   Step 1 (Eq. 18-19): y = R^{-1} fhat by a sparse forward solve over closure(struct fhat) and a
   partial backward solve over closure(Lset) only (amps_lsolve_sparse, amps_ltsolve_partial).
   Step 2 (Eq. 20): restarted GMRES on H R^{-1} J, each product the same sparse forward solve of
   J a2 and partial backward solve onto Lset (amps.h's sparse kernels instead of the paper's
   copied submatrices of L). Right preconditioning by M = H S J (paper §3.5), S ~ R^{-1}:
   none; D: S = D^{-1} of the LDL^T factor; tri: the tridiagonal sparse approximate inverse
   of R (Benson-Frederickson: column j minimizes ||R s_j - e_j||_2 over s_j supported on
   j-1, j, j+1; identity on the padding). M is sparse m x m; UMFPACK factors it per step.
   GMRES minimizes ||H R^{-1} fhat - H R^{-1} J a2||; it stops at relative norm <= tol.
   Step 3: a1 by a sparse forward and a full backward solve. */
typedef struct gmres {
    const amps_factor *F;
    int n0, m, n, *pos; /* pos[i] = position of equation i in Lset or -1 */
    double *w, *z, *sa, *sd,
            *sc; /* w: permuted work (n0), z: work (n); S = tridiag(sa sup, sd diag, sc sub) by columns */
    amps_int *cl, *bi, *req, *tch;
    amps_marker mk;
    int nreq;
    /* J (CSC n x m) for the current step */
    int *Jp, *Ji;
    double *Jx;
    void *num; /* UMFPACK factor of M */
} gmres;

static void gm_init(amps_ctx *ctx, gmres *G, const amps_factor *F, const bench_sys *S0, int ncap) {
    int j, n0 = (int)F->n;
    memset(G, 0, sizeof(*G));
    G->F = F;
    G->n0 = n0;
    G->w = (double *)bench_alloc(sizeof(double) * (size_t)n0);
    G->z = (double *)bench_alloc(sizeof(double) * (size_t)ncap);
    G->pos = (int *)bench_alloc(sizeof(int) * (size_t)ncap);
    for (j = 0; j < ncap; j++) G->pos[j] = -1;
    G->cl = (amps_int *)bench_alloc(sizeof(amps_int) * (size_t)n0);
    G->bi = (amps_int *)bench_alloc(sizeof(amps_int) * (size_t)ncap);
    G->tch = (amps_int *)bench_alloc(sizeof(amps_int) * (size_t)ncap);
    G->req = (amps_int *)bench_alloc(sizeof(amps_int) * (size_t)ncap);
    if (amps_marker_init(ctx, &G->mk, n0) != AMPS_OK) bench_die("amps_marker_init", ctx->msg);
    /* tridiagonal SPAI of K0 (setup, once per mesh) */
    G->sa = (double *)bench_alloc(sizeof(double) * (size_t)ncap);
    G->sd = (double *)bench_alloc(sizeof(double) * (size_t)ncap);
    G->sc = (double *)bench_alloc(sizeof(double) * (size_t)ncap);
    for (j = 0; j < ncap; j++) G->sd[j] = 1;
    for (j = 0; j < n0; j++) {
        const amps_csc *K = S0->Kf;
        int c[3], nc = 0, a, b, k;
        double Gm[9], rhs[3], s[3];
        for (a = j - 1; a <= j + 1; a++)
            if (a >= 0 && a < n0) c[nc++] = a;
        for (a = 0; a < nc; a++) {
            rhs[a] = 0;
            for (k = K->p[c[a]]; k < K->p[c[a] + 1]; k++)
                if (K->i[k] == j) rhs[a] = K->x[k];
            for (b = 0; b < nc; b++) { /* dot of sparse columns c[a], c[b] (rows sorted) */
                int p = K->p[c[a]], q = K->p[c[b]];
                double d = 0;
                while (p < K->p[c[a] + 1] && q < K->p[c[b] + 1]) {
                    if (K->i[p] < K->i[q]) p++;
                    else if (K->i[p] > K->i[q]) q++;
                    else d += K->x[p++] * K->x[q++];
                }
                Gm[3 * a + b] = d;
            }
        }
        for (a = 0; a < nc; a++) { /* Gaussian elimination, SPD */
            for (b = a + 1; b < nc; b++) {
                double l = Gm[3 * b + a] / Gm[3 * a + a];
                for (k = a; k < nc; k++) Gm[3 * b + k] -= l * Gm[3 * a + k];
                rhs[b] -= l * rhs[a];
            }
        }
        for (a = nc - 1; a >= 0; a--) {
            s[a] = rhs[a];
            for (b = a + 1; b < nc; b++) s[a] -= Gm[3 * a + b] * s[b];
            s[a] /= Gm[3 * a + a];
        }
        for (a = 0; a < nc; a++) {
            if (c[a] == j - 1) G->sa[j] = s[a]; /* S(j-1, j) */
            else if (c[a] == j) G->sd[j] = s[a];
            else G->sc[j] = s[a]; /* S(j+1, j) */
        }
    }
}

static void gm_free(amps_ctx *ctx, gmres *G) {
    free(G->w);
    free(G->z);
    free(G->pos);
    free(G->cl);
    free(G->bi);
    free(G->tch);
    free(G->req);
    free(G->sa);
    free(G->sd);
    free(G->sc);
    free(G->Jp);
    free(G->Ji);
    free(G->Jx);
    amps_marker_free(ctx, &G->mk);
}

/* out (m) = H R^{-1} v for v = z (dense n, nonzero only at tch[0..nt-1]); z is cleared */
static void gm_hrinv(gmres *G, const int *Lset, int nt, double *out) {
    const amps_factor *F = G->F;
    int k, nb = 0, nc;
    for (k = 0; k < nt; k++)
        if (G->tch[k] < G->n0) {
            amps_int pk = F->iperm[G->tch[k]];
            G->w[pk] = G->z[G->tch[k]];
            G->bi[nb++] = pk;
        }
    nc = (int)amps_lsolve_sparse(F, nb, G->bi, G->w, G->cl, &G->mk);
    for (k = 0; k < nc; k++) G->w[G->cl[k]] /= F->D[G->cl[k]];
    {
        int q;
        for (q = 0; q < G->m; q++) out[q] = Lset[q] < G->n0 ? 0 : G->z[Lset[q]];
        /* the forward closure's entries outside closure(req) keep D^-1 L^-1 v: clear them after reading */
        for (q = 0; q < nc; q++) G->bi[q] = G->cl[q];
        k = (int)amps_ltsolve_partial(F, G->nreq, G->req, G->w, G->cl, &G->mk);
        for (q = 0; q < G->m; q++)
            if (Lset[q] < G->n0) out[q] = G->w[F->iperm[Lset[q]]];
        while (k > 0) G->w[G->cl[--k]] = 0;
        for (q = 0; q < nc; q++) G->w[G->bi[q]] = 0;
    }
    for (k = 0; k < nt; k++) G->z[G->tch[k]] = 0;
}

/* z = J a (scatter; touched list in tch), returns the count */
static int gm_jmul(gmres *G, const double *a, double scale) {
    int k, p, nt = 0;
    for (k = 0; k < G->m; k++)
        for (p = G->Jp[k]; p < G->Jp[k + 1]; p++) {
            int i = G->Ji[p];
            if (G->z[i] == 0) G->tch[nt++] = i; /* may list an index twice if a sum cancels: harmless below */
            G->z[i] += scale * G->Jx[p] * a[k];
            if (G->z[i] == 0) G->z[i] = 1e-300; /* keep it listed once */
        }
    return nt;
}

static void gm_op(gmres *G, const int *Lset, const double *a, double *out) {
    int nt = gm_jmul(G, a, 1.0);
    gm_hrinv(G, Lset, nt, out);
}

/* preconditioner M = H S J (prec 1: S = D^-1, 2: tridiagonal SPAI); returns 0 if singular */
static int gm_prec_build(gmres *G, int prec, double *tx, int *ti, int *tj, int *Mp, int *Mi, double *Mx) {
    int k, p, nz = 0, st;
    void *sym = NULL;
    for (k = 0; k < G->m; k++)
        for (p = G->Jp[k]; p < G->Jp[k + 1]; p++) {
            int i = G->Ji[p], r;
            double y = G->Jx[p];
            double sv[3];
            /* column i of S: rows i-1, i, i+1 */
            sv[0] = prec == 2 ? G->sa[i] : 0;
            sv[1] = prec == 2 || i >= G->n0 ? G->sd[i] : 1 / G->F->D[G->F->iperm[i]];
            sv[2] = prec == 2 ? G->sc[i] : 0;
            for (r = -1; r <= 1; r++) {
                int row = i + r;
                if (row < 0 || row >= G->n || G->pos[row] < 0 || sv[r + 1] == 0) continue;
                ti[nz] = G->pos[row];
                tj[nz] = k;
                tx[nz++] = sv[r + 1] * y;
            }
        }
    umfpack_di_triplet_to_col(G->m, G->m, nz, ti, tj, tx, Mp, Mi, Mx, NULL);
    st = umfpack_di_symbolic(G->m, G->m, Mp, Mi, Mx, &sym, NULL, NULL);
    if (st == UMFPACK_OK) st = umfpack_di_numeric(Mp, Mi, Mx, sym, &G->num, NULL, NULL);
    umfpack_di_free_symbolic(&sym);
    if (st != UMFPACK_OK) {
        if (G->num) umfpack_di_free_numeric(&G->num);
        G->num = NULL;
        return 0;
    }
    return 1;
}

/* y = R^{-1} g for the leading j x j block of the rotated Hessenberg matrix (upper triangular R) */
static void hess_solve(const double *H, int mr, const double *g, int j, double *y) {
    int i, k;
    for (i = j - 1; i >= 0; i--) {
        y[i] = g[i];
        for (k = i + 1; k < j; k++) y[i] -= H[i * mr + k] * y[k];
        y[i] /= H[i * mr + i];
    }
}

/* Runs the method for one step to the tightest tolerance; snapshots of the full solution. */
static void gm_run(gmres *G, const bench_sys *S, const int *Lset, int m, const double *x0, int prec, int maxit,
                   int restart, bench_snaps *sn) {
    int n = S->n, k, p, i, j, it = 0, ti = 0, mr = restart < m ? restart : m;
    double t0 = amps_now(), tpause = 0, nrhs, beta;
    double *rhs = (double *)bench_alloc(sizeof(double) * (size_t)m),
           *a = (double *)bench_alloc(sizeof(double) * (size_t)m);
    double *r = (double *)bench_alloc(sizeof(double) * (size_t)m),
           *tmp = (double *)bench_alloc(sizeof(double) * (size_t)m);
    double *V = (double *)bench_alloc(sizeof(double) * (size_t)m * (size_t)(mr + 1)),
           *Z = (double *)bench_alloc(sizeof(double) * (size_t)m * (size_t)mr);
    double *H = (double *)bench_alloc(sizeof(double) * (size_t)(mr + 1) * (size_t)mr),
           *cs = (double *)bench_alloc(sizeof(double) * (size_t)mr);
    double *sn_ = (double *)bench_alloc(sizeof(double) * (size_t)mr),
           *g = (double *)bench_alloc(sizeof(double) * (size_t)(mr + 1));
    double *y = (double *)bench_alloc(sizeof(double) * (size_t)(mr + 1));
    double *a2s[NTOL], t_snap[NTOL];
    int *ti_ = NULL, *tj_ = NULL, *Mp = NULL, *Mi = NULL;
    double *tx_ = NULL, *Mx = NULL;
    int nz;
    G->m = m;
    G->n = n;
    for (k = 0; k < NTOL; k++) a2s[k] = (double *)bench_alloc(sizeof(double) * (size_t)m);
    /* J and H (Eq. 5-6) */
    for (k = 0, nz = 0; k < m; k++) nz += S->con[Lset[k]] ? 1 : S->Kf->p[Lset[k] + 1] - S->Kf->p[Lset[k]];
    free(G->Jp);
    free(G->Ji);
    free(G->Jx);
    G->Jp = (int *)bench_alloc(sizeof(int) * ((size_t)m + 1));
    G->Ji = (int *)bench_alloc(sizeof(int) * (size_t)nz);
    G->Jx = (double *)bench_alloc(sizeof(double) * (size_t)nz);
    for (k = 0, nz = 0, G->nreq = 0; k < m; k++) {
        int e = Lset[k];
        G->pos[e] = k;
        if (e < G->n0) G->req[G->nreq++] = G->F->iperm[e];
        G->Jp[k] = nz;
        if (S->con[e]) {
            G->Ji[nz] = e;
            G->Jx[nz++] = 1;
        } else
            for (p = S->Kf->p[e]; p < S->Kf->p[e + 1]; p++) {
                G->Ji[nz] = S->Kf->i[p];
                G->Jx[nz++] = S->Kf->x[p];
            }
    }
    G->Jp[m] = nz;
    if (prec) {
        int cap = 3 * nz + 1;
        ti_ = (int *)bench_alloc(sizeof(int) * (size_t)cap);
        tj_ = (int *)bench_alloc(sizeof(int) * (size_t)cap);
        tx_ = (double *)bench_alloc(sizeof(double) * (size_t)cap);
        Mp = (int *)bench_alloc(sizeof(int) * ((size_t)m + 1));
        Mi = (int *)bench_alloc(sizeof(int) * (size_t)cap);
        Mx = (double *)bench_alloc(sizeof(double) * (size_t)cap);
        if (!gm_prec_build(G, prec, tx_, ti_, tj_, Mp, Mi, Mx)) {
            fprintf(stderr, "gmres: M singular, no preconditioner\n");
            prec = 0;
        }
    }
#define PREC(in, out)                                                                       \
    do {                                                                                    \
        if (prec) umfpack_di_solve(UMFPACK_A, Mp, Mi, Mx, (out), (in), G->num, NULL, NULL); \
        else memcpy((out), (in), sizeof(double) * (size_t)m);                               \
    } while (0)
    /* step 1: rhs = H R^{-1} fhat, fhat = b */
    {
        int nt = 0;
        for (i = 0; i < n; i++)
            if (S->b[i] != 0) {
                G->z[i] = S->b[i];
                G->tch[nt++] = i;
            }
        gm_hrinv(G, Lset, nt, rhs);
    }
    nrhs = 0;
    for (k = 0; k < m; k++) nrhs += rhs[k] * rhs[k];
    nrhs = sqrt(nrhs);
    for (k = 0; k < m; k++) a[k] = S->con[Lset[k]] ? 0 : x0[Lset[k]]; /* warm start */
    for (;;) {                                                        /* restart cycles */
        int jj = 0;
        gm_op(G, Lset, a, tmp);
        for (k = 0, beta = 0; k < m; k++) {
            r[k] = rhs[k] - tmp[k];
            beta += r[k] * r[k];
        }
        beta = sqrt(beta);
        while (ti < NTOL && beta <= tols[ti] * nrhs) {
            memcpy(a2s[ti], a, sizeof(double) * (size_t)m);
            t_snap[ti] = amps_now() - t0 - tpause;
            sn->it[ti] = it;
            sn->conv[ti++] = 1;
        }
        if (ti == NTOL || it >= maxit || beta == 0) break;
        for (k = 0; k < m; k++) V[k] = r[k] / beta;
        memset(g, 0, sizeof(double) * (size_t)(mr + 1));
        g[0] = beta;
        for (j = 0; j < mr && it < maxit; j++) {
            double *vj = V + (size_t)j * m, *w = V + (size_t)(j + 1) * m, hn, res;
            PREC(vj, Z + (size_t)j * m);
            gm_op(G, Lset, Z + (size_t)j * m, w);
            for (i = 0; i <= j; i++) { /* modified Gram-Schmidt */
                double h = 0, *vi = V + (size_t)i * m;
                for (k = 0; k < m; k++) h += w[k] * vi[k];
                for (k = 0; k < m; k++) w[k] -= h * vi[k];
                H[i * mr + j] = h;
            }
            for (k = 0, hn = 0; k < m; k++) hn += w[k] * w[k];
            hn = sqrt(hn);
            if (hn > 0)
                for (k = 0; k < m; k++) w[k] /= hn;
            for (i = 0; i < j; i++) { /* previous Givens rotations */
                double h1 = H[i * mr + j], h2 = H[(i + 1) * mr + j];
                H[i * mr + j] = cs[i] * h1 + sn_[i] * h2;
                H[(i + 1) * mr + j] = -sn_[i] * h1 + cs[i] * h2;
            }
            {
                double h1 = H[j * mr + j], d = sqrt(h1 * h1 + hn * hn);
                cs[j] = h1 / d;
                sn_[j] = hn / d;
                H[j * mr + j] = d;
                g[j + 1] = -sn_[j] * g[j];
                g[j] = cs[j] * g[j];
            }
            it++;
            jj = j + 1;
            res = fabs(g[j + 1]);
            while (ti < NTOL && res <= tols[ti] * nrhs) { /* a2 = a + Z y, y = H^{-1} g */
                hess_solve(H, mr, g, j + 1, y);
                memcpy(a2s[ti], a, sizeof(double) * (size_t)m);
                for (i = 0; i <= j; i++)
                    for (k = 0; k < m; k++) a2s[ti][k] += y[i] * Z[(size_t)i * m + k];
                t_snap[ti] = amps_now() - t0 - tpause;
                sn->it[ti] = it;
                sn->conv[ti++] = 1;
            }
            if (ti == NTOL || hn == 0) break;
        }
        if (ti == NTOL) break;
        hess_solve(H, mr, g, jj, y);
        for (i = 0; i < jj; i++)
            for (k = 0; k < m; k++) a[k] += y[i] * Z[(size_t)i * m + k];
        if (it >= maxit) {
            for (; ti < NTOL; ti++) {
                memcpy(a2s[ti], a, sizeof(double) * (size_t)m);
                t_snap[ti] = amps_now() - t0 - tpause;
                sn->it[ti] = it;
                sn->conv[ti] = 0;
            }
            break;
        }
    }
#undef PREC
    /* step 3 for each snapshot (timed separately): a1 = R^{-1}(fhat - J a2) */
    for (ti = 0; ti < NTOL; ti++) {
        double t1 = amps_now(), *x = sn->x[ti], *w = G->w;
        const amps_factor *F = G->F;
        int nt = gm_jmul(G, a2s[ti], -1.0), nb = 0;
        for (i = 0; i < n; i++)
            if (S->b[i] != 0) {
                if (G->z[i] == 0) G->tch[nt++] = i;
                G->z[i] += S->b[i];
            }
        for (k = 0; k < nt; k++)
            if (G->tch[k] < G->n0) {
                amps_int pk = F->iperm[G->tch[k]];
                if (w[pk] == 0) G->bi[nb++] = pk;
                w[pk] = G->z[G->tch[k]];
            }
        amps_lsolve_sparse(F, nb, G->bi, w, G->cl, &G->mk);
        amps_dsolve(F, w);
        amps_ltsolve(F, w);
        for (i = 0; i < G->n0; i++) x[F->perm[i]] = w[i];
        for (i = G->n0; i < n; i++) x[i] = G->z[i];
        for (k = 0; k < m; k++) x[Lset[k]] = S->con[Lset[k]] ? S->g[Lset[k]] : a2s[ti][k];
        memset(w, 0, sizeof(double) * (size_t)G->n0);
        for (k = 0; k < nt; k++) G->z[G->tch[k]] = 0;
        sn->t[ti] = t_snap[ti] + amps_now() - t1;
    }
    for (k = 0; k < m; k++) G->pos[Lset[k]] = -1;
    if (G->num) umfpack_di_free_numeric(&G->num);
    G->num = NULL;
    for (k = 0; k < NTOL; k++) free(a2s[k]);
    free(rhs);
    free(a);
    free(r);
    free(tmp);
    free(V);
    free(Z);
    free(H);
    free(cs);
    free(sn_);
    free(g);
    free(y);
    free(ti_);
    free(tj_);
    free(tx_);
    free(Mp);
    free(Mi);
    free(Mx);
}

/* =================================== driver =================================== */
#define MAXCONF 5
int main(int argc, char **argv) {
    amps_ctx ctx, cctx[MAXCONF];
    const char *spec, *out;
    char conf[MAXCONF][16], metapath[1024];
    int steps, every, cut, nconf = 0, k, st, maxdeg = 0, v, ndofc, nL = 0, nsampled = 0;
    int cg_maxit = envi("BENCH_CG_MAXIT", 2000), gm_maxit = envi("BENCH_GM_MAXIT", 600),
        gm_restart = envi("BENCH_GM_RESTART", 150);
    int simpl_maxn = envi("BENCH_SIMPL_MAXN", 60000), iter = envi("BENCH_ITER", 1);
    double tmax = getenv("BENCH_TMAX") ? atof(getenv("BENCH_TMAX")) : 0, t_start = amps_now();
    amps_scene *S[MAXCONF];
    amps_mesh *M;
    bench_scen sc;
    bench_step s;
    bench_sys S0;
    updown ud;
    gmres gm;
    amps_int *ndof;
    int *Lset;
    unsigned char *inL, *udcon;
    double *uprev, *xprev, *x, *xref, *work, *xud, t_amps_setup[MAXCONF];
    bench_snaps sn;
    FILE *meta;
    if (argc < 6) {
        fprintf(stderr, "usage: harness <beam:h|brick:R|file> <cut|deform> <steps> <every> <out.csv>\n");
        return 2;
    }
    spec = argv[1];
    cut = !strcmp(argv[2], "cut");
    steps = atoi(argv[3]);
    every = atoi(argv[4]);
    out = argv[5];
    if (every < 1) every = 1;
    amps_ctx_init(&ctx);
    { /* amps configurations */
        const char *l = getenv("BENCH_AMPS") ? getenv("BENCH_AMPS") : "p2,p1,d2,d1,p1o";
        while (*l && nconf < MAXCONF) {
            int len = 0;
            while (l[len] && l[len] != ',' && len < 7) len++;
            snprintf(conf[nconf], sizeof(conf[nconf]), "amps_%.*s", len, l);
            nconf++;
            l += len;
            if (*l == ',') l++;
        }
    }
    M = bench_mesh(&ctx, spec);
    bench_scen_init(&sc, M, spec, cut, steps);
    if (amps_mesh_reserve(&ctx, M, sc.cap) != AMPS_OK) bench_die("amps_mesh_reserve", ctx.msg);
    for (v = 0; v < sc.nn0; v++)
        if (amps_mesh_degree(M, v) > maxdeg) maxdeg = (int)amps_mesh_degree(M, v);
    s.moved = (amps_int *)bench_alloc(sizeof(amps_int) * (size_t)maxdeg);
    for (k = 0; k < nconf; k++) {
        amps_scene_opts so;
        double t0;
        amps_ctx_init(&cctx[k]);
        cctx[k].nthreads = conf[k][6] - '0';
        amps_scene_opts_default(&so);
        if (conf[k][5] == 'd') so.update.formulation = AMPS_FORM_DUAL;
        if (getenv("BENCH_GUARD")) so.update.guard_tol = atof(getenv("BENCH_GUARD"));
        if (conf[k][7] == 'o') so.update.refine_tol = 0; /* no default refinement */
        /* background re-factorization off: its thread would run while the other methods are
           timed (bench/refactor measures it alone); BENCH_REFACTOR=auto turns it on */
        so.update.refactor = getenv("BENCH_REFACTOR") && !strcmp(getenv("BENCH_REFACTOR"), "auto") ? AMPS_REFACTOR_AUTO
                                                                                                   : AMPS_REFACTOR_OFF;
        S[k] = bench_scen_scene(&cctx[k], &sc, spec, &so);
        t0 = amps_now();
        if (amps_scene_solve(&cctx[k], S[k]) != AMPS_OK) bench_die("first solve", cctx[k].msg);
        t_amps_setup[k] = amps_now() - t0;
    }
    if (nconf == 0) bench_die("BENCH_AMPS", "no configuration");
    bench_sys_build(&ctx, &sc, M, &S0);
    /* equations by node, kept current as cuts append copies (= bench_sys numbering) */
    ndof = (amps_int *)bench_alloc(sizeof(amps_int) * 3 * (size_t)sc.cap);
    memcpy(ndof, S0.dof, sizeof(amps_int) * 3 * (size_t)sc.nn0);
    ndofc = S0.n;
    {
        int ncap = S0.n + 3 * (steps + 1);
        Lset = (int *)bench_alloc(sizeof(int) * (size_t)ncap);
        inL = (unsigned char *)bench_alloc((size_t)ncap);
        udcon = (unsigned char *)bench_alloc((size_t)ncap);
        uprev = (double *)bench_alloc(sizeof(double) * 3 * (size_t)sc.cap);
        xprev = (double *)bench_alloc(sizeof(double) * (size_t)ncap);
        x = (double *)bench_alloc(sizeof(double) * (size_t)ncap);
        xref = (double *)bench_alloc(sizeof(double) * (size_t)ncap);
        work = (double *)bench_alloc(sizeof(double) * (size_t)ncap);
        xud = (double *)bench_alloc(sizeof(double) * (size_t)ncap);
        for (k = 0; k < NTOL; k++) sn.x[k] = (double *)bench_alloc(sizeof(double) * (size_t)ncap);
        updown_init(&ud, &S0, cut ? 3 * (steps + 1) : 0);
        gm_init(&ctx, &gm, amps_scene_factor(S[0]), &S0, ncap);
    }
    {
        const amps_factor *F = amps_scene_factor(S[0]);
        printf("%s %s: %d nodes, %d equations, nnz(L) %.0f (CHOLMOD padded %.0f), path %d;"
               " setup: amps %.2f s, updown %.2f s\n",
               spec, argv[2], sc.nn0, S0.n, amps_factor_nnz(F), ud.lnz0, sc.cp.npath, t_amps_setup[0], ud.t_setup);
        snprintf(metapath, sizeof(metapath), "%.*s_meta.csv", (int)(strlen(out) > 4 ? strlen(out) - 4 : strlen(out)),
                 out);
        meta = fopen(metapath, "w");
        if (!meta) bench_die(metapath, "cannot write");
        fprintf(meta, "mesh,exp,nodes,n0,nnzL,nnzL_updown,height,t_setup_amps,t_setup_updown,path,steps,every\n");
        fprintf(meta, "%s,%s,%d,%d,%.0f,%.0f,%ld,%.4f,%.4f,%d,%d,%d\n", spec, argv[2], sc.nn0, S0.n, amps_factor_nnz(F),
                ud.lnz0, (long)F->height, t_amps_setup[0], ud.t_setup, sc.cp.npath, steps, every);
        fclose(meta);
    }
    csv = fopen(out, "w");
    if (!csv) bench_die(out, "cannot write");
    fprintf(csv, "step,method,tol,time,iters,relres,relerr,conv,dim,nsys,t1,t2,t3,t4,t5,t6\n");
    for (st = 1; st <= steps; st++) {
        double t_conf[MAXCONF], res_conf[MAXCONF], t_ud;
        amps_update_stats us[MAXCONF];
        int sampled, d, fail = 0;
        memcpy(uprev, amps_scene_displacements(S[0]), sizeof(double) * 3 * (size_t)M->nnode);
        if (tmax > 0 && amps_now() - t_start > tmax) {
            printf("  stopped after step %d: BENCH_TMAX = %g s reached\n", st - 1, tmax);
            break;
        }
        if (!bench_scen_next(&ctx, &sc, M, &s)) break;
        cur_step = st;
        for (k = 0; k < nconf; k++) {
            double t0 = amps_now();
            amps_status rc = bench_scen_apply(&cctx[k], S[k], &sc, &s);
            if (rc == AMPS_OK) rc = amps_scene_solve(&cctx[k], S[k]);
            t_conf[k] = amps_now() - t0;
            if (rc != AMPS_OK) {
                if (k > 0) bench_die("amps configurations disagree", cctx[k].msg);
                fprintf(stderr, "step %d: %s (skipped)\n", st, cctx[k].msg);
                fail = 1;
                break;
            }
            amps_update_get_stats(amps_scene_engine(S[k]), &us[k]);
            amps_scene_residual(&cctx[k], S[k], &res_conf[k]);
        }
        if (fail) {
            bench_scen_undo(&ctx, &sc, M, &s);
            st--;
            continue;
        }
        /* bookkeeping (not timed): new equations, the changed set of [Interactive cutting] */
        if (cut) {
            int q, a;
            for (d = 0; d < 3; d++) ndof[3 * s.vc + d] = ndof[3 * s.node + d] >= 0 ? ndofc++ : -1;
            uprev[3 * s.vc] = uprev[3 * s.node];
            uprev[3 * s.vc + 1] = uprev[3 * s.node + 1];
            uprev[3 * s.vc + 2] = uprev[3 * s.node + 2];
            for (q = -1; q < s.nmoved; q++)
                for (a = 0; a < 4; a++) {
                    int w = q < 0 ? (a == 0 ? s.node : -1) : (int)M->tet[4 * s.moved[q] + a];
                    if (w >= 0)
                        for (d = 0; d < 3; d++) {
                            int e = (int)ndof[3 * w + d];
                            if (e >= 0 && !inL[e]) {
                                inL[e] = 1;
                                Lset[nL++] = e;
                            }
                        }
                }
        } else {
            for (d = 0; d < 3; d++) {
                int e = (int)ndof[3 * s.node + d];
                if (e >= 0 && !inL[e]) {
                    inL[e] = 1;
                    Lset[nL++] = e;
                }
            }
            for (d = 0; d < 3; d++) uprev[3 * s.node + d] = s.u[d];
        }
        t_ud = updown_step(&ud, M, ndof, &s, &sc, S0.Kf, udcon, xud);
        sampled = st == 1 || st % every == 0 || st == steps || sc.cp.ip >= sc.cp.npath;
        if (!sampled) {
            for (k = 0; k < nconf; k++)
                put(conf[k], 0, t_conf[k], 0, res_conf[k], -1, 1, us[k].dim, us[k].nsys, us[k].t_step);
            put("chol_updown", 0, t_ud, 0, -1, -1, 1, ndofc, 0, NULL);
        } else {
            bench_sys Sy;
            int ti, prec;
            bench_sys_build(&ctx, &sc, M, &Sy);
            if (Sy.n != ndofc) bench_die("numbering", "equation count differs from the bookkeeping");
            nsampled++;
            reference(&Sy, xref, work, Sy.n <= simpl_maxn && (nsampled == 1 || st == steps));
            for (k = 0; k < nconf; k++) {
                bench_sys_from_disp(&Sy, amps_scene_displacements(S[k]), x);
                put(conf[k], 0, t_conf[k], 0, bench_sys_relres(&Sy, x, work), bench_sys_relerr(&Sy, x, xref), 1,
                    us[k].dim, us[k].nsys, us[k].t_step);
            }
            put("chol_updown", 0, t_ud, 0, bench_sys_relres(&Sy, xud, work), bench_sys_relerr(&Sy, xud, xref), 1, Sy.n,
                0, NULL);
            bench_sys_from_disp(&Sy, uprev, xprev);
            for (prec = 0; prec < 2 * iter; prec++) {
                bench_cg_run(&Sy, xprev, prec, cg_maxit, &sn);
                for (ti = 0; ti < NTOL; ti++)
                    put(prec ? "cg_jacobi" : "cg_none", tols[ti], sn.t[ti], sn.it[ti],
                        bench_sys_relres(&Sy, sn.x[ti], work), bench_sys_relerr(&Sy, sn.x[ti], xref), sn.conv[ti], Sy.n,
                        0, NULL);
            }
            for (prec = 0; prec < 3 * iter; prec++) {
                static const char *gname[3] = {"gmres_none", "gmres_D", "gmres_tri"};
                gm_run(&gm, &Sy, Lset, nL, xprev, prec, gm_maxit, gm_restart, &sn);
                for (ti = 0; ti < NTOL; ti++)
                    put(gname[prec], tols[ti], sn.t[ti], sn.it[ti], bench_sys_relres(&Sy, sn.x[ti], work),
                        bench_sys_relerr(&Sy, sn.x[ti], xref), sn.conv[ti], Sy.n, nL, NULL);
            }
            bench_sys_free(&ctx, &Sy);
            printf("  step %d: amps %.2f ms, updown %.2f ms, |Lset| %d\n", st, 1e3 * t_conf[0], 1e3 * t_ud, nL);
            fflush(stdout);
        }
        fflush(csv);
    }
    fclose(csv);
    {
        double lnz = 0;
        for (k = 0; k < ud.N; k++) lnz += ((int *)ud.L->nz)[k];
        printf("  CHOLMOD updown: nnz(L) %.0f initially, %.0f after the run\n", ud.lnz0, lnz);
    }
    updown_free(&ud);
    gm_free(&ctx, &gm);
    for (k = 0; k < nconf; k++) amps_scene_free(&cctx[k], S[k]);
    amps_mesh_free(&ctx, M);
    bench_sys_free(&ctx, &S0);
    bench_scen_free(&sc);
    for (k = 0; k < NTOL; k++) free(sn.x[k]);
    free(s.moved);
    free(ndof);
    free(Lset);
    free(inL);
    free(udcon);
    free(uprev);
    free(xprev);
    free(x);
    free(xref);
    free(work);
    free(xud);
    return 0;
}
