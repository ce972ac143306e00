#!/bin/sh
# test_includes.sh — the layering of the C tree (tools/check_includes.py states the rules): no
# #include cycles among the modules of server/, protocol/, common/ and clients/c/, each layer
# includes only the layers below it (the clients never server/), and a header declares only
# what its own .c defines. First the repository, then scratch trees with one planted fault
# each, which the checker must name and fail on (so a checker that sees nothing fails here).
# Last line: "test_includes: N passed, M failed".
set -u
cd "$(dirname "$0")/../.." || exit 2
SUITE=test_includes
. tests/integration/cli_lib.sh

CHECK=tools/check_includes.py

# includes ROOT: runs the checker on ROOT (the repository when empty); $rc, $tmp/out, $tmp/err.
includes() {
    /usr/bin/python3 "$CHECK" ${1:+"$1"} >"$tmp/out" 2>"$tmp/err"
    rc=$?
}

# plant TREE FILE TEXT: writes TEXT (printf format) into TREE/FILE.
plant() {
    mkdir -p "$(dirname "$1/$2")"
    # shellcheck disable=SC2059
    printf "$3" >"$1/$2"
}

includes
check "the repository: no cycles, layers kept, each header declares its own module's functions" 0 \
    "check_includes: 3 passed, 0 failed"

t=$tmp/clean
plant "$t" server/hub.h '#include "fxs_frame.h"\nint hub_run(void);\n'
plant "$t" server/hub.c '#include "hub.h"\nint hub_run(void) { return 0; }\n'
plant "$t" protocol/fxs_frame.h 'struct fxs_header { int kind; };\n'
plant "$t" clients/c/fxctl.c '#include "fxs_frame.h"\n#include "suggest.h"\n'
plant "$t" common/suggest.h 'int suggest(const char *w);\n'
plant "$t" common/suggest.c '#include "suggest.h"\nint suggest(const char *w)\n{\n    return w != 0;\n}\n'
includes "$t"
check "a small clean tree passes" 0 "check_includes: 3 passed, 0 failed"

t=$tmp/cycle
plant "$t" clients/c/fxload_run.h '#include "fxload_set.h"\n'
plant "$t" clients/c/fxload_set.c '#include "fxload_run.h"\n'
plant "$t" clients/c/fxload_set.h 'struct ld;\n'
includes "$t"
check "an include cycle in clients/c is named" 1 \
    "include cycle: clients/c/fxload_run <-> clients/c/fxload_set"

t=$tmp/layers
plant "$t" server/suggest.h 'struct suggest;\n'
plant "$t" clients/c/fxctl.c '#include "suggest.h"\n'
plant "$t" protocol/fxs_lut.c '#include "fxctl_print.h"\n'
plant "$t" clients/c/fxctl_print.h 'struct x;\n'
plant "$t" clients/c/fxload_run.c '#include "fxctl_print.h"\n'
includes "$t"
check "fxctl including a server header is a layer fault" 1 \
    "layers: clients/c/fxctl (fxctl) includes server/suggest (server)"
check "protocol/ including a client header is a layer fault" 1 \
    "layers: protocol/fxs_lut (protocol) includes clients/c/fxctl_print (fxctl)"
check "fxload including fxctl's header is a layer fault" 1 \
    "layers: clients/c/fxload_run (fxload) includes clients/c/fxctl_print (fxctl)"
check "three layer faults, one failed check" 1 "check_includes: 2 passed, 1 failed"

t=$tmp/declarations
plant "$t" clients/c/fxload.h 'struct ld;\n/* the run */\nint ld_run(struct ld *ld);\nvoid ld_main(void);\n'
plant "$t" clients/c/fxload.c '#include "fxload.h"\nvoid ld_main(void)\n{\n}\n'
plant "$t" clients/c/fxload_run.c '#include "fxload.h"\nint ld_run(struct ld *ld)\n{\n    return ld != 0;\n}\n'
includes "$t"
check "a header declaring another file's function is named" 1 \
    "declarations: clients/c/fxload.h declares what clients/c/fxload.c does not define: ld_run$"

summary
