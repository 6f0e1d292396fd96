/* bench/dynamics: implicit dynamics with element removal, fracture and cuts (paper "GPU-accelerated
   surgery simulation for opening a brain fissure", Sase et al.), amps.h against CHOLMOD
   re-factorization and Jacobi-PCG, step by step on the same system.

   usage: dynamics <cube|brain|bunny> <steps> <out.csv> [summary.csv]
   Scenes (meshes: bench/make_fissure.sh, bench/get_bunny.sh), all with gravity (9.81, down),
   density 1, dt = 0.02 (the paper's), Rayleigh damping alpha = 1, beta = 0.01, base fixed:
   cube   bench/data/fissure_cube: region 1 E = 1000, nu = 0.4, the fissure (region 2) E = 100,
          nu = 0.4; the bottom z = 0 fixed. Two spatulas: the nodes of the walls x = 0.48 and
          x = 0.52 with z > 0.8, 0.3 < y < 0.7, pinned and pushed apart along x at BENCH_SPEED
          (default 0.025 per second each). Fracture in region 2 at BENCH_SIGMA (default 100).
   brain  bench/data/brain: the same materials; the bottom z = 0 fixed; one spatula, the nodes of
          the wall x = -0.02 with z > 0.45, |y| < 0.15, pushed along -x at BENCH_SPEED. Between
          steps BENCH_HAPTIC (default 20) haptic calls: the spatula moved by 1/20 of a step's
          travel, amps_scene_solve_reactions and the reactions of its nodes, each call timed.
   bunny  bench/data/bunny50k: E = 1000, nu = 0.3, the lowest 4% in y fixed, gravity along -y;
          the advancing planar cut of bench.h, BENCH_CUTS (default 2) cuts before every step.
   Environment: BENCH_REFINE_TOL sets opts.update.refine_tol (default: the library's, 1 eps, up to
   3 refinement steps a solve; 0: none); BENCH_AMPS_ONLY=1 runs amps.h alone (no assembly, CHOLMOD
   or PCG; residual and error 0: for profiling, e.g. under callgrind). Per step (the state before it, read from the public scene: mesh with its removals and
   copies, u, w, pins): A = (1 + alpha dt) M + (beta dt + dt^2) K and b = M w + dt (M g - K u)
   assembled from scratch, pins w_P = (g - u_P) / dt, the reduced system A_FF w_F = b_F - A_FP w_P:
   amps         the pin moves, cuts and amps_scene_step(1) (its fracture pass and removal
                included), then the reactions of the spatula nodes (amps_scene_reaction; timed
                apart: column react_time);
   chol_refactor  CHOLMOD (supernodal) cholmod_analyze when the pattern changed, cholmod_factorize
                when the matrix changed (a removal, a cut, the first step), cholmod_solve;
   chol_solve   one cholmod_solve with the current factor;
   cg_jacobi    our Jacobi-PCG warm-started from the step's w (the last velocities), time and
                iterations at which each tolerance of bench_tols is met (BENCH_CG_MAXIT, 2000);
   assemble     the from-scratch assembly of A and b (not counted in the CHOLMOD times);
   haptic       (brain) the median of the step's haptic calls.
   Residual: ||(A w - b)_F|| / ||b_F - A_FP w_P||; error: against CHOLMOD + 2 refinement steps
   in quad precision. CSV row: scene,step,method,tol,time,iters,relres,relerr,removed,
   removed_total,nmod,nsys,changed,react1,react2 (reactions: the x sums over each spatula's
   nodes; amps rows). The summary row (summary.csv) holds the medians and ratios of the run. */
#define AMPS_IMPLEMENTATION
#include "../amps.h"
#include "bench.h"
#include "bench_solve.h"

#define DT 0.02
#define ALPHA 1.0
#define BETA 0.01

static double envd(const char *name, double def) {
    const char *s = getenv(name);
    return s ? atof(s) : def;
}

