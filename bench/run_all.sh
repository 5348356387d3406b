#!/bin/bash
# Run every benchmark once and keep its output in $OUT (default /tmp/cc_log_bench_out) (docs/RESULTS.md quotes these outputs).
#   cd /work/main && bash bench/run_all.sh [--quick]
# Needs the workspace sourced (done here) and /usr/bin/python3 (the one that sees ROS).
set -e
cd "$(dirname "$0")/.."
source .catkin_ws/devel/setup.bash
export PATH=/usr/bin:$PATH
OUT=${OUT:-/tmp/cc_log_bench_out}
mkdir -p "$OUT"
for script in detection_real detection_sim injected_husky storage cost_offline training cost_live memory_live context_track heavy_sensors; do
    args="$*"
    if [ "$script" = detection_real ]; then args=""; fi   # the detection engineer's script has no --quick
    echo "== bench/$script.py $args"
    python3 "bench/$script.py" $args | tee "$OUT/$script.txt"
done
