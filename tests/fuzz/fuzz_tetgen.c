/* libFuzzer target: TetGen reader on a memory buffer. The input is the .node text, a NUL
   byte, then the .ele text (no NUL: all of it is the .node text, the .ele is empty). */
#include "fuzz_common.h"

int LLVMFuzzerTestOneInput(const unsigned char *data, size_t size);
int LLVMFuzzerTestOneInput(const unsigned char *data, size_t size) {
    amps_ctx ctx;
    const char *s = (const char *)data, *z = (const char *)memchr(data, 0, size);
    size_t nl = z ? (size_t)(z - s) : size;
    amps_mesh *m;
    amps_ctx_init(&ctx);
    m = amps_mesh_read_tetgen_mem(&ctx, s, nl, "fuzz.node", z ? z + 1 : s + size, z ? size - nl - 1 : 0, "fuzz.ele");
    if (m) fuzz_check(&ctx, m, "");
    else if (ctx.status == AMPS_OK || ctx.msg[0] == 0 ||
             (ctx.status == AMPS_ERR_PARSE && strncmp(ctx.msg, "fuzz.node:", 10) && strncmp(ctx.msg, "fuzz.ele:", 9)))
        abort();
    return 0;
}