/* The scene of one run and what the benchmark knows of it besides the public scene state. */
typedef struct dyn {
    const char *name;
    amps_scene *S;
    unsigned char *fixed0;  /* fixed flag of the file nodes */
    int nspat, *spat;       /* spatula nodes */
    double *dir;            /* their direction of travel (3 each) */
    int *side;              /* their spatula: 0 or 1 */
    double *pinval;         /* 3 per node: pin targets */
    int cuts, haptic;       /* cuts before each step; haptic calls between steps */
    bench_cut cp;
    double speed;
} dyn;

/* Nodes with |x - wall| < 1e-6, z > zmin and y0 < y < y1 become spatula side moving along sx. */
static void add_spatula(dyn *D, const amps_mesh *m, double wall, double zmin, double y0, double y1, int side,
                        double sx) {
    amps_int v;
    for (v = 0; v < m->nnode; v++) {
        const double *x = m->xyz + 3 * v;
        if (fabs(x[0] - wall) < 1e-6 && x[2] > zmin && x[1] > y0 && x[1] < y1) {
            D->spat[D->nspat] = (int)v;
            D->side[D->nspat] = side;
            D->dir[3 * D->nspat] = sx;
            D->dir[3 * D->nspat + 1] = D->dir[3 * D->nspat + 2] = 0;
            D->nspat++;
        }
    }
}

static void dyn_setup(amps_ctx *ctx, dyn *D, const char *name) {
    amps_scene_opts so;
    amps_mesh *m;
    amps_int v, nn;
    double g[3] = {0, 0, -9.81}, lo[3], hi[3];
    int fiss = strcmp(name, "bunny") != 0;
    memset(D, 0, sizeof(*D));
    D->name = name;
    D->speed = envd("BENCH_SPEED", 0.025);
    if (fiss) {
        m = amps_mesh_read(ctx, !strcmp(name, "cube") ? "bench/data/fissure_cube.1.node" : "bench/data/brain.1.node");
        if (!m) bench_die(name, ctx->msg);
    } else {
        m = bench_mesh(ctx, "bench/data/bunny50k.1.node");
        g[1] = -9.81;
        g[2] = 0;
    }
    nn = m->nnode;
    bench_bbox(m, lo, hi);
    D->fixed0 = fiss ? bench_base(m, 2, lo, lo) : bench_base(m, 1, lo, hi); /* fissure scenes: z = 0 */
    D->spat = (int *)bench_alloc(sizeof(int) * (size_t)nn);
    D->side = (int *)bench_alloc(sizeof(int) * (size_t)nn);
    D->dir = (double *)bench_alloc(sizeof(double) * 3 * (size_t)nn);
    if (!strcmp(name, "cube")) {
        add_spatula(D, m, 0.48, 0.8, 0.3, 0.7, 0, -1);
        add_spatula(D, m, 0.52, 0.8, 0.3, 0.7, 1, 1);
    } else if (!strcmp(name, "brain")) {
        add_spatula(D, m, -0.02, 0.45, -0.15, 0.15, 0, -1);
        D->haptic = (int)envd("BENCH_HAPTIC", 20);
    } else {
        D->cuts = (int)envd("BENCH_CUTS", 2);
        bench_cut_init(&D->cp, m, D->fixed0, 1, lo, hi);
    }
    bench_scene_opts(&so);
    if (getenv("BENCH_REFINE_TOL")) so.update.refine_tol = envd("BENCH_REFINE_TOL", 0);
    D->S = amps_scene_create(ctx, m, &so);
    if (!D->S) bench_die(name, ctx->msg);
    if (fiss && (amps_scene_set_region(ctx, D->S, 1, 1000, 0.4, 1) || amps_scene_set_region(ctx, D->S, 2, 100, 0.4, 1)))
        bench_die("region", ctx->msg);
    if (bench_fix(ctx, D->S, nn, D->fixed0) || amps_scene_gravity(ctx, D->S, g) ||
        amps_scene_dynamics(ctx, D->S, DT, ALPHA, BETA))
        bench_die(name, ctx->msg);
    if (!strcmp(name, "cube") && amps_scene_fracture_region(ctx, D->S, 2, envd("BENCH_SIGMA", 100)))
        bench_die("fracture", ctx->msg);
    for (v = 0; v < D->nspat; v++) {
        double z[3] = {0, 0, 0};
        if (amps_scene_pin(ctx, D->S, D->spat[v], z)) bench_die("pin", ctx->msg);
    }
    if (amps_scene_prepare(ctx, D->S)) bench_die("prepare", ctx->msg);
}

