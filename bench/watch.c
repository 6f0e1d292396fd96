/* bench/watch: watch sets (amps_scene_watch + amps_scene_solve_watched) against the full solve.

   usage: watch <mesh> <reps> <cuts> <out.csv>
     mesh: beam:<h> | brick:<R> | path to a TetGen .node / .msh / .mesh file
   Setup as in bench/harness: the base held, the opposing forces at the start of the advancing
   cut, then <cuts> cut steps. Watch sets (surface = nodes of the faces of exactly one tet,
   cut faces included):
     surface    every surface node;
     random100  100 surface nodes drawn with a fixed seed;
     probe      one node: the surface node highest along the up axis.
   Per set: closure_L of the watched equations of the base factor (|closure| / n and the share of
   nnz(L) in its columns), and the medians over <reps> repetitions of amps_scene_solve and of
   amps_scene_solve_watched, each after a change of the force on the probe node (so no solve is
   cached), their ratio (the speed-up), the one-time cost of the first watched solve after
   amps_scene_watch (the closure), and the largest difference between the watched and the full
   displacements on the watched nodes relative to the largest watched displacement.
   Prints a table and appends one row per set to out.csv (header first if the file is new). */
#define AMPS_IMPLEMENTATION
#include "../amps.h"
#include "bench.h"

