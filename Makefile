# amps.h build: tests, tools, examples, benchmarks.
#   make test          build and run every test (last line: "N passed, N failed")
#   make test SAN=1    the same under AddressSanitizer + UndefinedBehaviorSanitizer
#   make test OMP=     the same without OpenMP
#   make tsan          ThreadSanitizer on the tests that run background re-factorizations, on
#                      tests/test_par.c (the parallel layer on a pthread job system) and on
#                      tests/test_corot.c (the corotational passes on 1-3 threads)
#   make test-tasks    the tests of the parallel kernels on the host-task back end (tests/jobs_test.h)
#   make examples      build the examples (build/default/readme_example, haptic_loop, frame_loop)
#   make switches      AMPS_NO_FEM / NO_STDIO / NO_THREADS combinations: build, tests, object sizes
#   make demo          the main job: replay examples/brick_incision.scn (VTU, CSV, PNG in build/demo)
#   make bench         benchmarks; results in bench/RESULTS.md and bench/out/*.csv (tracked)
#   make bench-quick   a subset of them; results in build/bench/quick
#   make bench-load    the load benchmark alone (spinning processes, a 1 kHz loop; bench/load.sh)
#   make bench-dynamics the dynamics benchmark alone (bench/dynamics.sh; its section of RESULTS.md)
#   make stress        the long stress suite (beams to 5x5x4096, 10,000-step runs; CSV/PNG in build/stress)
#   make fuzz          libFuzzer targets (clang), FUZZ_TIME seconds each (default 60)
#   make deps          install (as root) or list the Debian packages the tests need
#   make format        clang-format (.clang-format) on every C source and header
#   make format-check  the same as a check: fails if any file would change
#   make clean         remove build/ (every build product; the tracked results stay)
#   make distclean     also remove bench/data/ (the downloaded and meshed bunny)
CC      ?= cc
CXX     ?= c++
OPT     ?= -O2 -g
OMP     ?= -fopenmp
STD     ?= -std=c99
WARN    ?= -Wall -Wextra -pedantic
SSINC   ?= -I/usr/include/suitesparse
SAN     ?=
ifeq ($(SAN),1)
  SANFLAGS = -fsanitize=address,undefined -fno-omit-frame-pointer -fno-sanitize-recover=undefined
  BUILD  ?= build/san
else ifeq ($(SAN),thread)
  SANFLAGS = -fsanitize=thread
  BUILD  ?= build/tsan
else
  SANFLAGS =
endif
ifeq ($(OMP),)
  BUILD  ?= build/noomp
endif
BUILD   ?= build/default
CFLAGS_ALL = $(STD) $(WARN) $(OPT) $(OMP) $(SANFLAGS) -I. $(SSINC) $(EXTRA)
LDLIBS_T   = -lcholmod -lm
LDLIBS     = -lm

TEST_SRC  := $(wildcard tests/test_*.c)
TEST_BIN  := $(patsubst tests/%.c,$(BUILD)/%,$(TEST_SRC))
TEST_SH   := $(wildcard tests/test_*.sh)
TOOLS     := $(BUILD)/amps_replay $(BUILD)/readme_example $(BUILD)/haptic_loop $(BUILD)/frame_loop

.PHONY: tsan test-tasks all test deps deps-check tools examples demo bench bench-quick bench-load bench-dynamics clean distclean cxx switches stress fuzz \
        format format-check
all: tools

tools: $(TOOLS)

$(BUILD)/amps_replay: tools/amps_replay.c examples/jobs.h amps.h | $(BUILD)
	$(CC) $(CFLAGS_ALL) -o $@ $< -lpthread $(LDLIBS)

$(BUILD)/readme_example: examples/readme_example.c amps.h | $(BUILD)
	$(CC) $(CFLAGS_ALL) -o $@ $< $(LDLIBS)

$(BUILD)/haptic_loop: examples/haptic_loop.c examples/jobs.h amps.h | $(BUILD)
	$(CC) $(CFLAGS_ALL) -o $@ $< -lpthread $(LDLIBS)

$(BUILD)/frame_loop: examples/frame_loop.c amps.h | $(BUILD)
	$(CC) $(CFLAGS_ALL) -o $@ $< -lpthread $(LDLIBS)

examples: $(BUILD)/readme_example $(BUILD)/haptic_loop $(BUILD)/frame_loop

# The main job: replay the brick incision, write VTU/CSV (and a PNG when gnuplot is there).
demo: $(BUILD)/amps_replay
	@bash tools/deps.sh demo
	@mkdir -p build/demo
	cd build/demo && $(abspath $(BUILD))/amps_replay --surface brick_incision.surf $(abspath examples/brick_incision.scn)
	@bash tools/render.sh build/demo/brick_incision.surf build/demo/brick_incision.png
	@echo "results: build/demo/brick_incision.vtu (ParaView: Warp By Vector on displacement)," \
	      "build/demo/brick_incision.csv"