/* Moves the spatulas to time t (pins of nodes the scene still pins). */
static void move_spatulas(amps_ctx *ctx, dyn *D, double t) {
    int k, d;
    for (k = 0; k < D->nspat; k++) {
        int v = D->spat[k];
        double u[3];
        if (!amps_scene_is_pinned(D->S, v)) continue;
        for (d = 0; d < 3; d++) u[d] = D->dir[3 * k + d] * D->speed * t;
        if (amps_scene_pin(ctx, D->S, v, u)) bench_die("pin", ctx->msg);
    }
}

/* The system of the next step from scratch (bench_sys: K = A, f = b, g = w_P, con = pinned DOFs). */
static void dyn_system(amps_ctx *ctx, const dyn *D, bench_sys *Y) {
    const amps_mesh *m = amps_scene_mesh(D->S);
    const double *u = amps_scene_displacements(D->S), *w = amps_scene_velocities(D->S);
    int nn = (int)m->nnode, v, d, i, p;
    unsigned char *fixed = (unsigned char *)bench_alloc((size_t)nn);
    double *mass = (double *)bench_alloc(sizeof(double) * (size_t)nn), *t;
    double cM = 1 + ALPHA * DT, cK = BETA * DT + DT * DT, g = 9.81;
    int up = strcmp(D->name, "bunny") ? 2 : 1;
    memset(Y, 0, sizeof(*Y));
    Y->nn = nn;
    for (v = 0; v < nn; v++) fixed[v] = D->fixed0[m->origin[v]];
    Y->dof = (amps_int *)bench_alloc(sizeof(amps_int) * 3 * (size_t)nn);
    Y->n = (int)amps_mesh_number_dofs(m, fixed, Y->dof);
    Y->K = amps_mesh_assemble(ctx, m, Y->dof, Y->n);
    if (!Y->K) bench_die("amps_mesh_assemble", ctx->msg);
    amps_mesh_lumped_mass(m, mass);
    Y->f = (double *)bench_alloc(sizeof(double) * (size_t)Y->n);
    Y->g = (double *)bench_alloc(sizeof(double) * (size_t)Y->n);
    Y->b = (double *)bench_alloc(sizeof(double) * (size_t)Y->n);
    Y->con = (unsigned char *)bench_alloc((size_t)Y->n);
    t = (double *)bench_alloc(sizeof(double) * (size_t)Y->n);
    bench_sys_from_disp(Y, u, Y->g);
    Y->Kf = bench_sym_full(ctx, Y->K);
    bench_spmv(Y->Kf, Y->g, t); /* K u */
    for (v = 0; v < nn; v++)
        for (d = 0; d < 3; d++) {
            amps_int e = Y->dof[3 * v + d];
            if (e < 0) continue;
            Y->f[e] = mass[v] * w[3 * v + d] + DT * ((d == up ? -g * mass[v] : 0.0) - t[e]);
        }
    for (p = 0; p < Y->K->p[Y->n]; p++) Y->K->x[p] *= cK;
    for (v = 0; v < nn; v++)
        for (d = 0; d < 3; d++)
            if (Y->dof[3 * v + d] >= 0) Y->K->x[Y->K->p[Y->dof[3 * v + d] + 1] - 1] += cM * mass[v];
    amps_csc_free(ctx, Y->Kf);
    Y->Kf = bench_sym_full(ctx, Y->K);
    for (i = 0; i < Y->n; i++) Y->g[i] = 0;
    for (v = 0; v < nn; v++)
        if (amps_scene_is_pinned(D->S, v))
            for (d = 0; d < 3; d++) {
                amps_int e = Y->dof[3 * v + d];
                if (e < 0) continue;
                Y->con[e] = 1;
                Y->g[e] = (D->pinval[3 * v + d] - u[3 * v + d]) / DT;
            }
    bench_sys_rhs(Y, t);
    free(t);
    free(mass);
    free(fixed);
}

