/* Mesh readers and writers: round trips, TetGen numbering bases, Gmsh 2.2 / 4.1 with mixed
   element types, malformed input (status and file:line; the whole message of each reader
   error), random corruption, allocation failures, and a well-formed VTU file. Temporary files
   go next to the test binary. With AMPS_NO_STDIO only the from-memory readers are tested. */
#include <string.h>
#include "t_alloc.h"
#define AMPS_IMPLEMENTATION
#include "amps.h"
#include "amps_test.h"

static char g_dir[600];

#ifndef AMPS_NO_STDIO
static void t_path(char *out, const char *name) { snprintf(out, 700, "%s/%s", g_dir, name); }

static int t_write(const char *path, const char *s, size_t n) {
    FILE *f = fopen(path, "wb");
    if (!f) return 0;
    fwrite(s, 1, n, f);
    return fclose(f) == 0;
}

static char *t_slurp(const char *path, size_t *len) {
    FILE *f = fopen(path, "rb");
    char *b;
    long n;
    if (!f) return NULL;
    fseek(f, 0, SEEK_END);
    n = ftell(f);
    fseek(f, 0, SEEK_SET);
    b = (char *)malloc((size_t)n + 1);
    if (fread(b, 1, (size_t)n, f) != (size_t)n) {
        free(b);
        fclose(f);
        return NULL;
    }
    b[n] = 0;
    fclose(f);
    if (len) *len = (size_t)n;
    return b;
}
#endif

/* Readers on exact-size heap copies (no NUL terminator), so overreads are caught by ASan. */
static amps_mesh *t_gmsh(amps_ctx *ctx, const char *s) {
    size_t n = strlen(s);
    char *b = (char *)malloc(n ? n : 1);
    amps_mesh *m;
    memcpy(b, s, n);
    m = amps_mesh_read_gmsh_mem(ctx, b, n, "g.msh");
    free(b);
    return m;
}
static amps_mesh *t_medit(amps_ctx *ctx, const char *s) {
    size_t n = strlen(s);
    char *b = (char *)malloc(n ? n : 1);
    amps_mesh *m;
    memcpy(b, s, n);
    m = amps_mesh_read_medit_mem(ctx, b, n, "m.mesh");
    free(b);
    return m;
}
static amps_mesh *t_tetgen(amps_ctx *ctx, const char *node, const char *ele) {
    size_t n = strlen(node), e = strlen(ele);
    char *b = (char *)malloc(n ? n : 1), *c = (char *)malloc(e ? e : 1);
    amps_mesh *m;
    memcpy(b, node, n);
    memcpy(c, ele, e);
    m = amps_mesh_read_tetgen_mem(ctx, b, n, "t.node", c, e, "t.ele");
    free(b);
    free(c);
    return m;
}

/* m is NULL, ctx has status st and a message starting with prefix (e.g. "g.msh:13:"). */
static void t_expect(amps_ctx *ctx, amps_mesh *m, amps_status st, const char *prefix, const char *what) {
    CHECK(!m && ctx->status == st && !strncmp(ctx->msg, prefix, strlen(prefix)), "%s: want %d '%s', got %s (%d: %s)",
          what, (int)st, prefix, m ? "a mesh" : "NULL", (int)ctx->status, ctx->msg);
    amps_mesh_free(ctx, m);
}

static int t_same_mesh(const amps_mesh *a, const amps_mesh *b) {
    return a && b && a->nnode == b->nnode && a->ntet == b->ntet &&
           t_reldiff((int)(3 * a->nnode), a->xyz, b->xyz) == 0 &&
           t_norm((int)(3 * a->nnode), a->xyz) == t_norm((int)(3 * b->nnode), b->xyz) &&
           !memcmp(a->tet, b->tet, sizeof(amps_int) * 4 * a->ntet);
}

/* ---- fixtures ---- */

static const char *G22 =
        "$MeshFormat\n2.2 0 8\n$EndMeshFormat\n$Nodes\n4\n1 0 0 0\n2 1 0 0\n3 0 1 0\n4 0 0 1\n$EndNodes\n"
        "$Elements\n1\n1 4 2 0 1 1 2 3 4\n$EndElements\n";

static const char *G22_MIXED =
        "$MeshFormat\r\n2.2 0 8\r\n$EndMeshFormat\r\n$PhysicalNames\r\n2\r\n2 1 \"skin $EndNodes\"\r\n3 2 \"body\"\r\n$EndPhysicalNames\r\n"
        "$Nodes\r\n6\r\n10 0 0 0\r\n20 1 0 0\r\n30 0 1 0\r\n40 0 0 1\r\n7 1 1 1\r\n5 0.5 0.5 -1\r\n$EndNodes\r\n"
        "$Elements\r\n6\r\n1 15 2 0 1 10\r\n2 1 2 0 1 10 20\r\n3 2 2 1 1 10 20 30\r\n4 4 2 2 1 10 20 30 40\r\n"
        "5 4 3 2 1 0 20 30 40 7\r\n6 4 0 10 30 20 5\r\n$EndElements\r\n";

static const char *G41_MIXED =
        "$MeshFormat\n4.1 0 8\n$EndMeshFormat\n$Entities\n1 0 0 1\n1 0 0 0 0\n1 0 0 0 1 1 1 1 0 0\n$EndEntities\n"
        "$Nodes\n3 6 5 40\n0 1 0 1\n10\n0 0 0\n2 1 1 2\n20\n30\n1 0 0 0.5 0.5\n0 1 0 0.25 0.75\n3 1 0 3\n40\n7\n5\n0 0 1\n1 1 1\n0.5 0.5 -1\n$EndNodes\n"
        "$Elements\n3 5 1 5\n0 1 15 1\n1 10\n2 1 2 1\n2 10 20 30\n3 1 4 3\n3 10 20 30 40\n4 20 30 40 7\n5 10 30 20 5\n$EndElements\n";

static const double MIXED_XYZ[18] = {0, 0, 0, 1, 0, 0, 0, 1, 0, 0, 0, 1, 1, 1, 1, 0.5, 0.5, -1};
static const amps_int MIXED_TET[12] = {0, 1, 2, 3, 1, 2, 3, 4, 0, 2, 1, 5};

static const char *M_BASE =
        "MeshVersionFormatted 2\nDimension 3\nVertices\n4\n0 0 0 0\n1 0 0 0\n0 1 0 0\n0 0 1 0\nTetrahedra\n1\n1 2 3 4 0\nEnd\n";

static const char *M_MIXED =
        "MeshVersionFormatted 2\r\n# comment line\r\nDimension\r\n3\r\nVertices\r\n6\r\n0 0 0 1\r\n1 0 0 1\r\n0 1 0 1   # trailing comment\r\n"
        "0 0 1 2\r\n1 1 1 2\r\n0.5 0.5 -1 3\r\nEdges\r\n1\r\n1 2 0\r\nTriangles\r\n2\r\n1 2 3 1\r\n2 3 4 1\r\nRequiredVertices 1 3\r\n"
        "Tetrahedra\r\n3\r\n1 2 3 4 1\r\n2 3 4 5 7\r\n1 3 2 6 7\r\nCorners\r\n2\r\n1 2\r\nEnd\r\nanything after End is ignored\r\n";

static const char *T_NODE4 = "4 3 0 0\n0 0 0 0\n1 1 0 0\n2 0 1 0\n3 0 0 1\n";
static const char *T_ELE1 = "1 4 0\n0 0 1 2 3\n";

static void test_valid_inputs(void) {
    amps_ctx ctx;
    amps_mesh *m, *ref;
    amps_ctx_init(&ctx);
    ref = amps_mesh_create(&ctx, 6, MIXED_XYZ, 3, MIXED_TET);
    m = t_gmsh(&ctx, G22_MIXED);
    CHECK(t_same_mesh(m, ref), "gmsh 2.2 mixed types, tags, CRLF: %s", ctx.msg);
    amps_mesh_free(&ctx, m);
    m = t_gmsh(&ctx, G41_MIXED);
    CHECK(t_same_mesh(m, ref), "gmsh 4.1 mixed types, blocks, parametric nodes: %s", ctx.msg);
    amps_mesh_free(&ctx, m);
    m = t_medit(&ctx, M_MIXED);
    CHECK(t_same_mesh(m, ref), "medit mixed keywords, comments, CRLF: %s", ctx.msg);
    amps_mesh_free(&ctx, m);
    /* TetGen: 1-based, attributes, markers, comments, 10-node tets */
    m = t_tetgen(
            &ctx,
            "# points\n6 3 1 1\n1 0 0 0 0.5 1\n2 1 0 0 0.5 1\n\n3 0 1 0 0.5 0\n4 0 0 1 0.5 0 # last attr\n5 1 1 1 2 1\n6 0.5 0.5 -1 0 0\n# end\n",
            "# tets, 10 nodes, one attribute\n3 10 1\n1 1 2 3 4 1 2 3 4 5 1 7\n2 2 3 4 5 1 1 1 1 1 1 8\n3 1 3 2 6 6 6 6 6 6 6 0\n");
    CHECK(t_same_mesh(m, ref), "tetgen 1-based, 10-node: %s", ctx.msg);
    amps_mesh_free(&ctx, m);
    /* TetGen: 0-based, CRLF, header without optional fields */
    m = t_tetgen(&ctx, "6\r\n0 0 0 0\r\n1 1 0 0\r\n2 0 1 0\r\n3 0 0 1\r\n4 1 1 1\r\n5 0.5 0.5 -1\r\n",
                 "3\r\n0 0 1 2 3\r\n1 1 2 3 4\r\n2 0 2 1 5\r\n");
    CHECK(t_same_mesh(m, ref), "tetgen 0-based, CRLF: %s", ctx.msg);
    amps_mesh_free(&ctx, m);
    amps_mesh_free(&ctx, ref);
}

/* ---- malformed input: status and line ---- */

