#!/usr/bin/env bash
# Run one command as another CPU would (scripts/cpu-variants.txt): `scripts/cpu-variant.sh
# NAME COMMAND [ARG ...]`, e.g. a survey benchmark under the AVX2 variant:
#   scripts/cpu-variant.sh avx2-1-thread .venv/bin/python benchmarks/survey.py --quick ...
# `scripts/cpu-variant.sh default ...` runs the command as it is; with no command, the
# variant's environment is printed. Dask workers and other child processes inherit it.
set -euo pipefail
here="$(cd "$(dirname "$0")" && pwd)"
name=${1:?usage: cpu-variant.sh NAME [COMMAND ...] (NAME: default or one of scripts/cpu-variants.txt)}
shift
envs=""
if [ "$name" != default ]; then
    line=$(grep -v '^#' "$here/cpu-variants.txt" | grep "^$name|" || true)
    if [ -z "$line" ]; then
        echo "error: $here/cpu-variants.txt: no variant '$name'" >&2
        exit 1
    fi
    IFS='|' read -r _ envs _ <<<"$line"
fi
if [ $# -eq 0 ]; then
    echo "$envs"
    exit 0
fi
# shellcheck disable=SC2086  # the assignments are split on purpose
exec env $envs "$@"
