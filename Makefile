# terrafarm build.  `make` builds bin/terrafarm; `make test` builds and runs every test;
# `make asan` builds an AddressSanitizer+UBSan tree under build-asan/ (assertions on), runs
# the tests with it, then every fuzz target for a fixed number of runs (fuzz-runs);
# `make deps` installs the Debian packages the build and tests need; `make bench` builds the
# benchmarks.
#
# The objects are listed by layer, lowest first, as Lua's makefile lists its core and its
# libraries: a layer uses only the layers above it in this list, never one below.  Headers are
# included by folder ("render/trace.h", "coordinator/render/supervisor.h").  Every unit test
# tests/unit/test_*.c is its own cmocka program, every bench/*.c its own benchmark, every
# tests/fuzz/fuzz_*.c a fuzz target; all of them link the same objects as bin/terrafarm.

CC      ?= cc
BUILD   ?= build
BIN     ?= bin
VERSION := 0.2.0

PKGS      := inih libpng libsodium zlib libdeflate gdal libmicrohttpd jansson sqlite3
# GDAL is compiled against but not linked: common/gdal_loader.c dlopen()s it by this soname on
# first use (its hundred dependencies cost every process ~35 ms to load).  Programs that call
# GDAL directly (a unit test) link it with GDAL_LIBS.
GDAL_LIBS   := $(shell pkg-config --libs gdal 2>/dev/null)
GDAL_SONAME := $(shell readelf -d $$($(CC) -print-file-name=libgdal.so) 2>/dev/null | \
                 sed -n 's/.*(SONAME).*\[\(.*\)\]/\1/p')
EXR_CFLAGS := $(shell pkg-config --cflags OpenEXR 2>/dev/null)
EXR_LIBS   := $(filter -L% -lOpenEXRCore%,$(shell pkg-config --libs OpenEXR 2>/dev/null))
CL_LIBS    := $(shell pkg-config --libs OpenCL 2>/dev/null || echo -lOpenCL)

# -ffp-contract=off: no fused multiply-add contraction, so every machine computes the same
# bits (docs/contract.md section 4: deterministic terrain and pixels everywhere).
# -DNDEBUG: the numbered invariants (assert) are checked in `make asan`, not in release builds.
CFLAGS   ?= -O2 -g -DNDEBUG
# The render layer (tracing, shading, antialiasing: nearly all of a worker's time) is compiled
# with HOT_CFLAGS after CFLAGS: -O3 takes 4-5% off a render's CPU against -O2, and
# -fno-math-errno (sqrt inline: the layer never reads errno) 1-2% more, with the same bits
# (neither changes floating point; bench/README.md section 38).  So is the filter every result
# goes through before deflate (image/exrzip.c), whose loops -O3 vectorises (section 42), and
# the procedural terrain's levels, bounds and tile cache, which a procedural trace asks at
# every node of its quad-tree (section 47).  `make asan` clears it.
HOT_CFLAGS ?= -O3 -fno-math-errno
SAN      ?=
ALL_CFLAGS := $(CFLAGS) $(SAN) -std=c11 -D_GNU_SOURCE -Wall -Wextra -ffp-contract=off -pthread \
            -I. -Icommon -DTF_VERSION='"$(VERSION)"' \
            $(if $(GDAL_SONAME),-DTF_GDAL_SONAME='"$(GDAL_SONAME)"') \
            $(shell pkg-config --cflags $(PKGS) 2>/dev/null) $(EXR_CFLAGS)
LDLIBS   := $(shell pkg-config --libs $(filter-out gdal,$(PKGS)) 2>/dev/null) $(EXR_LIBS) $(CL_LIBS) -lm -pthread
TEST_LIBS := $(shell pkg-config --libs cmocka 2>/dev/null)
# Embree 3 (libembree-dev), linked into bench/embree_compare alone: from its pkg-config file
# where there is one, else -lembree3 when the compiler finds its header (Debian's package ships
# no .pc file).  Without it that bench is not built, and tests/e2e/bench_smoke.sh skips it.
EMBREE_CFLAGS := $(shell pkg-config --cflags embree3 2>/dev/null)
EMBREE_LIBS   := $(shell pkg-config --libs embree3 2>/dev/null || \
                   { $(CC) -E -include embree3/rtcore.h -x c /dev/null >/dev/null 2>&1 && echo -lembree3; })