static void test_malformed_tetgen(void) {
    amps_ctx ctx;
    amps_ctx_init(&ctx);
    t_expect(&ctx, t_tetgen(&ctx, "", T_ELE1), AMPS_ERR_PARSE, "t.node:1:", "empty node file");
    t_expect(&ctx, t_tetgen(&ctx, "# only a comment\n\n", T_ELE1), AMPS_ERR_PARSE,
             "t.node:2:", "node file without data");
    t_expect(&ctx, t_tetgen(&ctx, "4 3 0 0\n0 0 0 0\n1 1 0 0\n", T_ELE1), AMPS_ERR_PARSE,
             "t.node:3:", "truncated node file");
    t_expect(&ctx, t_tetgen(&ctx, "4 3 0 0\n0 0 0 0\n1 1 0", T_ELE1), AMPS_ERR_PARSE,
             "t.node:3:", "truncated mid-line");
    t_expect(&ctx, t_tetgen(&ctx, "4 3 0 0\n0 0 0 0\n1 1 0 0\n2 0 1 0\n3 0 0 1\n4 1 1 1\n", T_ELE1), AMPS_ERR_PARSE,
             "t.node:6:", "too many points");
    t_expect(&ctx, t_tetgen(&ctx, "-4 3 0 0\n0 0 0 0\n", T_ELE1), AMPS_ERR_PARSE, "t.node:1:", "negative count");
    t_expect(&ctx, t_tetgen(&ctx, "99999999999 3 0 0\n0 0 0 0\n", T_ELE1), AMPS_ERR_PARSE, "t.node:1:", "absurd count");
    t_expect(&ctx, t_tetgen(&ctx, "99999999999999999999999 3\n", T_ELE1), AMPS_ERR_PARSE,
             "t.node:1:", "overflowing count");
    t_expect(&ctx, t_tetgen(&ctx, "0 3 0 0\n", T_ELE1), AMPS_ERR_PARSE, "t.node:1:", "zero points");
    t_expect(&ctx, t_tetgen(&ctx, "4 2 0 0\n", T_ELE1), AMPS_ERR_PARSE, "t.node:1:", "dimension 2");
    t_expect(&ctx, t_tetgen(&ctx, "4 3 0 7\n", T_ELE1), AMPS_ERR_PARSE, "t.node:1:", "bad marker flag");
    t_expect(&ctx, t_tetgen(&ctx, "4 3 0 0\n0 0 0 0\n1 nan 0 0\n2 0 1 0\n3 0 0 1\n", T_ELE1), AMPS_ERR_PARSE,
             "t.node:3:", "NaN");
    t_expect(&ctx, t_tetgen(&ctx, "4 3 0 0\n0 0 0 0\n1 1 0 0\n2 0 1e999 0\n3 0 0 1\n", T_ELE1), AMPS_ERR_PARSE,
             "t.node:4:", "overflow to Inf");
    t_expect(&ctx, t_tetgen(&ctx, "4 3 0 0\n0 0 0 0\n1 1 0 0\n2 0 -inf 0\n3 0 0 1\n", T_ELE1), AMPS_ERR_PARSE,
             "t.node:4:", "-inf");
    t_expect(&ctx, t_tetgen(&ctx, "4 3 0 0\n0 0 0 0\n1 1 0 0\n2 0 abc 0\n3 0 0 1\n", T_ELE1), AMPS_ERR_PARSE,
             "t.node:4:", "non-numeric");
    t_expect(&ctx, t_tetgen(&ctx, "4 3 0 0\n2 0 0 0\n", T_ELE1), AMPS_ERR_PARSE, "t.node:2:", "first number 2");
    t_expect(&ctx, t_tetgen(&ctx, "4 3 0 0\n0 0 0 0\n2 1 0 0\n", T_ELE1), AMPS_ERR_PARSE,
             "t.node:3:", "out of sequence");
    t_expect(&ctx, t_tetgen(&ctx, "# c\n\n4 3 0 0\n0 0 0 0\n\n1 x 0 0\n", T_ELE1), AMPS_ERR_PARSE,
             "t.node:6:", "line count with comments");
    t_expect(&ctx, t_tetgen(&ctx, "4 3 0 0\r\n0 0 0 0\r\n1 1 0 0\r\n2 0 1 0\r\n3 0 0 z\r\n", T_ELE1), AMPS_ERR_PARSE,
             "t.node:5:", "CRLF line count");
    t_expect(&ctx, t_tetgen(&ctx, T_NODE4, ""), AMPS_ERR_PARSE, "t.ele:1:", "empty ele");
    t_expect(&ctx, t_tetgen(&ctx, T_NODE4, "1 4 0\n0 0 1 2 4\n"), AMPS_ERR_PARSE, "t.ele:2:", "index out of range");
    t_expect(&ctx, t_tetgen(&ctx, T_NODE4, "1 4 0\n0 0 1 2 -1\n"), AMPS_ERR_PARSE, "t.ele:2:", "negative index");
    t_expect(&ctx, t_tetgen(&ctx, "4 3 0 0\n1 0 0 0\n2 1 0 0\n3 0 1 0\n4 0 0 1\n", "1 4 0\n1 0 1 2 3\n"),
             AMPS_ERR_PARSE, "t.ele:2:", "0 in 1-based");
    t_expect(&ctx, t_tetgen(&ctx, T_NODE4, "1 4 0\n0 0 1 2\n"), AMPS_ERR_PARSE, "t.ele:2:", "missing index");
    t_expect(&ctx, t_tetgen(&ctx, T_NODE4, "1 4 0\n0 0 1 x 3\n"), AMPS_ERR_PARSE, "t.ele:2:", "non-numeric index");
    t_expect(&ctx, t_tetgen(&ctx, T_NODE4, "1 4 0\n0 0 1 2.0 3\n"), AMPS_ERR_PARSE, "t.ele:2:", "fractional index");
    t_expect(&ctx, t_tetgen(&ctx, T_NODE4, "1 5 0\n0 0 1 2 3 3\n"), AMPS_ERR_PARSE, "t.ele:1:", "5 nodes per tet");
    t_expect(&ctx, t_tetgen(&ctx, T_NODE4, "2 4 0\n0 0 1 2 3\n"), AMPS_ERR_PARSE,
             "t.ele:2:", "fewer tets than declared");
    t_expect(&ctx, t_tetgen(&ctx, T_NODE4, "1 4 0\n0 0 1 2 3\n1 0 1 2 3\n"), AMPS_ERR_PARSE,
             "t.ele:3:", "more tets than declared");
    t_expect(&ctx, t_tetgen(&ctx, T_NODE4, "-1 4 0\n"), AMPS_ERR_PARSE, "t.ele:1:", "negative tet count");
    t_expect(&ctx, t_tetgen(&ctx, T_NODE4, "1 4 -3\n0 0 1 2 3\n"), AMPS_ERR_PARSE,
             "t.ele:1:", "negative attribute count");
    t_expect(&ctx, t_tetgen(&ctx, T_NODE4, "0 4 0\n"), AMPS_ERR_PARSE, "t.ele:1:", "zero tets");
    t_expect(&ctx, t_tetgen(&ctx, T_NODE4, "# x\n1 4 0\n0 0 1 2 2\n"), AMPS_ERR_MESH, "t.ele:3:", "degenerate tet");
    t_expect(&ctx, t_tetgen(&ctx, "4 3 0 0\n0 0 0 0\n1 1 0 0\n2 2 0 0\n3 0 0 1\n", T_ELE1), AMPS_ERR_MESH,
             "t.ele:2:", "flat tet");
}

static void test_malformed_gmsh(void) {
    amps_ctx ctx;
    char buf[1000];
    amps_ctx_init(&ctx);
#define G_HEAD "$MeshFormat\n2.2 0 8\n$EndMeshFormat\n"
#define G_NODES "$Nodes\n4\n1 0 0 0\n2 1 0 0\n3 0 1 0\n4 0 0 1\n$EndNodes\n"
    {
        amps_mesh *m = t_gmsh(&ctx, G22);
        CHECK(m != NULL, "base file: %s", ctx.msg);
        amps_mesh_free(&ctx, m);
    }
    t_expect(&ctx, t_gmsh(&ctx, ""), AMPS_ERR_PARSE, "g.msh:1:", "empty");
    t_expect(&ctx, t_gmsh(&ctx, "\n\n\n"), AMPS_ERR_PARSE, "g.msh:3:", "blank");
    t_expect(&ctx, t_gmsh(&ctx, "hello\n"), AMPS_ERR_PARSE, "g.msh:1:", "garbage");
    t_expect(&ctx, t_gmsh(&ctx, G_NODES), AMPS_ERR_PARSE, "g.msh:1:", "no $MeshFormat");
    t_expect(&ctx, t_gmsh(&ctx, "$MeshFormat\n2.2 1 8\n\x01\x00\x00\x00\n$EndMeshFormat\n"), AMPS_ERR_PARSE,
             "g.msh:2:", "binary");
    CHECK(strstr(ctx.msg, "binary") != NULL, "binary message: %s", ctx.msg);
    t_expect(&ctx, t_gmsh(&ctx, "$MeshFormat\n3.0 0 8\n$EndMeshFormat\n"), AMPS_ERR_PARSE, "g.msh:2:", "version 3");
    t_expect(&ctx, t_gmsh(&ctx, "$MeshFormat\n4 0 8\n$EndMeshFormat\n"), AMPS_ERR_PARSE, "g.msh:2:", "version 4.0");
    t_expect(&ctx, t_gmsh(&ctx, "$MeshFormat\n2.2 0 8\n$Nodes\n"), AMPS_ERR_PARSE,
             "g.msh:3:", "missing $EndMeshFormat");
    t_expect(&ctx, t_gmsh(&ctx, G_HEAD "$Nodes\n3\n1 0 0 0\n2 1 0 0\n3 0 1 0\n4 0 0 1\n$EndNodes\n"), AMPS_ERR_PARSE,
             "g.msh:9:", "node count too small");
    t_expect(&ctx, t_gmsh(&ctx, G_HEAD "$Nodes\n5\n1 0 0 0\n2 1 0 0\n3 0 1 0\n4 0 0 1\n$EndNodes\n"), AMPS_ERR_PARSE,
             "g.msh:10:", "node count too large");
    t_expect(&ctx, t_gmsh(&ctx, G_HEAD "$Nodes\n-4\n"), AMPS_ERR_PARSE, "g.msh:5:", "negative node count");
    t_expect(&ctx, t_gmsh(&ctx, G_HEAD "$Nodes\n1000000000\n1 0 0 0\n"), AMPS_ERR_PARSE,
             "g.msh:5:", "absurd node count");
    t_expect(&ctx, t_gmsh(&ctx, G_HEAD "$Nodes\n4\n1 0 0 0\n1 1 0 0\n3 0 1 0\n4 0 0 1\n$EndNodes\n"), AMPS_ERR_PARSE,
             "g.msh:7:", "duplicate tag");
    t_expect(&ctx, t_gmsh(&ctx, G_HEAD "$Nodes\n4\n1 0 0 0\n2 1 0 0\n3 0 NaN 0\n4 0 0 1\n$EndNodes\n"), AMPS_ERR_PARSE,
             "g.msh:8:", "NaN");
    t_expect(&ctx,
             t_gmsh(&ctx, G_HEAD "$Nodes\r\n4\r\n1 0 0 0\r\n2 1 0 0\r\n3 0 0 0\r\n4 0 0 Infinity\r\n$EndNodes\r\n"),
             AMPS_ERR_PARSE, "g.msh:9:", "Inf CRLF");
    t_expect(&ctx, t_gmsh(&ctx, G_HEAD G_NODES "$Elements\n1\n1 4 2 0 1 1 2 3 9\n$EndElements\n"), AMPS_ERR_PARSE,
             "g.msh:13:", "undefined tag");
    t_expect(&ctx, t_gmsh(&ctx, G_HEAD G_NODES "$Elements\n1\n1 4 2 0 1 1 2 3\n$EndElements\n"), AMPS_ERR_PARSE,
             "g.msh:13:", "missing node");
    t_expect(&ctx, t_gmsh(&ctx, G_HEAD G_NODES "$Elements\n1\n"), AMPS_ERR_PARSE, "g.msh:12:", "truncated elements");
    t_expect(&ctx, t_gmsh(&ctx, G_HEAD G_NODES "$Elements\n1\n1 x 2 0 1 1 2 3 4\n$EndElements\n"), AMPS_ERR_PARSE,
             "g.msh:13:", "non-numeric type");
    t_expect(&ctx, t_gmsh(&ctx, G_HEAD G_NODES "$Elements\n-1\n$EndElements\n"), AMPS_ERR_PARSE,
             "g.msh:12:", "negative element count");
    t_expect(&ctx, t_gmsh(&ctx, G_HEAD G_NODES "$Elements\n2\n1 4 2 0 1 1 2 3 4\n$EndElements\n"), AMPS_ERR_PARSE,
             "g.msh:14:", "element count too large");
    t_expect(&ctx, t_gmsh(&ctx, G_HEAD G_NODES "$Elements\n1\n1 4 -2 1 2 3 4\n$EndElements\n"), AMPS_ERR_PARSE,
             "g.msh:13:", "negative tag count");
    t_expect(&ctx, t_gmsh(&ctx, G_HEAD G_NODES "$Elements\n1\n1 2 2 0 1 1 2 3\n$EndElements\n"), AMPS_ERR_PARSE,
             "g.msh:14:", "no tetrahedra");
    t_expect(&ctx, t_gmsh(&ctx, G_HEAD "$Elements\n1\n1 4 2 0 1 1 2 3 4\n$EndElements\n"), AMPS_ERR_PARSE,
             "g.msh:4:", "$Elements before $Nodes");
    t_expect(&ctx, t_gmsh(&ctx, G_HEAD G_NODES G_NODES), AMPS_ERR_PARSE, "g.msh:11:", "duplicate $Nodes");
    t_expect(&ctx, t_gmsh(&ctx, G_HEAD G_HEAD), AMPS_ERR_PARSE, "g.msh:4:", "duplicate $MeshFormat");
    t_expect(&ctx, t_gmsh(&ctx, G_HEAD G_NODES "$Elements\n0\n$EndElements\n$Elements\n"), AMPS_ERR_PARSE,
             "g.msh:14:", "duplicate $Elements");
    t_expect(&ctx, t_gmsh(&ctx, G_HEAD "$Comments\nhello\n$EndNodes\n"), AMPS_ERR_PARSE,
             "g.msh:4:", "unterminated section");
    t_expect(&ctx, t_gmsh(&ctx, G_HEAD G_NODES "$Elements\n1\n1 4 2 0 1 1 2 3 3\n$EndElements\n"), AMPS_ERR_MESH,
             "g.msh:13:", "degenerate");
    /* 4.1 */
#define G4_HEAD "$MeshFormat\n4.1 0 8\n$EndMeshFormat\n"
#define G4_NODES "$Nodes\n1 4 1 4\n3 1 0 4\n1\n2\n3\n4\n0 0 0\n1 0 0\n0 1 0\n0 0 1\n$EndNodes\n"
    {
        amps_mesh *m = t_gmsh(&ctx, G4_HEAD G4_NODES "$Elements\n1 1 1 1\n3 1 4 1\n1 1 2 3 4\n$EndElements\n");
        CHECK(m != NULL, "4.1 base: %s", ctx.msg);
        amps_mesh_free(&ctx, m);
    }
    t_expect(&ctx,
             t_gmsh(&ctx, G4_HEAD "$Nodes\n1 5 1 4\n3 1 0 4\n1\n2\n3\n4\n0 0 0\n1 0 0\n0 1 0\n0 0 1\n$EndNodes\n"),
             AMPS_ERR_PARSE, "g.msh:15:", "4.1 node count mismatch");
    t_expect(&ctx,
             t_gmsh(&ctx, G4_HEAD "$Nodes\n1 4 1 4\n3 1 0 5\n1\n2\n3\n4\n0 0 0\n1 0 0\n0 1 0\n0 0 1\n$EndNodes\n"),
             AMPS_ERR_PARSE, "g.msh:6:", "4.1 block too large");
    t_expect(&ctx, t_gmsh(&ctx, G4_HEAD "$Nodes\n1 4 1 4\n3 1 0 4\n1\n2\n3\n4\n0 0 0\n1 0 0\n0 1 0\n"), AMPS_ERR_PARSE,
             "g.msh:13:", "4.1 truncated coordinates");
    t_expect(&ctx, t_gmsh(&ctx, G4_HEAD G4_NODES "$Elements\n1 1 1 1\n3 1 4 1\n1 1 2 3 5\n$EndElements\n"),
             AMPS_ERR_PARSE, "g.msh:19:", "4.1 undefined tag");
    t_expect(&ctx, t_gmsh(&ctx, G4_HEAD G4_NODES "$Elements\n1 2 1 2\n3 1 4 1\n1 1 2 3 4\n$EndElements\n"),
             AMPS_ERR_PARSE, "g.msh:20:", "4.1 element count mismatch");
    t_expect(&ctx, t_gmsh(&ctx, G4_HEAD G4_NODES "$Elements\n1 3 1 3\n2 1 2 3\n1 1 2 3\n"), AMPS_ERR_PARSE,
             "g.msh:19:", "4.1 truncated block");
    snprintf(
            buf, sizeof(buf), "%s",
            G4_HEAD
            "$Nodes\n1 4 1 4\n3 1 0 4\n1\n2\n3\n4\n0 0 0\n1 0 0\n0 1 0\n0 0 1\n$EndNodes\n$Elements\n9999999999 1 1 1\n");
    t_expect(&ctx, t_gmsh(&ctx, buf), AMPS_ERR_PARSE, "g.msh:17:", "4.1 absurd block count");
#undef G_HEAD
#undef G_NODES
#undef G4_HEAD
#undef G4_NODES
}