int main(int argc, char **argv) {
    amps_ctx ctx;
    amps_mesh *m;
    amps_scene *S;
    const amps_factor *F;
    amps_marker mk;
    const char *spec, *out;
    char name[256];
    int reps, ncuts, ndid = 0, up, nn0, nn, v, k, r, nsurf, probe = -1, set, sign = 1;
    double *force, *tf, *tw, *xw;
    amps_int *dof0, *surf, *idx, *clo;
    unsigned char *fixed;
    bench_cut cp;
    bench_model B;
    amps_update_stats us;
    FILE *csv;
    if (argc < 5) {
        fprintf(stderr, "usage: watch <beam:h|brick:R|file> <reps> <cuts> <out.csv>\n");
        return 2;
    }
    spec = argv[1];
    reps = atoi(argv[2]);
    ncuts = atoi(argv[3]);
    out = argv[4];
    if (reps < 1) return 2;
    bench_mesh_name(spec, name, sizeof(name));
    amps_ctx_init(&ctx);
    bench_model_init(&ctx, spec, NULL, &B);
    m = B.m;
    S = B.S;
    fixed = B.fixed;
    force = B.force;
    nn0 = B.nn;
    up = B.up;
    cp = B.cp;
    /* the equations of the original nodes: the scene numbers them as amps_mesh_number_dofs does
       (checked below against the solution); cut copies get appended equations, outside L */
    dof0 = (amps_int *)malloc(sizeof(amps_int) * 3 * (size_t)nn0);
    if (!dof0) return 1;
    amps_mesh_number_dofs(m, fixed, dof0);
    /* factor the uncut model, then cut */
    if (amps_scene_prepare(&ctx, S) != AMPS_OK) {
        fprintf(stderr, "prepare: %s\n", ctx.msg);
        return 1;
    }
    ndid = bench_cuts(&ctx, &B, ncuts);
    if (amps_scene_solve(&ctx, S) != AMPS_OK) {
        fprintf(stderr, "solve: %s\n", ctx.msg);
        return 1;
    }
    F = amps_scene_factor(S);
    {
        const double *x = amps_update_solution(amps_scene_engine(S)), *u = amps_scene_displacements(S);
        for (k = 0; k < 3 * nn0; k++)
            if (dof0[k] >= 0 && x[dof0[k]] != u[k]) {
                fprintf(stderr, "equation numbering differs from amps_mesh_number_dofs\n");
                return 1;
            }
    }
    amps_update_get_stats(amps_scene_engine(S), &us);
    nn = (int)amps_scene_mesh(S)->nnode;
    surf = (amps_int *)malloc(sizeof(amps_int) * (size_t)nn);
    idx = (amps_int *)malloc(sizeof(amps_int) * 3 * (size_t)nn);
    clo = (amps_int *)malloc(sizeof(amps_int) * (size_t)F->n);
    xw = (double *)malloc(sizeof(double) * 3 * (size_t)nn);
    tf = (double *)malloc(sizeof(double) * (size_t)reps);
    tw = (double *)malloc(sizeof(double) * (size_t)reps);
    nsurf = bench_surface_nodes(amps_scene_mesh(S), surf);
    if (nsurf <= 0 || amps_marker_init(&ctx, &mk, F->n) != AMPS_OK) return 1;
    for (k = 0; k < nsurf; k++) {
        v = (int)surf[k];
        if (v < nn0 && !fixed[v] && (probe < 0 || m->xyz[3 * v + up] > m->xyz[3 * probe + up])) probe = v;
    }
    printf("%s: %d nodes (%d surface), %ld equations, nnz(L) %.0f, %d cuts, |S u C| %ld\n", name, nn, nsurf, (long)F->n,
           amps_factor_nnz(F), ndid, (long)us.nsys);
    printf("  %-10s %7s %9s %8s %8s %10s %10s %8s %10s %9s\n", "set", "nodes", "closure", "/n", "nnz(L)", "full ms",
           "watched ms", "speed-up", "setup ms", "rel diff");
    csv = bench_csv(out, "mesh,nodes,equations,nnzL,cuts,nsys,set,watched_nodes,closure,closure_frac,nnzL_frac,full_ms,"
                         "watched_ms,speedup,setup_ms,rel_diff");
    if (!csv) {
        fprintf(stderr, "cannot write %s\n", out);
        return 1;
    }
    for (set = 0; set < 3; set++) {
        static const char *names[3] = {"surface", "random100", "probe"};
        amps_int *w = surf, nw = nsurf, ni = 0, cnt, one = probe;
        double lnz = 0, setup, tfm, twm, dmax = 0, umax = 0;
        const double *u;
        if (set == 1) {
            /* 100 distinct surface nodes, fixed seed (partial Fisher-Yates on a copy) */
            unsigned long seed = 12345;
            w = (amps_int *)malloc(sizeof(amps_int) * (size_t)nsurf);
            memcpy(w, surf, sizeof(amps_int) * (size_t)nsurf);
            nw = nsurf < 100 ? nsurf : 100;
            for (k = 0; k < nw; k++) {
                amps_int j, t;
                seed = seed * 6364136223846793005UL + 1442695040888963407UL;
                j = k + (amps_int)((seed >> 33) % (unsigned long)(nsurf - k));
                t = w[k];
                w[k] = w[j];
                w[j] = t;
            }
        } else if (set == 2) {
            w = &one;
            nw = 1;
        }
        /* closure_L of the watched equations of original nodes (permuted numbering) */
        for (k = 0; k < nw; k++)
            if (w[k] < nn0) {
                int d;
                for (d = 0; d < 3; d++)
                    if (dof0[3 * w[k] + d] >= 0) idx[ni++] = F->iperm[dof0[3 * w[k] + d]];
            }
        cnt = amps_closure(F, ni, idx, clo, &mk);
        for (k = 0; k < cnt; k++) lnz += (double)(F->Lp[clo[k] + 1] - F->Lp[clo[k]] + 1);
        /* full solves */
        for (r = 0; r < reps; r++) {
            double f[3] = {0, 0, 0}, t0;
            f[up] = 0.1 * (sign = -sign);
            amps_scene_force(&ctx, S, probe, f);
            t0 = amps_now();
            if (amps_scene_solve(&ctx, S) != AMPS_OK) {
                fprintf(stderr, "solve: %s\n", ctx.msg);
                return 1;
            }
            tf[r] = amps_now() - t0;
        }
        /* watched solves: the first one computes the closure */
        amps_scene_watch(&ctx, S, nw, w);
        setup = amps_now();
        if (amps_scene_solve_watched(&ctx, S) != AMPS_OK) {
            fprintf(stderr, "watched: %s\n", ctx.msg);
            return 1;
        }
        setup = amps_now() - setup;
        for (r = 0; r < reps; r++) {
            double f[3] = {0, 0, 0}, t0;
            f[up] = 0.1 * (sign = -sign);
            amps_scene_force(&ctx, S, probe, f);
            t0 = amps_now();
            if (amps_scene_solve_watched(&ctx, S) != AMPS_OK) {
                fprintf(stderr, "watched: %s\n", ctx.msg);
                return 1;
            }
            tw[r] = amps_now() - t0;
        }
        /* the last watched solve against a full solve of the same system */
        u = amps_scene_displacements(S);
        for (k = 0; k < nw; k++) memcpy(xw + 3 * k, u + 3 * w[k], 3 * sizeof(double));
        amps_scene_solve(&ctx, S);
        u = amps_scene_displacements(S);
        for (k = 0; k < 3 * nw; k++) {
            double d = fabs(xw[k] - u[3 * w[k / 3] + k % 3]);
            if (d > dmax) dmax = d;
            if (fabs(u[3 * w[k / 3] + k % 3]) > umax) umax = fabs(u[3 * w[k / 3] + k % 3]);
        }
        tfm = bench_median(tf, reps);
        twm = bench_median(tw, reps);
        printf("  %-10s %7ld %9ld %8.4f %8.4f %10.3f %10.3f %8.1f %10.2f %9.1e\n", names[set], (long)nw, (long)cnt,
               (double)cnt / (double)F->n, lnz / amps_factor_nnz(F), 1e3 * tfm, 1e3 * twm, tfm / twm, 1e3 * setup,
               umax > 0 ? dmax / umax : dmax);
        fprintf(csv, "%s,%d,%ld,%.0f,%d,%ld,%s,%ld,%ld,%.5f,%.5f,%.4f,%.4f,%.2f,%.3f,%.2e\n", name, nn, (long)F->n,
                amps_factor_nnz(F), ndid, (long)us.nsys, names[set], (long)nw, (long)cnt, (double)cnt / (double)F->n,
                lnz / amps_factor_nnz(F), 1e3 * tfm, 1e3 * twm, tfm / twm, 1e3 * setup, umax > 0 ? dmax / umax : dmax);
        if (set == 1) free(w);
    }
    fclose(csv);
    amps_marker_free(&ctx, &mk);
    amps_scene_free(&ctx, S);
    free(fixed);
    free(force);
    free(cp.path);
    free(dof0);
    free(surf);
    free(idx);
    free(clo);
    free(xw);
    free(tf);
    free(tw);
    return 0;
}