$(BUILD):
	mkdir -p $(BUILD)

$(BUILD)/test_%: tests/test_%.c amps.h tests/*.h | $(BUILD)
	$(CC) $(CFLAGS_ALL) -o $@ $< $(LDLIBS_T)

# Without -j from the caller the test programs still build on every core (each compiles the
# whole implementation); the tests then run one at a time.
JOBS ?= $(shell nproc 2>/dev/null || echo 2)
test: deps-check
	@$(MAKE) --no-print-directory $(if $(findstring jobserver,$(MAKEFLAGS)),,-j$(JOBS)) $(TEST_BIN) $(TOOLS)
	@AMPS_BUILD=$(BUILD) bash tests/run.sh $(TEST_BIN) $(TEST_SH)

# Long mode of tests/test_stress.c (the short mode is part of make test); the bunny run uses
# bench/data/bunny20k.1.node (bench/get_bunny.sh) or $$AMPS_BUNNY, else it is skipped.
stress: $(BUILD)/test_stress
	./$(BUILD)/test_stress --long

FUZZ_TIME ?= 60
fuzz:
	bash tests/fuzz/run.sh $(FUZZ_TIME)

deps-check:
	@bash tools/deps.sh

deps:
	@bash tools/deps.sh

cxx: | $(BUILD)
	printf '#define AMPS_IMPLEMENTATION\n#include "amps.h"\n%s\n' \
	       'int main(void){amps_ctx c; amps_ctx_init(&c); return 0;}' > $(BUILD)/cxx_check.cpp
	$(CXX) -std=c++11 -Wall -Wextra -Werror -I. -c $(BUILD)/cxx_check.cpp -o $(BUILD)/cxx_check.o
	$(CXX) -std=c++11 -Wall -Wextra -Werror -I. -x c++ -c examples/haptic_loop.c -o $(BUILD)/haptic_loop_cxx.o
	$(CXX) -std=c++11 -Wall -Wextra -Werror -I. -x c++ -c examples/frame_loop.c -o $(BUILD)/frame_loop_cxx.o

# libgomp is not instrumented, so without OpenMP; the threads are the re-factorization's
tsan:
	$(MAKE) SAN=thread OMP= BUILD=build/tsan OPT="-O1 -g" build/tsan/test_update build/tsan/test_scene \
	  build/tsan/test_par build/tsan/test_corot
	@TSAN_OPTIONS="halt_on_error=1 suppressions=$(abspath tests/tsan.supp)" AMPS_BUILD=build/tsan \
	  bash tests/run.sh build/tsan/test_update build/tsan/test_scene build/tsan/test_par build/tsan/test_corot

# The tests that run the parallel kernels (factorization, solves, updates, scenes, dynamics,
# corotational passes, frame loop, haptic path, stress) on the host-callback back end
# (tests/jobs_test.h's pool of 4 workers), no OpenMP; the others do not reach the back end.
TASK_TESTS := factor solve update par scene dynamics corot frame haptic stress alloc_update render
test-tasks:
	$(MAKE) test OMP= BUILD=build/tasks EXTRA="-DAMPS_TEST_HOST_TASKS -DAMPS__PAR_ADAPT=0 -pthread $(EXTRA)" \
	  TEST_SRC="$(patsubst %,tests/test_%.c,$(TASK_TESTS))" TEST_SH=

# The compile-time switches, each combination built with -Werror, tested and sized (tests/switches.sh).
switches: deps-check
	@CC=$(CC) bash tests/switches.sh

bench:
	bash bench/run.sh full

bench-quick:
	bash bench/run.sh quick

# the load benchmark alone (part of make bench): bench/out/load.csv, load_summary.txt
bench-load:
	bash bench/load.sh full

bench-dynamics:
	bash bench/dynamics.sh full bench/out alone

# The sources clang-format keeps in the style of .clang-format (CLANG_FORMAT: version 14 or later).
CLANG_FORMAT ?= clang-format
FORMAT_SRC   := amps.h $(wildcard bench/*.c bench/*.h examples/*.c tools/*.c) \
                $(wildcard tests/*.c tests/*.h tests/fuzz/*.c tests/fuzz/*.h)
format:
	$(CLANG_FORMAT) -i $(FORMAT_SRC)

format-check:
	$(CLANG_FORMAT) --dry-run --Werror $(FORMAT_SRC)

# Build products only: bench/out/ holds the tracked results of the last full benchmark run.
clean:
	rm -rf build

distclean: clean
	rm -rf bench/data