static void test_malformed_medit(void) {
    amps_ctx ctx;
    amps_ctx_init(&ctx);
#define M_V "MeshVersionFormatted 2\nDimension 3\nVertices\n4\n0 0 0 0\n1 0 0 0\n0 1 0 0\n0 0 1 0\n"
    {
        amps_mesh *m = t_medit(&ctx, M_BASE);
        CHECK(m != NULL, "medit base: %s", ctx.msg);
        amps_mesh_free(&ctx, m);
    }
    t_expect(&ctx, t_medit(&ctx, ""), AMPS_ERR_PARSE, "m.mesh:1:", "empty");
    t_expect(&ctx, t_medit(&ctx, "MeshVersionFormatted 2\nDimension 2\n"), AMPS_ERR_PARSE, "m.mesh:2:", "2D");
    t_expect(&ctx, t_medit(&ctx, M_V "Tetrahedra\n1\n0 2 3 4 0\nEnd\n"), AMPS_ERR_PARSE, "m.mesh:11:", "index 0");
    t_expect(&ctx, t_medit(&ctx, M_V "Tetrahedra\n1\n1 2 3 5 0\nEnd\n"), AMPS_ERR_PARSE, "m.mesh:11:", "index 5");
    t_expect(&ctx, t_medit(&ctx, M_V "Tetrahedra\n1\n1 2 x 4 0\nEnd\n"), AMPS_ERR_PARSE,
             "m.mesh:11:", "non-numeric index");
    t_expect(&ctx, t_medit(&ctx, M_V "Tetrahedra\n1\n1 2 3"), AMPS_ERR_PARSE, "m.mesh:11:", "truncated tet");
    t_expect(&ctx, t_medit(&ctx, M_V "Tetrahedra\n2\n1 2 3 4 0\nEnd\n"), AMPS_ERR_PARSE,
             "m.mesh:12:", "fewer tets than declared");
    t_expect(&ctx, t_medit(&ctx, "Vertices\n4\n0 0 0 0\n1 0 0 0\n0 1 0 0\nTetrahedra\n1\n1 2 3 4 0\n"), AMPS_ERR_PARSE,
             "m.mesh:6:", "fewer vertices than declared");
    t_expect(&ctx, t_medit(&ctx, "Vertices\n4\n0 0 0 0\n1 0 nan 0\n"), AMPS_ERR_PARSE, "m.mesh:4:", "NaN");
    t_expect(&ctx, t_medit(&ctx, "Vertices\n4\n0 0 0 0\n1 0 0 0\n0 1e400 0 0\n0 0 1 0\n"), AMPS_ERR_PARSE,
             "m.mesh:5:", "Inf");
    t_expect(&ctx,
             t_medit(&ctx,
                     "Vertices\r\n4\r\n0 0 0 0\r\n\r\n1 0 0 0\r\n0 1 0 0\r\n0 0 1 0\r\nTetrahedra\r\n1\r\n1 2 3 4\r\n"),
             AMPS_ERR_PARSE, "m.mesh:10:", "missing reference, CRLF");
    t_expect(&ctx, t_medit(&ctx, "Vertices\n-4\n"), AMPS_ERR_PARSE, "m.mesh:2:", "negative count");
    t_expect(&ctx, t_medit(&ctx, "Vertices\n123456789012\n0 0 0 0\n"), AMPS_ERR_PARSE, "m.mesh:2:", "absurd count");
    t_expect(&ctx, t_medit(&ctx, "Tetrahedra\n1\n1 2 3 4 0\n" M_V), AMPS_ERR_PARSE,
             "m.mesh:1:", "Tetrahedra before Vertices");
    t_expect(&ctx, t_medit(&ctx, M_V "End\n"), AMPS_ERR_PARSE, "m.mesh:9:", "no Tetrahedra");
    t_expect(&ctx, t_medit(&ctx, "MeshVersionFormatted 2\n5\n"), AMPS_ERR_PARSE,
             "m.mesh:2:", "number instead of keyword");
    t_expect(&ctx, t_medit(&ctx, M_V M_V), AMPS_ERR_PARSE, "m.mesh:11:", "duplicate Vertices");
    t_expect(&ctx, t_medit(&ctx, M_V "Tetrahedra\n0\n\nTetrahedra 0\n"), AMPS_ERR_PARSE,
             "m.mesh:12:", "duplicate Tetrahedra");
    t_expect(&ctx, t_medit(&ctx, M_V "Tetrahedra\n1\n1 2 3 4 0.5\n"), AMPS_ERR_PARSE,
             "m.mesh:11:", "fractional reference");
    t_expect(&ctx,
             t_medit(&ctx,
                     "Vertices\r\n4\r\n0 0 0 0\r\n1 0 0 0\r\n0 1 0 0\r\n0 0 0 0\r\nTetrahedra\r\n1\r\n1 2 3 4 0\r\n"),
             AMPS_ERR_MESH, "m.mesh:9:", "degenerate");
#undef M_V
}

/* ---- the whole message of each reader error ---- */

enum { T_TETGEN, T_GMSH, T_MEDIT };

