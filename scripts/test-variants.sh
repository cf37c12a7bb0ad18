#!/usr/bin/env bash
# The numeric tests under the CPU variants another machine brings (docs/determinism.md):
# what numpy, OpenBLAS, numba and the ray caster pick at run time on an Intel Xeon, on an old
# CPU and with other thread counts, imitated on this one. Run it (`make test-variants`) before
# resolving an issue that adds numeric tests: a test that passes here and fails under a variant
# asserts one machine's last bits, not a property of the method.
#
# Each variant runs the suite but for its non-numeric files (bad input, parsers, the code's
# structure, signals), in TEST_WORKERS processes. Prints one line per variant and exits non-zero
# when any variant fails; the logs are kept in $VARIANT_LOGS (default .variant-logs/).
set -uo pipefail
cd "$(dirname "$0")/.."
PY=${PY:-.venv/bin/python}
WORKERS=${TEST_WORKERS:-2}
LOGS=${VARIANT_LOGS:-.variant-logs}
mkdir -p "$LOGS"
# numpy refuses to disable its baseline (X86_V2), so its lowest level is SSE4.2 + POPCNT
NO_AVX512="X86_V4 AVX512_ICL AVX512_SPR"
NO_AVX2="X86_V3 X86_V4 AVX512_ICL AVX512_SPR"
variants=(
    # an AVX-512 Intel Xeon: OpenBLAS's SkylakeX kernels, numba for Skylake-SP, rays +1 ulp
    "xeon|OPENBLAS_CORETYPE=SkylakeX NUMBA_CPU_NAME=skylake-avx512 NPY_DISABLE_CPU_FEATURES=AVX512_ICL|--ray-ulp=1"
    # an AVX2 machine without AVX-512, everything on one thread, rays -1 ulp
    "avx2-1-thread|OPENBLAS_CORETYPE=Haswell NUMBA_CPU_NAME=haswell NPY_DISABLE_CPU_FEATURES=${NO_AVX512// /,} NUMBA_NUM_THREADS=1 OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1|--ray-ulp=-1"
    # the lowest common denominator: SSE only, numba for a generic x86-64, four threads, rays +2 ulp
    "generic-4-threads|OPENBLAS_CORETYPE=Sandybridge NUMBA_CPU_NAME=generic NPY_DISABLE_CPU_FEATURES=${NO_AVX2// /,} NUMBA_NUM_THREADS=4 OMP_NUM_THREADS=4|--ray-ulp=2"
)
not_numeric=(
    --ignore=tests/badinput --ignore=tests/test_fuzz_parsers.py
    --ignore=tests/test_architecture.py --ignore=tests/test_interrupt.py
    --ignore=tests/test_safety.py --ignore=tests/test_outputs_overwrite.py
)
[ $# -gt 0 ] && not_numeric=("$@")  # or the tests given on the command line
failed=0
for v in "${variants[@]}"; do
    IFS='|' read -r name envs opts <<<"$v"
    # NPY_DISABLE_CPU_FEATURES takes a space- or comma-separated list
    start=$(date +%s)
    env $envs "$PY" -m pytest -q -n "$WORKERS" --dist loadfile -p no:cacheprovider $opts \
        "${not_numeric[@]}" >"$LOGS/$name.log" 2>&1
    rc=$?
    summary=$(tail -n 1 "$LOGS/$name.log")
    printf '%-18s exit %d in %4d s: %s\n' "$name" "$rc" "$(($(date +%s) - start))" "$summary"
    [ $rc -eq 0 ] || failed=1
done
exit $failed