# 0. base: messages, clocks, vectors, the SIMD kernels' ISA choice, GDAL loaded on first use,
#    files written around the page cache; the scene file (parsed, validated, hashed)
BASE_SRC    := common/log.c common/clock.c common/datadir.c common/gdal_loader.c common/cachefile.c \
               common/directfile.c common/animation.c common/isa.c common/scene_keys.c \
               common/scene_report.c common/scene_values.c common/scene_ini.c common/scene_check.c \
               common/scene_canonical.c common/scene_frame.c common/scene.c
# 1. terrain: noise, fractal and grid generators, erosion, the height field and its max/min grids
TERRAIN_SRC := $(wildcard common/terrain/*.c)
# 2. image: the pixel, OpenEXR (OpenEXRCore) checkpoint files, PNG and the preview
IMAGE_SRC   := $(wildcard common/image/*.c)
# 3. render: camera, grid tracing, shading and mist, adaptive antialiasing over a rectangle
RENDER_SRC  := $(wildcard common/render/*.c)
HOT_TERRAIN_OBJ := $(BUILD)/common/terrain/procedural.o $(BUILD)/common/terrain/tilecache.o
# 4. linda: tuples, the wire protocol, sockets, authentication, the store, client and server
LINDA_SRC   := $(wildcard common/linda/*.c)
# 5. the farm's tuples (task, result, failure, scene, height map), spoken by both sides
FARM_SRC    := common/http_client.c common/farm_keys.c common/farmproto.c common/heightmap_tuples.c common/erosion_tuples.c \
               common/paintproto.c
# 6. worker: the worker loop, its C and OpenCL backends, the simulated worker
WORKER_SRC  := $(wildcard worker/*.c)
# 7. coordinator, in sub-layers of its own folders, lowest first like the layers above (a folder
#    uses only the folders before it in this list, never one after):
#    7a. render: one job's render, the run as a sequence of steps (coordinator.c), the supervisor
#        (dealer and watermark, leases, admission, spot checks, stragglers), the in-order
#        writer, progress, stats and the event log
#    7b. erosion: an erosion on the farm and the erosion film (uses render/)
#    7c. dashboard: the HTTP server, its API and the snapshots it reads of the render (uses
#        render/)
#    7d. farm: the standing farm: its queue (SQLite), scheduler, jobs' renders and API (uses
#        the folders before it)
#    7e. paint: Raypaint, the interactive progressive view (uses render/ and dashboard/)
#    Two arrows still point back up, both from the render's entry point (render/coordinator.c):
#    it opens, feeds and closes its dashboard (dashboard/dashboard.h) and hands an erosion film
#    to erosion/erosion_film.c.  No other file of a folder includes one of a later folder.
COORD_RENDER_SRC    := $(wildcard coordinator/render/*.c)
COORD_EROSION_SRC   := $(wildcard coordinator/erosion/*.c)
COORD_DASHBOARD_SRC := $(wildcard coordinator/dashboard/*.c)
COORD_FARM_SRC      := $(wildcard coordinator/farm/*.c)
COORD_PAINT_SRC     := $(wildcard coordinator/paint/*.c)
COORD_SRC   := $(COORD_RENDER_SRC) $(COORD_EROSION_SRC) $(COORD_DASHBOARD_SRC) $(COORD_FARM_SRC) \
               $(COORD_PAINT_SRC)
LIB_SRC     := $(BASE_SRC) $(TERRAIN_SRC) $(IMAGE_SRC) $(RENDER_SRC) $(LINDA_SRC) $(FARM_SRC) \
               $(WORKER_SRC) $(COORD_SRC)
# 8. cli: bin/terrafarm's subcommands
CLI_SRC   := $(wildcard cli/*.c)
TEST_SRC  := $(wildcard tests/unit/test_*.c)
BENCH_SRC := $(if $(EMBREE_LIBS),$(wildcard bench/*.c),$(filter-out bench/embree_compare.c,$(wildcard bench/*.c)))
FUZZ_SRC  := $(wildcard tests/fuzz/fuzz_*.c)
KERNELS   := $(wildcard worker/kernels/*.cl)

LIB_OBJ   := $(LIB_SRC:%.c=$(BUILD)/%.o)
CLI_OBJ   := $(CLI_SRC:%.c=$(BUILD)/%.o)
TESTS     := $(TEST_SRC:tests/unit/%.c=$(BUILD)/tests/%)
BENCHES   := $(BENCH_SRC:bench/%.c=$(BUILD)/bench/%)
LIB       := $(BUILD)/libterrafarm.a
PROG      := $(BIN)/terrafarm

.PHONY: all test asan bench bench-deps fuzz fuzz-runs deps clean install FORCE
all: $(PROG)

# Every object depends on the compiler flags it was built with (the version among them), so
# changing CFLAGS or VERSION rebuilds what it must instead of linking stale objects.
FLAGS_STAMP := $(BUILD)/cflags.txt
$(FLAGS_STAMP): FORCE
	@mkdir -p $(dir $@)
	@printf '%s\n' '$(subst ','\'',$(ALL_CFLAGS)) hot: $(HOT_CFLAGS)' >$@.new
	@if cmp -s $@.new $@; then rm -f $@.new; else mv -f $@.new $@; fi
FORCE:

$(BUILD)/%.o: %.c $(FLAGS_STAMP)
	@mkdir -p $(dir $@)
	$(CC) $(ALL_CFLAGS) -MMD -MP -c $< -o $@
# private: the flags stamp, a prerequisite of these objects too, records the common flags only
$(RENDER_SRC:%.c=$(BUILD)/%.o) $(BUILD)/common/image/exrzip.o $(HOT_TERRAIN_OBJ): private ALL_CFLAGS += $(HOT_CFLAGS)

$(LIB): $(LIB_OBJ)
	@mkdir -p $(dir $@)
	rm -f $@ && ar rcs $@ $^

$(PROG): $(CLI_OBJ) $(LIB_OBJ)
	@mkdir -p $(dir $@)
	$(CC) $(ALL_CFLAGS) -o $@ $(CLI_OBJ) $(LIB_OBJ) $(LDLIBS)

$(BUILD)/tests/%: tests/unit/%.c $(LIB_OBJ)
	@mkdir -p $(dir $@)
	$(CC) $(ALL_CFLAGS) -MMD -MP -o $@ $< $(LIB_OBJ) $(TEST_LIBS) $(LDLIBS) $(GDAL_LIBS)

$(BUILD)/bench/%: bench/%.c $(LIB_OBJ)
	@mkdir -p $(dir $@)
	$(CC) $(ALL_CFLAGS) -MMD -MP -o $@ $< $(LIB_OBJ) $(LDLIBS)
$(BUILD)/bench/embree_compare: ALL_CFLAGS += $(EMBREE_CFLAGS)
$(BUILD)/bench/embree_compare: LDLIBS += $(EMBREE_LIBS)

# libFuzzer targets (clang).  The harness sources are plain LLVMFuzzerTestOneInput files; the
# test suite also links each one with tests/fuzz/replay_main.c (gcc) to replay the corpus.
# The library is compiled once for all of them (instrumented, without libFuzzer's main:
# fuzzer-no-link); UB stops a run as it stops `make asan`.
FUZZ_SAN     := address,undefined -fno-sanitize-recover=undefined
FUZZ_CFLAGS  := -O1 -g -std=c11 -D_GNU_SOURCE -I. -Icommon -DTF_VERSION='"$(VERSION)"' \
                $(if $(GDAL_SONAME),-DTF_GDAL_SONAME='"$(GDAL_SONAME)"') \
                $(shell pkg-config --cflags $(PKGS) 2>/dev/null) $(EXR_CFLAGS)
FUZZ_LIB_OBJ := $(LIB_SRC:%.c=$(BUILD)/fuzzobj/%.o)
# Named only by a pattern rule, they would be deleted as intermediates after every link.
.SECONDARY: $(FUZZ_LIB_OBJ)
# Helper programs of the e2e tests (tests/tools/*.c), e.g. exrcmp.
TOOLS := $(patsubst tests/tools/%.c,$(BUILD)/tools/%,$(wildcard tests/tools/*.c))
$(BUILD)/tools/%: tests/tools/%.c $(LIB_OBJ)
	@mkdir -p $(dir $@)
	$(CC) $(ALL_CFLAGS) -o $@ $< $(LIB_OBJ) $(LDLIBS)

$(BUILD)/fuzzobj/%.o: %.c
	@mkdir -p $(dir $@)
	clang $(FUZZ_CFLAGS) -fsanitize=fuzzer-no-link,$(FUZZ_SAN) -MMD -MP -c $< -o $@
$(BUILD)/fuzz/%: tests/fuzz/%.c $(FUZZ_LIB_OBJ)
	@mkdir -p $(dir $@)
	clang $(FUZZ_CFLAGS) -fsanitize=fuzzer,$(FUZZ_SAN) -MMD -MP -o $@ $< $(FUZZ_LIB_OBJ) $(LDLIBS)
$(BUILD)/replay/%: tests/fuzz/%.c tests/fuzz/replay_main.c $(LIB_OBJ)
	@mkdir -p $(dir $@)
	$(CC) $(ALL_CFLAGS) -o $@ $< tests/fuzz/replay_main.c $(LIB_OBJ) $(LDLIBS)

FUZZERS := $(FUZZ_SRC:tests/fuzz/%.c=$(BUILD)/fuzz/%)
fuzz: $(FUZZERS)

# Every fuzz target for FUZZ_RUNS mutations after its committed corpus (tests/fuzz/bounded.sh:
# a count, not a time, and a fixed seed).  Run by `make asan` after the suite; about 40 s of
# running on two cores (fuzz_heightmap's decoders are most of it), plus the clang build.
FUZZ_RUNS ?= 5000
fuzz-runs: $(FUZZERS)
	tests/fuzz/bounded.sh $(BUILD) $(FUZZ_RUNS)

REPLAYS := $(FUZZ_SRC:tests/fuzz/%.c=$(BUILD)/replay/%)

# The benchmarks are built too (not run: tests/e2e/bench_smoke.sh runs their --smoke modes),
# so an API change that breaks one breaks the suite.
test: $(PROG) $(TESTS) $(REPLAYS) $(TOOLS) $(BENCHES)
	BUILD=$(BUILD) BIN=$(BIN) tests/run.sh

ASAN_MAKE := $(MAKE) BUILD=build-asan BIN=build-asan/bin CFLAGS="-O1 -g" HOT_CFLAGS= \
  SAN="-fsanitize=address,undefined -fno-omit-frame-pointer -fno-sanitize-recover=undefined"
# PoCL's own leaks are suppressed (tests/lsan-pocl.supp says which and why).
asan:
	LSAN_OPTIONS=suppressions=$(CURDIR)/tests/lsan-pocl.supp $(ASAN_MAKE) test
	$(ASAN_MAKE) fuzz-runs

bench: $(PROG) $(BENCHES)

# Every Debian package the build, the tests and the benchmarks use.
DEB_PKGS := build-essential pkg-config clang libinih-dev libpng-dev libsodium-dev libcmocka-dev \
            libopenexr-dev openexr zlib1g-dev libdeflate-dev ocl-icd-opencl-dev opencl-headers pocl-opencl-icd clinfo \
            iproute2 python3 python3-yaml gnuplot-nox ffmpeg libgdal-dev gdal-bin openssh-server openssh-client \
            slurm-wlm munge libmicrohttpd-dev libjansson-dev libsqlite3-dev sqlite3 chromium povray redis-server \
            libembree-dev
# The benchmarks' measuring tools (make bench-deps); their peers POV-Ray, Redis and Embree are in
# DEB_PKGS, since the tests run every benchmark's smoke mode (tests/e2e/bench_smoke.sh).
BENCH_PKGS := hyperfine linux-perf valgrind
deps:
	@missing=""; for p in $(DEB_PKGS); do dpkg-query -W -f='$${Status}' $$p 2>/dev/null | \
	  grep -q 'ok installed' || missing="$$missing $$p"; done; \
	if [ -n "$$missing" ]; then echo "installing:$$missing"; \
	  apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq $$missing; \
	else echo "all build and test packages present"; fi

bench-deps:
	@$(MAKE) --no-print-directory deps DEB_PKGS="$(BENCH_PKGS)"

# The OpenCL backend reads its kernels at run time, and the dashboard its page (web/): beside
# the executable (bin/../worker/kernels, bin/../web) in a checkout, from
# PREFIX/share/terrafarm/{kernels,web} once installed.  The kernel build also reads the C
# renderer's headers it shares (SOURCE_FILES in worker/backend_opencl.c): from the checkout's
# common/, or installed flat beside the kernels.
PREFIX ?= /usr/local
KERNEL_SHARED := common/portable.h common/render/constants.h common/render/sample_math.h \
                 common/render/trace_math.h common/render/sun_math.h common/terrain/noise_kernel.h \
                 common/terrain/grid_height.h
WEB_FILES := web/index.html web/dashboard.js web/dashboard.css web/farm.html web/farm.js web/farm.css \
             web/paint.html web/paint.js web/paint.css
install: $(PROG)
	install -D -m 755 $(PROG) $(DESTDIR)$(PREFIX)/bin/terrafarm
	install -d $(DESTDIR)$(PREFIX)/share/terrafarm/kernels $(DESTDIR)$(PREFIX)/share/terrafarm/web
	install -m 644 $(KERNELS) $(wildcard worker/kernels/*.h) $(KERNEL_SHARED) \
	  $(DESTDIR)$(PREFIX)/share/terrafarm/kernels/
	install -m 644 $(WEB_FILES) $(DESTDIR)$(PREFIX)/share/terrafarm/web/

clean:
	rm -rf build build-asan bin

-include $(shell find build build-asan -name '*.d' 2>/dev/null)
