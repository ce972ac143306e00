#!/bin/sh
# gpu_check.sh — the device check of issue 30, run on the lent GPU machine from the repo root with
# .gpu/ carried (tools/gpu_pack.sh made it here):
#   run(command: "sh .gpu/gpu_check.sh", carry: [".gpu"], timeout_s: 540)
# Finds NVIDIA's OpenCL driver, runs every kernel test on it (FX_OCL_DEVICE=gpu), then the flame,
# energy and eye benches on it, and writes each one's output to $OUT (at most 8 files come back):
# env.txt (device, driver), tests.txt, bench_flame.txt, bench_other.txt. Each step has a time
# limit so that one hung kernel does not take the session's device time.
set -u
OUT=${OUT:-/tmp/gpu_out}
mkdir -p "$OUT"
export LD_LIBRARY_PATH="$PWD/.gpu/lib${LD_LIBRARY_PATH:+:$LD_LIBRARY_PATH}"
# NVIDIA's ICD: the loader (carried) reads /etc/OpenCL/vendors; name the driver when none is listed.
if ! ls /etc/OpenCL/vendors/*.icd >/dev/null 2>&1; then
    lib=$(find / -name 'libnvidia-opencl.so*' -not -path '/proc/*' 2>/dev/null | head -n 1)
    if [ -n "$lib" ]; then mkdir -p /etc/OpenCL/vendors && echo "$lib" >/etc/OpenCL/vendors/nvidia.icd; fi
fi
B=.gpu/bin
{
    nvidia-smi --query-gpu=name,driver_version,memory.total --format=csv 2>&1
    cat /etc/OpenCL/vendors/*.icd 2>&1
    nproc
} >"$OUT/env.txt"
: >"$OUT/tests.txt"
for t in test_flame_kernel test_flame_behaviour test_flame_frames test_flame_shape test_energy_kernel test_eye_kernel; do
    echo "== $t" >>"$OUT/tests.txt"
    FX_OCL_DEVICE=gpu timeout 120 "$B/$t" >>"$OUT/tests.txt" 2>&1
    echo "== $t exit $?" >>"$OUT/tests.txt"
done
timeout 180 "$B/bench_flame" gpu >"$OUT/bench_flame.txt" 2>&1
echo "exit $?" >>"$OUT/bench_flame.txt"
{
    FX_OCL_DEVICE=gpu timeout 60 "$B/bench_energy"
    timeout 60 "$B/bench_eye"
    timeout 120 "$B/bench_flame_shape" gpu
} >"$OUT/bench_other.txt" 2>&1
grep -E "passed|failed|exit" "$OUT/tests.txt" | tail -n 20
tail -n 15 "$OUT/bench_flame.txt"
