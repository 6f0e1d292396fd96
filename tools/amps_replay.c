/* amps_replay: runs a scenario (mesh, material, fixed nodes, forces, pins, cuts, solves) with
   amps.h and prints one line per solve and a summary.

   usage: amps_replay [-q] [--residual] [--threads N] [--openmp] [--jobs N] [--order auto|amd|nd|metis|natural]
                      [--refactor auto|count|off] [--dual] [--xs-from-dense] [--surface FILE]
                      [--frames PREFIX] scenario
   --refactor picks the background re-factorization's policy: auto (the default; its swaps
   depend on the clock, so runs agree to rounding, not bits), count (at points fixed by the
   count of structural commits: identical runs give identical bits, on any thread count and back
   end) or off.
   --jobs N runs amps.h's parallel loops on N worker threads of examples/jobs.h (the host task
   system of amps_ctx: enqueue_task/finish_task; the calling thread helps) instead of amps' own
   workers; --openmp runs them in OpenMP regions (AMPS_BACKEND_OPENMP).
   --surface FILE writes the deformed boundary triangles (cut faces included) at the end, one
   block of 4 lines "x y z |u|" per triangle, for gnuplot's "with polygons".
   --frames PREFIX writes PREFIX_NNNNN.vtu after every solve or time step (frame NNNNN from 1) and
   at the end PREFIX.pvd, the ParaView time series of the frames (time k dt in dynamics, the
   solve's number k in statics; the .vtu names relative to the .pvd's folder).

   Scenario lines (# starts a comment anywhere; node indices 0-based in the mesh's order):
     mesh <file> | mesh beam <h> | mesh brick <R>   (.node with its .ele, .msh or .mesh; paths
                                                      relative to the scenario's directory)
     material <E> <nu>        all tetrahedra; only before the first solve
     fix <x|y|z> <lt|gt> <v>  fix the nodes whose coordinate is below / above v
     force <node> <fx> <fy> <fz>
     pin <node> <ux> <uy> <uz>
     release <node>
     cut <node> <px> <py> <pz> <nx> <ny> <nz>
     stroke <radius> <bx> <by> <bz> <x0> <y0> <z0> <x1> <y1> <z1> [<x2> <y2> <z2>]
                              a blade stroke (amps_scene_stroke): the polyline of 2 or 3 points
                              swept along the blade direction b cuts the nodes within radius of
                              it, one commit; prints the nodes cut, the no-ops and the refusals
     batch                    open a batch: cuts, strokes, pins, releases, removals only
                              record ...
     commit                   ... until commit applies them at once (amps_scene_commit; a solve
                              or a step commits an open batch too); a commit that leaves a piece
                              loose is undone and reported, and the scenario goes on
     cancel                   undoes the open batch (amps_scene_cancel_batch)
     solve
     residual on|off
     dump <file.csv>          node,ux,uy,uz of every node (values of the last solve)
     write <file.vtu>         mesh, displacement and stresses for ParaView
     fixnodes <v> [<v> ...]   fix the listed nodes (before the first solve)
     fixbox x0 y0 z0 x1 y1 z1 fix the nodes in the box [x0, x1] x [y0, y1] x [z0, z1]
     fixsphere x y z r        fix the nodes within distance r of (x, y, z)
     watch <v> [<v> ...]      the watched nodes (replaces the set; copies of cut nodes join it)
     solve_watched            solve for the watched nodes only
     haptic <n>               n haptic steps (pin reactions from the dense system); prints the
                              median and worst step
     boundary <file>          the boundary triangles at their deformed positions: an OBJ file
                              if the name ends in .obj, else the --surface format
   Dynamics (tetrahedron indices 0-based in file order; removed ones keep their index):
     density <rho>            all tetrahedra (default 1); before the first solve or step
     region <id> <E> <nu> [<rho>]  tetrahedra with region attribute id; before the first solve or step
     gravity <gx> <gy> <gz>   body force per unit mass (default 0); any time
     dynamics <dt> <alpha> <beta>  implicit dynamics from now on; before the first solve or step
     step [<n>]               n time steps (default 1); dynamics only (solve is an error there)
     remove <tet> [<tet> ...] element removal with the default singularity avoidance
     fracture <sigma_max> | off  automatic removal after each step
     corotational on|off      corotational elasticity (large rotations; amps_scene_corotational):
                              after dynamics, before the first step; each step line then reports
                              the PCG iterations and its relative residual
   In dynamics dump writes node,ux,uy,uz,vx,vy,vz. */
#define AMPS_IMPLEMENTATION
#include "amps.h"
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <ctype.h>
#include <math.h>
#include <errno.h>
#include <limits.h>
#ifndef AMPS_REPLAY_NO_MAIN
#define JOBS_IMPLEMENTATION
#include "../examples/jobs.h"
#endif


typedef struct replay {
    amps_ctx ctx;
    amps_scene *S;
    const char *file;
    char dir[4096];
    int line, quiet, residual_on, steps, solved;
    amps_scene_opts opts;
    double step_time, *times;
    int ntimes, captimes;
    double worst_res;
    char last_cmd[64];
    double E, nu;
    int have_material;
    int dynamic; /* 'dynamics' given */
    int sandbox; /* fuzzing: no file access (mesh files, dump, write), small meshes only */
    const char *frames; /* --frames PREFIX: a VTU per solve or step and the .pvd of them */
    int nframes;
    double *frame_t, dt; /* the frames' times; the time step (dynamics) */
    char *buf;           /* the line being run (bufcap bytes) */
    char **tok;          /* its tokens (tokcap) */
    amps_int *ids;       /* a node or tet list of the line (tokcap) */
    size_t bufcap, tokcap;
} replay;


static int fail(replay *R, const char *fmt, const char *a) {
    fprintf(stderr, "%s:%d: ", R->file, R->line);
    fprintf(stderr, fmt, a);
    fprintf(stderr, "\n");
    return 1;
}

static int parse_num(const char *s, double *v) {
    char *end;
    *v = strtod(s, &end);
    return *end == '\0' && end != s && (*v - *v == 0.0);
}