static void test_messages(void) {
    static const struct {
        int reader;
        const char *in, *ele; /* ele: the .ele text of T_TETGEN */
        amps_status st;
        const char *msg;
    } cases[] = {
            {T_TETGEN, "", "", AMPS_ERR_PARSE, "t.node:1: missing point count"},
            {T_TETGEN, "x\n", "", AMPS_ERR_PARSE, "t.node:1: invalid integer 'x' for point count"},
            {T_TETGEN, "4 3\n0 0 0 0\n1 a 0 0\n", "", AMPS_ERR_PARSE, "t.node:3: invalid number 'a' for x coordinate"},
            {T_TETGEN, "4 3\n0 0 0 0\n1 nan 0 0\n", "", AMPS_ERR_PARSE, "t.node:3: non-finite x coordinate 'nan'"},
            {T_TETGEN, "-4\n", "", AMPS_ERR_PARSE, "t.node:1: negative point count -4"},
            {T_TETGEN, "99999999999 3\n0 0 0 0\n", "", AMPS_ERR_PARSE,
             "t.node:1: point count 99999999999 exceeds what the file can hold"},
            {T_TETGEN, "0 3 0 0\n", "", AMPS_ERR_PARSE, "t.node:1: the file declares no points"},
            {T_TETGEN, "4 2 0 0\n0 0 0 0\n1 1 0 0\n2 0 1 0\n3 0 0 1\n", "", AMPS_ERR_PARSE,
             "t.node:1: dimension must be 3, found '2'"},
            {T_TETGEN, "4 3.0\n0 0 0 0\n1 1 0 0\n2 0 1 0\n3 0 0 1\n", "", AMPS_ERR_PARSE,
             "t.node:1: dimension must be 3, found '3.0'"},
            {T_TETGEN, "4 3 -1 0\n0 0 0 0\n1 1 0 0\n2 0 1 0\n3 0 0 1\n", "", AMPS_ERR_PARSE,
             "t.node:1: invalid attribute count '-1'"},
            {T_TETGEN, "4 3 0 7\n0 0 0 0\n1 1 0 0\n2 0 1 0\n3 0 0 1\n", "", AMPS_ERR_PARSE,
             "t.node:1: boundary marker flag must be 0 or 1, found '7'"},
            {T_TETGEN, "4 3 0 x\n0 0 0 0\n1 1 0 0\n2 0 1 0\n3 0 0 1\n", "", AMPS_ERR_PARSE,
             "t.node:1: boundary marker flag must be 0 or 1, found 'x'"},
            {T_TETGEN, "4 3 0 0\n0 0 0 0\n1 1 0 0\n", "", AMPS_ERR_PARSE,
             "t.node:3: unexpected end of file: 2 of 4 points read"},
            {T_TETGEN, "4 3 0 0\n2 0 0 0\n", "", AMPS_ERR_PARSE,
             "t.node:2: first point number must be 0 or 1, found 2"},
            {T_TETGEN, "4 3 0 0\n0 0 0 0\n2 1 0 0\n", "", AMPS_ERR_PARSE,
             "t.node:3: point number 2 out of sequence (expected 1)"},
            {T_TETGEN, "4 3 0 0\n0 0 0 0\n1 1 0 0\n2 0 1 0\n3 0 0 1\n4 1 1 1\n", "", AMPS_ERR_PARSE,
             "t.node:6: unexpected data '4' after 4 points"},
            {T_TETGEN, "4 3 0 0\n0 0 0 0\n1 1 0 0\n2 0 1 0\n3 0 0 1 # c\n", "1 6 0\n0 0 1 2 3\n", AMPS_ERR_PARSE,
             "t.ele:1: nodes per tetrahedron must be 4 or 10, found '6'"},
            {T_TETGEN, "4 3 0 0\n0 0 0 0\n1 1 0 0\n2 0 1 0\n3 0 0 1\n", "1 4 -2\n0 0 1 2 3\n", AMPS_ERR_PARSE,
             "t.ele:1: invalid attribute count '-2'"},
            {T_TETGEN, "4 3 0 0\n0 0 0 0\n1 1 0 0\n2 0 1 0\n3 0 0 1\n", "2 4 0\n0 0 1 2 3\n", AMPS_ERR_PARSE,
             "t.ele:2: unexpected end of file: 1 of 2 tetrahedra read"},
            {T_TETGEN, "4 3 0 0\n0 0 0 0\n1 1 0 0\n2 0 1 0\n3 0 0 1\n", "1 4 0\n0 0 1 2 4\n", AMPS_ERR_PARSE,
             "t.ele:2: node index 4 out of range [0, 3]"},
            {T_TETGEN, "4 3 0 0\n1 0 0 0\n2 1 0 0\n3 0 1 0\n4 0 0 1\n", "1 10 0\n1 1 2 3 4 1 2 3 4 1 5\n",
             AMPS_ERR_PARSE, "t.ele:2: node index 5 out of range [1, 4]"},
            {T_TETGEN, "4 3 0 0\n0 0 0 0\n1 1 0 0\n2 0 1 0\n3 0 0 1\n", "1 4 0\n0 0 1 2 3\n1 0 1 2 3\n", AMPS_ERR_PARSE,
             "t.ele:3: unexpected data '1' after 1 tetrahedra"},
            {T_TETGEN, "4 3 0 0\n0 0 0 0\n1 1 0 0\n2 0 1 0\n3 0 0 1\n", "0\n", AMPS_ERR_PARSE,
             "t.ele:1: no tetrahedra in the file"},
            {T_TETGEN, "4 3 0 0\n0 0 0 0\n1 1 0 0\n2 0 1 0\n3 0 0 1\n", "# d\n1 4 0\n0 0 1 2 2\n", AMPS_ERR_MESH,
             "t.ele:3: degenerate tetrahedron (file nodes 0 1 2 2, 0-based)"},
            {T_TETGEN, "4 3 0 0\n0 0 0 0\n1 1 0 0\n2 0 1 0\n3 0 0 1\n", "1\n0 0 1 2\n", AMPS_ERR_PARSE,
             "t.ele:2: missing node index"},
            {T_GMSH, "hello\n", "", AMPS_ERR_PARSE, "g.msh:1: expected a section header like $Nodes, found 'hello'"},
            {T_GMSH, "$Nodes\n", "", AMPS_ERR_PARSE, "g.msh:1: the file must start with $MeshFormat, found '$Nodes'"},
            {T_GMSH, "$MeshFormat\n2.2 0 8\n$EndMeshFormat\n$MeshFormat\n", "", AMPS_ERR_PARSE,
             "g.msh:4: duplicate $MeshFormat"},
            {T_GMSH, "$MeshFormat\n3.0 0 8\n$EndMeshFormat\n", "", AMPS_ERR_PARSE,
             "g.msh:2: unsupported .msh version 3.0 (readable: 2.x, 4.1)"},
            {T_GMSH, "$MeshFormat\n2.2 1 8\n", "", AMPS_ERR_PARSE,
             "g.msh:2: binary .msh files are not supported; save the mesh as ASCII"},
            {T_GMSH, "$MeshFormat\n2.2 5 8\n", "", AMPS_ERR_PARSE, "g.msh:2: invalid file type 5 (0 = ASCII)"},
            {T_GMSH, "$MeshFormat\n2.2 0 8\n", "", AMPS_ERR_PARSE,
             "g.msh:2: unexpected end of file, expected $EndMeshFormat"},
            {T_GMSH, "$MeshFormat\n2.2 0 8\n$EndMeshFormat\n$Nodes\n3\n1 0 0 0\n2 1 0 0\n3 0 1 0\n4 0 0 1\n$EndNodes\n",
             "", AMPS_ERR_PARSE, "g.msh:9: expected $EndNodes (node count mismatch?), found '4'"},
            {T_GMSH, "$MeshFormat\n2.2 0 8\n$EndMeshFormat\n$Nodes\n1\n1 0 0 0\n$EndNodes\n$Nodes\n", "",
             AMPS_ERR_PARSE, "g.msh:8: duplicate $Nodes section"},
            {T_GMSH, "$MeshFormat\n4.1 0 8\n$EndMeshFormat\n$Nodes\n1 4 1 4\n3 1 0 5\n", "", AMPS_ERR_PARSE,
             "g.msh:6: block node count 5 exceeds the 4 nodes declared"},
            {T_GMSH,
             "$MeshFormat\n4.1 0 8\n$EndMeshFormat\n$Nodes\n1 5 1 4\n3 1 0 4\n1\n2\n3\n4\n0 0 0\n1 0 0\n0 1 0\n0 0 1\n$EndNodes\n",
             "", AMPS_ERR_PARSE, "g.msh:15: $Nodes declares 5 nodes, its blocks hold 4"},
            {T_GMSH, "$MeshFormat\n2.2 0 8\n$EndMeshFormat\n$Nodes\n2\n7 0 0 0\n7 1 0 0\n$EndNodes\n", "",
             AMPS_ERR_PARSE, "g.msh:7: duplicate node tag 7 (first on line 6)"},
            {T_GMSH, "$MeshFormat\n2.2 0 8\n$EndMeshFormat\n$Elements\n", "", AMPS_ERR_PARSE,
             "g.msh:4: $Elements before $Nodes"},
            {T_GMSH,
             "$MeshFormat\n2.2 0 8\n$EndMeshFormat\n$Nodes\n4\n1 0 0 0\n2 1 0 0\n3 0 1 0\n4 0 0 1\n$EndNodes\n$Elements\n1\n1 4 -2 1 2 3 4\n$EndElements\n",
             "", AMPS_ERR_PARSE, "g.msh:13: negative tag count -2"},
            {T_GMSH,
             "$MeshFormat\n2.2 0 8\n$EndMeshFormat\n$Nodes\n4\n1 0 0 0\n2 1 0 0\n3 0 1 0\n4 0 0 1\n$EndNodes\n$Elements\n1\n1 4 2 0 1 1 2 3 9\n$EndElements\n",
             "", AMPS_ERR_PARSE, "g.msh:13: element refers to undefined node tag 9"},
            {T_GMSH,
             "$MeshFormat\n2.2 0 8\n$EndMeshFormat\n$Nodes\n4\n1 0 0 0\n2 1 0 0\n3 0 1 0\n4 0 0 1\n$EndNodes\n$Elements\n1\n1 4 2 0 1 1 2 3 4\n2 4 2 0 1 1 2 3 4\n$EndElements\n",
             "", AMPS_ERR_PARSE, "g.msh:14: expected $EndElements (element count mismatch?), found '2'"},
            {T_GMSH,
             "$MeshFormat\n2.2 0 8\n$EndMeshFormat\n$Nodes\n4\n1 0 0 0\n2 1 0 0\n3 0 1 0\n4 0 0 1\n$EndNodes\n$Elements\n0\n$EndElements\n$Elements\n",
             "", AMPS_ERR_PARSE, "g.msh:14: duplicate $Elements section"},
            {T_GMSH,
             "$MeshFormat\n4.1 0 8\n$EndMeshFormat\n$Nodes\n1 4 1 4\n3 1 0 4\n1\n2\n3\n4\n0 0 0\n1 0 0\n0 1 0\n0 0 1\n$EndNodes\n$Elements\n1 1 1 1\n3 1 4 2\n",
             "", AMPS_ERR_PARSE, "g.msh:18: block element count 2 exceeds the 1 elements declared"},
            {T_GMSH,
             "$MeshFormat\n4.1 0 8\n$EndMeshFormat\n$Nodes\n1 4 1 4\n3 1 0 4\n1\n2\n3\n4\n0 0 0\n1 0 0\n0 1 0\n0 0 1\n$EndNodes\n$Elements\n1 2 1 2\n2 1 2 2\n1 1 2 3\n",
             "", AMPS_ERR_PARSE, "g.msh:19: unexpected end of file in an element block"},
            {T_GMSH,
             "$MeshFormat\n4.1 0 8\n$EndMeshFormat\n$Nodes\n1 4 1 4\n3 1 0 4\n1\n2\n3\n4\n0 0 0\n1 0 0\n0 1 0\n0 0 1\n$EndNodes\n$Elements\n1 2 1 2\n3 1 4 1\n1 1 2 3 4\n$EndElements\n",
             "", AMPS_ERR_PARSE, "g.msh:20: $Elements declares 2 elements, its blocks hold 1"},
            {T_GMSH,
             "$MeshFormat\n4.1 0 8\n$EndMeshFormat\n$Nodes\n1 4 1 4\n3 1 0 4\n1\n2\n3\n4\n0 0 0\n1 0 0\n0 1 0\n0 0 1\n$EndNodes\n$Elements\n1 1 1 1\n3 1 4 1\n1 1 2 3 3\n$EndElements\n",
             "", AMPS_ERR_MESH, "g.msh:19: degenerate tetrahedron (file nodes 0 1 2 2, 0-based)"},
            {T_GMSH, "$MeshFormat\n2.2 0 8\n$EndMeshFormat\n$Comments\nhello\n", "", AMPS_ERR_PARSE,
             "g.msh:4: section $Comments is not closed by $EndComments"},
            {T_GMSH, "\n\n", "", AMPS_ERR_PARSE, "g.msh:2: empty file (no $MeshFormat)"},
            {T_GMSH, "$MeshFormat\n2.2 0 8\n$EndMeshFormat\n", "", AMPS_ERR_PARSE, "g.msh:3: no $Nodes section"},
            {T_GMSH,
             "$MeshFormat\n2.2 0 8\n$EndMeshFormat\n$Nodes\n4\n1 0 0 0\n2 1 0 0\n3 0 1 0\n4 0 0 1\n$EndNodes\n$Elements\n1\n1 2 2 0 1 1 2 3\n$EndElements\n",
             "", AMPS_ERR_PARSE, "g.msh:14: no tetrahedra (element type 4, 11, 29, 30 or 31) in the file"},
            {T_GMSH, "$MeshFormat\n2.2 0 8\n$EndMeshFormat\n$ThisSectionNameIsFarTooLongToKeep\n", "", AMPS_ERR_PARSE,
             "g.msh:4: expected a section header like $Nodes, found '$ThisSectionNameIsFarToo...'"},
            {T_MEDIT, "Dimension 2\n", "", AMPS_ERR_PARSE, "m.mesh:1: dimension must be 3, found 2"},
            {T_MEDIT, "Vertices\n1\n0 0 0 0\nVertices\n", "", AMPS_ERR_PARSE, "m.mesh:4: duplicate Vertices section"},
            {T_MEDIT, "Tetrahedra\n0\n", "", AMPS_ERR_PARSE, "m.mesh:1: Tetrahedra before Vertices"},
            {T_MEDIT, "Vertices\n1\n0 0 0 0\nTetrahedra\n0\nTetrahedra\n", "", AMPS_ERR_PARSE,
             "m.mesh:6: duplicate Tetrahedra section"},
            {T_MEDIT, "Vertices\n1\n0 0 0 0\nTetrahedra\n1\n1 1 1 2 0\n", "", AMPS_ERR_PARSE,
             "m.mesh:6: vertex index 2 out of range [1, 1]"},
            {T_MEDIT, "Vertices\n1\n0 0 0 0\n7\n", "", AMPS_ERR_PARSE, "m.mesh:4: expected a keyword, found '7'"},
            {T_MEDIT, "Vertices\n1\n0 0 0 0\nHexahedra\n1\n1 1 1 1 1 1 1 1 0\n", "", AMPS_ERR_MESH,
             "m.mesh:4: 1 Hexahedra: amps reads linear tetrahedra only (Tetrahedra); mesh with them only"},
            {T_MEDIT, "Vertices\n1\n0 0 0 0\nTetrahedraP2\n2\n", "", AMPS_ERR_MESH,
             "m.mesh:4: 2 TetrahedraP2: amps reads linear tetrahedra only (Tetrahedra); mesh with them only"},
            {T_MEDIT, "MeshVersionFormatted 2\nEnd\n", "", AMPS_ERR_PARSE, "m.mesh:2: no Vertices section"},
            {T_MEDIT, "Vertices\n1\n0 0 0 0\nCorners 1 1\nEnd\n", "", AMPS_ERR_PARSE,
             "m.mesh:5: no Tetrahedra in the file"},
            {T_MEDIT, "Vertices\n4\n0 0 0 0\n1 0 0 0\n0 1 0 0\n0 0 0 0\nTetrahedra\n1\n1 2 3 4 0\n", "", AMPS_ERR_MESH,
             "m.mesh:9: degenerate tetrahedron (file nodes 0 1 2 3, 0-based)"},
            {T_MEDIT, "Vertices\n4\n0 0 0 0\n1 0 0 0\n0 1 0 0\n0 0 1 0\nTetrahedra\n1\n1 2 3 4\n", "", AMPS_ERR_PARSE,
             "m.mesh:9: missing tetrahedron reference"},
    };
    amps_ctx ctx;
    size_t k;
    amps_ctx_init(&ctx);
    for (k = 0; k < sizeof(cases) / sizeof(cases[0]); k++) {
        amps_mesh *m = cases[k].reader == T_TETGEN ? t_tetgen(&ctx, cases[k].in, cases[k].ele)
                       : cases[k].reader == T_GMSH ? t_gmsh(&ctx, cases[k].in)
                                                   : t_medit(&ctx, cases[k].in);
        CHECK(!m && ctx.status == cases[k].st && !strcmp(ctx.msg, cases[k].msg),
              "message %d: want %d '%s', got %s (%d: %s)", (int)k, (int)cases[k].st, cases[k].msg,
              m ? "a mesh" : "NULL", (int)ctx.status, ctx.msg);
        amps_mesh_free(&ctx, m);
    }
}

