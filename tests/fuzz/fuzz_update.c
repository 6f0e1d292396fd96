/* libFuzzer target: the update engine's public API (amps_update_*) driven by calls decoded from
   the input: random (also negative and out-of-range) indices, NaN/Inf, huge, tiny and denormal
   values, singular updates, add_dofs, constrain/release, set_rows, forces, commit / solve /
   discard, in any order, with small random capacities (growth on or off). Contract checked:
   no crash, leak or UB (ASan/UBSan); every failure returns a negative status that ctx also
   holds, with a message; after every successful solve on finite, moderate input the solution is
   finite. Input layout: 8 header bytes (size, seed, options), then one opcode byte per call
   followed by its operands. */
#include <stdlib.h>
#include <string.h>
#include <math.h>
#define AMPS_IMPLEMENTATION
#include "amps.h"

typedef struct rd {
    const unsigned char *p;
    size_t n, k;
} rd;
static unsigned rb(rd *r) { return r->k < r->n ? r->p[r->k++] : 0u; }
static int more(const rd *r) { return r->k < r->n; }

/* A value: mostly moderate numbers, sometimes special ones; *tame cleared for huge/tiny. */
static double rv(rd *r, int *tame) {
    unsigned b = rb(r);
    switch (b % 16) {
    case 0: *tame = 0; return NAN;
    case 1: *tame = 0; return b & 16 ? INFINITY : -INFINITY;
    case 2: *tame = 0; return b & 16 ? 1e300 : -1e300;
    case 3: *tame = 0; return 1e-300;
    case 4: *tame = 0; return 4.9e-324;
    case 5: return 0.0;
    case 6: return -0.0;
    case 7: {
        double d;
        unsigned char by[8];
        int i;
        for (i = 0; i < 8; i++) by[i] = (unsigned char)rb(r);
        memcpy(&d, by, 8);
        if (!(fabs(d) < 1e6 && (d == 0 || fabs(d) > 1e-6))) *tame = 0;
        return d;
    }
    default: return ((double)(int)rb(r) - 128.0) / 16.0;
    }
}

/* An index around the current dimension: mostly valid, sometimes negative or too large. */
static amps_int ri(rd *r, amps_int dim) {
    unsigned b = rb(r);
    if (b >= 250) return (amps_int)b - 260;         /* negative */
    if (b >= 240) return dim + (amps_int)(b - 240); /* out of range */
    return dim > 0 ? (amps_int)(b % (unsigned)dim) : 0;
}

static void check_status(const amps_ctx *ctx, amps_status s) {
    if (s < 0 && (ctx->status != s || ctx->msg[0] == 0)) abort();
}