/* An integer that amps_int holds (else 0: a bad number, out of range). */
static int parse_int(const char *s, amps_int *v) {
    char *end;
    long x;
    errno = 0;
    x = strtol(s, &end, 10);
    if (*end != '\0' || end == s || errno == ERANGE || x != (long)(amps_int)x) return 0;
    *v = (amps_int)x;
    return 1;
}

/* A non-negative index or count that amps_int holds (else 0). */
static int parse_node(const char *s, amps_int *v) {
    amps_int x;
    if (!parse_int(s, &x) || x < 0) return 0;
    *v = (amps_int)x;
    return 1;
}

/* A file that cannot be written: "file:line: ..." for a command (cmd), else "path: ...". */
static int write_fail(replay *R, const char *path, int cmd) {
    if (cmd) return fail(R, "cannot write '%s'", path);
    fprintf(stderr, "%s: cannot write\n", path);
    return 1;
}

/* Boundary triangles (amps_mesh_boundary: faces of exactly one tet, cut faces included) at their
   deformed positions: an OBJ file (obj != 0) or blocks of 4 lines "x y z |u|" per triangle. */
static int write_boundary(replay *R, const char *path, int obj) {
    const amps_mesh *m = amps_scene_mesh(R->S);
    const double *u = amps_scene_displacements(R->S);
    amps_int n = amps_mesh_boundary(&R->ctx, m, NULL, NULL), k, v;
    amps_int *tri = (amps_int *)malloc(sizeof(amps_int) * 3 * (size_t)(n > 0 ? n : 1));
    FILE *o = n >= 0 && tri ? fopen(path, "w") : NULL;
    int q;
    if (!o) {
        free(tri);
        return write_fail(R, path, obj);
    }
    amps_mesh_boundary(&R->ctx, m, tri, NULL);
    if (obj) {
        for (v = 0; v < m->nnode; v++)
            fprintf(o, "v %.17g %.17g %.17g\n", m->xyz[3 * v] + u[3 * v], m->xyz[3 * v + 1] + u[3 * v + 1],
                    m->xyz[3 * v + 2] + u[3 * v + 2]);
        for (k = 0; k < n; k++)
            fprintf(o, "f %ld %ld %ld\n", (long)tri[3 * k] + 1, (long)tri[3 * k + 1] + 1, (long)tri[3 * k + 2] + 1);
    } else
        for (k = 0; k < n; k++) {
            for (q = 0; q <= 3; q++) {
                v = tri[3 * k + q % 3];
                fprintf(o, "%g %g %g %g\n", m->xyz[3 * v] + u[3 * v], m->xyz[3 * v + 1] + u[3 * v + 1],
                        m->xyz[3 * v + 2] + u[3 * v + 2],
                        sqrt(u[3 * v] * u[3 * v] + u[3 * v + 1] * u[3 * v + 1] + u[3 * v + 2] * u[3 * v + 2]));
            }
            fprintf(o, "\n");
        }
    free(tri);
    if (fclose(o)) return write_fail(R, path, obj);
    if (!R->quiet) printf("%s: %s (%ld triangles)\n", obj ? "boundary" : "surface", path, (long)n);
    return 0;
}

static int write_surface(replay *R, const char *path) { return write_boundary(R, path, 0); }

static int cmp_double(const void *a, const void *b) {
    double x = *(const double *)a, y = *(const double *)b;
    return x < y ? -1 : (x > y ? 1 : 0);
}

/* Library error: a fatal stop with file:line and the library's message. */
static int lib_fail(replay *R, const char *what) {
    fprintf(stderr, "%s:%d: %s: %s\n", R->file, R->line, what, R->ctx.msg);
    return 1;
}

static int need_scene(replay *R) {
    if (!R->S) {
        fail(R, "%s", "no mesh yet (the first command must be 'mesh')");
        return 0;
    }
    return 1;
}

static int cmd_mesh(replay *R, int nt, char **t) {
    amps_mesh *m = NULL;
    if (R->S) return fail(R, "%s", "mesh given twice");
    if (nt == 3 && (!strcmp(t[1], "beam") || !strcmp(t[1], "brick"))) {
        amps_int k;
        if (!parse_node(t[2], &k) || k < 1) return fail(R, "bad size '%s'", t[2]);
        if (R->sandbox && k > 8) return fail(R, "size '%s' too large for the sandbox", t[2]);
        m = !strcmp(t[1], "beam") ? amps_mesh_beam(&R->ctx, k) : amps_mesh_brick(&R->ctx, k);
    } else if (nt == 2) {
        char path[8192];
        if (R->sandbox) return fail(R, "%s", "mesh files are not read in the sandbox");
        if (t[1][0] == '/') snprintf(path, sizeof(path), "%s", t[1]);
        else snprintf(path, sizeof(path), "%s%s", R->dir, t[1]);
        m = amps_mesh_read(&R->ctx, path);
    } else return fail(R, "%s", "usage: mesh <file> | mesh beam <h> | mesh brick <R>");
    if (!m) return lib_fail(R, "mesh");
    R->S = amps_scene_create(&R->ctx, m, &R->opts);
    if (!R->S) {
        amps_mesh_free(&R->ctx, m);
        return lib_fail(R, "mesh");
    }
    if (!R->quiet) printf("mesh: %ld nodes, %ld tetrahedra\n", (long)m->nnode, (long)m->ntet);
    return 0;
}

static void print_factor_info(replay *R, double t) {
    const amps_factor *F = amps_scene_factor(R->S);
    if (R->quiet || !F) return;
    printf("factor: %ld equations, nnz(L) %.0f, elimination tree height %ld, %.1f ms (ordering, analysis, numeric)\n",
           (long)F->n, amps_factor_nnz(F), (long)F->height, 1e3 * t);
}