/* CHOLMOD with the factor kept across steps: analysis when the pattern (order, entries) changed,
   factorization when the matrix changed. */
typedef struct chol {
    cholmod_common c;
    cholmod_factor *L;
    size_t n, nz;
} chol;

/* Solves the reduced system of Y: *t_ref the refactor path (analysis, factorization as needed,
   solve), *t_sol a second plain solve; x the solution, xref the refined reference (n each). */
static void chol_step(chol *C, const bench_sys *Y, int changed, double *t_ref, double *t_sol, double *x, double *xref) {
    int *fmap = (int *)bench_alloc(sizeof(int) * (size_t)Y->n);
    cholmod_dense *B, *X, *X2;
    cholmod_sparse *A = bench_reduced(Y, fmap, &B, &C->c);
    size_t nz = ((int *)A->p)[A->ncol];
    double t0 = amps_now();
    if (!C->L || A->ncol != C->n || nz != C->nz) {
        cholmod_free_factor(&C->L, &C->c);
        C->L = cholmod_analyze(A, &C->c);
        C->n = A->ncol;
        C->nz = nz;
        changed = 1;
    }
    if (changed) cholmod_factorize(A, C->L, &C->c);
    X = cholmod_solve(CHOLMOD_A, C->L, B, &C->c);
    *t_ref = amps_now() - t0;
    t0 = amps_now();
    X2 = cholmod_solve(CHOLMOD_A, C->L, B, &C->c);
    *t_sol = amps_now() - t0;
    if (!X || !X2 || C->c.status != CHOLMOD_OK) bench_die("cholmod", "factorization failed");
    bench_expand(Y, fmap, (double *)X->x, x);
    bench_refine(A, C->L, B, X2, 2, &C->c);
    bench_expand(Y, fmap, (double *)X2->x, xref);
    cholmod_free_dense(&X, &C->c);
    cholmod_free_dense(&X2, &C->c);
    cholmod_free_dense(&B, &C->c);
    cholmod_free_sparse(&A, &C->c);
    free(fmap);
}

static FILE *csv;

static void put(const dyn *D, int step, const char *method, double tol, double t, int iters, double res, double err,
                int removed, int total, const amps_update_stats *st, int changed, const double *react) {
    fprintf(csv, "%s,%d,%s,%g,%.6e,%d,%.3e,%.3e,%d,%d,%ld,%ld,%d,%.6e,%.6e\n", D->name, step, method, tol, t, iters,
            res, err, removed, total, st ? (long)st->nmod : 0L, st ? (long)st->nsys : 0L, changed,
            react ? react[0] : 0.0, react ? react[1] : 0.0);
}

/* The x sums of the spatula reactions into react[0..1]. */
static void spatula_reactions(amps_ctx *ctx, const dyn *D, double react[2]) {
    int k;
    react[0] = react[1] = 0;
    for (k = 0; k < D->nspat; k++) {
        double r[3];
        if (amps_scene_reaction(ctx, D->S, D->spat[k], r)) bench_die("reaction", ctx->msg);
        react[D->side[k]] += r[0];
    }
}