#ifndef AMPS_NO_STDIO
/* ---- round trips through files ---- */

static void test_roundtrip(void) {
    amps_ctx ctx;
    amps_mesh *m, *r;
    char p1[700], p2[700];
    double p[3] = {0.5, 0.5, 1.0}, n[3] = {0.3, 0.1, 1};
    amps_int moved[64], nm, vc, v;
    int base, ver;
    amps_ctx_init(&ctx);
    m = amps_mesh_brick(&ctx, 2);
    if (!m) {
        CHECK(0, "brick");
        return;
    }
    for (v = 0; v < m->nnode; v++)
        if (m->xyz[3 * v + 2] == 1.0) amps_mesh_cut(&ctx, m, v, p, n, &vc, moved, &nm);
    CHECK(m->nnode > m->nfile, "cuts made copies");
    for (base = 0; base < 2; base++) {
        t_path(p1, base ? "rt1" : "rt0");
        CHECK(amps_mesh_write_tetgen(&ctx, p1, m, base) == AMPS_OK, "write tetgen %d: %s", base, ctx.msg);
        t_path(p1, base ? "rt1.node" : "rt0.node");
        t_path(p2, base ? "rt1.ele" : "rt0.ele");
        r = amps_mesh_read(&ctx, p1);
        CHECK(t_same_mesh(r, m), "tetgen base %d via .node: %s", base, ctx.msg);
        amps_mesh_free(&ctx, r);
        r = amps_mesh_read(&ctx, p2);
        CHECK(t_same_mesh(r, m), "tetgen base %d via .ele: %s", base, ctx.msg);
        amps_mesh_free(&ctx, r);
        remove(p1);
        remove(p2);
    }
    for (ver = 2; ver <= 4; ver += 2) {
        t_path(p1, ver == 2 ? "rt22.msh" : "rt41.MSH");
        CHECK(amps_mesh_write_gmsh(&ctx, p1, m, ver) == AMPS_OK, "write gmsh %d: %s", ver, ctx.msg);
        r = amps_mesh_read(&ctx, p1);
        CHECK(t_same_mesh(r, m), "gmsh %d round trip: %s", ver, ctx.msg);
        amps_mesh_free(&ctx, r);
        remove(p1);
    }
    t_path(p1, "rt.mesh");
    CHECK(amps_mesh_write_medit(&ctx, p1, m) == AMPS_OK, "write medit: %s", ctx.msg);
    r = amps_mesh_read(&ctx, p1);
    CHECK(t_same_mesh(r, m), "medit round trip: %s", ctx.msg);
    amps_mesh_free(&ctx, r);
    remove(p1);
    /* file-level errors */
    t_path(p1, "does_not_exist.msh");
    t_expect(&ctx, amps_mesh_read(&ctx, p1), AMPS_ERR_IO, p1, "missing file");
    t_path(p1, "x.vtk");
    t_expect(&ctx, amps_mesh_read(&ctx, p1), AMPS_ERR_ARG, p1, "unknown extension");
    t_path(p1, "lonely.node");
    t_write(p1, T_NODE4, strlen(T_NODE4));
    t_path(p2, "lonely.ele");
    t_expect(&ctx, amps_mesh_read(&ctx, p1), AMPS_ERR_IO, p2, "missing .ele");
    remove(p1);
    t_path(p1, "bad.msh");
    t_write(p1, G22, strlen(G22) - 30);
    t_expect(&ctx, amps_mesh_read(&ctx, p1), AMPS_ERR_PARSE, p1, "file message names the path");
    remove(p1);
    t_path(p1, "no_such_dir/x.msh");
    CHECK(amps_mesh_write_gmsh(&ctx, p1, m, 2) == AMPS_ERR_IO && strstr(ctx.msg, p1),
          "write to a missing directory: %s", ctx.msg);
    CHECK(amps_mesh_write_gmsh(&ctx, p1, m, 3) == AMPS_ERR_ARG, "gmsh version 3");
    CHECK(amps_mesh_write_tetgen(&ctx, p1, m, 2) == AMPS_ERR_ARG, "tetgen base 2");
    amps_mesh_free(&ctx, m);
}

/* ---- VTU ---- */

/* Minimal XML check: balanced tags, quoted attributes, one root element named root.
   Returns 1 if well-formed. */
static int t_xml_ok(const char *s, const char *root) {
    char stack[32][64];
    int depth = 0, roots = 0;
    const char *p = s;
    while ((p = strchr(p, '<')) != NULL) {
        const char *e = strchr(p, '>'), *q;
        int quotes = 0, close, n;
        if (!e) return 0;
        for (q = p; q < e; q++)
            if (*q == '"') quotes++;
        if (quotes % 2) return 0;
        if (p[1] == '?') {
            if (e[-1] != '?') return 0;
            p = e + 1;
            continue;
        }
        close = p[1] == '/';
        q = p + 1 + close;
        for (n = 0; q + n < e && q[n] != ' ' && q[n] != '/' && n < 63; n++) {}
        if (n == 0) return 0;
        if (close) {
            if (depth == 0 || (int)strlen(stack[depth - 1]) != n || strncmp(stack[depth - 1], q, (size_t)n)) return 0;
            depth--;
        } else if (e[-1] != '/') {
            if (depth == 32) return 0;
            if (depth == 0) {
                roots++;
                if ((int)strlen(root) != n || strncmp(root, q, (size_t)n)) return 0;
            }
            memcpy(stack[depth], q, (size_t)n);
            stack[depth][n] = 0;
            depth++;
        }
        p = e + 1;
    }
    return depth == 0 && roots == 1;
}

/* Number of whitespace-separated values in the DataArray named name; sum of their values. */
static long t_array_count(const char *s, const char *name, double *sum) {
    char key[100];
    const char *p, *e;
    long n = 0;
    snprintf(key, sizeof(key), "Name=\"%s\"", name);
    p = strstr(s, key);
    if (!p) return -1;
    p = strchr(p, '>') + 1;
    e = strstr(p, "</DataArray>");
    *sum = 0;
    while (p < e) {
        char *end;
        double v = strtod(p, &end);
        if (end == p) {
            p++;
            continue;
        }
        if (end > e) break;
        n++;
        *sum += v;
        p = end;
    }
    return n;
}