/* Nodes t[1..nt-1] into v (room for nt); 0 after a message if one is bad or out of range. */
static int parse_nodes(replay *R, int nt, char **t, amps_int *v) {
    int k;
    for (k = 1; k < nt; k++)
        if (!parse_node(t[k], v + k - 1) || v[k - 1] >= amps_scene_mesh(R->S)->nnode) {
            fail(R, "bad node '%s'", t[k]);
            return 0;
        }
    return 1;
}

/* fixnodes <v> [<v> ...] | watch <v> [<v> ...] */
static int cmd_nodelist(replay *R, int nt, char **t) {
    amps_int *v = R->ids;
    int fix = !strcmp(t[0], "fixnodes");
    if (nt < 2) return fail(R, "usage: %s <node> [<node> ...]", t[0]);
    if (!parse_nodes(R, nt, t, v)) return 1;
    if (fix ? amps_scene_fix(&R->ctx, R->S, nt - 1, v) : amps_scene_watch(&R->ctx, R->S, nt - 1, v))
        return lib_fail(R, t[0]);
    if (fix && !R->quiet) printf("fixnodes: %d nodes\n", nt - 1);
    return 0;
}

/* fixbox x0 y0 z0 x1 y1 z1 | fixsphere x y z r */
static int cmd_fixregion(replay *R, int nt, char **t) {
    int box = !strcmp(t[0], "fixbox"), k;
    double x[6];
    amps_int cnt = 0;
    amps_status s;
    if (nt != (box ? 7 : 5)) return fail(R, "%s", box ? "usage: fixbox x0 y0 z0 x1 y1 z1" : "usage: fixsphere x y z r");
    for (k = 1; k < nt; k++)
        if (!parse_num(t[k], &x[k - 1])) return fail(R, "bad number '%s'", t[k]);
    s = box ? amps_scene_fix_box(&R->ctx, R->S, x, x + 3, &cnt) : amps_scene_fix_sphere(&R->ctx, R->S, x, x[3], &cnt);
    if (s != AMPS_OK) return lib_fail(R, t[0]);
    if (!R->quiet) printf("%s: %ld nodes\n", t[0], (long)cnt);
    return 0;
}

/* solve_watched */
static int cmd_solve_watched(replay *R, int nt) {
    double t0 = amps_now(), dt;
    amps_int n;
    if (nt != 1) return fail(R, "%s", "usage: solve_watched");
    if (amps_scene_solve_watched(&R->ctx, R->S) < 0) return lib_fail(R, "solve_watched");
    dt = amps_now() - t0;
    if (!R->solved) print_factor_info(R, dt);
    R->solved = 1;
    amps_scene_watched(R->S, &n);
    if (!R->quiet) printf("solve_watched: %ld nodes, %.3f ms\n", (long)n, 1e3 * dt);
    return 0;
}

/* haptic <n> */
static int cmd_haptic(replay *R, int nt, char **t) {
    amps_int n, k;
    double *dt;
    if (nt != 2 || !parse_node(t[1], &n) || n < 1 || n > 10000000) return fail(R, "%s", "usage: haptic <steps>");
    if (R->sandbox && n > 100) n = 100;
    dt = (double *)malloc(sizeof(double) * (size_t)n);
    if (!dt) return fail(R, "%s", "out of memory");
    for (k = 0; k < n; k++) {
        double t0 = amps_now();
        if (amps_scene_solve_reactions(&R->ctx, R->S) < 0) {
            free(dt);
            return lib_fail(R, "haptic");
        }
        dt[k] = amps_now() - t0;
        if (k == 0 && !R->solved) print_factor_info(R, dt[0]);
        R->solved = 1;
    }
    qsort(dt, (size_t)n, sizeof(double), cmp_double);
    if (!R->quiet)
        printf("haptic: %ld steps, median %.2f us, worst %.2f us\n", (long)n, 1e6 * dt[n / 2], 1e6 * dt[n - 1]);
    free(dt);
    return 0;
}

/* boundary <file> */
static int cmd_boundary(replay *R, int nt, char **t) {
    size_t n;
    if (nt != 2) return fail(R, "%s", "usage: boundary <file.obj|file.surf>");
    if (R->sandbox) return 0;
    n = strlen(t[1]);
    return write_boundary(R, t[1], n >= 4 && !strcmp(t[1] + n - 4, ".obj"));
}

/* The selection, watch, haptic and boundary commands; -1 if c is none of them. */
static int run_selection_line(replay *R, int nt, char **t) {
    const char *c = t[0];
    if (!strcmp(c, "fixnodes") || !strcmp(c, "watch")) return cmd_nodelist(R, nt, t);
    if (!strcmp(c, "fixbox") || !strcmp(c, "fixsphere")) return cmd_fixregion(R, nt, t);
    if (!strcmp(c, "solve_watched")) return cmd_solve_watched(R, nt);
    if (!strcmp(c, "haptic")) return cmd_haptic(R, nt, t);
    if (!strcmp(c, "boundary")) return cmd_boundary(R, nt, t);
    return -1;
}

/* stroke <radius> <blade xyz> <2 or 3 points xyz> */
static int cmd_stroke(replay *R, int nt, char **t, double t0) {
    double x[13];
    amps_scene_stroke_result r;
    amps_status *st, s;
    int k, np = (nt - 5) / 3, noop = 0, refused = 0;
    if ((nt != 11 && nt != 14))
        return fail(R, "%s", "usage: stroke <radius> <bx> <by> <bz> <x0> <y0> <z0> <x1> <y1> <z1> [<x2> <y2> <z2>]");
    for (k = 1; k < nt; k++)
        if (!parse_num(t[k], &x[k - 1])) return fail(R, "bad number '%s'", t[k]);
    memset(&r, 0, sizeof(r));
    r.cap = amps_scene_mesh(R->S)->nnode; /* the nodes touched are at most the nodes */
    st = (amps_status *)malloc(sizeof(amps_status) * (size_t)(r.cap > 0 ? r.cap : 1));
    if (!st) return fail(R, "%s", "out of memory");
    r.status = st;
    s = amps_scene_stroke(&R->ctx, R->S, np, x + 4, x + 1, x[0], &r);
    for (k = 0; s == AMPS_OK && k < r.n && k < r.cap; k++) {
        noop += st[k] == AMPS_WARN_NOOP;
        refused += st[k] == AMPS_ERR_SINGULAR_UPDATE;
    }
    free(st);
    if (s == AMPS_ERR_SINGULAR_UPDATE) printf("%s:%d: stroke undone: %s\n", R->file, R->line, R->ctx.msg);
    else if (s != AMPS_OK) return lib_fail(R, "stroke");
    if (!R->quiet)
        printf("%s:%d: stroke: %ld nodes touched, %ld cut, %d no-ops, %d refused\n", R->file, R->line, (long)r.n,
               (long)r.ncut, noop, refused);
    snprintf(R->last_cmd, sizeof(R->last_cmd), "stroke %ld", (long)r.ncut);
    R->step_time += amps_now() - t0;
    return 0;
}

