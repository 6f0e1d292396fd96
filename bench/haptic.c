/* bench/haptic: the haptic step (pin moves -> reaction forces) on a cut model.

   usage: haptic <mesh> <steps> <cuts> <out.csv> [npins]
     mesh: beam:<h> | brick:<R> | path to a TetGen .node / .msh / .mesh file
   Setup as in bench/harness: the base held (the low 4% of the up axis: z for beam and brick, y for
   the bunny), the opposing forces at the start of the advancing cut, then <cuts> cut steps. The
   tool: the npins (default 20) free, unloaded nodes highest along the up axis, all moved by the
   same smooth path, amplitude A = 1% of the largest extent of the model, period 400 steps:
     u(t) = A (-(1 - cos wt) / 2 along the up axis, sin(wt) / 2 along the third axis).
   Haptic step (timed): amps_scene_pin for every tool node, amps_scene_solve_reactions, and
   amps_scene_reaction for every tool node (the summed tool force).
   Every 100 steps (untimed for the haptic statistics) a full amps_scene_solve (the visual update,
   timed separately) gives the reference reactions: the relative difference
   ||r_forces - r_full|| / ||r_full|| over the 3 npins components.
   Prints a summary and appends one row to out.csv (header first if the file is new). */
#define AMPS_IMPLEMENTATION
#include "../amps.h"
#include "bench.h"

#define HAPTIC_PERIOD 400
#define HAPTIC_CHECK 100