/* A fresh context and the beam 5 x 5 x 4 (NULL, with a failed check, if it cannot be made). */
static amps_mesh *t_beam4(amps_ctx *ctx) {
    amps_mesh *m;
    amps_ctx_init(ctx);
    m = amps_mesh_beam(ctx, 4);
    CHECK(m != NULL, "beam: %s", ctx->msg);
    return m;
}

static void test_vtu(void) {
    amps_ctx ctx;
    amps_mesh *m;
    char path[700], script[700], cmd[2200];
    double p[3] = {0, 0, 2}, n[3] = {0, 0, 1}, *disp, *vm, *pr, sum;
    amps_int moved[64], nm, vc, v, t, ncut = 0;
    size_t len;
    char *txt;
    m = t_beam4(&ctx);
    if (!m) return;
    for (v = 50; v < 55; v++) amps_mesh_cut(&ctx, m, v, p, n, &vc, moved, &nm);
    for (t = 0; t < m->ntet; t++) {
        int k, c = 0;
        for (k = 0; k < 4; k++) c |= m->tet[4 * t + k] >= m->nfile;
        ncut += c;
    }
    disp = (double *)malloc(sizeof(double) * 3 * m->nnode);
    vm = (double *)malloc(sizeof(double) * m->ntet);
    pr = (double *)malloc(sizeof(double) * 3 * m->ntet);
    for (v = 0; v < m->nnode; v++) {
        disp[3 * v] = 0.01 * m->xyz[3 * v + 2];
        disp[3 * v + 1] = 0;
        disp[3 * v + 2] = v >= m->nfile ? -0.1 : 0;
    }
    CHECK(amps_mesh_stress(&ctx, m, disp, NULL, vm, pr) == AMPS_OK, "stress");
    t_path(path, "out.vtu");
    CHECK(amps_mesh_write_vtu(&ctx, path, m, disp, vm, pr) == AMPS_OK, "write vtu: %s", ctx.msg);
    txt = t_slurp(path, &len);
    CHECK(txt != NULL, "read back vtu");
    if (txt) {
        char head[200];
        CHECK(t_xml_ok(txt, "VTKFile"), "vtu not well-formed");
        snprintf(head, sizeof(head), "NumberOfPoints=\"%ld\" NumberOfCells=\"%ld\"", (long)m->nnode, (long)m->ntet);
        CHECK(strstr(txt, head) != NULL, "piece header");
        CHECK(t_array_count(txt, "connectivity", &sum) == 4 * m->ntet, "connectivity");
        CHECK(t_array_count(txt, "offsets", &sum) == m->ntet, "offsets");
        CHECK(t_array_count(txt, "types", &sum) == m->ntet && sum == 10.0 * m->ntet, "types");
        CHECK(t_array_count(txt, "displacement", &sum) == 3 * m->nnode, "displacement");
        CHECK(t_array_count(txt, "origin", &sum) == m->nnode, "origin");
        CHECK(t_array_count(txt, "von_mises", &sum) == m->ntet, "von_mises");
        CHECK(t_array_count(txt, "principal_stress", &sum) == 3 * m->ntet, "principal");
        CHECK(t_array_count(txt, "cut", &sum) == m->ntet && sum == (double)ncut && ncut > 0, "cut flags %g vs %d", sum,
              (int)ncut);
        free(txt);
    }
    /* python3's XML parser, when available (the test passes without it) */
    if (system("python3 -c 'import xml.etree.ElementTree' >/dev/null 2>&1") == 0) {
        FILE *f;
        t_path(script, "check_vtu.py");
        f = fopen(script, "w");
        if (f) {
            fprintf(f, "import sys, xml.etree.ElementTree as ET\n"
                       "r = ET.parse(sys.argv[1]).getroot()\n"
                       "assert r.tag == 'VTKFile' and r.get('type') == 'UnstructuredGrid'\n"
                       "pc = r.find('UnstructuredGrid/Piece')\n"
                       "n, m = int(pc.get('NumberOfPoints')), int(pc.get('NumberOfCells'))\n"
                       "arr = {a.get('Name'): a for a in pc.iter('DataArray')}\n"
                       "assert len(pc.find('Points/DataArray').text.split()) == 3 * n\n"
                       "assert len(arr['connectivity'].text.split()) == 4 * m\n"
                       "assert len(arr['displacement'].text.split()) == 3 * n\n"
                       "assert len(arr['von_mises'].text.split()) == m\n"
                       "assert len(arr['cut'].text.split()) == m\n"
                       "assert max(int(x) for x in arr['connectivity'].text.split()) < n\n");
            fclose(f);
            snprintf(cmd, sizeof(cmd), "python3 '%s' '%s'", script, path);
            CHECK(system(cmd) == 0, "python3 xml check failed");
            remove(script);
        }
    }
    /* without optional arrays */
    CHECK(amps_mesh_write_vtu(&ctx, path, m, NULL, NULL, NULL) == AMPS_OK, "vtu without data");
    txt = t_slurp(path, &len);
    CHECK(txt && t_xml_ok(txt, "VTKFile") && !strstr(txt, "displacement") && strstr(txt, "Name=\"cut\""),
          "minimal vtu");
    free(txt);
    remove(path);
    free(disp);
    free(vm);
    free(pr);
    amps_mesh_free(&ctx, m);
}
#endif /* AMPS_NO_STDIO */

/* ---- robustness: random corruption never crashes and keeps the contract ---- */

static void t_contract(amps_ctx *ctx, amps_mesh *m, const char *name, int *bad) {
    if (m) {
        if (amps_mesh_check(ctx, m) != AMPS_OK) (*bad)++;
        amps_mesh_free(ctx, m);
    } else {
        /* TetGen reports element errors in the .ele file */
        int named = !strncmp(ctx->msg, name, strlen(name)) || (name[0] == 't' && !strncmp(ctx->msg, "t.ele:", 6));
        if (ctx->status == AMPS_OK || !ctx->msg[0] ||
            ((ctx->status == AMPS_ERR_PARSE || ctx->status == AMPS_ERR_MESH) && !named)) {
            (*bad)++;
            if (getenv("T_VERBOSE")) fprintf(stderr, "contract: %s %d %s\n", name, (int)ctx->status, ctx->msg);
        }
    }
}

static void test_corruption(void) {
    static const char *pieces[] = {"\n",         " ",   "\r\n",  "0",         "-1",         "4",
                                   "9",          "nan", "1e999", "$EndNodes", "$Nodes",     "Vertices",
                                   "Tetrahedra", "#",   "x",     "\0",        "99999999999"};
    const char *src[3];
    int f, trial, bad = 0, parsed = 0;
    amps_ctx ctx;
    amps_ctx_init(&ctx);
    src[0] = G41_MIXED;
    src[1] = G22_MIXED;
    src[2] = M_MIXED;
    t_seed(7);
    for (f = 0; f < 4; f++) {
        const char *s = f < 3 ? src[f] : T_NODE4;
        size_t n0 = strlen(s);
        for (trial = 0; trial < 3000; trial++) {
            char *b = (char *)malloc(n0 + 64);
            size_t n = n0, k;
            int edits = 1 + t_int(4), e;
            amps_mesh *m;
            memcpy(b, s, n0);
            for (e = 0; e < edits; e++) {
                int kind = t_unif() < 0.3 ? 0 : 1 + t_int(3);
                size_t at = n ? (size_t)t_int((int)n) : 0;
                if (kind == 0 && n) b[at] = (char)t_int(256); /* flip a byte */
                else if (kind == 1 && n) {
                    memmove(b + at, b + at + 1, n - at - 1);
                    n--;
                } /* delete */
                else if (kind == 2)
                    n = at; /* truncate */
                else { /* insert a token */ const char *pc = pieces[t_int((int)(sizeof(pieces) / sizeof(pieces[0])))];
                    size_t l = pc[0] ? strlen(pc) : 1;
                    if (n + l > n0 + 60) continue;
                    memmove(b + at + l, b + at, n - at);
                    for (k = 0; k < l; k++) b[at + k] = pc[k];
                    n += l;
                }
            }
            {
                char *exact = (char *)malloc(n ? n : 1);
                memcpy(exact, b, n);
                if (f < 2) m = amps_mesh_read_gmsh_mem(&ctx, exact, n, "g.msh");
                else if (f == 2) m = amps_mesh_read_medit_mem(&ctx, exact, n, "m.mesh");
                else m = amps_mesh_read_tetgen_mem(&ctx, exact, n, "t.node", T_ELE1, strlen(T_ELE1), "t.ele");
                parsed += m != NULL;
#ifndef AMPS_NO_STDIO
                if (m && parsed % 10 == 1) { /* what parses survives a write / read round trip */
                    char path[700];
                    amps_mesh *r;
                    t_path(path, f == 2 ? "fz.mesh" : "fz.msh");
                    if (f == 2) amps_mesh_write_medit(&ctx, path, m);
                    else amps_mesh_write_gmsh(&ctx, path, m, f == 0 ? 4 : 2);
                    r = amps_mesh_read(&ctx, path);
                    if (!t_same_mesh(r, m)) bad++;
                    amps_mesh_free(&ctx, r);
                    remove(path);
                }
#endif
                t_contract(&ctx, m, f < 2 ? "g.msh" : f == 2 ? "m.mesh" : "t.node", &bad);
                free(exact);
            }
            free(b);
        }
    }
    CHECK(bad == 0, "corrupted inputs broke the contract %d times", bad);
    CHECK(parsed > 100, "some corrupted inputs still parse (%d)", parsed);
}

/* ---- allocation failures inside the readers ---- */

static void test_reader_oom(void) {
    amps_ctx ctx;
    int f, k, fails;
    amps_ctx_init(&ctx);
    ctx.alloc_user = &t_al;
    for (f = 0; f < 4; f++) {
        long base = t_al.live;
        amps_mesh *m = NULL;
        for (fails = 0, k = 0; k < 200; k++) {
            t_al.fail_at = k;
            if (f == 0) m = t_gmsh(&ctx, G22_MIXED);
            else if (f == 1) m = t_gmsh(&ctx, G41_MIXED);
            else if (f == 2) m = t_medit(&ctx, M_MIXED);
            else m = t_tetgen(&ctx, T_NODE4, T_ELE1);
            t_al.fail_at = -1;
            if (m) break;
            fails++;
            if (ctx.status != AMPS_ERR_OOM || t_al.live != base) {
                CHECK(0, "reader %d, failure %d: status %d leak %ld", f, k, (int)ctx.status, t_al.live - base);
                break;
            }
        }
        CHECK(m && fails >= 3, "reader %d: %d failure paths", f, fails);
        amps_mesh_free(&ctx, m);
        CHECK(t_al.live == base, "reader %d leaked", f);
    }
}

/* ---- region attributes ---- */

static const char *G41_REGIONS =
        "$MeshFormat\n4.1 0 8\n$EndMeshFormat\n$PhysicalNames\n2\n3 5 \"body\"\n3 9 \"fissure\"\n$EndPhysicalNames\n"
        "$Entities\n1 1 0 3\n1 0 0 0 0\n1 0 0 0 1 1 1 0 2 1 -1\n"
        "7 0 0 0 1 1 1 1 5 0\n8 0 0 0 1 1 1 2 9 5 0\n4 0 0 0 1 1 1 0 0\n$EndEntities\n"
        "$Nodes\n1 6 1 6\n3 7 0 6\n1\n2\n3\n4\n5\n6\n0 0 0\n1 0 0\n0 1 0\n0 0 1\n1 1 1\n0.5 0.5 -1\n$EndNodes\n"
        "$Elements\n3 3 1 3\n3 8 4 1\n1 1 2 3 4\n3 4 4 1\n2 2 3 4 5\n3 7 4 1\n3 1 3 2 6\n$EndElements\n";