/* batch | commit | cancel */
static int cmd_batch(replay *R, int nt, char **t, double t0) {
    int begin = !strcmp(t[0], "batch");
    amps_status s;
    if (nt != 1) return fail(R, "usage: %s", t[0]);
    if (!strcmp(t[0], "cancel")) return amps_scene_cancel_batch(&R->ctx, R->S) ? lib_fail(R, t[0]) : 0;
    s = begin ? amps_scene_begin_batch(&R->ctx, R->S) : amps_scene_commit(&R->ctx, R->S);
    if (s == AMPS_ERR_SINGULAR_UPDATE && !begin) /* the batch is undone; the scenario goes on */
        printf("%s:%d: commit undone: %s\n", R->file, R->line, R->ctx.msg);
    else if (s != AMPS_OK) return lib_fail(R, t[0]);
    if (!begin) snprintf(R->last_cmd, sizeof(R->last_cmd), "commit");
    R->step_time += amps_now() - t0;
    return 0;
}
/* After a solve or a step that started at t0: the factorization (first time), the residual,
   the timing and the step line. */
static int write_vtu(replay *R, const char *path);

/* --frames PREFIX: PREFIX_NNNNN.vtu of this solve or step (frame NNNNN, from 1; time k dt in
   dynamics, the solve's number k in statics). */
static int write_frame(replay *R) {
    char path[4200];
    double *t2;
    if (!R->frames || R->sandbox) return 0;
    if (!(t2 = (double *)realloc(R->frame_t, sizeof(double) * (size_t)(R->nframes + 1))))
        return fail(R, "%s", "out of memory");
    R->frame_t = t2;
    R->frame_t[R->nframes] = R->dynamic ? (R->nframes + 1) * R->dt : R->nframes + 1;
    snprintf(path, sizeof(path), "%s_%05d.vtu", R->frames, R->nframes + 1);
    if (write_vtu(R, path)) return 1;
    R->nframes++;
    return 0;
}

/* --frames PREFIX: PREFIX.pvd, the time series of the frames written (at the end of a run, also
   of one that failed). */
static int write_pvd(replay *R) {
    const char *base = R->frames ? strrchr(R->frames, '/') : NULL;
    char path[4200], **names;
    int k, rc = 0;
    if (!R->frames || R->sandbox) return 0;
    base = base ? base + 1 : R->frames;
    if (!(names = (char **)calloc((size_t)R->nframes + 1, sizeof(char *)))) return fail(R, "%s", "out of memory");
    for (k = 0; k < R->nframes && !rc; k++) {
        size_t n = strlen(base) + 16;
        if (!(names[k] = (char *)malloc(n))) rc = fail(R, "%s", "out of memory");
        else snprintf(names[k], n, "%s_%05d.vtu", base, k + 1);
    }
    snprintf(path, sizeof(path), "%s.pvd", R->frames);
    if (!rc && amps_pvd_write(&R->ctx, path, R->nframes, (const char *const *)names, R->frame_t)) {
        fprintf(stderr, "%s: %s\n", path, R->ctx.msg);
        rc = 1;
    }
    for (k = 0; k < R->nframes; k++) free(names[k]);
    free(names);
    return rc;
}

static int report_solve(replay *R, double t0) {
    double res = -1, dt;
    amps_update_stats st;
    int first = !R->solved;
    dt = R->step_time + amps_now() - t0;
    if (first) print_factor_info(R, dt);
    R->solved = 1;
    if (R->residual_on) {
        if (amps_scene_residual(&R->ctx, R->S, &res)) return lib_fail(R, "residual");
        if (res > R->worst_res) R->worst_res = res;
    }
    amps_update_get_stats(amps_scene_engine(R->S), &st);
    R->steps++;
    if (!first) {
        if (R->ntimes == R->captimes) {
            R->captimes = 2 * R->captimes + 64;
            R->times = (double *)realloc(R->times, sizeof(double) * R->captimes);
        }
        R->times[R->ntimes++] = dt;
    }
    if (!R->quiet) {
        printf("step %4d  %-14s dofs %7ld  |S|%6ld  %9.3f ms  %9.1f Hz", R->steps,
               R->last_cmd[0] ? R->last_cmd : "solve", (long)st.dim, (long)st.nsys, 1e3 * dt, dt > 0 ? 1.0 / dt : 0.0);
        if (res >= 0) printf("  residual %.2e", res);
        printf("%s\n", first ? "  (includes the factorization)" : "");
    }
    R->step_time = 0;
    R->last_cmd[0] = 0;
    return write_frame(R);
}

static int run_dynamics_line(replay *R, int nt, char **t);
static int dump_dynamic(replay *R, FILE *f, const char *path);

