/* Sparse matrix basics: allocation, validation, assembly from triplets, symmetric product. */
#define AMPS_IMPLEMENTATION
#include "amps.h"
#include "amps_test.h"
#include <string.h>

/* Expects status s from amps_csc_check and a message containing the strings a and b (may be NULL). */
static void expect_check(const char *what, const amps_csc *A, amps_stype st, amps_status s, const char *a,
                         const char *b) {
    amps_ctx ctx;
    amps_status r;
    amps_ctx_init(&ctx);
    r = amps_csc_check(&ctx, A, st);
    CHECK(r == s && ctx.status == s, "%s: status %d, expected %d (%s)", what, (int)r, (int)s, ctx.msg);
    CHECK(!a || strstr(ctx.msg, a), "%s: message '%s' lacks '%s'", what, ctx.msg, a);
    CHECK(!b || strstr(ctx.msg, b), "%s: message '%s' lacks '%s'", what, ctx.msg, b);
}

/* Dense n x n symmetric matrix of A (stype part). */
static void to_dense(const amps_csc *A, amps_stype st, double *M) {
    int n = A->ncol, j, p;
    memset(M, 0, sizeof(double) * n * n);
    for (j = 0; j < n; j++)
        for (p = A->p[j]; p < A->p[j + 1]; p++) {
            int i = A->i[p];
            M[i + n * j] = A->x[p];
            if (st != AMPS_FULL) M[j + n * i] = A->x[p];
        }
}