/* The same partitioned: the blocks in volumes of $PartitionedEntities (one with its own physical
   tag, one taking its parent's, one with none), a ghost entity and a point entity. */
static const char *G41_PART =
        "$MeshFormat\n4.1 0 8\n$EndMeshFormat\n"
        "$Entities\n1 1 0 3\n1 0 0 0 0\n1 0 0 0 1 1 1 0 2 1 -1\n"
        "7 0 0 0 1 1 1 1 5 0\n8 0 0 0 1 1 1 2 9 5 0\n4 0 0 0 1 1 1 0 0\n$EndEntities\n"
        "$PartitionedEntities\n2\n1\n20 2\n1 0 0 3\n21 0 1 1 2 0 0 0 0\n"
        "10 3 7 1 1 0 0 0 1 1 1 1 5 0\n11 3 8 1 2 0 0 0 1 1 1 0 0\n12 3 4 1 2 0 0 0 1 1 1 0 0\n"
        "$EndPartitionedEntities\n"
        "$Nodes\n1 6 1 6\n3 10 0 6\n1\n2\n3\n4\n5\n6\n0 0 0\n1 0 0\n0 1 0\n0 0 1\n1 1 1\n0.5 0.5 -1\n$EndNodes\n"
        "$Elements\n3 3 1 3\n3 11 4 1\n1 1 2 3 4\n3 12 4 1\n2 2 3 4 5\n3 10 4 1\n3 1 3 2 6\n$EndElements\n";

static int t_regions_are(const amps_mesh *m, amps_int a, amps_int b, amps_int c) {
    return m && m->ntet == 3 && m->region[0] == a && m->region[1] == b && m->region[2] == c;
}

/* Regions of every reader on hand-written files. */
static void test_region_readers(void) {
    amps_ctx ctx;
    amps_mesh *m;
    amps_ctx_init(&ctx);
    m = t_gmsh(&ctx, G22_MIXED);
    CHECK(t_regions_are(m, 2, 2, 0), "gmsh 2.2 physical tags (0 without tags)");
    amps_mesh_free(&ctx, m);
    m = t_gmsh(&ctx, G41_MIXED);
    CHECK(t_regions_are(m, 0, 0, 0), "gmsh 4.1 entity without physical tag");
    amps_mesh_free(&ctx, m);
    m = t_gmsh(&ctx, G41_REGIONS);
    CHECK(t_regions_are(m, 9, 0, 5), "gmsh 4.1 first physical tag of the volume entity: %s", ctx.msg);
    amps_mesh_free(&ctx, m);
    m = t_gmsh(&ctx, G41_PART);
    CHECK(t_regions_are(m, 9, 0, 5), "gmsh 4.1 partitioned entities: %s", ctx.msg);
    amps_mesh_free(&ctx, m);
    { /* tets in a volume the file does not list, in a surface entity, after $Elements */
        static const char *bad[3][2] = {
                {"3 4 4 1\n2 2", "3 99 4 1\n2 2"}, {"3 4 4 1\n2 2", "2 4 4 1\n2 2"}, {"$Entities", "$Entitie0"}};
        static const char *want[3] = {"volume entity 99", "dimension 2", "$Entities after $Elements"};
        int q;
        for (q = 0; q < 3; q++) {
            char buf[2048], *at;
            snprintf(buf, sizeof(buf), "%s", G41_REGIONS);
            at = strstr(buf, bad[q][0]);
            if (q == 2) { /* $Entities moved after $Elements */
                const char *e = strstr(G41_REGIONS, "$Nodes");
                snprintf(buf, sizeof(buf), "$MeshFormat\n4.1 0 8\n$EndMeshFormat\n%s%.*s", e,
                         (int)(e - strstr(G41_REGIONS, "$Entities")), strstr(G41_REGIONS, "$Entities"));
            } else if (at) memcpy(at, bad[q][1], strlen(bad[q][1]));
            m = t_gmsh(&ctx, buf);
            CHECK(!m && ctx.status == AMPS_ERR_PARSE && strstr(ctx.msg, want[q]), "gmsh 4.1 bad entity %d: %s", q,
                  ctx.msg);
            amps_mesh_free(&ctx, m);
        }
    }
    m = t_gmsh(&ctx, G22);
    CHECK(m && m->region[0] == 0, "gmsh 2.2 physical tag 0");
    amps_mesh_free(&ctx, m);
    m = t_medit(&ctx, M_MIXED);
    CHECK(t_regions_are(m, 1, 7, 7), "medit references");
    amps_mesh_free(&ctx, m);
    { /* an empty Hexahedra section is harmless */
        char buf[1024];
        const char *at = strstr(M_MIXED, "Corners");
        snprintf(buf, sizeof(buf), "%.*sHexahedra\n0\nPrisms 0\n%s", (int)(at - M_MIXED), M_MIXED, at);
        m = t_medit(&ctx, buf);
        CHECK(t_regions_are(m, 1, 7, 7), "medit: empty Hexahedra and Prisms sections: %s", ctx.msg);
        amps_mesh_free(&ctx, m);
    }
    /* gmsh 2.2 writes an element once per physical group of its volume: read once, the first
       group's region, the file order of the first lines kept */
    m = t_gmsh(&ctx, "$MeshFormat\n2.2 0 8\n$EndMeshFormat\n$Nodes\n5\n1 0 0 0\n2 1 0 0\n3 0 1 0\n4 0 0 1\n5 1 1 1\n"
                     "$EndNodes\n$Elements\n4\n1 4 2 5 1 1 2 3 4\n2 4 2 6 1 2 1 3 4\n3 4 2 6 2 2 3 4 5\n"
                     "4 4 2 7 1 4 3 2 1\n$EndElements\n");
    CHECK(m && m->ntet == 2 && m->region[0] == 5 && m->region[1] == 6 && m->tet[4] == 1 && m->tet[7] == 4,
          "gmsh 2.2 repeated tets: %s", ctx.msg);
    amps_mesh_free(&ctx, m);
    /* higher-order tets (type 11) by their corners; the edge nodes belong to no tet */
    m = t_gmsh(&ctx, "$MeshFormat\n2.2 0 8\n$EndMeshFormat\n$Nodes\n10\n1 0 0 0\n2 1 0 0\n3 0 1 0\n4 0 0 1\n"
                     "5 .5 0 0\n6 .5 .5 0\n7 0 .5 0\n8 0 0 .5\n9 0 .5 .5\n10 .5 0 .5\n$EndNodes\n$Elements\n1\n"
                     "1 11 2 3 1 1 2 3 4 5 6 7 8 9 10\n$EndElements\n");
    CHECK(m && m->nnode == 10 && m->ntet == 1 && m->region[0] == 3 && m->tet[0] == 0 && m->tet[3] == 3,
          "gmsh 2.2 10-node tet: %s", ctx.msg);
    amps_mesh_free(&ctx, m);
    /* as tetgen -A writes it: one attribute column, integer valued */
    m = t_tetgen(&ctx, "6 3 0 0\n0 0 0 0\n1 1 0 0\n2 0 1 0\n3 0 0 1\n4 1 1 1\n5 0.5 0.5 -1\n",
                 "3 4 1\n0 0 1 2 3 1\n1 1 2 3 4 2\n2 0 2 1 5 1.0 # comment\n");
    CHECK(t_regions_are(m, 1, 2, 1), "tetgen -A attribute: %s", ctx.msg);
    amps_mesh_free(&ctx, m);
    m = t_tetgen(&ctx, T_NODE4, "1 4 2\n0 0 1 2 3 -4 0.5\n");
    CHECK(m && m->region[0] == -4, "tetgen: first of two attributes");
    amps_mesh_free(&ctx, m);
    m = t_tetgen(&ctx, T_NODE4, T_ELE1);
    CHECK(m && m->region[0] == 0, "tetgen without attributes");
    amps_mesh_free(&ctx, m);
    m = t_tetgen(&ctx, T_NODE4, "1 4 1\n0 0 1 2 3 1.5\n");
    t_expect(&ctx, m, AMPS_ERR_PARSE, "t.ele:2: region attribute 1.5 is not an integer", "fractional attribute");
    m = t_tetgen(&ctx, T_NODE4, "1 4 1\n0 0 1 2 3 3000000000\n");
    t_expect(&ctx, m, AMPS_ERR_PARSE, "t.ele:2: region attribute 3000000000 does not fit the index type",
             "attribute beyond the index type");
    m = t_tetgen(&ctx, T_NODE4, "1 4 1\n0 0 1 2 3\n");
    t_expect(&ctx, m, AMPS_ERR_PARSE, "t.ele:2:", "missing attribute");
}

#ifndef AMPS_NO_STDIO
/* m2 is m with the removed tets left out, regions kept. */
static int t_same_live(const amps_mesh *m, const amps_mesh *m2) {
    amps_int t, k = 0;
    if (!m2 || m2->nnode != m->nnode || m2->ntet != m->ntet - m->nremoved) return 0;
    if (t_reldiff((int)(3 * m->nnode), m->xyz, m2->xyz) != 0) return 0;
    for (t = 0; t < m->ntet; t++) {
        if (m->removed[t]) continue;
        if (memcmp(m->tet + 4 * t, m2->tet + 4 * k, 4 * sizeof(amps_int)) || m->region[t] != m2->region[k]) return 0;
        k++;
    }
    return 1;
}

/* Regions round-trip through every writer and reader; removed tets are not written. */
static void test_region_roundtrip(void) {
    amps_ctx ctx;
    amps_mesh *m, *r;
    char p1[700], p2[700];
    amps_int t, rm[3] = {4, 30, 31};
    int ver, pass;
    amps_ctx_init(&ctx);
    m = amps_mesh_brick(&ctx, 2);
    if (!m) {
        CHECK(0, "brick");
        return;
    }
    for (pass = 0; pass < 3; pass++) {
        if (pass == 1) /* regions in runs and scattered, one negative */
            for (t = 0; t < m->ntet; t++) amps_mesh_set_tet_region(&ctx, m, t, t < 20 ? 3 : (t % 5 == 0 ? -2 : t % 3));
        if (pass == 2) CHECK(amps_mesh_remove(&ctx, m, 3, rm, AMPS_SINGULAR_IGNORE, NULL) == AMPS_OK, "remove");
        t_path(p1, "reg");
        CHECK(amps_mesh_write_tetgen(&ctx, p1, m, pass == 1) == AMPS_OK, "write tetgen");
        t_path(p1, "reg.node");
        t_path(p2, "reg.ele");
        r = amps_mesh_read(&ctx, p1);
        CHECK(t_same_live(m, r), "tetgen pass %d: %s", pass, ctx.msg);
        amps_mesh_free(&ctx, r);
        remove(p1);
        remove(p2);
        for (ver = 2; ver <= 4; ver += 2) {
            t_path(p1, "reg.msh");
            CHECK(amps_mesh_write_gmsh(&ctx, p1, m, ver) == AMPS_OK, "write gmsh %d", ver);
            r = amps_mesh_read(&ctx, p1);
            CHECK(t_same_live(m, r), "gmsh %d pass %d: %s", ver, pass, ctx.msg);
            amps_mesh_free(&ctx, r);
            remove(p1);
        }
        t_path(p1, "reg.mesh");
        CHECK(amps_mesh_write_medit(&ctx, p1, m) == AMPS_OK, "write medit");
        r = amps_mesh_read(&ctx, p1);
        CHECK(t_same_live(m, r), "medit pass %d: %s", pass, ctx.msg);
        amps_mesh_free(&ctx, r);
        remove(p1);
    }
    amps_mesh_free(&ctx, m);
}

