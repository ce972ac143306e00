#!/bin/sh
# gpu_check.sh — the device check of issue 30, run on the lent GPU machine from the repo root with
# .gpu/ carried (tools/gpu_pack.sh made it here):
#   run(command: "sh .gpu/gpu_check.sh", carry: [".gpu"], timeout_s: 540)
# Finds NVIDIA's OpenCL driver, runs every kernel test on it (FX_OCL_DEVICE=gpu), then bench_flame
# (lattice blocks up to ~2 M particles, the CPU's serial passes beside the wide ones, the default
# scene and the `large` preset paced at 30 fps), the shape of the default and `large` flames, and
# fxstreamd with one `large` stream and one fxctl subscriber for 20 s (/metrics read at the end).
# Output under $OUT: env.txt, tests.txt, bench_flame.txt, shape.txt, daemon.txt. Each step has a
# time limit so that one hung kernel does not take the session's device time. GPU_CHECK_QUICK=1
# (in the command) skips the tests and shapes and benches only the `large` preset: a second look
# after a host-side change.
set -u
OUT=${OUT:-/tmp/gpu_out}
mkdir -p "$OUT"
export LD_LIBRARY_PATH="$PWD/.gpu/lib${LD_LIBRARY_PATH:+:$LD_LIBRARY_PATH}"
# NVIDIA's ICD: the loader (carried) reads /etc/OpenCL/vendors; name the driver when no file there
# does (the machine may list only PoCL's).
if ! grep -qi nvidia /etc/OpenCL/vendors/*.icd 2>/dev/null; then
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
[ -n "${GPU_CHECK_QUICK:-}" ] || for t in test_flame_kernel test_flame_behaviour test_flame_frames test_flame_shape test_energy_kernel test_eye_kernel; do
    echo "== $t" >>"$OUT/tests.txt"
    FX_OCL_DEVICE=gpu timeout 120 "$B/$t" >>"$OUT/tests.txt" 2>&1
    echo "== $t exit $?" >>"$OUT/tests.txt"
done
BENCH_FLAME_ONLY=${GPU_CHECK_QUICK:+large} timeout 200 "$B/bench_flame" gpu >"$OUT/bench_flame.txt" 2>&1
echo "exit $?" >>"$OUT/bench_flame.txt"
[ -n "${GPU_CHECK_QUICK:-}" ] || for c in default large; do
    BENCH_SHAPE_ONLY=$c timeout 90 "$B/bench_flame_shape" gpu >>"$OUT/shape.txt" 2>&1
    echo "$c exit $?" >>"$OUT/shape.txt"
done

# The daemon: one `large` stream, its preset loaded, 5 s to settle, one subscriber for 600 frames.
P=17681
U=ws://127.0.0.1:$P
echo '{"streams":[{"stream":"large","effect":"flame"}],"log_level":"warn"}' >/tmp/fx_large.json
"$B/fxstreamd" --port $P --config /tmp/fx_large.json --device gpu >/tmp/fx_daemon.log 2>&1 &
D=$!
sleep 3
{
    timeout 10 "$B/fxctl" --url $U preset load large large 2>&1
    sleep 5
    timeout 60 "$B/fxctl" --url $U subscribe large --frames 600 >/tmp/fx_sub.txt 2>&1
    echo "subscribe exit $? lines $(wc -l </tmp/fx_sub.txt)"
    head -c 600 /tmp/fx_sub.txt
    echo
    # frames a second from server_time_us, bytes and latency of the frames
    awk -F'[:,]' '/"seq"/ { for (i = 1; i < NF; i++) { if ($i ~ /server_time_us/) t = $(i + 1); if ($i ~ /latency_ms/) l += $(i + 1);
        if ($i ~ /payload_bytes/) b += $(i + 1); if ($i ~ /"count"/) c += $(i + 1) }
        if (!t0) t0 = t; n++ } END { if (n > 1) printf "frames %d in %.2f s: %.1f fps, mean %.0f particles, %.0f kB, latency %.1f ms\n",
        n, (t - t0) / 1e6, (n - 1) / ((t - t0) / 1e6), c / n, b / n / 1024, l / n }' /tmp/fx_sub.txt
    bash -c "exec 3<>/dev/tcp/127.0.0.1/$P; printf 'GET /metrics HTTP/1.0\r\nHost: 127.0.0.1\r\n\r\n' >&3; cat <&3" 2>&1 |
        grep -E 'stream="large"|fxs_kernel_seconds_total' | grep -vE '_bucket' | head -n 60
} >"$OUT/daemon.txt" 2>&1
kill $D 2>/dev/null
wait $D 2>/dev/null
tail -n 20 /tmp/fx_daemon.log >>"$OUT/daemon.txt"

grep -E "passed|failed|exit" "$OUT/tests.txt" | tail -n 20
grep -E "M particle-steps|busy|real-time factor|encoding" "$OUT/bench_flame.txt"
cat "$OUT/shape.txt"
grep -E "^frames|realtime|delivered|exit" "$OUT/daemon.txt"