static int run_line(replay *R, int nt, char **t) {
    const char *c = t[0];
    amps_int v;
    double x[6];
    int k;
    double t0 = amps_now();
    if (!strcmp(c, "mesh")) return cmd_mesh(R, nt, t);
    if (!need_scene(R)) return 1;
    if ((k = run_selection_line(R, nt, t)) >= 0) return k;
    if (!strcmp(c, "material")) {
        if (nt != 3 || !parse_num(t[1], &x[0]) || !parse_num(t[2], &x[1]))
            return fail(R, "%s", "usage: material <E> <nu>");
        if (R->solved) return fail(R, "%s", "material is allowed only before the first solve");
        if (amps_scene_set_material(&R->ctx, R->S, x[0], x[1])) return lib_fail(R, "material");
        return 0;
    }
    if (!strcmp(c, "fix")) {
        int axis;
        amps_int cnt;
        if (nt != 4) return fail(R, "%s", "usage: fix <x|y|z> <lt|gt> <value>");
        if (!strcmp(t[1], "x")) axis = 0;
        else if (!strcmp(t[1], "y")) axis = 1;
        else if (!strcmp(t[1], "z")) axis = 2;
        else return fail(R, "bad axis '%s' (x, y or z)", t[1]);
        if (strcmp(t[2], "lt") && strcmp(t[2], "gt")) return fail(R, "bad comparison '%s' (lt or gt)", t[2]);
        if (!parse_num(t[3], &x[0])) return fail(R, "bad value '%s'", t[3]);
        if (amps_scene_fix_where(&R->ctx, R->S, axis, !strcmp(t[2], "lt") ? AMPS_LT : AMPS_GT, x[0], &cnt))
            return lib_fail(R, "fix");
        if (!R->quiet) printf("fix: %ld nodes\n", (long)cnt);
        return 0;
    }
    if (!strcmp(c, "force") || !strcmp(c, "pin")) {
        amps_status s;
        if (nt != 5 || !parse_node(t[1], &v)) return fail(R, "usage: %s <node> <x> <y> <z>", c);
        for (k = 0; k < 3; k++)
            if (!parse_num(t[2 + k], &x[k])) return fail(R, "bad number '%s'", t[2 + k]);
        if (v >= amps_scene_mesh(R->S)->nnode) return fail(R, "node %s out of range", t[1]);
        s = !strcmp(c, "force") ? amps_scene_force(&R->ctx, R->S, v, x) : amps_scene_pin(&R->ctx, R->S, v, x);
        if (s != AMPS_OK) return lib_fail(R, c);
        snprintf(R->last_cmd, sizeof(R->last_cmd), "%s %ld", c, (long)v);
        R->step_time += amps_now() - t0;
        return 0;
    }
    if (!strcmp(c, "release")) {
        if (nt != 2 || !parse_node(t[1], &v)) return fail(R, "%s", "usage: release <node>");
        if (v >= amps_scene_mesh(R->S)->nnode) return fail(R, "node %s out of range", t[1]);
        if (amps_scene_release(&R->ctx, R->S, v) != AMPS_OK) {
            if (R->ctx.status != AMPS_ERR_SINGULAR_UPDATE) return lib_fail(R, "release");
            printf("%s:%d: release kept: %s\n", R->file, R->line, R->ctx.msg);
        }
        snprintf(R->last_cmd, sizeof(R->last_cmd), "release %ld", (long)v);
        R->step_time += amps_now() - t0;
        return 0;
    }
    if (!strcmp(c, "cut")) {
        amps_int vn;
        amps_status s;
        if (nt != 8 || !parse_node(t[1], &v)) return fail(R, "%s", "usage: cut <node> <px> <py> <pz> <nx> <ny> <nz>");
        for (k = 0; k < 6; k++)
            if (!parse_num(t[2 + k], &x[k])) return fail(R, "bad number '%s'", t[2 + k]);
        if (v >= amps_scene_mesh(R->S)->nnode) return fail(R, "node %s out of range", t[1]);
        if (x[3] == 0 && x[4] == 0 && x[5] == 0) return fail(R, "%s", "zero plane normal");
        s = amps_scene_cut(&R->ctx, R->S, v, x, x + 3, &vn);
        if (s == AMPS_WARN_NOOP) {
            if (!R->quiet) printf("%s:%d: cut %ld is a no-op: %s\n", R->file, R->line, (long)v, R->ctx.msg);
        } else if (s == AMPS_ERR_SINGULAR_UPDATE)
            printf("%s:%d: cut %ld undone: %s\n", R->file, R->line, (long)v, R->ctx.msg);
        else if (s != AMPS_OK) return lib_fail(R, "cut");
        snprintf(R->last_cmd, sizeof(R->last_cmd), "cut %ld", (long)v);
        R->step_time += amps_now() - t0;
        return 0;
    }
    if (!strcmp(c, "stroke")) return cmd_stroke(R, nt, t, t0);
    if (!strcmp(c, "batch") || !strcmp(c, "commit") || !strcmp(c, "cancel")) return cmd_batch(R, nt, t, t0);
    if (!strcmp(c, "solve")) {
        if (nt != 1) return fail(R, "%s", "usage: solve");
        if (amps_scene_solve(&R->ctx, R->S) != AMPS_OK) return lib_fail(R, "solve");
        return report_solve(R, t0);
    }
    if (!strcmp(c, "residual")) {
        if (nt != 2 || (strcmp(t[1], "on") && strcmp(t[1], "off"))) return fail(R, "%s", "usage: residual on|off");
        R->residual_on = !strcmp(t[1], "on");
        return 0;
    }
    if (!strcmp(c, "dump")) {
        FILE *f;
        const amps_mesh *m = amps_scene_mesh(R->S);
        const double *d = amps_scene_displacements(R->S);
        amps_int i;
        if (nt != 2) return fail(R, "%s", "usage: dump <file.csv>");
        if (R->sandbox) return 0;
        f = fopen(t[1], "w");
        if (!f) return fail(R, "cannot write '%s'", t[1]);
        if (R->dynamic) return dump_dynamic(R, f, t[1]);
        fprintf(f, "node,ux,uy,uz\n");
        for (i = 0; i < m->nnode; i++)
            fprintf(f, "%ld,%.17g,%.17g,%.17g\n", (long)i, d[3 * i], d[3 * i + 1], d[3 * i + 2]);
        if (fclose(f)) return fail(R, "cannot write '%s'", t[1]);
        if (!R->quiet) printf("dump: %s (%ld nodes)\n", t[1], (long)m->nnode);
        return 0;
    }
    if (!strcmp(c, "write")) {
        if (nt != 2) return fail(R, "%s", "usage: write <file.vtu>");
        if (R->sandbox) return 0;
        if (write_vtu(R, t[1])) return 1;
        if (!R->quiet) printf("write: %s\n", t[1]);
        return 0;
    }
    if ((k = run_dynamics_line(R, nt, t)) >= 0) return k;
    return fail(R, "unknown command '%s'", c);
}