/* VTU of a mesh with removed tets, and a .pvd time series. */
static void test_vtu_frames(void) {
    amps_ctx ctx;
    amps_mesh *m;
    char path[700], pvd[700];
    const char *files[3] = {"f0.vtu", "dir/f1.vtu", "a&b<\"c\">.vtu"};
    double times[3] = {0.0, 0.01, 0.25}, *u, *vm, *pr, sum, bad[1] = {NAN};
    amps_int rm[4] = {0, 7, 8, 50}, v, t, live, rsum = 0;
    size_t len;
    char *txt;
    m = t_beam4(&ctx);
    if (!m) return;
    for (t = 0; t < m->ntet; t++) amps_mesh_set_tet_region(&ctx, m, t, t % 4);
    CHECK(amps_mesh_remove(&ctx, m, 4, rm, AMPS_SINGULAR_IGNORE, NULL) == AMPS_OK, "remove");
    live = m->ntet - m->nremoved;
    for (t = 0; t < m->ntet; t++) rsum += m->removed[t] ? 0 : m->region[t];
    u = (double *)calloc(3 * (size_t)m->nnode, sizeof(double));
    vm = (double *)malloc(sizeof(double) * m->ntet);
    pr = (double *)malloc(sizeof(double) * 3 * m->ntet);
    for (v = 0; v < m->nnode; v++) u[3 * v] = 0.01 * m->xyz[3 * v + 2] * m->xyz[3 * v + 2];
    amps_mesh_stress(&ctx, m, u, NULL, vm, pr);
    t_path(path, "frame.vtu");
    CHECK(amps_mesh_write_vtu(&ctx, path, m, u, vm, pr) == AMPS_OK, "write vtu: %s", ctx.msg);
    txt = t_slurp(path, &len);
    if (txt) {
        char head[200];
        CHECK(t_xml_ok(txt, "VTKFile"), "vtu not well-formed");
        snprintf(head, sizeof(head), "NumberOfPoints=\"%ld\" NumberOfCells=\"%ld\"", (long)m->nnode, (long)live);
        CHECK(strstr(txt, head) != NULL, "piece header counts the kept tets");
        CHECK(t_array_count(txt, "connectivity", &sum) == 4 * live, "connectivity");
        CHECK(t_array_count(txt, "offsets", &sum) == live, "offsets");
        CHECK(t_array_count(txt, "von_mises", &sum) == live, "von_mises");
        CHECK(t_array_count(txt, "principal_stress", &sum) == 3 * live, "principal");
        CHECK(t_array_count(txt, "region", &sum) == live && sum == (double)rsum, "region cell data");
        CHECK(t_array_count(txt, "cut", &sum) == live, "cut");
        free(txt);
    } else {
        CHECK(0, "read back vtu");
    }
    remove(path);
    t_path(pvd, "series.pvd");
    CHECK(amps_pvd_write(&ctx, pvd, 3, files, times) == AMPS_OK, "write pvd: %s", ctx.msg);
    txt = t_slurp(pvd, &len);
    CHECK(txt && t_xml_ok(txt, "VTKFile") && strstr(txt, "type=\"Collection\"") &&
                  strstr(txt, "<DataSet timestep=\"0.01\" group=\"\" part=\"0\" file=\"dir/f1.vtu\"/>") &&
                  strstr(txt, "file=\"a&amp;b&lt;&quot;c&quot;&gt;.vtu\""),
          "pvd contents");
    free(txt);
    CHECK(amps_pvd_write(&ctx, pvd, 0, NULL, NULL) == AMPS_OK, "empty pvd");
    CHECK(amps_pvd_write(&ctx, pvd, 1, files, bad) == AMPS_ERR_VALUE, "NaN time");
    CHECK(amps_pvd_write(&ctx, pvd, -1, files, times) == AMPS_ERR_ARG, "negative count");
    CHECK(amps_pvd_write(&ctx, NULL, 1, files, times) == AMPS_ERR_ARG, "NULL path");
    remove(pvd);
    free(u);
    free(vm);
    free(pr);
    amps_mesh_free(&ctx, m);
}

/* Regions of a real `tetgen -A` run (two stacked unit cubes, regions 10 and 20), when tetgen
   is installed; skipped otherwise. */
/* The Gmsh 2.2 writer gives each region its own elementary tag (Gmsh itself groups a file's
   elements by elementary entity: one tag for all would put every tet in every physical group);
   with the gmsh binary installed, a file re-saved by gmsh reads back with the regions. */
static void test_gmsh2_entities(void) {
    static const amps_int ids[3] = {7, 3, 11};
    char path[700], out[700], cmd[1600], *txt, *p;
    amps_ctx ctx;
    amps_mesh *m = t_beam4(&ctx), *r;
    amps_int t, elem[3] = {-1, -1, -1}, k;
    size_t len;
    int bad = 0, lines = 0;
    if (!m) return;
    for (t = 0; t < m->ntet; t++) amps_mesh_set_tet_region(&ctx, m, t, ids[t % 3]);
    t_path(path, "regions22.msh");
    CHECK(amps_mesh_write_gmsh(&ctx, path, m, 2) == AMPS_OK, "write gmsh 2: %s", ctx.msg);
    txt = t_slurp(path, &len);
    p = txt ? strstr(txt, "$Elements\n") : NULL;
    if (p) p = strchr(p + 10, '\n'); /* past the count */
    while (p && p[1] != '$') {
        long long num, type, ntag, phys, el;
        if (sscanf(p + 1, "%lld %lld %lld %lld %lld", &num, &type, &ntag, &phys, &el) != 5) break;
        for (k = 0; k < 3 && ids[k] != phys; k++) {}
        if (k == 3 || (elem[k] >= 0 && elem[k] != el)) bad++;
        else elem[k] = (amps_int)el;
        lines++;
        p = strchr(p + 1, '\n');
    }
    CHECK(lines == m->ntet && !bad && elem[0] != elem[1] && elem[1] != elem[2] && elem[0] != elem[2],
          "gmsh 2.2: elementary tags per region (%d lines, %d bad)", lines, bad);
    free(txt);
    if (system("command -v gmsh >/dev/null 2>&1") == 0) {
        int v;
        for (v = 2; v <= 4; v += 2) {
            t_path(out, "regions22_resaved.msh");
            snprintf(cmd, sizeof(cmd), "gmsh -0 '%s' -format %s -o '%s' >/dev/null 2>&1", path,
                     v == 2 ? "msh22" : "msh41", out);
            CHECK(system(cmd) == 0, "gmsh re-save");
            amps_ctx_init(&ctx);
            r = amps_mesh_read(&ctx, out);
            { /* gmsh orders the elements by entity: the tets and volume of each region */
                double vol[2][3] = {{0, 0, 0}, {0, 0, 0}};
                int q;
                for (q = 0; q < 2; q++) {
                    const amps_mesh *x = q ? r : m;
                    for (t = 0; x && t < x->ntet; t++) {
                        double X[12], G[12];
                        for (k = 0; k < 3 && ids[k] != x->region[t]; k++) {}
                        amps_mesh_tet_coords(x, t, X);
                        if (k < 3) vol[q][k] += fabs(amps_tet_gradients(X, G));
                        else bad++;
                    }
                }
                for (k = 0; k < 3; k++) bad += fabs(vol[0][k] - vol[1][k]) > 1e-12 * (1 + vol[0][k]);
            }
            CHECK(r && r->ntet == m->ntet && !bad, "gmsh re-saved as %d: %s (%d regions differ)", v, r ? "" : ctx.msg,
                  bad);
            amps_mesh_free(&ctx, r);
            remove(out);
        }
    }
    remove(path);
    amps_mesh_free(&ctx, m);
}

static void test_tetgen_regions(void) {
    static const char *poly =
            "12 3 0 0\n1 0 0 0\n2 1 0 0\n3 1 1 0\n4 0 1 0\n5 0 0 1\n6 1 0 1\n7 1 1 1\n8 0 1 1\n9 0 0 2\n10 1 0 2\n"
            "11 1 1 2\n12 0 1 2\n11 0\n1\n4 1 2 3 4\n1\n4 5 6 7 8\n1\n4 9 10 11 12\n1\n4 1 2 6 5\n1\n4 2 3 7 6\n"
            "1\n4 3 4 8 7\n1\n4 4 1 5 8\n1\n4 5 6 10 9\n1\n4 6 7 11 10\n1\n4 7 8 12 11\n1\n4 8 5 9 12\n0\n"
            "2\n1 0.5 0.5 0.5 10 -1\n2 0.5 0.5 1.5 20 -1\n";
    char path[700], out[700], cmd[1600];
    amps_ctx ctx;
    amps_mesh *m;
    amps_int t;
    double v10 = 0, v20 = 0;
    int other = 0;
    if (system("command -v tetgen >/dev/null 2>&1") != 0) return;
    t_path(path, "tg_regions.poly");
    if (!t_write(path, poly, strlen(poly))) return;
    snprintf(cmd, sizeof(cmd), "tetgen -pqAQ '%s' >/dev/null 2>&1", path);
    CHECK(system(cmd) == 0, "tetgen run");
    amps_ctx_init(&ctx);
    t_path(out, "tg_regions.1.ele");
    m = amps_mesh_read(&ctx, out);
    CHECK(m != NULL, "read tetgen -A output: %s", ctx.msg);
    for (t = 0; m && t < m->ntet; t++) {
        double X[12], G[12], vol;
        amps_mesh_tet_coords(m, t, X);
        vol = fabs(amps_tet_gradients(X, G));
        if (m->region[t] == 10) v10 += vol;
        else if (m->region[t] == 20) v20 += vol;
        else other++;
    }
    CHECK(m && other == 0 && fabs(v10 - 1) < 1e-12 && fabs(v20 - 1) < 1e-12, "tetgen regions: volumes %g %g", v10, v20);
    amps_mesh_free(&ctx, m);
    remove(path);
    remove(out);
    t_path(out, "tg_regions.1.node");
    remove(out);
    t_path(out, "tg_regions.1.face");
    remove(out);
    t_path(out, "tg_regions.1.edge");
    remove(out);
}
#endif

int main(int argc, char **argv) {
    const char *slash = argc > 0 ? strrchr(argv[0], '/') : NULL;
    if (slash) snprintf(g_dir, sizeof(g_dir), "%.*s", (int)(slash - argv[0]), argv[0]);
    else snprintf(g_dir, sizeof(g_dir), ".");
    test_valid_inputs();
    test_malformed_tetgen();
    test_malformed_gmsh();
    test_malformed_medit();
    test_messages();
    test_region_readers();
#ifndef AMPS_NO_STDIO
    test_roundtrip();
    test_vtu();
    test_region_roundtrip();
    test_vtu_frames();
    test_tetgen_regions();
    test_gmsh2_entities();
#endif
    test_corruption();
    test_reader_oom();
    return amps_t_end("test_io");
}
