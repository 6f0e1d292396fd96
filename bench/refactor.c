/* bench/refactor: a long advancing cut with and without background re-factorization.

   usage: refactor <mesh> <steps> <on|off|paced> <out.csv> [tmax] [run]
     mesh: beam:<h> | brick:<R> | path to a TetGen .node / .msh / .mesh file
   Setup as in bench/harness (base held, opposing forces at the start of the cut). Each step cuts
   the next node of the path and solves (amps_scene_cut + amps_scene_solve, timed together).
   When the path is used up it is walked again with the plane normal along the next axis, so
   nodes are cut repeatedly. Cuts that would detach a piece are undone by the scene and skipped.
   on: the default policy (AUTO: the cost model starts background re-factorizations); off:
   refactor = OFF (the augmentation grows for ever).
   Per step (CSV): step time, |S u C|, re-factorizations swapped in so far, whether one is
   running, the time of a swap that happened in this step (0 otherwise), the residual every 50
   steps. The summary compares the median step time of steps 5-15 with the median and the mean
   of the last min(100, steps/5) steps. With on, the run then re-factors synchronously and cuts
   15 more steps (CSV policy "fresh"): their median over steps 5-15 is the rate a fresh base
   gives at the end of the run, the best any re-factorization policy can reach there. run: a
   label appended to the CSV policy (on2, fresh2, ...) of repeated runs into one file.
   paced: on, wall-clock paced as a user with a scalpel at 60 frames per second: a frame every
   1/60 s (sleep to its deadline) solves (amps_scene_solve, nothing to do unless a swap is
   ready), every third frame (50 ms) after a cut; the step time is that frame's cut + solve.
   The fresh steps are paced the same way (CSV policy "pfresh").
   Per re-factorization swapped in, the CSV gives its phases in the worker (ordering, symbolic
   analysis, numeric factorization, engine and catch-up), whether the base's ordering was kept
   and its fill against the last fresh ordering's; the summary gives their means.
   AMPS_REFACTOR_REUSE=0 turns the kept ordering off (a fresh one every time). */
#if !defined(_POSIX_C_SOURCE)
#define _POSIX_C_SOURCE 200112L /* nanosleep */
#endif
#include <time.h>
#define AMPS_IMPLEMENTATION
#include "../amps.h"
#include "bench.h"

/* One cut step: the next path node whose cut the scene accepts (bench_cut_next; cuts that would
   detach a piece are undone by the scene and skipped, counted in *nsk), then a solve. Returns
   the step time, -1 on error. */
static double cut_step(amps_ctx *ctx, amps_scene *S, bench_cut *cp, int *nsk, int st);

/* Paced: sleeps to the frame deadline *next (then advanced by 1/60 s), solving on each frame,
   until the third frame, which cuts and solves (cut_step). A late frame runs at once. */
static double paced_step(amps_ctx *ctx, amps_scene *S, bench_cut *cp, int *nsk, int st, double *next, int *frame) {
    for (;;) {
        double now = amps_now();
        if (*next > now) {
            struct timespec ts;
            double d = *next - now;
            ts.tv_sec = (time_t)d;
            ts.tv_nsec = (long)((d - (double)ts.tv_sec) * 1e9);
            nanosleep(&ts, NULL);
        }
        *next += 1.0 / 60;
        if ((*frame)++ % 3 == 0) return cut_step(ctx, S, cp, nsk, st);
        if (amps_scene_solve(ctx, S) != AMPS_OK) {
            fprintf(stderr, "step %d: frame solve: %s\n", st, ctx->msg);
            return -1;
        }
    }
}

static double cut_step(amps_ctx *ctx, amps_scene *S, bench_cut *cp, int *nsk, int st) {
    amps_status s;
    int node;
    double t0 = amps_now();
    while ((s = bench_cut_next(ctx, S, cp, &node)) == AMPS_ERR_SINGULAR_UPDATE) (*nsk)++;
    if (s != AMPS_OK) {
        fprintf(stderr, "step %d: cut at %d: %s\n", st, node, ctx->msg);
        return -1;
    }
    s = amps_scene_solve(ctx, S);
    if (s != AMPS_OK) {
        fprintf(stderr, "step %d: solve: %s\n", st, ctx->msg);
        return -1;
    }
    return amps_now() - t0;
}

