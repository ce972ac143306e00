#!/bin/sh
# gpu_pack.sh — prepares the GPU check of a session that is lent a device machine (the `device`
# tool's `run`, issue 30): copies the kernel tests, the benches, fxstreamd and the shared libraries
# they load (the device machine has NVIDIA's OpenCL driver but none of this project's packages)
# into .gpu/ (git-ignored through .git/info/exclude), for `carry: [".gpu"]` and tools/gpu_check.sh
# there. Run after `make all unit bench`, from the repo root.
set -eu
cd "$(dirname "$0")/.."
BINS="build/fxstreamd build/tests/test_flame_kernel build/tests/test_flame_behaviour build/tests/test_flame_shape
build/tests/test_flame_frames build/tests/test_energy_kernel build/tests/test_eye_kernel build/bench/bench_flame
build/bench/bench_flame_shape build/bench/bench_energy build/bench/bench_eye build/fxctl"
rm -rf .gpu
mkdir -p .gpu/bin .gpu/lib
exclude=$(git rev-parse --git-path info/exclude)
grep -qx '/.gpu/' "$exclude" 2>/dev/null || echo /.gpu/ >>"$exclude"
for b in $BINS; do
    [ -x "$b" ] || { echo "gpu_pack: $b missing (make all unit bench)" >&2; exit 1; }
    cp "$b" .gpu/bin/
done
# Every library but the C library's own (the device machine's glibc is the newer one).
ldd $BINS 2>/dev/null | awk '/=>/ {print $3}' | sort -u | grep -Ev '/lib(c|m|dl|pthread|rt)\.so' | while read -r l; do
    cp -L "$l" .gpu/lib/
done
cp tools/gpu_check.sh .gpu/
du -sh .gpu
