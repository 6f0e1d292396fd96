/* bench/factor: orderings, symbolic analysis, numeric LDL^T and solves of amps.h against CHOLMOD
   on the stiffness matrix of one mesh.

   usage: factor <mesh> <out.csv>
     mesh: beam:<h>   amps_mesh_beam(h), nodes with z < 0.5 fixed
           brick:<R>  amps_mesh_brick(R), nodes with z < 1e-9 fixed
           a TetGen .node / .msh / .mesh file (amps_mesh_read), the nodes in the lowest 4% of the
           y range fixed (as bench/harness does)
   Material E = 1000, nu = 0.3. K = upper triangle from amps_mesh_number_dofs + amps_mesh_assemble.
   Prints one table row and appends one row to out.csv (the header first if the file is new or empty).

   Measured (wall clock, omp_get_wtime; amps with the current OMP_NUM_THREADS, CHOLMOD simplicial is
   sequential, CHOLMOD supernodal uses whatever threads its BLAS takes):
   - nnz(L) with the unit diagonal for: our AMD (block 3), CHOLMOD AMD, CHOLMOD METIS (cholmod_analyze,
     its own METIS), our ND with the node coordinates (block 3) and our AUTO (block 3, coordinates).
     Our orderings come from amps_order; their nnz(L) is the exact symbolic count (the ColCount of a
     CHOLMOD simplicial symbolic analysis with the perm given, no postorder), so no L is allocated for
     them; for the ND perm it is checked against amps_factor_nnz.
   - ordering time of our ND (amps_order), and analysis time: amps_analyze with that perm given as
     AMPS_ORDER_GIVEN (symbolic only: etree, counts, groups, allocation of L); CHOLMOD's analysis
     with the same perm given (cholmod_analyze_p, CHOLMOD_GIVEN, postorder off), simplicial.
   - numeric factorization, all three on the same (our ND) permutation: amps_factorize; CHOLMOD
     simplicial LDL^T (final_ll = 0); CHOLMOD supernodal LL^T. Best of 3 (of 2 when the first takes
     more than 2 s). The repetitions refactorize the same factor object (L already allocated).
   - full solve, best of 5: amps_solve with caller work; cholmod_solve2 (cholmod_solve with reused
     workspace) on the simplicial and the supernodal factors.
   - single-nonzero right-hand side: amps_lsolve_sparse and amps_ltsolve_partial (one requested
     index) for 50 random indices, mean time and mean closure size.
   - relative residuals ||K x - b|| / ||b||.
   Each factor is freed before the next one is built (the 50k-node bunny has nnz(L) ~ 75M).
   Build: cc -std=c99 -O2 -fopenmp -I. -I/usr/include/suitesparse -o build/bench/factor bench/factor.c -lcholmod -lm */
#define AMPS_IMPLEMENTATION
#include "../amps.h"
#include "bench.h"
#include <cholmod.h>

#define NSPARSE 50 /* random indices for the single-nonzero solves */


static int nthreads(void) {
#ifdef _OPENMP
    return omp_get_max_threads();
#else
    return 1;
#endif
}

static unsigned long rng_state = 12345u;
static unsigned long rng(void) {
    rng_state = rng_state * 6364136223846793005ul + 1442695040888963407ul;
    return (rng_state >> 33) & 0x7fffffffu;
}

static double relres(const amps_csc *K, const double *x, const double *b, double *r) {
    amps_int i, n = K->ncol;
    double nr = 0, nb = 0;
    amps_csc_symv(K, AMPS_UPPER, x, r);
    for (i = 0; i < n; i++) {
        nr += (r[i] - b[i]) * (r[i] - b[i]);
        nb += b[i] * b[i];
    }
    return nb > 0 ? sqrt(nr / nb) : sqrt(nr);
}

/* nnz(L) incl. diagonal of a CHOLMOD simplicial symbolic analysis: with perm given (ordering =
   CHOLMOD_GIVEN, no postorder) or with CHOLMOD's own ordering method. *t = analysis time. */
