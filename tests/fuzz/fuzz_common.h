/* Shared by the libFuzzer targets: builds the library once per target, checks the reader's
   contract on every input (a mesh passes amps_mesh_check; a failure has a status and a
   "name:line: message" or I/O message) and frees everything (leaks are reported by ASan). */
#ifndef FUZZ_COMMON_H
#define FUZZ_COMMON_H
#include <stdlib.h>
#include <string.h>
#define AMPS_IMPLEMENTATION
#include "amps.h"

static void fuzz_check(amps_ctx *ctx, amps_mesh *m, const char *name) {
    if (m) {
        if (amps_mesh_check(ctx, m) != AMPS_OK) abort();
        amps_mesh_free(ctx, m);
    } else {
        size_t n = strlen(name);
        if (ctx->status == AMPS_OK || ctx->msg[0] == 0) abort();
        /* parse errors name the file and a line */
        if (ctx->status == AMPS_ERR_PARSE && (strncmp(ctx->msg, name, n) != 0 || ctx->msg[n] != ':')) abort();
    }
}
#endif
