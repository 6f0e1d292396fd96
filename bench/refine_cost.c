/* bench/refine_cost: the instructions the default refinement (opts.update.refine_tol) adds to
   the cut steps, for callgrind (issue 18, item 4: at most 1.1x the step without it).

   usage: refine_cost <mesh> <ncuts> <refine_tol>
     mesh: beam:<h> | brick:<R> | a TetGen .node / .msh / .mesh file (bench.h)
   The model of bench.h (base held, the advancing planar cut's path and opposing forces), the
   first solve (the factorization), then ncuts cut steps from the uncut model: the next node of
   the path cut (bench_cut_next) and amps_scene_solve. Re-factorization off; refine_tol = 0 turns
   the default refinement off (1 eps is the default). The cut steps run inside cut_steps(), so
     OMP_NUM_THREADS=1 valgrind --tool=callgrind --toggle-collect=cut_steps \
       build/bench/refine_cost bench/data/bunny20k.1.node 20 0
   counts their instructions only. Prints per step |S u C|, the backward error of the solve and
   the refinement steps it took, then a checksum of the displacements (the two runs differ only
   by the refinement's correction). */
#define AMPS_IMPLEMENTATION
#include "../amps.h"
#include "bench.h"

#if defined(__GNUC__)
#define RC_NOINLINE __attribute__((noinline)) /* callgrind's --toggle-collect needs the call */
#else
#define RC_NOINLINE
#endif

/* The ncuts cut steps of model b (cut + solve); returns the cuts done. */
static RC_NOINLINE int cut_steps(amps_ctx *ctx, bench_model *b, int ncuts) {
    int k, done = 0;
    for (k = 0; k < ncuts; k++) {
        int node = -1;
        amps_status s = bench_cut_next(ctx, b->S, &b->cp, &node);
        amps_update_stats st;
        if (s == AMPS_WARN_NOOP) break;
        if (s != AMPS_OK) {
            fprintf(stderr, "cut at %d: %s\n", node, ctx->msg);
            continue;
        }
        done++;
        if (amps_scene_solve(ctx, b->S) < 0) bench_die("solve", ctx->msg);
        amps_update_get_stats(amps_scene_engine(b->S), &st);
        printf("step %2d  node %6d  |S u C| %5ld  backward error %.2f eps (-1: not computed)  refinement steps %ld\n",
               k + 1, node, (long)st.nsys, st.backward_error < 0 ? -1.0 : st.backward_error / 2.220446049250313e-16,
               (long)st.guard_steps);
    }
    return done;
}

int main(int argc, char **argv) {
    amps_ctx ctx;
    amps_scene_opts so;
    bench_model b;
    const double *u;
    double sum = 0, sabs = 0;
    amps_int v;
    int done;
    if (argc < 4) {
        fprintf(stderr, "usage: refine_cost <mesh> <ncuts> <refine_tol>\n");
        return 2;
    }
    amps_ctx_init(&ctx);
    bench_scene_opts(&so);
    so.update.refactor = AMPS_REFACTOR_OFF;
    so.update.refine_tol = atof(argv[3]);
    bench_model_init(&ctx, argv[1], &so, &b);
    if (amps_scene_solve(&ctx, b.S) < 0) bench_die("first solve", ctx.msg);
    {
        amps_update_stats st;
        amps_update_get_stats(amps_scene_engine(b.S), &st);
        printf("base: condition estimate %.2e (the forward refinement fires above %.1e)\n", st.base_cond,
               AMPS__FWD_KAPPA_EPS / 2.220446049250313e-16);
    }
    done = cut_steps(&ctx, &b, atoi(argv[2]));
    u = amps_scene_displacements(b.S);
    for (v = 0; v < 3 * amps_scene_mesh(b.S)->nnode; v++) {
        sum += u[v];
        sabs += fabs(u[v]);
    }
    printf("%s: %d cuts, refine_tol %g; displacements: sum %.17g, sum |u| %.17g\n", argv[1], done, so.update.refine_tol,
           sum, sabs);
    amps_scene_free(&ctx, b.S);
    free(b.fixed);
    free(b.force);
    free(b.cp.path);
    return 0;
}