/* The mesh with the displacements, von Mises and principal stresses of the last solve or step. */
static int write_vtu(replay *R, const char *path) {
    const amps_mesh *m = amps_scene_mesh(R->S);
    double *vm = (double *)malloc(sizeof(double) * (m->ntet + 1)),
           *pr = (double *)malloc(sizeof(double) * 3 * (m->ntet + 1));
    amps_status s = vm && pr ? amps_scene_stress(&R->ctx, R->S, NULL, vm, pr) : AMPS_ERR_OOM;
    if (s == AMPS_OK) s = amps_mesh_write_vtu(&R->ctx, path, m, amps_scene_displacements(R->S), vm, pr);
    free(vm);
    free(pr);
    return s == AMPS_ERR_OOM && !vm ? fail(R, "%s", "out of memory") : s != AMPS_OK ? lib_fail(R, "write") : 0;
}

/* dump in dynamics: node,ux,uy,uz,vx,vy,vz (f open for writing; closed here). */
static int dump_dynamic(replay *R, FILE *f, const char *path) {
    const amps_mesh *m = amps_scene_mesh(R->S);
    const double *d = amps_scene_displacements(R->S), *w = amps_scene_velocities(R->S);
    amps_int i;
    fprintf(f, "node,ux,uy,uz,vx,vy,vz\n");
    for (i = 0; i < m->nnode; i++)
        fprintf(f, "%ld,%.17g,%.17g,%.17g,%.17g,%.17g,%.17g\n", (long)i, d[3 * i], d[3 * i + 1], d[3 * i + 2], w[3 * i],
                w[3 * i + 1], w[3 * i + 2]);
    if (fclose(f)) return fail(R, "cannot write '%s'", path);
    if (!R->quiet) printf("dump: %s (%ld nodes)\n", path, (long)m->nnode);
    return 0;
}

/* density <rho> | region <id> <E> <nu> [<rho>]: before the first solve or step. */
static int cmd_material_dyn(replay *R, int nt, char **t) {
    double x[4];
    amps_int id;
    int k;
    if (!strcmp(t[0], "density")) {
        if (nt != 2 || !parse_num(t[1], &x[0])) return fail(R, "%s", "usage: density <rho>");
        if (R->solved) return fail(R, "%s", "density is allowed only before the first solve or step");
        return amps_scene_set_density(&R->ctx, R->S, x[0]) ? lib_fail(R, "density") : 0;
    }
    if ((nt != 4 && nt != 5) || !parse_int(t[1], &id)) return fail(R, "%s", "usage: region <id> <E> <nu> [<rho>]");
    x[2] = 0; /* no density given: amps_scene_set_region keeps it */
    for (k = 2; k < nt; k++)
        if (!parse_num(t[k], &x[k - 2])) return fail(R, "bad number '%s'", t[k]);
    if (nt == 5 && !(x[2] > 0)) return fail(R, "region: density %s is not > 0", t[4]);
    if (R->solved) return fail(R, "%s", "region is allowed only before the first solve or step");
    return amps_scene_set_region(&R->ctx, R->S, id, x[0], x[1], x[2]) ? lib_fail(R, "region") : 0;
}

/* gravity <gx> <gy> <gz> | dynamics <dt> <alpha> <beta> | fracture <sigma_max>|off */
static int cmd_dynamics(replay *R, int nt, char **t) {
    double x[3];
    int k;
    if (!strcmp(t[0], "fracture")) {
        if (nt != 2 || (strcmp(t[1], "off") && !parse_num(t[1], &x[0])))
            return fail(R, "%s", "usage: fracture <sigma_max> | off");
        if (strcmp(t[1], "off") && !(x[0] > 0)) return fail(R, "%s", "fracture: sigma_max must be > 0 (or off)");
        return amps_scene_fracture(&R->ctx, R->S, strcmp(t[1], "off") ? x[0] : 0.0) ? lib_fail(R, "fracture") : 0;
    }
    if (nt != 4)
        return fail(R, "usage: %s",
                    !strcmp(t[0], "gravity") ? "gravity <gx> <gy> <gz>" : "dynamics <dt> <alpha> <beta>");
    for (k = 0; k < 3; k++)
        if (!parse_num(t[1 + k], &x[k])) return fail(R, "bad number '%s'", t[1 + k]);
    if (!strcmp(t[0], "gravity")) return amps_scene_gravity(&R->ctx, R->S, x) ? lib_fail(R, "gravity") : 0;
    if (R->solved) return fail(R, "%s", "dynamics is allowed only before the first solve or step");
    if (amps_scene_dynamics(&R->ctx, R->S, x[0], x[1], x[2])) return lib_fail(R, "dynamics");
    R->dynamic = 1;
    R->dt = x[0];
    return 0;
}

/* step [<n>]: n time steps, one report line each. */
static int cmd_step(replay *R, int nt, char **t) {
    amps_int n = 1, k;
    if (nt > 2 || (nt == 2 && !parse_node(t[1], &n))) return fail(R, "%s", "usage: step [<n>]");
    if (!R->dynamic) return fail(R, "%s", "step needs dynamics (use solve in statics)");
    for (k = 0; k < n; k++) {
        double t0 = amps_now();
        amps_int nf;
        if (amps_scene_step(&R->ctx, R->S, 1) < 0) return lib_fail(R, "step");
        nf = amps_scene_fractured(R->S, NULL);
        if (!R->last_cmd[0]) snprintf(R->last_cmd, sizeof(R->last_cmd), "step");
        if (nf > 0) snprintf(R->last_cmd, sizeof(R->last_cmd), "step (tore %ld)", (long)nf);
        {
            amps_scene_step_stats st;
            size_t l = strlen(R->last_cmd);
            if (amps_scene_step_info(R->S, &st) == AMPS_OK && st.corotational && l + 1 < sizeof(R->last_cmd))
                snprintf(R->last_cmd + l, sizeof(R->last_cmd) - l, " pcg %ld", (long)st.iterations);
        }
        if (nf > 0) { /* the tear changed the system after the solve: no residual for this step */
            int on = R->residual_on, rc;
            R->residual_on = 0;
            rc = report_solve(R, t0);
            R->residual_on = on;
            if (rc) return 1;
        } else if (report_solve(R, t0)) return 1;
    }
    return 0;
}

