/* The example of README.md: cut into a soft brick held at its bottom face and pulled by a pin. */
#define AMPS_IMPLEMENTATION /* in exactly one .c file */
#include "amps.h"
#include <stdio.h>

/* node (i, j, k) of amps_mesh_brick(R = 8): (R+1) x (R+1) x (2R+1) nodes, spacing 1/8 */
#define NODE(i, j, k) ((i) + 9 * ((j) + 9 * (k)))

int main(void) {
    amps_ctx ctx;
    amps_scene *S;
    amps_int copy;
    double pull[3] = {0.0, 0.02, 0.0}, p[3] = {0.5, 0.5, 2.0}, nrm[3] = {0.0, 1.0, 0.0};
    const double *u;
    amps_ctx_init(&ctx);
    S = amps_scene_create(&ctx, amps_mesh_brick(&ctx, 8), NULL); /* 1 x 1 x 2 brick */
    if (!S) {
        printf("error: %s\n", ctx.msg);
        return 1;
    }
    amps_scene_set_material(&ctx, S, 3000.0, 0.45);                   /* E = 3 kPa, nu = 0.45 */
    amps_scene_fix_where(&ctx, S, 2, AMPS_LT, 1e-9, NULL);            /* bottom face z = 0 held */
    amps_scene_pin(&ctx, S, NODE(4, 6, 16), pull);                    /* a grasper on the top face */
    if (amps_scene_cut(&ctx, S, NODE(4, 4, 16), p, nrm, &copy) < 0 || /* cut the top centre node */
        amps_scene_solve(&ctx, S) != AMPS_OK) {
        printf("error: %s\n", ctx.msg);
        return 1;
    }
    u = amps_scene_displacements(S);
    printf("top centre node moved by (%g, %g, %g); its copy %ld by (%g, %g, %g)\n", u[3 * NODE(4, 4, 16)],
           u[3 * NODE(4, 4, 16) + 1], u[3 * NODE(4, 4, 16) + 2], (long)copy, u[3 * copy], u[3 * copy + 1],
           u[3 * copy + 2]);
    amps_scene_free(&ctx, S);
    return 0;
}
