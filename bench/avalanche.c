/* bench/avalanche: a fracture-avalanche-like removal in dynamics, the steps after it, and a
   re-factorization: what orphans (nodes left in no tet) cost.

   usage: avalanche [beam length (64)] [z above which tets go (16)] [steps (40)]
   A beam 5 x 5 x length fixed below z = 0.5 under gravity (dt 0.01, alpha 0.1, beta 0.01) takes
   2 steps, then loses every tet whose centroid lies above z in one amps_scene_remove (the nodes
   above z become orphans), then steps; after a third of the steps amps_update_refactor runs
   synchronously. Prints the removal's time, each fifth step's time with the dense system's
   order |S u C|, the re-factorization's time, and the norms of the displacements of the live
   nodes and of the orphans (so two builds can be checked to agree). */
#define AMPS_IMPLEMENTATION
#include "../amps.h"
#include <stdio.h>
#include <stdlib.h>

int main(int argc, char **argv) {
    amps_ctx ctx;
    amps_scene *S;
    const amps_mesh *m;
    amps_update_stats st;
    amps_int t, n = 0, v, *tets;
    int len = argc > 1 ? atoi(argv[1]) : 64, steps = argc > 3 ? atoi(argv[3]) : 40, k, d;
    double zcut = argc > 2 ? atof(argv[2]) : 16, g[3] = {0, 0, -0.01}, t0, live = 0, orph = 0;
    const double *u;
    amps_ctx_init(&ctx);
    if (len < 2 || steps < 1) {
        fprintf(stderr, "usage: avalanche [beam length >= 2] [z] [steps >= 1]\n");
        return 1;
    }
    S = amps_scene_create(&ctx, amps_mesh_beam(&ctx, len), NULL);
    if (!S || amps_scene_fix_where(&ctx, S, 2, AMPS_LT, 0.5, NULL) < 0 || amps_scene_gravity(&ctx, S, g) ||
        amps_scene_dynamics(&ctx, S, 0.01, 0.1, 0.01) || amps_scene_step(&ctx, S, 2) < 0) {
        fprintf(stderr, "setup: %s\n", ctx.msg);
        return 1;
    }
    m = amps_scene_mesh(S);
    tets = (amps_int *)malloc(sizeof(amps_int) * (size_t)m->ntet);
    for (t = 0; t < m->ntet; t++) {
        double zc = 0;
        for (k = 0; k < 4; k++) zc += 0.25 * m->xyz[3 * m->tet[4 * t + k] + 2];
        if (zc > zcut) tets[n++] = t;
    }
    t0 = amps_now();
    if (amps_scene_remove(&ctx, S, n, tets, AMPS_SINGULAR_REMOVE, NULL) != AMPS_OK) {
        fprintf(stderr, "remove: %s\n", ctx.msg);
        return 1;
    }
    printf("removal of %ld tets: %.1f ms\n", (long)n, 1e3 * (amps_now() - t0));
    for (k = 0; k < steps; k++) {
        t0 = amps_now();
        if (amps_scene_step(&ctx, S, 1) < 0) {
            fprintf(stderr, "step: %s\n", ctx.msg);
            return 1;
        }
        amps_update_get_stats(amps_scene_engine(S), &st);
        if (k % 5 == 0 || k == steps - 1)
            printf("step %d: %.2f ms, |S u C| %ld\n", k, 1e3 * (amps_now() - t0), (long)st.nsys);
        if (k == steps / 3) {
            t0 = amps_now();
            if (amps_update_refactor(&ctx, amps_scene_engine(S)) != AMPS_OK) fprintf(stderr, "refactor: %s\n", ctx.msg);
            printf("re-factorization: %.1f ms\n", 1e3 * (amps_now() - t0));
        }
    }
    u = amps_scene_displacements(S);
    for (v = 0; v < m->nnode; v++)
        for (d = 0; d < 3; d++) {
            if (amps_mesh_degree(m, v) > 0) live += u[3 * v + d] * u[3 * v + d];
            else orph += u[3 * v + d] * u[3 * v + d];
        }
    printf("|u| live nodes %.15e, orphans %.15e\n", sqrt(live), sqrt(orph));
    free(tets);
    amps_scene_free(&ctx, S);
    return 0;
}