/* remove <tet> [<tet> ...]: a removal that would leave a loose piece is undone (reported). */
static int cmd_remove(replay *R, int nt, char **t) {
    amps_int *tets = R->ids;
    amps_mesh_removal rep;
    amps_status s;
    int k;
    double t0 = amps_now();
    if (nt < 2) return fail(R, "%s", "usage: remove <tet> [<tet> ...]");
    for (k = 1; k < nt; k++) {
        if (!parse_node(t[k], &tets[k - 1])) return fail(R, "bad tetrahedron '%s'", t[k]);
        if (tets[k - 1] >= amps_scene_mesh(R->S)->ntet) return fail(R, "tetrahedron %s out of range", t[k]);
    }
    s = amps_scene_remove(&R->ctx, R->S, nt - 1, tets, AMPS_SINGULAR_REMOVE, &rep);
    if (s == AMPS_ERR_SINGULAR_UPDATE) {
        printf("%s:%d: remove undone: %s\n", R->file, R->line, R->ctx.msg);
        return 0;
    }
    if (s != AMPS_OK) return lib_fail(R, "remove");
    if (!R->quiet)
        printf("remove: %ld tetrahedra, %ld nodes separated, %ld removed in all\n", (long)rep.ntet, (long)rep.nsep,
               (long)amps_scene_mesh(R->S)->nremoved);
    snprintf(R->last_cmd, sizeof(R->last_cmd), "remove %ld", (long)tets[0]);
    R->step_time += amps_now() - t0;
    return 0;
}

/* corotational on|off: dynamics only, before the first step. */
static int cmd_corotational(replay *R, int nt, char **t) {
    if (nt != 2 || (strcmp(t[1], "on") && strcmp(t[1], "off"))) return fail(R, "%s", "usage: corotational on|off");
    if (!R->dynamic) return fail(R, "%s", "corotational needs dynamics (give dynamics first)");
    if (R->solved) return fail(R, "%s", "corotational is allowed only before the first step");
    return amps_scene_corotational(&R->ctx, R->S, !strcmp(t[1], "on")) ? lib_fail(R, "corotational") : 0;
}

/* The dynamics commands; -1 if t[0] is none of them. */
static int run_dynamics_line(replay *R, int nt, char **t) {
    const char *c = t[0];
    if (!strcmp(c, "density") || !strcmp(c, "region")) return cmd_material_dyn(R, nt, t);
    if (!strcmp(c, "gravity") || !strcmp(c, "dynamics") || !strcmp(c, "fracture")) return cmd_dynamics(R, nt, t);
    if (!strcmp(c, "step")) return cmd_step(R, nt, t);
    if (!strcmp(c, "remove")) return cmd_remove(R, nt, t);
    if (!strcmp(c, "corotational")) return cmd_corotational(R, nt, t);
    return -1;
}

/* Room for a line of n characters: the line buffer and at most n / 2 + 1 tokens (a token and a
   separator each). 0 or 1 (out of memory, or a line too long for an int count of tokens). */
static int replay_line_room(replay *R, size_t n) {
    size_t nt = n / 2 + 2;
    if (n > (size_t)INT_MAX) return fail(R, "%s", "line too long");
    if (n + 1 > R->bufcap) {
        char *b = (char *)realloc(R->buf, n + 1 + n / 2);
        if (!b) return fail(R, "%s", "out of memory");
        R->buf = b;
        R->bufcap = n + 1 + n / 2;
    }
    if (nt > R->tokcap) {
        char **t = (char **)realloc(R->tok, sizeof(char *) * (nt + nt / 2));
        amps_int *v;
        if (t) R->tok = t;
        v = t ? (amps_int *)realloc(R->ids, sizeof(amps_int) * (nt + nt / 2)) : NULL;
        if (!v) return fail(R, "%s", "out of memory");
        R->ids = v;
        R->tokcap = nt + nt / 2;
    }
    return 0;
}

/* Runs the scenario text buf[0..len-1] (no NUL needed) line by line; returns 0 or 1 after the
   first failing line (message on stderr). A UTF-8 byte order mark at the start is skipped. */
static int replay_run_buffer(replay *R, const char *text, size_t len) {
    size_t pos = 0;
    int rc = 0;
    if (len >= 3 && !memcmp(text, "\xEF\xBB\xBF", 3)) pos = 3;
    while (pos < len) {
        char **tok, *p, *hash;
        size_t e = pos, n;
        int nt = 0;
        while (e < len && text[e] != '\n') e++;
        n = e - pos;
        R->line++;
        if ((rc = replay_line_room(R, n)) != 0) return rc;
        p = R->buf;
        tok = R->tok;
        memcpy(p, text + pos, n);
        p[n] = 0;
        pos = e < len ? e + 1 : e;
        if (strlen(p) != n) return fail(R, "%s", "NUL character in the line");
        hash = strchr(p, '#');
        if (hash) *hash = 0;
        while (*p) {
            while (*p && isspace((unsigned char)*p)) *p++ = 0;
            if (!*p) break;
            tok[nt++] = p;
            while (*p && !isspace((unsigned char)*p)) p++;
        }
        if (nt == 0) continue;
        if ((rc = run_line(R, nt, tok)) != 0) return rc;
    }
    return 0;
}

/* Fresh replay state (options at their defaults). */
static void replay_init(replay *R) {
    memset(R, 0, sizeof(*R));
    amps_ctx_init(&R->ctx);
    amps_scene_opts_default(&R->opts);
}

