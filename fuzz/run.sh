#!/usr/bin/env bash
# Runs one fuzz target for a while: bash fuzz/run.sh TARGET SECONDS [more libFuzzer flags].
# Starts from the committed seeds (fuzz/seeds/TARGET); what it finds goes to fuzz/corpus/TARGET
# and crashes to fuzz/artifacts/TARGET (both ignored by git). Each crash fixed is kept in
# fuzz/regressions/TARGET and replayed by `bash fuzz/run.sh --replay`.
set -euo pipefail
cd "$(dirname "$0")/.."
source .ci/env
cd fuzz
if [ "${1:-}" = "--replay" ]; then
  for dir in regressions/*/; do
    t=$(basename "$dir")
    files=("$dir"*)
    [ -e "${files[0]}" ] || continue
    cargo +nightly fuzz run "$t" -O "${files[@]}" -- -runs=1
  done
  exit 0
fi
target=$1
secs=$2
shift 2
mkdir -p "corpus/$target" "artifacts/$target" "seeds/$target"
exec cargo +nightly fuzz run "$target" -O "corpus/$target" "seeds/$target" -- \
  -max_total_time="$secs" -timeout=20 -rss_limit_mb=3000 -max_len=65536 \
  -artifact_prefix="artifacts/$target/" -print_final_stats=1 "$@"
