/* libFuzzer target: Gmsh .msh reader on a memory buffer. */
#include "fuzz_common.h"

int LLVMFuzzerTestOneInput(const unsigned char *data, size_t size);
int LLVMFuzzerTestOneInput(const unsigned char *data, size_t size) {
    amps_ctx ctx;
    amps_ctx_init(&ctx);
    fuzz_check(&ctx, amps_mesh_read_gmsh_mem(&ctx, (const char *)data, size, "fuzz.msh"), "fuzz.msh");
    return 0;
}
