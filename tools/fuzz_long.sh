#!/bin/sh
# The longer fuzzing run of docs/RELIABILITY.md: rounds of test/test_fuzz_{readers,live,side}.py, each round a new process
# with its own seed (CC_LOG_FUZZ_SEED=1, 2, ...) and EXAMPLES examples per test, started until MINUTES have
# passed; the inputs of a call past a bound are copied to OUT/findings, each round's output is OUT/round-N.log,
# and the examples run per test are summed at the end. Usage: tools/fuzz_long.sh [MINUTES [EXAMPLES [OUT]]]
set -u
minutes=${1:-30}
examples=${2:-150}
out=${3:-/tmp/cc_log_fuzz}
cd "$(dirname "$0")/.." || exit 1
mkdir -p "$out"
end=$(( $(date +%s) + minutes * 60 ))
round=0
failed=0
while [ "$(date +%s)" -lt "$end" ]; do
  round=$((round + 1))
  started=$(date +%s)
  CC_LOG_FUZZ_SEED=$round CC_LOG_FUZZ_EXAMPLES=$examples CC_LOG_FUZZ_FINDINGS="$out/findings" \
    nice -n 10 /usr/bin/python3 -m pytest -q -p no:cacheprovider --hypothesis-show-statistics \
    test/test_fuzz_readers.py test/test_fuzz_live.py test/test_fuzz_side.py >"$out/round-$round.log" 2>&1 || failed=$((failed + 1))
  echo "round $round: $(tail -n 1 "$out/round-$round.log") ($(( $(date +%s) - started )) s)"
done
echo "$round rounds in $(( (minutes * 60 + $(date +%s) - end) / 60 )) min, $failed with failures; examples per test:"
# "test/test_fuzz_<file>.py::test_x[p]:" then "- N passing examples, M failing examples, ..." per phase
cat "$out"/round-*.log | awk '
  /^test\/test_fuzz_(readers|live|side).py::/ { name = $1; sub(/\[.*/, "", name); sub(/:$/, "", name) }
  /during generate phase/ { generating = 1; next }
  /during (shrink|reuse|explicit|target) phase/ { generating = 0 }
  generating && /passing examples/ { examples[name] += $2 + $5 }
  END { for (name in examples) printf "  %8d %s\n", examples[name], name }' | sort -k2
