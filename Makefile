# fxstream — build, run, test, bench.
#
# Sources are picked up by wildcard so adding a module, a unit test (tests/unit/test_*.c)
# or a benchmark (tests/bench/bench_*.c) needs no edit here. Everything lands in build/.
#
# run, test, bench and fuzz first install what is missing (deps), then build in a second
# make: the pkg-config flags below are read when a makefile is parsed, so only a make started
# after the install sees the packages it installed (a fresh machine needs one command).

CC      ?= cc
BUILD   := build
PKGS    := libwebsockets libcjson OpenCL libzstd hiredis
EXRLIB  := $(filter -lOpenEXRCore%,$(shell pkg-config --libs OpenEXR 2>/dev/null))
# CFLAGS/LDFLAGS are the user's (e.g. make CFLAGS="-O1 -g -fsanitize=address"); what the
# build needs regardless lives in FX_CFLAGS/FX_LDLIBS so a command line cannot drop it.
CFLAGS  ?= -O2 -g
FX_CFLAGS := -std=c11 -D_GNU_SOURCE -Wall -Wextra -Werror -MMD -MP -pthread \
             $(shell pkg-config --cflags $(PKGS) OpenEXR 2>/dev/null) -Iprotocol -Icommon -Iserver -Iclients/c -Ikernels
FX_LDLIBS := $(shell pkg-config --libs $(PKGS) 2>/dev/null) $(EXRLIB) -lm -lpthread
CC_ALL  = $(CC) $(FX_CFLAGS) $(CFLAGS)
LINK    = $(CC) $(CFLAGS) $(LDFLAGS)

