#!/bin/bash
# Run the commands of docs/RESULTS.md's summary once and keep each output in $OUT (default /tmp/cc_log_bench_out);
# bench/README.md says which question each answers.
#   cd <tree> && bash bench/run_all.sh [--quick]
# Needs the workspace sourced (done here) and /usr/bin/python3 (the one that sees ROS).
set -e
cd "$(dirname "$0")/.."
source .catkin_ws/devel/setup.bash
export PATH=/usr/bin:$PATH
OUT=${OUT:-/tmp/cc_log_bench_out}
mkdir -p "$OUT"
for command in "detection.py real" "detection.py sim" "detection.py injected" storage.py cost_offline.py training.py \
               cost_live.py memory_live.py context_track.py heavy_sensors.py; do
    args="$*"
    if [ "$command" = "detection.py real" ]; then args=""; fi   # it has no --quick
    echo "== bench/$command $args"
    python3 bench/$command $args | tee "$OUT/$(echo "$command" | tr ' ' _ | sed 's/\.py//').txt"
done