int main(int argc, char **argv) {
    amps_ctx ctx;
    amps_scene *S;
    amps_scene_opts so;
    bench_cut cp;
    unsigned char *fixed;
    double *force, *t, first[11], last[100], worst_res = 0, fresh = 0;
    double tmax, t_run = 0, next = 0, ph[6] = {0, 0, 0, 0, 0, 0};
    int steps, on, st, nsk = 0, paced, frame = 0, nph = 0, nkept = 0;
    char name[256], pol[32], frl[32];
    const char *run = argc > 6 ? argv[6] : "";
    FILE *f;
    bench_model B;
    amps_update_stats uend;
    if (argc < 5) {
        fprintf(stderr, "usage: refactor <mesh> <steps> <on|off> <out.csv> [tmax] [run]\n");
        return 2;
    }
    steps = atoi(argv[2]);
    on = strcmp(argv[3], "off") != 0;
    paced = strcmp(argv[3], "paced") == 0;
    tmax = argc > 5 ? atof(argv[5]) : 0;
    snprintf(pol, sizeof(pol), "%s%s", paced ? "paced" : on ? "on" : "off", run);
    snprintf(frl, sizeof(frl), "%sfresh%s", paced ? "p" : "", run);
    amps_ctx_init(&ctx);
    bench_mesh_name(argv[1], name, sizeof(name));
    bench_scene_opts(&so);
    so.update.refactor = on ? AMPS_REFACTOR_AUTO : AMPS_REFACTOR_OFF;
    if (getenv("AMPS_REFACTOR_RATIO")) so.update.refactor_ratio = atof(getenv("AMPS_REFACTOR_RATIO"));
    if (getenv("AMPS_REFACTOR_REUSE")) so.update.refactor_reuse = atoi(getenv("AMPS_REFACTOR_REUSE"));
    if (getenv("AMPS_REFACTOR_ORDER"))
        so.update.refactor_order.method = !strcmp(getenv("AMPS_REFACTOR_ORDER"), "nd") ? AMPS_ORDER_ND : AMPS_ORDER_AMD;
    bench_model_init(&ctx, argv[1], &so, &B);
    S = B.S;
    fixed = B.fixed;
    force = B.force;
    cp = B.cp;
    cp.wrap = 1;
    t = (double *)malloc(sizeof(double) * (size_t)steps);
    if (amps_scene_solve(&ctx, S) != AMPS_OK) {
        fprintf(stderr, "first solve: %s\n", ctx.msg);
        return 1;
    }
    f = bench_csv(argv[4], "mesh,policy,step,t_step,nsys,nrefactor,running,t_swap,t_refactor,relres,lu_cols,"
                           "t_order,t_symbolic,t_numeric,t_catchup,kept,fill");
    next = amps_now();
    for (st = 0; st < steps; st++) {
        amps_update_stats us;
        int nref0;
        double res = -1;
        amps_update_get_stats(amps_scene_engine(S), &us);
        nref0 = (int)us.nrefactor;
        t[st] = paced ? paced_step(&ctx, S, &cp, &nsk, st, &next, &frame) : cut_step(&ctx, S, &cp, &nsk, st);
        if (t[st] < 0) return 1;
        t_run += t[st];
        if (st % 50 == 49 && amps_scene_residual(&ctx, S, &res) == AMPS_OK && res > worst_res) worst_res = res;
        amps_update_get_stats(amps_scene_engine(S), &us);
        if ((int)us.nrefactor > nref0) {
            ph[0] += us.t_refactor;
            ph[1] += us.t_refactor_order;
            ph[2] += us.t_refactor_symbolic;
            ph[3] += us.t_refactor_numeric;
            ph[4] += us.t_refactor_catchup;
            ph[5] += us.t_swap;
            nph++;
            nkept += us.refactor_order_kept > 0;
        }
        if (f) {
            int sw = (int)us.nrefactor > nref0;
            fprintf(f, "%s,%s,%d,%.6e,%d,%d,%d,%.6e,%.6e,%.3e,%d,%.6e,%.6e,%.6e,%.6e,%d,%.4f\n", name, pol, st + 1,
                    t[st], (int)us.nsys, (int)us.nrefactor, us.refactor_running, sw ? us.t_swap : 0.0,
                    sw ? us.t_refactor : 0.0, res, (int)us.lu_cols, sw ? us.t_refactor_order : 0.0,
                    sw ? us.t_refactor_symbolic : 0.0, sw ? us.t_refactor_numeric : 0.0,
                    sw ? us.t_refactor_catchup : 0.0, sw ? us.refactor_order_kept : -1, sw ? us.refactor_fill : 0.0);
        }
        if (tmax > 0 && t_run > tmax && st + 1 < steps) { /* time guard: the summary covers the steps run */
            printf("  stopped after %d of %d steps: %.0f s of step time (tmax %.0f s)\n", st + 1, steps, t_run, tmax);
            steps = st + 1;
            break;
        }
    }
    amps_update_get_stats(amps_scene_engine(S), &uend);
    if (on) { /* a fresh base at the end: synchronous re-factorization, then 15 steps */
        double tf[15];
        int k;
        amps_update *E = amps_scene_engine(S);
        amps_update_stats a, c;
        if (amps_update_refactor_start(&ctx, E) < 0 || amps_update_refactor_wait(&ctx, E) < 0) { /* kept */
            fprintf(stderr, "kept re-factorization at the end: %s\n", ctx.msg);
            return 1;
        }
        amps_update_get_stats(E, &a);
        if (amps_update_refactor(&ctx, E) != AMPS_OK) { /* fresh */
            fprintf(stderr, "re-factorization at the end: %s\n", ctx.msg);
            return 1;
        }
        amps_update_get_stats(E, &c);
        printf("%-10s synchronous at the end (ms): kept (%d) %.0f = ordering %.0f + symbolic %.0f + numeric %.0f + "
               "catch-up %.0f; fresh %.0f = %.0f + %.0f + %.0f + %.0f; nnz(L) kept / fresh x%.3f\n",
               name, a.refactor_order_kept, 1e3 * a.t_refactor, 1e3 * a.t_refactor_order, 1e3 * a.t_refactor_symbolic,
               1e3 * a.t_refactor_numeric, 1e3 * a.t_refactor_catchup, 1e3 * c.t_refactor, 1e3 * c.t_refactor_order,
               1e3 * c.t_refactor_symbolic, 1e3 * c.t_refactor_numeric, 1e3 * c.t_refactor_catchup,
               a.refactor_nnzL / c.refactor_nnzL);
        if (amps_scene_solve(&ctx, S) != AMPS_OK) {
            fprintf(stderr, "re-factorization at the end: %s\n", ctx.msg);
            return 1;
        }
        for (k = 0; k < 15; k++) {
            amps_update_stats us;
            tf[k] = paced ? paced_step(&ctx, S, &cp, &nsk, steps + k, &next, &frame)
                          : cut_step(&ctx, S, &cp, &nsk, steps + k);
            if (tf[k] < 0) return 1;
            amps_update_get_stats(amps_scene_engine(S), &us);
            if (f)
                fprintf(f, "%s,%s,%d,%.6e,%d,%d,%d,0,0,-1,%d,0,0,0,0,-1,0\n", name, frl, steps + k + 1, tf[k],
                        (int)us.nsys, (int)us.nrefactor, us.refactor_running, (int)us.lu_cols);
        }
        fresh = bench_median(tf + 4, 11);
    }
    if (f) fclose(f);
    { /* rate at the end: median and mean of the last min(100, steps/5) steps against the
           median of steps 5-15 */
        int k, nf = 0, nl = steps / 5 < 100 ? steps / 5 : 100;
        double mean = 0, m0, m1;
        for (k = 4; k < 15 && k < steps; k++) first[nf++] = t[k];
        for (k = 0; k < nl; k++) {
            last[k] = t[steps - 1 - k];
            mean += last[k] / nl;
        }
        m0 = bench_median(first, nf);
        m1 = bench_median(last, nl);
        printf("%-10s re-factorization %-3s  steps %d (skipped cuts %d)  step 5-15 median %.2f ms;"
               " last %d steps: median %.2f ms (x%.2f), "
               "mean %.2f ms (x%.2f)  |S u C| at the end %d  re-factorizations %d (failed %d)  worst residual %.1e\n",
               name, pol, steps, nsk, 1e3 * m0, nl, 1e3 * m1, m1 / m0, 1e3 * mean, mean / m0, (int)uend.nsys,
               (int)uend.nrefactor, (int)uend.refactor_failed, worst_res);
        if (nph)
            printf("%-10s %d jobs (%d kept the ordering): mean %.0f ms = ordering %.0f + symbolic %.0f + numeric %.0f"
                   " + catch-up %.0f (+ other %.0f); swap %.1f ms\n",
                   name, nph, nkept, 1e3 * ph[0] / nph, 1e3 * ph[1] / nph, 1e3 * ph[2] / nph, 1e3 * ph[3] / nph,
                   1e3 * ph[4] / nph, 1e3 * (ph[0] - ph[1] - ph[2] - ph[3] - ph[4]) / nph, 1e3 * ph[5] / nph);
        if (on)
            printf("%-10s fresh base after step %d: median %.2f ms (x%.2f of steps 5-15);"
                   " the last %d steps are x%.2f of it\n",
                   name, steps, 1e3 * fresh, fresh / m0, nl, m1 / fresh);
    }
    amps_scene_free(&ctx, S);
    free(fixed);
    free(force);
    free(t);
    free(cp.path);
    return 0;
}