static double chol_count(cholmod_sparse *A, int *perm, int ordering, cholmod_common *c, double *t) {
    cholmod_factor *L;
    double lnz = 0, t0;
    size_t j;
    c->nmethods = 1;
    c->method[0].ordering = ordering;
    c->postorder = ordering != CHOLMOD_GIVEN;
    c->supernodal = CHOLMOD_SIMPLICIAL;
    t0 = amps_now();
    L = ordering == CHOLMOD_GIVEN ? cholmod_analyze_p(A, perm, NULL, 0, c) : cholmod_analyze(A, c);
    if (t) *t = amps_now() - t0;
    if (!L) bench_die("cholmod_analyze", "failed");
    if (ordering != CHOLMOD_GIVEN && L->ordering != ordering)
        fprintf(stderr, "factor: warning: CHOLMOD used ordering %d instead of %d\n", L->ordering, ordering);
    for (j = 0; j < L->n; j++) lnz += ((int *)L->ColCount)[j];
    cholmod_free_factor(&L, c);
    return lnz;
}

/* our ordering, timed; nnz(L) by the symbolic count */
static int *our_order(amps_ctx *ctx, const amps_csc *K, amps_ordering method, const double *coords, double *t) {
    amps_order_opts o;
    amps_int *p = (amps_int *)malloc(sizeof(amps_int) * (size_t)K->ncol + 1);
    int *ip = (int *)malloc(sizeof(int) * (size_t)K->ncol + 1);
    amps_int k;
    double t0;
    memset(&o, 0, sizeof(o));
    o.method = method;
    o.block = 3;
    o.coords = coords;
    t0 = amps_now();
    if (amps_order(ctx, K, AMPS_UPPER, &o, p) != AMPS_OK) bench_die("amps_order", ctx->msg);
    *t = amps_now() - t0;
    for (k = 0; k < K->ncol; k++) ip[k] = (int)p[k];
    free(p);
    return ip;
}

/* adaptive repetitions: 3, or 2 when the first run takes more than 2 s */
#define NREP(first) ((first) > 2.0 ? 2 : 3)