int main(void) {
    amps_ctx ctx;
    amps_csc *A;
    int k;
    amps_ctx_init(&ctx);

    /* allocation */
    A = amps_csc_alloc(&ctx, 3, 4, 0, 1);
    CHECK(A && A->nrow == 3 && A->ncol == 4 && A->p[0] == 0 && A->p[4] == 0 && A->x, "alloc 3x4");
    amps_csc_free(&ctx, A);
    A = amps_csc_alloc(&ctx, 5, 5, 10, 0);
    CHECK(A && A->x == NULL && A->i, "alloc pattern");
    amps_csc_free(&ctx, A);
    amps_csc_free(&ctx, NULL);
    CHECK(amps_csc_alloc(&ctx, -1, 2, 0, 1) == NULL && ctx.status == AMPS_ERR_ARG, "alloc negative nrow");
    CHECK(amps_csc_alloc(&ctx, 2, 2, -3, 1) == NULL && ctx.status == AMPS_ERR_ARG, "alloc negative nzmax");

    /* amps_csc_check: a valid 4x4 upper matrix, then one violation at a time */
    {
        int p0[5] = {0, 1, 3, 4, 6}, i0[6] = {0, 0, 1, 2, 1, 3};
        double x0[6] = {4, 1, 4, 4, 1, 4};
        int p[5], i[6];
        double x[6];
        amps_csc M;
        M.nrow = M.ncol = 4;
        M.p = p;
        M.i = i;
        M.x = x;
#define RESET() (memcpy(p, p0, sizeof(p)), memcpy(i, i0, sizeof(i)), memcpy(x, x0, sizeof(x)), M.nrow = M.ncol = 4)
        RESET();
        expect_check("valid upper", &M, AMPS_UPPER, AMPS_OK, NULL, NULL);
        expect_check("upper as full", &M, AMPS_FULL, AMPS_OK, NULL, NULL);
        expect_check("upper as lower", &M, AMPS_LOWER, AMPS_ERR_PATTERN, "column 1", "row 0");
        expect_check("bad stype", &M, (amps_stype)5, AMPS_ERR_ARG, "stype", NULL);
        expect_check("NULL matrix", NULL, AMPS_UPPER, AMPS_ERR_ARG, NULL, NULL);
        M.nrow = -1;
        M.ncol = -1;
        expect_check("negative dims", &M, AMPS_UPPER, AMPS_ERR_ARG, "negative", NULL);
        RESET();
        M.nrow = 5;
        expect_check("non-square", &M, AMPS_UPPER, AMPS_ERR_ARG, "not square", NULL);
        RESET();
        p[0] = 1;
        expect_check("p[0] != 0", &M, AMPS_UPPER, AMPS_ERR_PATTERN, "p[0]", NULL);
        RESET();
        p[2] = 0;
        expect_check("decreasing p", &M, AMPS_UPPER, AMPS_ERR_PATTERN, "column 1", NULL);
        RESET();
        i[2] = 7;
        expect_check("row out of range", &M, AMPS_UPPER, AMPS_ERR_INDEX, "column 1", "row 7");
        RESET();
        i[0] = -2;
        expect_check("negative row", &M, AMPS_UPPER, AMPS_ERR_INDEX, "column 0", "row -2");
        RESET();
        i[4] = 3;
        i[5] = 1;
        expect_check("unsorted rows", &M, AMPS_UPPER, AMPS_ERR_PATTERN, "column 3", "row 1");
        RESET();
        i[4] = 3;
        expect_check("duplicate rows", &M, AMPS_UPPER, AMPS_ERR_PATTERN, "column 3", "row 3");
        RESET();
        i[3] = 3;
        expect_check("below diagonal in upper", &M, AMPS_UPPER, AMPS_ERR_PATTERN, "column 2", "row 3");
        RESET();
        x[3] = NAN;
        expect_check("NaN", &M, AMPS_UPPER, AMPS_ERR_VALUE, "column 2", "row 2");
        RESET();
        x[5] = -INFINITY;
        expect_check("-Inf", &M, AMPS_UPPER, AMPS_ERR_VALUE, "column 3", "row 3");
        RESET();
        M.x = NULL;
        expect_check("pattern only", &M, AMPS_UPPER, AMPS_OK, NULL, NULL);
        M.x = x;
        RESET();
        M.p = NULL;
        expect_check("NULL p", &M, AMPS_UPPER, AMPS_ERR_ARG, NULL, NULL);
        M.p = p;
        RESET();
        M.nrow = M.ncol = 0;
        expect_check("empty", &M, AMPS_UPPER, AMPS_OK, NULL, NULL);
        /* lower: the transpose */
        {
            int pl[5] = {0, 2, 4, 5, 6}, il[6] = {0, 1, 1, 3, 2, 3};
            amps_csc Lm;
            Lm.nrow = Lm.ncol = 4;
            Lm.p = pl;
            Lm.i = il;
            Lm.x = x0;
            expect_check("valid lower", &Lm, AMPS_LOWER, AMPS_OK, NULL, NULL);
            expect_check("lower as upper", &Lm, AMPS_UPPER, AMPS_ERR_PATTERN, "column 0", "row 1");
        }
#undef RESET
    }

    /* from_triplets: duplicates summed, either triangle mapped, sorted; against dense assembly */
    {
        static const amps_stype sts[3] = {AMPS_UPPER, AMPS_LOWER, AMPS_FULL};
        int n = 23, nz = 300, s, ok;
        int *ti = (int *)malloc(sizeof(int) * nz), *tj = (int *)malloc(sizeof(int) * nz);
        double *tx = (double *)malloc(sizeof(double) * nz), *M = (double *)malloc(sizeof(double) * n * n);
        double *R = (double *)malloc(sizeof(double) * n * n), *x = (double *)malloc(sizeof(double) * n);
        double *y = (double *)malloc(sizeof(double) * n), *yr = (double *)malloc(sizeof(double) * n);
        t_seed(3);
        for (k = 0; k < nz; k++) {
            ti[k] = t_int(n);
            tj[k] = t_int(n);
            tx[k] = t_unif() - 0.5;
        }
        memset(R, 0, sizeof(double) * n * n);
        for (k = 0; k < nz; k++) {
            R[ti[k] + n * tj[k]] += tx[k];
            if (ti[k] != tj[k]) R[tj[k] + n * ti[k]] += tx[k];
        }
        for (k = 0; k < n; k++) x[k] = t_unif();
        for (k = 0; k < n; k++) {
            int j;
            yr[k] = 0;
            for (j = 0; j < n; j++) yr[k] += R[k + n * j] * x[j];
        }
        for (s = 0; s < 3; s++) {
            A = amps_csc_from_triplets(&ctx, n, nz, ti, tj, tx, sts[s]);
            CHECK(A != NULL, "from_triplets stype %d: %s", sts[s], ctx.msg);
            if (!A) continue;
            CHECK(amps_csc_check(&ctx, A, sts[s]) == AMPS_OK, "from_triplets result invalid: %s", ctx.msg);
            to_dense(A, sts[s], M);
            for (k = 0, ok = 1; k < n * n; k++) ok &= fabs(M[k] - R[k]) < 1e-14;
            CHECK(ok, "from_triplets stype %d: values differ from dense assembly", sts[s]);
            amps_csc_symv(A, sts[s], x, y);
            CHECK(t_reldiff(n, y, yr) < 1e-14 && t_norm(n, y) > 0, "symv stype %d: %g", sts[s], t_reldiff(n, y, yr));
            amps_csc_free(&ctx, A);
        }
        /* finite element style: many duplicates of few entries */
        {
            int fi[6] = {0, 0, 1, 0, 1, 1}, fj[6] = {0, 1, 1, 0, 0, 1};
            double fx[6] = {1, 2, 3, 4, 5, 6};
            A = amps_csc_from_triplets(&ctx, 2, 6, fi, fj, fx, AMPS_UPPER);
            CHECK(A && A->p[2] == 3 && A->x[0] == 5 && A->x[1] == 7 && A->x[2] == 9 && A->i[1] == 0,
                  "duplicate summation");
            amps_csc_free(&ctx, A);
            A = amps_csc_from_triplets(&ctx, 2, 6, fi, fj, fx, AMPS_LOWER);
            CHECK(A && A->p[1] == 2 && A->i[1] == 1 && A->x[1] == 7, "lower duplicate summation");
            amps_csc_free(&ctx, A);
        }
        A = amps_csc_from_triplets(&ctx, 0, 0, NULL, NULL, NULL, AMPS_UPPER);
        CHECK(A && A->ncol == 0 && A->p[0] == 0, "empty from_triplets: %s", ctx.msg);
        amps_csc_free(&ctx, A);
        A = amps_csc_from_triplets(&ctx, 4, 0, NULL, NULL, NULL, AMPS_LOWER);
        CHECK(A && A->p[4] == 0, "no triplets: %s", ctx.msg);
        amps_csc_free(&ctx, A);
        /* rejections */
        ti[5] = n;
        CHECK(!amps_csc_from_triplets(&ctx, n, nz, ti, tj, tx, AMPS_UPPER) && ctx.status == AMPS_ERR_INDEX &&
                      strstr(ctx.msg, "triplet 5") && strstr(ctx.msg, "row 23"),
              "row out of range: %s", ctx.msg);
        ti[5] = 0;
        tj[7] = -1;
        CHECK(!amps_csc_from_triplets(&ctx, n, nz, ti, tj, tx, AMPS_FULL) && ctx.status == AMPS_ERR_INDEX &&
                      strstr(ctx.msg, "column -1"),
              "negative column: %s", ctx.msg);
        tj[7] = 0;
        tx[9] = NAN;
        CHECK(!amps_csc_from_triplets(&ctx, n, nz, ti, tj, tx, AMPS_UPPER) && ctx.status == AMPS_ERR_VALUE &&
                      strstr(ctx.msg, "triplet 9"),
              "NaN value: %s", ctx.msg);
        tx[9] = INFINITY;
        CHECK(!amps_csc_from_triplets(&ctx, n, nz, ti, tj, tx, AMPS_UPPER) && ctx.status == AMPS_ERR_VALUE,
              "Inf value");
        tx[9] = 0;
        CHECK(!amps_csc_from_triplets(&ctx, -1, nz, ti, tj, tx, AMPS_UPPER) && ctx.status == AMPS_ERR_ARG,
              "negative n");
        CHECK(!amps_csc_from_triplets(&ctx, n, -2, ti, tj, tx, AMPS_UPPER) && ctx.status == AMPS_ERR_ARG,
              "negative nz");
        CHECK(!amps_csc_from_triplets(&ctx, n, nz, NULL, tj, tx, AMPS_UPPER) && ctx.status == AMPS_ERR_ARG, "NULL ti");
        CHECK(!amps_csc_from_triplets(&ctx, n, nz, ti, tj, tx, (amps_stype)3) && ctx.status == AMPS_ERR_ARG,
              "bad stype");
        free(ti);
        free(tj);
        free(tx);
        free(M);
        free(R);
        free(x);
        free(y);
        free(yr);
    }
    return amps_t_end("test_sparse");
}