int LLVMFuzzerTestOneInput(const unsigned char *data, size_t size);
int LLVMFuzzerTestOneInput(const unsigned char *data, size_t size) {
    rd r;
    amps_ctx ctx;
    amps_update_opts o;
    amps_csc *K = NULL;
    amps_factor *F = NULL;
    amps_update *U = NULL;
    amps_int n, k, nz = 0, *ti, *tj;
    double *tx, *x = NULL;
    unsigned seed, ops = 0;
    int tame = 1;
    r.p = data;
    r.n = size;
    r.k = 0;
    if (size < 8) return 0;
    amps_ctx_init(&ctx);
    ctx.nthreads = 1;
    n = 1 + (amps_int)(rb(&r) % 24);
    seed = rb(&r);
    /* base: SPD, diagonally dominant, a few couplings chosen by the seed */
    ti = (amps_int *)malloc(sizeof(amps_int) * 4 * (size_t)n);
    tj = (amps_int *)malloc(sizeof(amps_int) * 4 * (size_t)n);
    tx = (double *)malloc(sizeof(double) * 4 * (size_t)n);
    for (k = 0; k < n; k++) {
        ti[nz] = k;
        tj[nz] = k;
        tx[nz] = 4.0 + (double)((seed + (unsigned)k) % 5);
        nz++;
    }
    for (k = 0; k + 1 < n; k++) {
        ti[nz] = k;
        tj[nz] = k + 1;
        tx[nz] = -1.0;
        nz++;
    }
    for (k = 0; k + 3 < n; k += 1 + (amps_int)(seed % 3)) {
        ti[nz] = k;
        tj[nz] = k + 3;
        tx[nz] = 0.5;
        nz++;
    }
    K = amps_csc_from_triplets(&ctx, n, nz, ti, tj, tx, AMPS_UPPER);
    free(ti);
    free(tj);
    free(tx);
    if (!K) abort();
    F = amps_analyze(&ctx, K, AMPS_UPPER, NULL);
    if (!F || amps_factorize(&ctx, F, K) != AMPS_OK) abort();
    amps_update_opts_default(&o);
    {
        unsigned b0 = rb(&r), b1 = rb(&r), b2 = rb(&r), b3 = rb(&r), b4 = rb(&r), b5 = rb(&r);
        o.cap_mod = (amps_int)(b0 % 9);
        o.cap_new = (amps_int)(b1 % 7);
        o.cap_pending = (amps_int)(b2 % 9);
        o.grow = (int)(b3 & 1);
        o.formulation = (b3 & 2) ? AMPS_FORM_DUAL : AMPS_FORM_PRIMAL;
        o.xs_from_dense = (int)((b3 >> 2) & 1);
        o.refine = (int)((b3 >> 3) % 3);
        o.guard_tol = (b3 & 64) ? 1e-12 : 0.0;
        o.cap_delta = (amps_int)(b4 % 40);
        o.cap_vpool = (double)(b5 % 64);
    }
    U = amps_update_create(&ctx, K, AMPS_UPPER, F, &o);
    if (!U) {
        check_status(&ctx, ctx.status);
        goto done;
    }
    while (more(&r) && ops++ < 200) {
        amps_int dim = amps_update_dim(U), idx[4], cols[4], cp[5], ci[12];
        double val[12];
        amps_status s = AMPS_OK;
        unsigned op = rb(&r) % 12, m = 1 + rb(&r) % 4, a;
        switch (op) {
        case 0: {
            amps_int first = -1, cnt = (amps_int)(rb(&r) % 6) - 1;
            s = amps_update_add_dofs(&ctx, U, cnt, &first);
            if (s == AMPS_OK && cnt > 0 && first != dim) abort();
            break;
        }
        case 1:
            for (a = 0; a < m; a++) {
                idx[a] = ri(&r, dim);
                cols[a] = ri(&r, dim);
                val[a] = rv(&r, &tame);
            }
            s = amps_update_add(&ctx, U, (amps_int)m, idx, cols, val);
            break;
        case 2: {
            amps_int nrow = (amps_int)(m > 3 ? 3 : m), t = 0;
            cp[0] = 0;
            for (a = 0; a < (unsigned)nrow; a++) {
                unsigned e = rb(&r) % 5, q;
                idx[a] = ri(&r, dim);
                for (q = 0; q < e && t < 12; q++) {
                    ci[t] = ri(&r, dim);
                    val[t] = rv(&r, &tame);
                    t++;
                }
                cp[a + 1] = t;
            }
            s = amps_update_set_rows(&ctx, U, nrow, idx, cp, ci, val);
            break;
        }
        case 3:
            for (a = 0; a < m; a++) {
                idx[a] = ri(&r, dim);
                val[a] = rv(&r, &tame);
            }
            s = amps_update_constrain(&ctx, U, (amps_int)m, idx, val);
            break;
        case 4:
            for (a = 0; a < m; a++) idx[a] = ri(&r, dim);
            s = amps_update_release(&ctx, U, (amps_int)m, idx);
            break;
        case 5:
            for (a = 0; a < m; a++) {
                idx[a] = ri(&r, dim);
                val[a] = rv(&r, &tame);
            }
            s = amps_update_set_force(&ctx, U, (amps_int)m, idx, val);
            break;
        case 6: s = amps_update_commit(&ctx, U); break;
        case 7:
        case 8: {
            double *x2 = (double *)realloc(x, sizeof(double) * (size_t)(dim > 0 ? dim : 1));
            if (!x2) goto done;
            x = x2;
            s = amps_update_solve(&ctx, U, x);
            if (s == AMPS_OK) {
                amps_int d2 = amps_update_dim(U), q;
                double res = -1;
                if (d2 > dim) abort();
                if (tame)
                    for (q = 0; q < d2; q++)
                        if (!(x[q] - x[q] == 0)) abort(); /* finite input, finite answer */
                if (amps_update_residual(&ctx, U, &res) != AMPS_OK || (tame && !(res >= 0))) abort();
                (void)amps_update_reaction(U, ri(&r, d2));
                (void)amps_update_solution(U);
            }
            break;
        }
        case 9: amps_update_discard(U); break;
        case 10: {
            amps_update_stats st;
            double res;
            amps_update_get_stats(U, &st);
            if (st.dim < 0 || st.nsys < 0) abort();
            s = amps_update_residual(&ctx, U, &res);
            break;
        }
        default:
            /* bad pointers and counts */
            s = amps_update_add(&ctx, U, -1, idx, cols, val);
            if (s == AMPS_OK) abort();
            s = amps_update_constrain(&ctx, U, 1, NULL, val);
            if (s == AMPS_OK) abort();
            break;
        }
        check_status(&ctx, s);
    }
done:
    free(x);
    amps_update_free(&ctx, U);
    amps_factor_free(&ctx, F);
    amps_csc_free(&ctx, K);
    return 0;
}