# protocol/*.c (codecs shared by both sides) goes into the server and the client library.
PROTO_SRC   := $(wildcard protocol/*.c)
# common/*.c (helpers both sides own that are not the wire format: "did you mean") goes into
# the server and into the programs that use it, not into libfxclient's API.
COMMON_SRC  := $(wildcard common/*.c)
COMMON_OBJ  := $(COMMON_SRC:%.c=$(BUILD)/obj/%.o)
SERVER_SRC  := $(filter-out server/main.c,$(wildcard server/*.c server/effects/*.c)) $(PROTO_SRC) \
               $(COMMON_SRC)
SERVER_OBJ  := $(SERVER_SRC:%.c=$(BUILD)/obj/%.o) $(BUILD)/obj/gen/kernels.o
FXCTL_SRC   := clients/c/fxctl.c clients/c/fxctl_print.c clients/c/fxctl_save.c clients/c/fxctl_sub.c clients/c/png.c
FXLOAD_SRC  := $(wildcard clients/c/fxload*.c)
CLIENT_MAIN := $(FXCTL_SRC) $(FXLOAD_SRC)
# libfxclient: every other clients/c/*.c and the codecs, compiled once position-independent
# with hidden visibility into both libraries: the static one links into fxctl, fxload, the
# tests and a game plugin (a shared object itself); the shared one exports only fxclient.h's
# FXC_API (soname libfxclient.so.MAJOR, the version from fxclient.h).
CLIENT_SRC  := $(filter-out $(CLIENT_MAIN),$(wildcard clients/c/*.c)) $(PROTO_SRC)
CLIENT_OBJ  := $(CLIENT_SRC:%.c=$(BUILD)/pic/%.o)
FXC_VERSION := $(shell sed -n 's/^\#define FXC_VERSION "\(.*\)"$$/\1/p' clients/c/fxclient.h)
FXC_SOMAJOR := $(firstword $(subst ., ,$(FXC_VERSION)))
CLIENT_SO   := $(BUILD)/libfxclient.so.$(FXC_VERSION)
CLIENT_LIBS := $(shell pkg-config --libs libwebsockets libcjson libzstd 2>/dev/null) -lm -lpthread
# What make install puts in PREFIX/include/fxclient: the public API and the headers it includes.
CLIENT_HDR  := clients/c/fxclient.h protocol/fxs_frame.h protocol/fxs_bytes.h
# tests/ref/: the references and probes the tests and benchmarks link, with the tests' own
# OpenCL entry points (tests/ref/*.cl, embedded as probe_kernels_source; never in the daemon).
PROBE_KERNELS := $(wildcard tests/ref/*.cl)
REF_OBJ     := $(patsubst %.c,$(BUILD)/obj/%.o,$(wildcard tests/ref/*.c)) $(BUILD)/obj/gen/probe_kernels.o
UNIT_BIN    := $(patsubst tests/unit/%.c,$(BUILD)/tests/%,$(wildcard tests/unit/test_*.c))
BENCH_BIN   := $(patsubst tests/bench/%.c,$(BUILD)/bench/%,$(wildcard tests/bench/bench_*.c))
# tests/bench/*.c that are not bench_*.c: shared by the benchmarks (the fan-out trial), linked into each.
BENCH_OBJ   := $(patsubst %.c,$(BUILD)/obj/%.o,$(filter-out tests/bench/bench_%.c,$(wildcard tests/bench/*.c)))
FUZZ_BIN    := $(patsubst tests/fuzz/%.c,$(BUILD)/fuzz/%,$(wildcard tests/fuzz/fuzz_*.c))
# libFuzzer targets: clang with ASan/UBSan over sanitized copies of both libraries (BUILD/fz),
# which also give an ASan/UBSan daemon (BUILD/fz/fxstreamd) for the churn test.
FUZZ_CC     := clang
FUZZ_FLAGS  := -O1 -g -fsanitize=address,undefined -fno-sanitize-recover=undefined
FUZZ_SECONDS ?= 300
KERNELS     := $(wildcard kernels/*.cl)
KERNEL_LAYOUTS := $(wildcard kernels/*_layout.h)
# The browser client: npm packages from the committed lock file (npm ci), bundled by esbuild
# into clients/web/dist/ (git-ignored), which fxstreamd serves with the rest of clients/web.
WEB_SRC     := $(wildcard clients/web/src/*.js clients/web/test/*.js) clients/web/fxs_particles.js clients/web/build.mjs
WEB_OUT     := clients/web/dist/app.js
# The page decodes particles with the C decoder compiled to WebAssembly (the module
# imports nothing): clang for wasm32-wasi against Debian's wasi-libc, linked by lld's wasm-ld.
# -O3: 4-8% faster than -O2 in V8 on real flame frames (docs/particle-codec-performance.md).
WASM_CC     ?= clang
WASM_SRC    := clients/web/wasm/fxs_particles_wasm.c protocol/fxs_particles_dec.c protocol/fxs_particles_format.c \
               protocol/fxs_particles_near.c
WASM_OUT    := clients/web/dist/fxs_particles.wasm
WASM_FLAGS  := --target=wasm32-wasi --sysroot=/usr -std=c11 -O3 -msimd128 -ffp-contract=off -Wall -Wextra -Werror \
               -Iprotocol -nostartfiles -Wl,--no-entry -Wl,--strip-all
NPM_STAMP   := node_modules/.package-lock.json

.PHONY: all deps run test bench screenshots clean unit web fuzz fuzz-libs install uninstall pkgs-present
.SECONDARY: # keep object files of tests and benches between runs
all: $(BUILD)/fxstreamd $(BUILD)/fxctl $(BUILD)/fxload $(CLIENT_SO) $(WEB_OUT) $(WASM_OUT)

deps:
	@deploy/install-deps.sh
	@$(MAKE) --no-print-directory $(NPM_STAMP)

web: $(WEB_OUT) $(WASM_OUT)

# npm ci installs exactly the lock file (no network at run time: the bundle is static).
$(NPM_STAMP): package.json package-lock.json
	npm ci --no-audit --no-fund --loglevel=error
	@touch $@

$(WEB_OUT): $(WEB_SRC) $(NPM_STAMP)
	node clients/web/build.mjs

$(WASM_OUT): $(WASM_SRC) $(wildcard protocol/*.h)
	@test -e /usr/lib/wasm32-wasi/libc.a && command -v wasm-ld >/dev/null || { deploy/install-deps.sh --check; exit 1; }
	@mkdir -p $(@D)
	$(WASM_CC) $(WASM_FLAGS) $(WASM_SRC) -o $@

# The second make builds on every core unless the command line chose -j.
SUBMAKE = $(MAKE) --no-print-directory $(if $(findstring -j,$(MAKEFLAGS)),,-j$(shell nproc))

run: deps
	@$(SUBMAKE) all
	$(BUILD)/fxstreamd $(RUN_ARGS)

test: deps
	@$(SUBMAKE) all $(UNIT_BIN) $(FUZZ_BIN) $(BUILD)/lib/libclfault.so
	@tests/run.sh

# Longer fuzzing than make test's bounded run; new inputs are merged into tests/fuzz/corpus.
fuzz: deps
	@$(SUBMAKE) $(FUZZ_BIN)
	@tests/fuzz/run.sh $(FUZZ_SECONDS) merge

bench: deps
	@$(SUBMAKE) all $(BENCH_BIN)
	@tests/bench/run.sh

# README's pictures (docs/images/), all from the default streams: the page's views taken in
# headless chromium by the first-look browser test (tests/integration/web_look_check.mjs), which
# also checks them, and the Godot demo under Xvfb (tools/screenshot_godot.sh).
screenshots: deps
	@deploy/install-deps.sh --screenshots
	@$(SUBMAKE) all
	@mkdir -p docs/images
	@tests/integration/test_web_look.sh --shots $(CURDIR)/docs/images
	@tools/screenshot_godot.sh docs/images/godot-demo.png

unit: $(UNIT_BIN)

# make install [PREFIX=/usr/local] [DESTDIR=...] [SYSCONFDIR=PREFIX/etc]: the three programs,
# libfxclient (shared and static, its headers in PREFIX/include/fxclient, fxclient.pc), the
# web client (as the daemon serves it: the pages and the esbuild bundle, without its
# sources), the systemd unit and an example configuration that points the daemon there.
# Kernels are embedded in fxstreamd, nothing else to install. An existing config is kept.
# Paths in deploy/fxstreamd.service and deploy/fxstreamd.json are written for /usr/local.
# Installed by root without DESTDIR, ldconfig then finds the new shared library.
PREFIX     ?= /usr/local
BINDIR     ?= $(PREFIX)/bin
LIBDIR     ?= $(PREFIX)/lib
INCLUDEDIR ?= $(PREFIX)/include
PKGCONFIGDIR ?= $(LIBDIR)/pkgconfig
SYSCONFDIR ?= $(PREFIX)/etc
FXDATADIR  ?= $(PREFIX)/share/fxstream
DOCDIR     ?= $(PREFIX)/share/doc/fxstream
UNITDIR    ?= $(PREFIX)/lib/systemd/system
WEB_FILES  := $(wildcard clients/web/*.html clients/web/*.js clients/web/*.css)
FX_PATHS   := -e 's|/usr/local/bin|$(BINDIR)|g' -e 's|/usr/local/etc|$(SYSCONFDIR)|g' \
              -e 's|/usr/local/share/fxstream|$(FXDATADIR)|g' -e 's|/usr/local/share/doc/fxstream|$(DOCDIR)|g'

install: all
	install -d $(DESTDIR)$(BINDIR) $(DESTDIR)$(FXDATADIR)/web $(DESTDIR)$(SYSCONFDIR)/fxstream \
	    $(DESTDIR)$(UNITDIR) $(DESTDIR)$(DOCDIR) $(DESTDIR)$(LIBDIR) $(DESTDIR)$(INCLUDEDIR)/fxclient \
	    $(DESTDIR)$(PKGCONFIGDIR)
	install -m 0755 $(BUILD)/fxstreamd $(BUILD)/fxctl $(BUILD)/fxload $(DESTDIR)$(BINDIR)/
	install -m 0755 $(CLIENT_SO) $(DESTDIR)$(LIBDIR)/
	ln -sf libfxclient.so.$(FXC_VERSION) $(DESTDIR)$(LIBDIR)/libfxclient.so.$(FXC_SOMAJOR)
	ln -sf libfxclient.so.$(FXC_SOMAJOR) $(DESTDIR)$(LIBDIR)/libfxclient.so
	install -m 0644 $(BUILD)/libfxclient.a $(DESTDIR)$(LIBDIR)/
	install -m 0644 $(CLIENT_HDR) $(DESTDIR)$(INCLUDEDIR)/fxclient/
	sed -e 's|@VERSION@|$(FXC_VERSION)|' -e 's|@LIBDIR@|$(LIBDIR)|' -e 's|@INCLUDEDIR@|$(INCLUDEDIR)|' \
	    clients/c/fxclient.pc.in > $(DESTDIR)$(PKGCONFIGDIR)/fxclient.pc
	@if [ -z "$(DESTDIR)" ] && [ "$$(id -u)" -eq 0 ] && command -v ldconfig >/dev/null; then ldconfig; fi
	install -m 0644 $(WEB_FILES) $(DESTDIR)$(FXDATADIR)/web/
	cp -R clients/web/dist $(DESTDIR)$(FXDATADIR)/web/ && rm -f $(DESTDIR)$(FXDATADIR)/web/dist/app-test.js && \
	    chmod -R u=rwX,go=rX $(DESTDIR)$(FXDATADIR)/web/dist
	sed $(FX_PATHS) deploy/fxstreamd.service > $(DESTDIR)$(UNITDIR)/fxstreamd.service
	sed $(FX_PATHS) deploy/fxstreamd.json > $(DESTDIR)$(DOCDIR)/fxstreamd.json
	test -e $(DESTDIR)$(SYSCONFDIR)/fxstream/fxstreamd.json || \
	    install -m 0644 $(DESTDIR)$(DOCDIR)/fxstreamd.json $(DESTDIR)$(SYSCONFDIR)/fxstream/fxstreamd.json
	install -m 0644 README.md deploy/tokens.env.example deploy/nginx/fxstream.conf protocol/PROTOCOL.md \
	    $(DESTDIR)$(DOCDIR)/
	install -m 0644 deploy/README.md $(DESTDIR)$(DOCDIR)/DEPLOY.md
	chmod 0644 $(DESTDIR)$(UNITDIR)/fxstreamd.service

# Keeps SYSCONFDIR/fxstream (the configuration and tokens are the operator's).
uninstall:
	rm -f $(DESTDIR)$(BINDIR)/fxstreamd $(DESTDIR)$(BINDIR)/fxctl $(DESTDIR)$(BINDIR)/fxload \
	    $(DESTDIR)$(UNITDIR)/fxstreamd.service $(DESTDIR)$(LIBDIR)/libfxclient.so* $(DESTDIR)$(LIBDIR)/libfxclient.a \
	    $(DESTDIR)$(PKGCONFIGDIR)/fxclient.pc
	rm -rf $(DESTDIR)$(FXDATADIR) $(DESTDIR)$(DOCDIR) $(DESTDIR)$(INCLUDEDIR)/fxclient

clean:
	rm -rf $(BUILD) clients/web/dist

$(BUILD)/gen/kernels.c: $(KERNELS) $(KERNEL_LAYOUTS) tools/embed_kernels.sh
	@mkdir -p $(@D)
	tools/embed_kernels.sh $(KERNELS) > $@

$(BUILD)/gen/probe_kernels.c: $(PROBE_KERNELS) tools/embed_kernels.sh
	@mkdir -p $(@D)
	tools/embed_kernels.sh -f probe_kernels_source $(PROBE_KERNELS) > $@

$(BUILD)/obj/gen/%.o: $(BUILD)/gen/%.c
	@mkdir -p $(@D)
	$(CC_ALL) -c $< -o $@

$(BUILD)/obj/%.o: %.c | pkgs-present
	@mkdir -p $(@D)
	$(CC_ALL) -c $< -o $@

$(BUILD)/pic/%.o: %.c | pkgs-present
	@mkdir -p $(@D)
	$(CC_ALL) -fPIC -fvisibility=hidden -c $< -o $@

# make all (or a single target) does not install: name what is missing instead of a compiler error.
pkgs-present:
	@pkg-config --exists $(PKGS) OpenEXR || { deploy/install-deps.sh --check; exit 1; }

$(BUILD)/libfxserver.a: $(SERVER_OBJ)
	@rm -f $@
	ar rcs $@ $^

$(BUILD)/libfxclient.a: $(CLIENT_OBJ)
	@rm -f $@
	ar rcs $@ $^

$(CLIENT_SO): $(CLIENT_OBJ)
	$(LINK) -shared -Wl,-soname,libfxclient.so.$(FXC_SOMAJOR) -Wl,--no-undefined $^ -o $@ $(CLIENT_LIBS)

$(BUILD)/fxstreamd: $(BUILD)/obj/server/main.o $(BUILD)/libfxserver.a
	$(LINK) $^ -o $@ $(FX_LDLIBS) $(LDLIBS)

# fxctl's "did you mean" for commands (common/suggest.c) and its EXR files of engine-encoded
# textures (common/exr.c) are what the daemon uses too.
$(BUILD)/fxctl: $(FXCTL_SRC:%.c=$(BUILD)/obj/%.o) $(COMMON_OBJ) $(BUILD)/libfxclient.a
	$(LINK) $^ -o $@ $(FX_LDLIBS) $(LDLIBS)

$(BUILD)/fxload: $(FXLOAD_SRC:%.c=$(BUILD)/obj/%.o) $(BUILD)/libfxclient.a
	$(LINK) $^ -o $@ $(FX_LDLIBS) $(LDLIBS)

$(BUILD)/tests/%: $(BUILD)/obj/tests/unit/%.o $(REF_OBJ) $(BUILD)/libfxserver.a $(BUILD)/libfxclient.a
	@mkdir -p $(@D)
	$(LINK) $^ -o $@ $(FX_LDLIBS) $(LDLIBS)

$(BUILD)/bench/%: $(BUILD)/obj/tests/bench/%.o $(BENCH_OBJ) $(REF_OBJ) $(BUILD)/libfxserver.a $(BUILD)/libfxclient.a
	@mkdir -p $(@D)
	$(LINK) $^ -o $@ $(FX_LDLIBS) $(LDLIBS)

# OpenCL fault injection for tests/integration/test_cl_faults.py (LD_PRELOAD, FXS_CLFAULT).
$(BUILD)/lib/libclfault.so: tests/faults/clfault.c
	@mkdir -p $(@D)
	$(CC) $(FX_CFLAGS) $(CFLAGS) -fPIC -shared $< -o $@ -ldl

fuzz-libs:
	@$(MAKE) --no-print-directory BUILD=$(BUILD)/fz CC=$(FUZZ_CC) CFLAGS="$(FUZZ_FLAGS) -fsanitize=fuzzer-no-link" \
	    $(BUILD)/fz/libfxserver.a $(BUILD)/fz/libfxclient.a $(BUILD)/fz/fxstreamd

$(BUILD)/fuzz/%: tests/fuzz/%.c fuzz-libs
	@mkdir -p $(@D)
	$(FUZZ_CC) $(FX_CFLAGS) $(FUZZ_FLAGS) -fsanitize=fuzzer $< $(BUILD)/fz/libfxserver.a $(BUILD)/fz/libfxclient.a \
	    -o $@ $(FX_LDLIBS)

-include $(shell find $(BUILD)/obj $(BUILD)/pic -name '*.d' 2>/dev/null)
