# fxstream — build, run, test, bench.
#
# Sources are picked up by wildcard so adding a module, a unit test (tests/unit/test_*.c)
# or a benchmark (tests/bench/bench_*.c) needs no edit here. Everything lands in build/.

CC      ?= cc
BUILD   := build
PKGS    := libwebsockets libcjson OpenCL libzstd
EXRLIB  := $(filter -lOpenEXRCore%,$(shell pkg-config --libs OpenEXR 2>/dev/null))
# CFLAGS/LDFLAGS are the user's (e.g. make CFLAGS="-O1 -g -fsanitize=address"); what the
# build needs regardless lives in FX_CFLAGS/FX_LDLIBS so a command line cannot drop it.
CFLAGS  ?= -O2 -g
FX_CFLAGS := -std=c11 -D_GNU_SOURCE -Wall -Wextra -Werror -MMD -MP -pthread \
             $(shell pkg-config --cflags $(PKGS) OpenEXR 2>/dev/null) -Iprotocol -Iserver -Iclients/c
FX_LDLIBS := $(shell pkg-config --libs $(PKGS) 2>/dev/null) $(EXRLIB) -lm -lpthread
CC_ALL  = $(CC) $(FX_CFLAGS) $(CFLAGS)
LINK    = $(CC) $(CFLAGS) $(LDFLAGS)

# protocol/*.c (codecs shared by both sides) goes into the server and the client library.
PROTO_SRC   := $(wildcard protocol/*.c)
SERVER_SRC  := $(filter-out server/main.c,$(wildcard server/*.c server/effects/*.c server/codec/*.c)) $(PROTO_SRC)
SERVER_OBJ  := $(SERVER_SRC:%.c=$(BUILD)/obj/%.o) $(BUILD)/obj/gen/kernels.o
CLIENT_MAIN := clients/c/fxctl.c clients/c/fxload.c
CLIENT_SRC  := $(filter-out $(CLIENT_MAIN),$(wildcard clients/c/*.c)) $(PROTO_SRC)
CLIENT_OBJ  := $(CLIENT_SRC:%.c=$(BUILD)/obj/%.o)
REF_OBJ     := $(patsubst %.c,$(BUILD)/obj/%.o,$(wildcard tests/ref/*.c))
UNIT_BIN    := $(patsubst tests/unit/%.c,$(BUILD)/tests/%,$(wildcard tests/unit/test_*.c))
BENCH_BIN   := $(patsubst tests/bench/%.c,$(BUILD)/bench/%,$(wildcard tests/bench/bench_*.c))
FUZZ_BIN    := $(patsubst tests/fuzz/%.c,$(BUILD)/fuzz/%,$(wildcard tests/fuzz/fuzz_*.c))
# libFuzzer targets: clang with ASan/UBSan over sanitized copies of both libraries (BUILD/fz),
# which also give an ASan/UBSan daemon (BUILD/fz/fxstreamd) for the churn test.
FUZZ_CC     := clang
FUZZ_FLAGS  := -O1 -g -fsanitize=address,undefined -fno-sanitize-recover=undefined
FUZZ_SECONDS ?= 300
KERNELS     := $(wildcard kernels/*.cl)

.PHONY: all deps run test bench clean unit fuzz fuzz-libs
.SECONDARY: # keep object files of tests and benches between runs
all: $(BUILD)/fxstreamd $(BUILD)/fxctl $(BUILD)/fxload

deps:
	@deploy/install-deps.sh

run: deps all
	$(BUILD)/fxstreamd $(RUN_ARGS)

test: deps all $(UNIT_BIN) $(FUZZ_BIN)
	@tests/run.sh

# Longer fuzzing than make test's bounded run; new inputs are merged into tests/fuzz/corpus.
fuzz: deps $(FUZZ_BIN)
	@tests/fuzz/run.sh $(FUZZ_SECONDS) merge

bench: deps all $(BENCH_BIN)
	@tests/bench/run.sh

unit: $(UNIT_BIN)

clean:
	rm -rf $(BUILD)

$(BUILD)/gen/kernels.c: $(KERNELS) tools/embed_kernels.sh
	@mkdir -p $(@D)
	tools/embed_kernels.sh $(KERNELS) > $@

$(BUILD)/obj/gen/%.o: $(BUILD)/gen/%.c
	@mkdir -p $(@D)
	$(CC_ALL) -c $< -o $@

$(BUILD)/obj/%.o: %.c
	@mkdir -p $(@D)
	$(CC_ALL) -c $< -o $@

$(BUILD)/libfxserver.a: $(SERVER_OBJ)
	@rm -f $@
	ar rcs $@ $^

$(BUILD)/libfxclient.a: $(CLIENT_OBJ)
	@rm -f $@
	ar rcs $@ $^

$(BUILD)/fxstreamd: $(BUILD)/obj/server/main.o $(BUILD)/libfxserver.a
	$(LINK) $^ -o $@ $(FX_LDLIBS) $(LDLIBS)

$(BUILD)/fxctl: $(BUILD)/obj/clients/c/fxctl.o $(BUILD)/libfxclient.a
	$(LINK) $^ -o $@ $(FX_LDLIBS) $(LDLIBS)

$(BUILD)/fxload: $(BUILD)/obj/clients/c/fxload.o $(BUILD)/libfxclient.a
	$(LINK) $^ -o $@ $(FX_LDLIBS) $(LDLIBS)

$(BUILD)/tests/%: $(BUILD)/obj/tests/unit/%.o $(REF_OBJ) $(BUILD)/libfxserver.a $(BUILD)/libfxclient.a
	@mkdir -p $(@D)
	$(LINK) $^ -o $@ $(FX_LDLIBS) $(LDLIBS)

$(BUILD)/bench/%: $(BUILD)/obj/tests/bench/%.o $(REF_OBJ) $(BUILD)/libfxserver.a $(BUILD)/libfxclient.a
	@mkdir -p $(@D)
	$(LINK) $^ -o $@ $(FX_LDLIBS) $(LDLIBS)

fuzz-libs:
	@$(MAKE) --no-print-directory BUILD=$(BUILD)/fz CC=$(FUZZ_CC) CFLAGS="$(FUZZ_FLAGS) -fsanitize=fuzzer-no-link" \
	    $(BUILD)/fz/libfxserver.a $(BUILD)/fz/libfxclient.a $(BUILD)/fz/fxstreamd

$(BUILD)/fuzz/%: tests/fuzz/%.c fuzz-libs
	@mkdir -p $(@D)
	$(FUZZ_CC) $(FX_CFLAGS) $(FUZZ_FLAGS) -fsanitize=fuzzer $< $(BUILD)/fz/libfxserver.a $(BUILD)/fz/libfxclient.a \
	    -o $@ $(FX_LDLIBS)

-include $(shell find $(BUILD)/obj -name '*.d' 2>/dev/null)