int main(int argc, char **argv) {
    amps_ctx ctx;
    amps_mesh *m;
    const char *spec, *out;
    amps_int nn, v, n, k, *dof, nfree = 0;
    unsigned char *fixed;
    double *coords, lo[3], hi[3];
    amps_csc *K;
    cholmod_common c;
    cholmod_sparse *A;
    cholmod_factor *L;
    cholmod_dense *B, *X = NULL, *Y = NULL, *E = NULL;
    amps_factor *F;
    amps_order_opts go;
    int *p_amd, *p_nd, *p_auto, nthr, r, nrep, i;
    double t0, t, *b, *x, *w, *y0, *y, *xs;
    amps_int *clos;
    amps_marker mk;
    /* results */
    double nnzK, l_amd, l_camd, l_metis, l_nd, l_auto, l_nd_amps, t_amd, t_nd, t_auto, t_camd, t_metis;
    double t_ana, t_cana_s, t_cana_S, flops, t_f = 1e300, t_fs = 1e300, t_fS = 1e300;
    double t_s = 1e300, t_ss = 1e300, t_sS = 1e300, t_lsp = 0, t_ltp = 0, clos_avg = 0;
    double res, res_s, res_S, err_ltp = 0;
    FILE *csv;

    if (argc < 3) {
        fprintf(stderr, "usage: factor <beam:h|brick:R|mesh file> <out.csv>\n");
        return 2;
    }
    spec = argv[1];
    out = argv[2];
    amps_ctx_init(&ctx);
    nthr = nthreads();

    /* mesh, fixed nodes, K */
    m = bench_mesh(&ctx, spec);
    nn = m->nnode;
    bench_bbox(m, lo, hi);
    fixed = bench_base(m, 1, lo, hi); /* a file: the bunny's base; beam, brick: the face z = 0 */
    if (!strncmp(spec, "beam:", 5))
        for (v = 0; v < nn; v++) fixed[v] = m->xyz[3 * v + 2] < 0.5;
    else if (!strncmp(spec, "brick:", 6))
        for (v = 0; v < nn; v++) fixed[v] = m->xyz[3 * v + 2] < 1e-9;
    dof = (amps_int *)malloc(sizeof(amps_int) * 3 * (size_t)nn);
    n = amps_mesh_number_dofs(m, fixed, dof);
    if (n <= 0) bench_die(spec, "no free DOFs");
    K = amps_mesh_assemble(&ctx, m, dof, n);
    if (!K) bench_die("amps_mesh_assemble", ctx.msg);
    nnzK = (double)K->p[n];
    /* coordinates of the free nodes in DOF-block order (as amps_scene_prepare does) */
    coords = (double *)malloc(sizeof(double) * (size_t)n);
    for (v = 0; v < nn; v++)
        if (dof[3 * v] >= 0) {
            for (k = 0; k < 3; k++) coords[3 * nfree + k] = m->xyz[3 * v + k];
            nfree++;
        }
    if (3 * nfree != n) bench_die(spec, "free nodes do not have 3 consecutive DOFs each");
    amps_mesh_free(&ctx, m);
    free(fixed);
    free(dof);

    /* CHOLMOD copy of K (upper, stype 1) */
    cholmod_start(&c);
    A = cholmod_allocate_sparse((size_t)n, (size_t)n, (size_t)K->p[n], 1, 1, 1, CHOLMOD_REAL, &c);
    if (!A) bench_die("cholmod_allocate_sparse", "out of memory");
    for (k = 0; k <= n; k++) ((int *)A->p)[k] = (int)K->p[k];
    for (k = 0; k < K->p[n]; k++) {
        ((int *)A->i)[k] = (int)K->i[k];
        ((double *)A->x)[k] = K->x[k];
    }

    /* orderings and their fill */
    p_amd = our_order(&ctx, K, AMPS_ORDER_AMD, NULL, &t_amd);
    p_nd = our_order(&ctx, K, AMPS_ORDER_ND, coords, &t_nd);
    p_auto = our_order(&ctx, K, AMPS_ORDER_AUTO, coords, &t_auto);
    l_amd = chol_count(A, p_amd, CHOLMOD_GIVEN, &c, NULL);
    l_nd = chol_count(A, p_nd, CHOLMOD_GIVEN, &c, &t_cana_s);
    l_auto = chol_count(A, p_auto, CHOLMOD_GIVEN, &c, NULL);
    l_camd = chol_count(A, NULL, CHOLMOD_AMD, &c, &t_camd);
    l_metis = chol_count(A, NULL, CHOLMOD_METIS, &c, &t_metis);
    free(p_amd);
    free(p_auto);

    /* right-hand side, solution vectors */
    b = (double *)malloc(sizeof(double) * (size_t)n);
    x = (double *)malloc(sizeof(double) * (size_t)n);
    w = (double *)malloc(sizeof(double) * (size_t)n);
    for (k = 0; k < n; k++) b[k] = (double)rng() / 2147483648.0 - 0.5;

    /* ---- ours: analysis with the ND perm given, factorization, solves ---- */
    memset(&go, 0, sizeof(go));
    go.method = AMPS_ORDER_GIVEN;
    go.block = 3;
    {
        amps_int *pg = (amps_int *)malloc(sizeof(amps_int) * (size_t)n);
        for (k = 0; k < n; k++) pg[k] = p_nd[k];
        go.perm = pg;
        t0 = amps_now();
        F = amps_analyze(&ctx, K, AMPS_UPPER, &go);
        t_ana = amps_now() - t0;
        free(pg);
    }
    if (!F) bench_die("amps_analyze", ctx.msg);
    l_nd_amps = amps_factor_nnz(F);
    if (l_nd_amps != l_nd)
        fprintf(stderr, "factor: warning: nnz(L) of the ND perm: amps %.0f, CHOLMOD symbolic %.0f\n", l_nd_amps, l_nd);
    for (r = 0, nrep = 3; r < nrep; r++) {
        t0 = amps_now();
        if (amps_factorize(&ctx, F, K) != AMPS_OK) bench_die("amps_factorize", ctx.msg);
        t = amps_now() - t0;
        if (r == 0) nrep = NREP(t);
        if (t < t_f) t_f = t;
    }
    for (r = 0; r < 5; r++) {
        t0 = amps_now();
        if (amps_solve(&ctx, F, b, x, w) != AMPS_OK) bench_die("amps_solve", ctx.msg);
        t = amps_now() - t0;
        if (t < t_s) t_s = t;
    }
    res = relres(K, x, b, w);
    /* single-nonzero right-hand sides, permuted numbering */
    clos = (amps_int *)malloc(sizeof(amps_int) * (size_t)n);
    y0 = (double *)malloc(sizeof(double) * (size_t)n);
    y = (double *)malloc(sizeof(double) * (size_t)n);
    xs = (double *)calloc((size_t)n, sizeof(double));
    if (amps_marker_init(&ctx, &mk, n) != AMPS_OK) bench_die("amps_marker_init", ctx.msg);
    for (k = 0; k < n; k++) y0[k] = b[F->perm[k]];
    amps_lsolve(F, y0);
    amps_dsolve(F, y0);
    memcpy(y, y0, sizeof(double) * (size_t)n);
    for (i = 0; i < NSPARSE; i++) {
        amps_int orig = (amps_int)(rng() % (unsigned long)n), kk = F->iperm[orig], cnt, j;
        double d;
        xs[kk] = 1.0;
        t0 = amps_now();
        cnt = amps_lsolve_sparse(F, 1, &kk, xs, clos, &mk);
        t_lsp += amps_now() - t0;
        clos_avg += (double)cnt;
        for (j = 0; j < cnt; j++) xs[clos[j]] = 0.0;
        t0 = amps_now();
        cnt = amps_ltsolve_partial(F, 1, &kk, y, clos, &mk);
        t_ltp += amps_now() - t0;
        d = fabs(y[kk] - x[orig]) / (fabs(x[orig]) + 1e-300);
        if (d > err_ltp) err_ltp = d;
        for (j = 0; j < cnt; j++) y[clos[j]] = y0[clos[j]];
    }
    t_lsp /= NSPARSE;
    t_ltp /= NSPARSE;
    clos_avg /= NSPARSE;
    if (err_ltp > 1e-8)
        fprintf(stderr, "factor: warning: amps_ltsolve_partial differs from amps_solve by %.1e\n", err_ltp);
    amps_marker_free(&ctx, &mk);
    free(clos);
    free(y0);
    free(y);
    free(xs);
    amps_factor_free(&ctx, F);

    /* ---- CHOLMOD on the same permutation ---- */
    B = cholmod_allocate_dense((size_t)n, 1, (size_t)n, CHOLMOD_REAL, &c);
    memcpy(B->x, b, sizeof(double) * (size_t)n);
    c.nmethods = 1;
    c.method[0].ordering = CHOLMOD_GIVEN;
    c.postorder = 0;
    /* simplicial LDL^T */
    c.supernodal = CHOLMOD_SIMPLICIAL;
    c.final_ll = 0;
    L = cholmod_analyze_p(A, p_nd, NULL, 0, &c);
    if (!L) bench_die("cholmod_analyze_p (simplicial)", "failed");
    flops = c.fl;
    for (r = 0, nrep = 3; r < nrep; r++) {
        t0 = amps_now();
        if (!cholmod_factorize(A, L, &c) || L->minor < L->n) bench_die("cholmod_factorize (simplicial)", "failed");
        t = amps_now() - t0;
        if (r == 0) nrep = NREP(t);
        if (t < t_fs) t_fs = t;
    }
    for (r = 0; r < 5; r++) {
        t0 = amps_now();
        if (!cholmod_solve2(CHOLMOD_A, L, B, NULL, &X, NULL, &Y, &E, &c)) bench_die("cholmod_solve2", "failed");
        t = amps_now() - t0;
        if (t < t_ss) t_ss = t;
    }
    res_s = relres(K, (double *)X->x, b, w);
    cholmod_free_factor(&L, &c);
    /* supernodal LL^T */
    c.supernodal = CHOLMOD_SUPERNODAL;
    t0 = amps_now();
    L = cholmod_analyze_p(A, p_nd, NULL, 0, &c);
    t_cana_S = amps_now() - t0;
    if (!L) bench_die("cholmod_analyze_p (supernodal)", "failed");
    for (r = 0, nrep = 3; r < nrep; r++) {
        t0 = amps_now();
        if (!cholmod_factorize(A, L, &c) || L->minor < L->n) bench_die("cholmod_factorize (supernodal)", "failed");
        t = amps_now() - t0;
        if (r == 0) nrep = NREP(t);
        if (t < t_fS) t_fS = t;
    }
    for (r = 0; r < 5; r++) {
        t0 = amps_now();
        if (!cholmod_solve2(CHOLMOD_A, L, B, NULL, &X, NULL, &Y, &E, &c)) bench_die("cholmod_solve2", "failed");
        t = amps_now() - t0;
        if (t < t_sS) t_sS = t;
    }
    res_S = relres(K, (double *)X->x, b, w);
    cholmod_free_factor(&L, &c);
    cholmod_free_dense(&X, &c);
    cholmod_free_dense(&Y, &c);
    cholmod_free_dense(&E, &c);
    cholmod_free_dense(&B, &c);
    cholmod_free_sparse(&A, &c);
    cholmod_finish(&c);

    /* ---- report ---- */
    {
        double t_sbest = t_ss < t_sS ? t_ss : t_sS;
        printf("%-28s %3s %7s %9s | %10s %10s %5s | %10s %10s %5s %10s | %7s %7s %7s | %8s %8s %8s %6s %6s | "
               "%8s %8s %8s %6s | %8s %6s %8s | %7s %7s %7s\n",
               "mesh", "thr", "n", "nnz(K)", "L ourAMD", "L cAMD", "ratio", "L ourND", "L METIS", "ratio", "L AUTO",
               "ord ND", "anaGIV", "c.ana", "fact", "c.simpl", "c.super", "/simpl", "/super", "solve", "c.simpl",
               "c.super", "/best", "lsp1", "clos/n", "ltp1", "res", "c.simpl", "c.super");
        printf("%-28s %3d %7ld %9.0f | %10.0f %10.0f %5.3f | %10.0f %10.0f %5.3f %10.0f | %7.3f %7.3f %7.3f | "
               "%8.4f %8.4f %8.4f %6.2f %6.2f | %8.5f %8.5f %8.5f %6.2f | %8.2e %6.4f %8.2e | %7.1e %7.1e %7.1e\n",
               spec, nthr, (long)n, nnzK, l_amd, l_camd, l_amd / l_camd, l_nd, l_metis, l_nd / l_metis, l_auto, t_nd,
               t_ana, t_cana_s, t_f, t_fs, t_fS, t_f / t_fs, t_f / t_fS, t_s, t_ss, t_sS, t_s / t_sbest, t_lsp,
               clos_avg / (double)n, t_ltp, res, res_s, res_S);
        printf("  (times in s; orderings: amps_order; anaGIV = amps_analyze with the ND perm as AMPS_ORDER_GIVEN;"
               " c.ana = cholmod_analyze_p with it (simplicial); factorizations on the ND perm,"
               " %.2f GFlop (CHOLMOD count), ours %.2f GFlop/s;"
               " lsp1/ltp1 = amps_lsolve_sparse / amps_ltsolve_partial of one index, mean of %d,"
               " closure %.0f of %ld)\n",
               1e-9 * flops, 1e-9 * flops / t_f, NSPARSE, clos_avg, (long)n);
        fflush(stdout);
        csv = bench_csv(out,
                        "mesh,threads,n,nnzK,nnzL_amd,nnzL_cholmod_amd,ratio_amd,nnzL_nd,nnzL_cholmod_metis,"
                        "ratio_nd,nnzL_auto,t_order_amd,t_order_nd,t_order_auto,t_cholmod_amd,t_cholmod_metis,"
                        "t_analyze_given,t_cholmod_analyze_given_simpl,t_cholmod_analyze_given_super,flops,"
                        "t_factor,t_factor_cholmod_simpl,t_factor_cholmod_super,ratio_factor_simpl,"
                        "ratio_factor_super,t_solve,t_solve_cholmod_simpl,t_solve_cholmod_super,ratio_solve_best,"
                        "t_lsolve_sparse1,"
                        "closure1,closure1_frac,t_ltsolve_partial1,relres,relres_cholmod_simpl,relres_cholmod_super");
        if (!csv) bench_die(out, "cannot open for appending");
        fprintf(csv,
                "%s,%d,%ld,%.0f,%.0f,%.0f,%.4f,%.0f,%.0f,%.4f,%.0f,%.6e,%.6e,%.6e,%.6e,%.6e,%.6e,%.6e,%.6e,%.6e,"
                "%.6e,%.6e,%.6e,%.4f,%.4f,%.6e,%.6e,%.6e,%.4f,%.6e,%.1f,%.6f,%.6e,%.3e,%.3e,%.3e\n",
                spec, nthr, (long)n, nnzK, l_amd, l_camd, l_amd / l_camd, l_nd, l_metis, l_nd / l_metis, l_auto, t_amd,
                t_nd, t_auto, t_camd, t_metis, t_ana, t_cana_s, t_cana_S, flops, t_f, t_fs, t_fS, t_f / t_fs,
                t_f / t_fS, t_s, t_ss, t_sS, t_s / t_sbest, t_lsp, clos_avg, clos_avg / (double)n, t_ltp, res, res_s,
                res_S);
        fclose(csv);
    }
    free(p_nd);
    free(coords);
    free(b);
    free(x);
    free(w);
    amps_csc_free(&ctx, K);
    return 0;
}