/* Haptic calls between steps: the spatula moved by a fraction of a step's travel each time, the
   reactions from the dense system alone; returns the median call time. */
static double haptic_calls(amps_ctx *ctx, dyn *D, double t) {
    double *tc = (double *)bench_alloc(sizeof(double) * (size_t)(D->haptic + 1)), react[2], med;
    int k;
    for (k = 0; k < D->haptic; k++) {
        double t0 = amps_now();
        move_spatulas(ctx, D, t + DT * (k + 1) / D->haptic);
        if (amps_scene_solve_reactions(ctx, D->S) < 0) bench_die("solve_reactions", ctx->msg);
        spatula_reactions(ctx, D, react);
        tc[k] = amps_now() - t0;
    }
    med = bench_median(tc, D->haptic);
    free(tc);
    return med;
}

/* The run's medians and ratios, printed and appended to path (if given). Sorts the arrays. */
static void summary(const dyn *D, const char *path, int steps, double *ta, double *ts, double *tac, int nev,
                    double *trc, int nref, double *th, double err, double res, int removed, double wall) {
    const amps_mesh *m = amps_scene_mesh(D->S);
    double la[3] = {0, 0, 0}, ma = bench_median(ta, steps), ms = bench_median(ts, steps);
    double mae = nev ? bench_median(tac, nev) : 0, mrc = nref ? bench_median(trc, nref) : 0;
    double mh = D->haptic ? bench_median(th, steps) : 0;
    FILE *f, *lf = fopen("/proc/loadavg", "r");
    if (lf) {
        if (fscanf(lf, "%lf %lf %lf", la, la + 1, la + 2) != 3) la[0] = -1;
        fclose(lf);
    }
    printf("%s: %d steps (%.0f s): median step amps %.3f ms, CHOLMOD solve %.3f ms (ratio %.2f); steps with a removal "
           "or cut %d: amps median %.3f ms, CHOLMOD re-factorization (%d changed steps) median %.1f ms (%.0fx); "
           "haptic %.0f Hz; removed %d; worst error %.1e, residual %.1e; load %.2f\n",
           D->name, steps, wall, 1e3 * ma, 1e3 * ms, ma / ms, nev, 1e3 * mae, nref, 1e3 * mrc, mae > 0 ? mrc / mae : 0,
           mh > 0 ? 1 / mh : 0, removed, err, res, la[0]);
    if (!path) return;
    f = bench_csv(path, "scene,steps,nodes,tets,ndof,amps_ms,chol_solve_ms,ratio_solve,event_steps,amps_event_ms,"
                        "refactor_steps,chol_refactor_ms,speedup_refactor,haptic_hz,removed,worst_err,worst_res,"
                        "load1,wall_s");
    if (!f) bench_die(path, "cannot open");
    fprintf(f, "%s,%d,%ld,%ld,%ld,%.4f,%.4f,%.3f,%d,%.4f,%d,%.3f,%.1f,%.0f,%d,%.2e,%.2e,%.2f,%.0f\n", D->name, steps,
            (long)m->nnode, (long)m->ntet, (long)amps_scene_ndof(D->S), 1e3 * ma, 1e3 * ms, ma / ms, nev, 1e3 * mae,
            nref, 1e3 * mrc, mae > 0 ? mrc / mae : 0, mh > 0 ? 1 / mh : 0, removed, err, res, la[0], wall);
    fclose(f);
}