int main(int argc, char **argv) {
    amps_ctx ctx;
    amps_mesh *m;
    amps_scene *S;
    const char *spec, *out;
    char name[256];
    int steps, ncuts, ndid = 0, npins = 20, up, ax3, nn, v, k, st, ndone = 0, nchk = 0, *pins;
    double lo[3], hi[3], amp = 0, t_prep, *t_step, *t_full, *r1, *r2, *force, relmax = 0, relsum = 0, fmax = 0;
    unsigned char *fixed;
    bench_cut cp;
    bench_model B;
    amps_update_stats us;
    FILE *csv;
    if (argc < 5) {
        fprintf(stderr, "usage: haptic <beam:h|brick:R|file> <steps> <cuts> <out.csv> [npins]\n");
        return 2;
    }
    spec = argv[1];
    steps = atoi(argv[2]);
    ncuts = atoi(argv[3]);
    out = argv[4];
    if (argc > 5) npins = atoi(argv[5]);
    if (steps < 1 || npins < 1) return 2;
    bench_mesh_name(spec, name, sizeof(name));
    amps_ctx_init(&ctx);
    bench_model_init(&ctx, spec, NULL, &B);
    m = B.m;
    S = B.S;
    fixed = B.fixed;
    force = B.force;
    nn = B.nn;
    up = B.up;
    cp = B.cp;
    memcpy(lo, B.lo, sizeof(lo));
    memcpy(hi, B.hi, sizeof(hi));
    ax3 = up == 2 ? 1 : 2;
    for (k = 0; k < 3; k++)
        if (hi[k] - lo[k] > amp) amp = hi[k] - lo[k];
    amp *= 0.01;
    t_prep = amps_now();
    if (amps_scene_solve(&ctx, S) != AMPS_OK) {
        fprintf(stderr, "first solve: %s\n", ctx.msg);
        return 1;
    }
    t_prep = amps_now() - t_prep;
    ndid = bench_cuts(&ctx, &B, ncuts);
    /* the tool: the npins highest free, unloaded original nodes (selection by repeated maximum) */
    pins = (int *)malloc(sizeof(int) * (size_t)npins);
    {
        unsigned char *taken = (unsigned char *)calloc((size_t)nn, 1);
        for (k = 0; k < npins; k++) {
            int best = -1;
            for (v = 0; v < nn; v++) {
                if (fixed[v] || taken[v] || force[3 * v] != 0.0) continue;
                if (best < 0 || m->xyz[3 * v + up] > m->xyz[3 * best + up]) best = v;
            }
            if (best < 0) {
                npins = k;
                break;
            }
            pins[k] = best;
            taken[best] = 1;
        }
        free(taken);
    }
    t_step = (double *)malloc(sizeof(double) * (size_t)steps);
    t_full = (double *)malloc(sizeof(double) * (size_t)(steps / HAPTIC_CHECK + 2));
    r1 = (double *)malloc(sizeof(double) * 3 * (size_t)npins);
    r2 = (double *)malloc(sizeof(double) * 3 * (size_t)npins);
    /* step 0 (untimed): pins at zero displacement, the first haptic solve commits the new constraints */
    {
        double u0[3] = {0, 0, 0};
        for (k = 0; k < npins; k++) amps_scene_pin(&ctx, S, pins[k], u0);
        if (amps_scene_solve_reactions(&ctx, S) != AMPS_OK) {
            fprintf(stderr, "forces: %s\n", ctx.msg);
            return 1;
        }
    }
    amps_update_get_stats(amps_scene_engine(S), &us);
    for (st = 1; st <= steps; st++) {
        double wt = 2 * 3.14159265358979323846 * st / HAPTIC_PERIOD, u[3] = {0, 0, 0}, t0, ftot[3] = {0, 0, 0};
        u[up] = -0.5 * amp * (1 - cos(wt));
        u[ax3] = 0.5 * amp * sin(wt);
        t0 = amps_now();
        for (k = 0; k < npins; k++) amps_scene_pin(&ctx, S, pins[k], u);
        if (amps_scene_solve_reactions(&ctx, S) != AMPS_OK) {
            fprintf(stderr, "step %d: %s\n", st, ctx.msg);
            return 1;
        }
        for (k = 0; k < npins; k++) {
            amps_scene_reaction(&ctx, S, pins[k], r1 + 3 * k);
            ftot[0] += r1[3 * k];
            ftot[1] += r1[3 * k + 1];
            ftot[2] += r1[3 * k + 2];
        }
        t_step[ndone++] = amps_now() - t0;
        {
            double fn = sqrt(ftot[0] * ftot[0] + ftot[1] * ftot[1] + ftot[2] * ftot[2]);
            if (fn > fmax) fmax = fn;
        }
        if (st % HAPTIC_CHECK == 0) {
            double num = 0, den = 0, rel;
            t0 = amps_now();
            if (amps_scene_solve(&ctx, S) != AMPS_OK) {
                fprintf(stderr, "full solve: %s\n", ctx.msg);
                return 1;
            }
            t_full[nchk] = amps_now() - t0;
            for (k = 0; k < npins; k++) amps_scene_reaction(&ctx, S, pins[k], r2 + 3 * k);
            for (k = 0; k < 3 * npins; k++) {
                num += (r1[k] - r2[k]) * (r1[k] - r2[k]);
                den += r2[k] * r2[k];
            }
            rel = den > 0 ? sqrt(num / den) : sqrt(num);
            if (rel > relmax) relmax = rel;
            relsum += rel;
            nchk++;
        }
    }
    {
        double mean = 0, med, p99, mx, fmed;
        const amps_factor *F = amps_scene_factor(S);
        for (k = 0; k < ndone; k++) mean += t_step[k];
        mean /= ndone;
        mx = bench_quantile(t_step, ndone, 1.0);
        p99 = bench_quantile(t_step, ndone, 0.99);
        med = bench_quantile(t_step, ndone, 0.5);
        fmed = bench_median(t_full, nchk);
        printf("%s: %d nodes, %ld equations, nnz(L) %.0f, prepare %.2f s; %d cuts, %d pins, |S u C| %ld,"
               " amplitude %.3g, max tool force %.3g\n",
               name, nn, (long)F->n, amps_factor_nnz(F), t_prep, ndid, npins, (long)us.nsys, amp, fmax);
        printf("  haptic step (%d steps): mean %.3f ms, median %.3f ms, p99 %.3f ms, max %.3f ms"
               " -> %.0f Hz (mean), %.0f Hz (median)\n",
               ndone, 1e3 * mean, 1e3 * med, 1e3 * p99, 1e3 * mx, 1 / mean, 1 / med);
        printf("  full solve (visual, %d samples): median %.2f ms (x%.0f the haptic step);"
               " reactions vs full solve: max rel diff %.2e, mean %.2e\n",
               nchk, 1e3 * fmed, fmed / med, relmax, nchk ? relsum / nchk : 0.0);
        csv = bench_csv(out, "mesh,nodes,equations,nnzL,cuts,pins,nsys,steps,mean_ms,median_ms,p99_ms,max_ms,rate_hz,"
                             "full_solve_ms,reaction_reldiff_max,reaction_reldiff_mean");
        if (!csv) {
            fprintf(stderr, "cannot write %s\n", out);
            return 1;
        }
        fprintf(csv, "%s,%d,%ld,%.0f,%d,%d,%ld,%d,%.4f,%.4f,%.4f,%.4f,%.0f,%.3f,%.3e,%.3e\n", name, nn, (long)F->n,
                amps_factor_nnz(F), ndid, npins, (long)us.nsys, ndone, 1e3 * mean, 1e3 * med, 1e3 * p99, 1e3 * mx,
                1 / mean, 1e3 * fmed, relmax, nchk ? relsum / nchk : 0.0);
        fclose(csv);
    }
    amps_scene_free(&ctx, S);
    free(fixed);
    free(force);
    free(cp.path);
    free(pins);
    free(t_step);
    free(t_full);
    free(r1);
    free(r2);
    return 0;
}
