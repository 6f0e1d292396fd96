/* libFuzzer target: the scenario parser and commands of tools/amps_replay.c on a memory buffer, in
   its sandbox (no file access, meshes of size <= 8). Every input either runs or stops at a line
   with a message; nothing leaks (ASan) or trips UBSan. */
#include <stdio.h>
#include <stdlib.h>
#define AMPS_REPLAY_NO_MAIN
#include "../../tools/amps_replay.c"

int LLVMFuzzerTestOneInput(const unsigned char *data, size_t size);
int LLVMFuzzerTestOneInput(const unsigned char *data, size_t size) {
    replay R;
    static int quiet_io = 0;
    if (!quiet_io) { /* the replayer prints per line: keep the fuzzer's output readable */
        if (!freopen("/dev/null", "w", stdout)) return 0;
        quiet_io = 1;
    }
    replay_init(&R);
    R.sandbox = 1;
    R.quiet = 1;
    R.residual_on = 1;
    R.file = "fuzz.scn";
    (void)replay_run_buffer(&R, (const char *)data, size);
    replay_free(&R);
    (void)write_surface;
    (void)cmp_double; /* main's helpers, unused here */
    return 0;
}