int main(int argc, char **argv) {
    amps_ctx ctx;
    dyn D;
    chol C;
    int steps, step, k, cg_maxit = (int)envd("BENCH_CG_MAXIT", 2000), nchg = 0, total = 0, nev = 0, nref = 0;
    int only = envd("BENCH_AMPS_ONLY", 0) != 0;
    double *ta, *tr, *ts, *tac, *trc, *th, worst_err = 0, worst_res = 0, t_all = amps_now();
    bench_snaps sn;
    if (argc < 4) {
        fprintf(stderr, "usage: dynamics <cube|brain|bunny> <steps> <out.csv> [summary.csv]\n");
        return 2;
    }
    amps_ctx_init(&ctx);
    steps = atoi(argv[2]);
    dyn_setup(&ctx, &D, argv[1]);
    csv = bench_csv(argv[3], "scene,step,method,tol,time,iters,relres,relerr,removed,removed_total,nmod,nsys,changed,"
                             "react1,react2");
    if (!csv) bench_die(argv[3], "cannot open");
    cholmod_start(&C.c);
    C.c.supernodal = CHOLMOD_SUPERNODAL;
    C.L = NULL;
    ta = (double *)bench_alloc(sizeof(double) * (size_t)(steps + 1) * 6);
    tr = ta + steps + 1;
    ts = tr + steps + 1;
    tac = ts + steps + 1;
    trc = tac + steps + 1;
    th = trc + steps + 1;
    printf("%s: %ld nodes, %ld tets, %d spatula nodes, %d equations\n", D.name, (long)amps_scene_mesh(D.S)->nnode,
           (long)amps_scene_mesh(D.S)->ntet, D.nspat, (int)amps_scene_ndof(D.S));
    for (step = 1; step <= steps; step++) {
        const amps_mesh *m = amps_scene_mesh(D.S);
        amps_int nn0 = m->nnode, nr0 = m->nremoved, nfr;
        bench_sys Y;
        amps_update_stats st;
        double t0, t_amps, t_asm, t_ref, t_sol, t_react, react[2], *x, *xref, *xa, *work;
        int changed, v, d;
        D.pinval = (double *)realloc(D.pinval, sizeof(double) * 3 * ((size_t)nn0 + 3 * (size_t)D.cuts + 1));
        t0 = amps_now(); /* amps: the changes before the step */
        move_spatulas(&ctx, &D, step * DT);
        for (k = 0; k < D.cuts; k++) {
            int node;
            amps_status s = bench_cut_next(&ctx, D.S, &D.cp, &node);
            if (s != AMPS_OK && s != AMPS_WARN_NOOP) fprintf(stderr, "cut at %d: %s\n", node, ctx.msg);
        }
        t_amps = amps_now() - t0;
        for (k = 0; k < D.nspat; k++)
            for (d = 0; d < 3; d++) D.pinval[3 * D.spat[k] + d] = D.dir[3 * k + d] * D.speed * step * DT;
        changed = step == 1 || m->nnode != nn0 || nchg;
        if (only) { /* amps.h alone */
            t0 = amps_now();
            if (amps_scene_step(&ctx, D.S, 1) < 0) bench_die("amps_scene_step", ctx.msg);
            t_amps += amps_now() - t0;
            spatula_reactions(&ctx, &D, react);
            nfr = amps_scene_fractured(D.S, NULL);
            nchg = amps_scene_mesh(D.S)->nremoved != nr0;
            total = (int)amps_scene_mesh(D.S)->nremoved;
            amps_update_get_stats(amps_scene_engine(D.S), &st);
            put(&D, step, "amps", 0, t_amps, 0, 0, 0, (int)nfr, total, &st, changed, react);
            ta[step - 1] = ts[step - 1] = t_amps;
            if (nfr > 0 || amps_scene_mesh(D.S)->nnode != nn0) tac[nev++] = t_amps;
            if (D.haptic) th[step - 1] = haptic_calls(&ctx, &D, step * DT);
            printf("  step %d: amps %.2f ms, removed %d (total %d), |S| %ld\n", step, 1e3 * t_amps, (int)nfr, total,
                   (long)st.nmod);
            continue;
        }
        t0 = amps_now();
        dyn_system(&ctx, &D, &Y);
        t_asm = amps_now() - t0;
        x = (double *)bench_alloc(sizeof(double) * 4 * (size_t)Y.n);
        xref = x + Y.n;
        xa = xref + Y.n;
        work = xa + Y.n;
        chol_step(&C, &Y, changed, &t_ref, &t_sol, x, xref);
        put(&D, step, "assemble", 0, t_asm, 0, 0, 0, 0, 0, NULL, changed, NULL);
        put(&D, step, "chol_refactor", 0, t_ref, 0, bench_sys_relres(&Y, x, work), bench_sys_relerr(&Y, x, xref), 0, 0,
            NULL, changed, NULL);
        put(&D, step, "chol_solve", 0, t_sol, 0, 0, 0, 0, 0, NULL, changed, NULL);
        for (k = 0; k < BENCH_NTOL; k++) sn.x[k] = (double *)bench_alloc(sizeof(double) * (size_t)Y.n);
        bench_sys_from_disp(&Y, amps_scene_velocities(D.S), xa); /* warm start: the last w */
        bench_cg_run(&Y, xa, 1, cg_maxit, &sn);
        for (k = 0; k < BENCH_NTOL; k++) {
            put(&D, step, "cg_jacobi", bench_tols[k], sn.t[k], sn.it[k], bench_sys_relres(&Y, sn.x[k], work),
                bench_sys_relerr(&Y, sn.x[k], xref), 0, 0, NULL, changed, NULL);
            free(sn.x[k]);
        }
        t0 = amps_now();
        if (amps_scene_step(&ctx, D.S, 1) < 0) bench_die("amps_scene_step", ctx.msg);
        t_amps += amps_now() - t0;
        t0 = amps_now();
        spatula_reactions(&ctx, &D, react);
        t_react = amps_now() - t0;
        nfr = amps_scene_fractured(D.S, NULL);
        nchg = amps_scene_mesh(D.S)->nremoved != nr0;
        total = (int)amps_scene_mesh(D.S)->nremoved;
        amps_update_get_stats(amps_scene_engine(D.S), &st);
        for (v = 0; v < Y.n; v++) xa[v] = 0;
        bench_sys_from_disp(&Y, amps_scene_velocities(D.S), xa);
        {
            double res = bench_sys_relres(&Y, xa, work), err = bench_sys_relerr(&Y, xa, xref);
            put(&D, step, "amps", 0, t_amps, 0, res, err, (int)nfr, total, &st, changed, react);
            fprintf(csv, "%s,%d,react_time,0,%.6e,0,0,0,0,0,0,0,%d,0,0\n", D.name, step, t_react, changed);
            if (err > worst_err) worst_err = err;
            if (res > worst_res) worst_res = res;
        }
        ta[step - 1] = t_amps;
        tr[step - 1] = t_ref;
        ts[step - 1] = t_sol;
        if (nfr > 0 || amps_scene_mesh(D.S)->nnode != nn0) tac[nev++] = t_amps; /* a removal or a cut */
        if (changed && step > 1) trc[nref++] = t_ref;
        if (D.haptic) {
            double h = haptic_calls(&ctx, &D, step * DT);
            th[step - 1] = h;
            put(&D, step, "haptic", 0, h, D.haptic, 0, 0, 0, 0, NULL, changed, NULL);
        }
        if (step % 10 == 0 || step == steps)
            printf("  step %d: amps %.2f ms, chol refactor %.2f ms, solve %.2f ms, removed %d (total %d), |S| %ld, "
                   "err %.1e\n",
                   step, 1e3 * t_amps, 1e3 * t_ref, 1e3 * t_sol, (int)nfr, total, (long)st.nmod, worst_err);
        fflush(stdout);
        free(x);
        bench_sys_free(&ctx, &Y);
    }
    summary(&D, argc > 4 ? argv[4] : NULL, steps, ta, ts, tac, nev, trc, nref, th, worst_err, worst_res, total,
            amps_now() - t_all);
    cholmod_free_factor(&C.L, &C.c);
    cholmod_finish(&C.c);
    fclose(csv);
    return 0;
}
