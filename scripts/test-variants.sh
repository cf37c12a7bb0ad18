#!/usr/bin/env bash
# The numeric tests under the CPU variants another machine brings (docs/determinism.md):
# what numpy, OpenBLAS, OpenCV, numba and the ray caster pick at run time on an Intel Xeon, on
# an AVX2 machine, on an old CPU and with other thread counts, imitated on this one
# (scripts/cpu-variants.txt). Run it (`make test-variants`) before
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
# the variants, one per line: NAME|ENVIRONMENT|PYTEST OPTIONS (shared with cpu-variant.sh)
mapfile -t variants < <(grep -v '^#' scripts/cpu-variants.txt | grep '|')
not_numeric=(
    --ignore=tests/badinput --ignore=tests/test_fuzz_parsers.py
    --ignore=tests/test_architecture.py --ignore=tests/test_interrupt.py
    --ignore=tests/test_safety.py --ignore=tests/test_outputs_overwrite.py
)
[ $# -gt 0 ] && not_numeric=("$@")  # or the tests given on the command line
failed=0
for v in "${variants[@]}"; do
    IFS='|' read -r name envs opts <<<"$v"
    start=$(date +%s)
    env $envs "$PY" -m pytest -q -n "$WORKERS" --dist loadfile -p no:cacheprovider $opts \
        "${not_numeric[@]}" >"$LOGS/$name.log" 2>&1
    rc=$?
    summary=$(tail -n 1 "$LOGS/$name.log")
    printf '%-18s exit %d in %4d s: %s\n' "$name" "$rc" "$(($(date +%s) - start))" "$summary"
    [ $rc -eq 0 ] || failed=1
done
exit $failed
