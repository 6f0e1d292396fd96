/* bench/order_metis: check of the METIS build (AMPS_USE_METIS). Orders a brick (or, with a
   negative argument, a beam) with AMPS_ORDER_METIS and AUTO and compares nnz(L) (counted by
   CHOLMOD) with CHOLMOD's own METIS ordering. Exit status 1 if an ordering fails.
   usage: order_metis [R]   (brick R, default 12; -h: beam 5x5xh)
   Build: see bench/run.sh (-DAMPS_USE_METIS ... -lcholmod -lmetis -lm). */
#define AMPS_IMPLEMENTATION
#include "amps.h"
#include <stdlib.h>
#include "tests/fe_util.h"
#include "tests/cholmod_ref.h"

int main(int argc, char **argv) {
    int R = argc > 1 ? atoi(argv[1]) : 12, *dof, *ti, *tj, n, nz, k, j, q, *Ap, *Ai, *cnt, *perm, m, bad = 0;
    double *tx, *Ax, ref;
    fe_mesh mesh = R > 0 ? fe_brick(R) : fe_beam(-R);
    amps_ctx ctx;
    amps_csc A;
    amps_order_opts o;
    amps_ordering meths[2] = {AMPS_ORDER_METIS, AMPS_ORDER_AUTO};
    amps_ctx_init(&ctx);
    (void)ref_solve; /* shared header helper not needed here */
    dof = (int *)malloc(sizeof(int) * 3 * mesh.nn);
    n = fe_number(&mesh, NULL, dof);
    nz = fe_assemble(&mesh, dof, 1.0, 0.3, &ti, &tj, &tx);
    /* upper CSC with duplicates summed, through amps_csc-independent counting */
    cnt = (int *)calloc((size_t)n + 1, sizeof(int));
    Ap = (int *)malloc(sizeof(int) * (n + 1));
    Ai = (int *)malloc(sizeof(int) * nz);
    Ax = (double *)malloc(sizeof(double) * nz);
    {
        int *mark = (int *)malloc(sizeof(int) * n), *ord = (int *)malloc(sizeof(int) * nz);
        int *rp = (int *)calloc((size_t)n + 1, sizeof(int));
        int *w = (int *)malloc(sizeof(int) * (n + 1)), *ord2 = (int *)malloc(sizeof(int) * nz);
        for (k = 0; k < nz; k++) {
            rp[ti[k] + 1]++;
            cnt[tj[k] + 1]++;
        }
        for (j = 0; j < n; j++) {
            rp[j + 1] += rp[j];
            cnt[j + 1] += cnt[j];
        }
        memcpy(w, rp, sizeof(int) * n);
        for (k = 0; k < nz; k++) ord[w[ti[k]]++] = k;
        memcpy(w, cnt, sizeof(int) * n);
        for (k = 0; k < nz; k++) ord2[w[tj[ord[k]]]++] = ord[k];
        for (j = 0; j < n; j++) mark[j] = -1;
        for (q = 0, j = 0; j < n; j++) {
            int start = q;
            Ap[j] = q;
            for (k = cnt[j]; k < cnt[j + 1]; k++) {
                int e = ord2[k];
                if (mark[ti[e]] >= start) Ax[mark[ti[e]]] += tx[e];
                else {
                    mark[ti[e]] = q;
                    Ai[q] = ti[e];
                    Ax[q++] = tx[e];
                }
            }
        }
        Ap[n] = q;
        free(mark);
        free(ord);
        free(rp);
        free(w);
        free(ord2);
    }
    A.nrow = A.ncol = n;
    A.p = Ap;
    A.i = Ai;
    A.x = Ax;
    perm = (int *)malloc(sizeof(int) * n);
    ref = ref_nnzL(n, Ap, Ai, Ax, NULL, CHOLMOD_METIS, NULL);
    for (m = 0; m < 2; m++) {
        amps_status s;
        memset(&o, 0, sizeof o);
        o.method = meths[m];
        o.block = 3;
        s = amps_order(&ctx, &A, AMPS_UPPER, &o, perm);
        if (s != AMPS_OK) {
            printf("%s: error %s\n", m ? "AUTO" : "METIS", ctx.msg);
            bad = 1;
            continue;
        }
        printf("%s %d n=%d  %-5s nnz(L) %.0f  (CHOLMOD METIS %.0f, ratio %.3f)\n", R > 0 ? "brick R" : "beam h",
               R > 0 ? R : -R, n, m ? "AUTO" : "METIS", ref_nnzL(n, Ap, Ai, Ax, perm, 0, NULL), ref,
               ref_nnzL(n, Ap, Ai, Ax, perm, 0, NULL) / ref);
    }
    free(dof);
    free(ti);
    free(tj);
    free(tx);
    free(cnt);
    free(Ap);
    free(Ai);
    free(Ax);
    free(perm);
    fe_free(&mesh);
    return bad;
}