static void replay_free(replay *R) {
    free(R->times);
    free(R->buf);
    free(R->tok);
    free(R->ids);
    free(R->frame_t);
    R->frame_t = NULL;
    amps_scene_free(&R->ctx, R->S);
    R->buf = NULL;
    R->tok = NULL;
    R->ids = NULL;
    R->bufcap = R->tokcap = 0;
    R->times = NULL;
    R->S = NULL;
}

#ifndef AMPS_REPLAY_NO_MAIN
int main(int argc, char **argv) {
    replay R;
    FILE *f;
    char *text = NULL;
    size_t len = 0, cap = 0;
    int a, rc = 0;
    const char *path = NULL, *surface = NULL;
    jobs_pool *pool = NULL;
    int njobs = 0;
    replay_init(&R);
    for (a = 1; a < argc; a++) {
        if (!strcmp(argv[a], "-q")) R.quiet = 1;
        else if (!strcmp(argv[a], "--residual")) R.residual_on = 1;
        else if (!strcmp(argv[a], "--dual")) R.opts.update.formulation = AMPS_FORM_DUAL;
        else if (!strcmp(argv[a], "--xs-from-dense")) R.opts.update.xs_from_dense = 1;
        else if (!strcmp(argv[a], "--threads") && a + 1 < argc) R.ctx.nthreads = atoi(argv[++a]);
        else if (!strcmp(argv[a], "--jobs") && a + 1 < argc) njobs = atoi(argv[++a]);
        else if (!strcmp(argv[a], "--openmp")) R.ctx.backend = AMPS_BACKEND_OPENMP;
        else if (!strcmp(argv[a], "--surface") && a + 1 < argc) surface = argv[++a];
        else if (!strcmp(argv[a], "--frames") && a + 1 < argc) R.frames = argv[++a];
        else if (!strcmp(argv[a], "--refactor") && a + 1 < argc) {
            const char *o = argv[++a];
            if (!strcmp(o, "auto")) R.opts.update.refactor = AMPS_REFACTOR_AUTO;
            else if (!strcmp(o, "count")) R.opts.update.refactor = AMPS_REFACTOR_COUNT;
            else if (!strcmp(o, "off")) R.opts.update.refactor = AMPS_REFACTOR_OFF;
            else {
                fprintf(stderr, "amps_replay: unknown re-factorization policy '%s'\n", o);
                return 2;
            }
        } else if (!strcmp(argv[a], "--order") && a + 1 < argc) {
            const char *o = argv[++a];
            if (!strcmp(o, "amd")) R.opts.order.method = AMPS_ORDER_AMD;
            else if (!strcmp(o, "nd")) R.opts.order.method = AMPS_ORDER_ND;
            else if (!strcmp(o, "metis")) R.opts.order.method = AMPS_ORDER_METIS;
            else if (!strcmp(o, "natural")) R.opts.order.method = AMPS_ORDER_NATURAL;
            else if (!strcmp(o, "auto")) R.opts.order.method = AMPS_ORDER_AUTO;
            else {
                fprintf(stderr, "amps_replay: unknown ordering '%s'\n", o);
                return 2;
            }
        } else if (argv[a][0] == '-' && argv[a][1]) {
            fprintf(stderr, "amps_replay: unknown option '%s'\n", argv[a]);
            return 2;
        } else path = argv[a];
    }
    if (!path) {
        fprintf(stderr,
                "usage: amps_replay [-q] [--residual] [--threads N] [--openmp] [--jobs N] [--order auto|amd|nd|metis|natural] [--refactor auto|count|off] [--dual] [--xs-from-dense] [--surface FILE] [--frames PREFIX] scenario\n");
        return 2;
    }
#ifdef _OPENMP
    if (R.ctx.nthreads > 0) omp_set_num_threads(R.ctx.nthreads);
#endif
    R.file = path;
    {
        const char *sl = strrchr(path, '/');
        size_t n = sl ? (size_t)(sl - path + 1) : 0;
        if (n >= sizeof(R.dir)) n = 0;
        memcpy(R.dir, path, n);
        R.dir[n] = 0;
    }
    f = fopen(path, "r");
    if (!f) {
        fprintf(stderr, "%s: cannot open\n", path);
        return 1;
    }
    for (;;) {
        size_t got;
        if (len == cap) {
            char *t2 = (char *)realloc(text, cap = 2 * cap + 65536);
            if (!t2) {
                fclose(f);
                free(text);
                fprintf(stderr, "%s: out of memory\n", path);
                return 1;
            }
            text = t2;
        }
        got = fread(text + len, 1, cap - len, f);
        len += got;
        if (got == 0) break;
    }
    if (ferror(f)) {
        fclose(f);
        free(text);
        fprintf(stderr, "%s: read error\n", path);
        return 1;
    }
    fclose(f);
    if (njobs > 0) {
        if (!(pool = jobs_create(njobs))) {
            free(text);
            fprintf(stderr, "amps_replay: cannot start %d worker threads\n", njobs);
            return 1;
        }
        jobs_attach(pool, &R.ctx);
    }
    rc = replay_run_buffer(&R, text, len);
    free(text);
    if (write_pvd(&R)) rc = 1;
    if (rc == 0) {
        if (R.ntimes > 0) {
            double med, worst;
            qsort(R.times, (size_t)R.ntimes, sizeof(double), cmp_double);
            med = R.times[R.ntimes / 2];
            worst = R.times[R.ntimes - 1];
            printf("summary: %d solves; after the first: median step %.3f ms (%.1f Hz), worst %.3f ms", R.steps,
                   1e3 * med, 1.0 / med, 1e3 * worst);
        } else printf("summary: %d solves", R.steps);
        if (R.residual_on) printf(", worst residual %.2e", R.worst_res);
        printf("\n");
        if (surface && R.S) rc = write_surface(&R, surface);
    }
    replay_free(&R);
    if (pool) jobs_destroy(pool);
    return rc;
}
#endif
