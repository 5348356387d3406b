#!/usr/bin/env bash
# Set up cc_log on this machine and run one of its jobs.
#
#   ./dev.sh demo     install what is missing, build, run the demo
#   ./dev.sh test     install what is missing, build, run every test (unit tests and rostests)
#   ./dev.sh setup    install what is missing and build only
#
# Setup installs the Debian packages cc_log needs when they are missing (quick when they are present) and
# builds a catkin workspace in .catkin_ws/ whose src/cc_log points at this repository (entry by entry). Afterwards
# `source .catkin_ws/devel/setup.bash` makes rosrun, roslaunch and rostest find cc_log.
set -euo pipefail

ROOT=$(cd "$(dirname "$(readlink -f "${BASH_SOURCE[0]}")")" && pwd)
WS="$ROOT/.catkin_ws"
# Debian's ROS lives in the system interpreter; another python3 first on PATH cannot see it.
export PATH="/usr/bin:/bin:$PATH"

DEBIAN_PACKAGES=(
  ros-core catkin cmake g++ ros-message-generation ros-environment
  python3-rospy python3-rosbag python3-roslz4 python3-rostest python3-roslaunch
  ros-std-msgs python3-std-msgs ros-nav-msgs python3-nav-msgs ros-sensor-msgs python3-sensor-msgs
  ros-std-srvs python3-std-srvs ros-diagnostic-msgs python3-diagnostic-msgs
  python3-numpy python3-sklearn python3-matplotlib python3-zstandard python3-lz4 python3-psutil
  python3-pytest python3-hypothesis xz-utils jq
)

log() { printf '[dev.sh] %s\n' "$*" >&2; }

install_missing() {
  local missing=()
  for pkg in "${DEBIAN_PACKAGES[@]}"; do
    dpkg-query -W -f='${Status}' "$pkg" 2>/dev/null | grep -q "install ok installed" || missing+=("$pkg")
  done
  [ ${#missing[@]} -eq 0 ] && return 0
  log "installing ${missing[*]}"
  local sudo=()
  [ "$(id -u)" -eq 0 ] || sudo=(sudo)
  "${sudo[@]}" env DEBIAN_FRONTEND=noninteractive apt-get update -q >/dev/null
  "${sudo[@]}" env DEBIAN_FRONTEND=noninteractive apt-get install -y -q --no-install-recommends \
    "${missing[@]}" >/dev/null
}

link_package() {
  # src/cc_log mirrors the repository root entry by entry (symlinks), leaving out .catkin_ws itself, so
  # that tools which search the package directory (rosrun's find -L) never walk into the workspace.
  local pkg="$WS/src/cc_log" entry
  [ -L "$pkg" ] && rm -f "$pkg"
  mkdir -p "$pkg"
  find "$pkg" -mindepth 1 -maxdepth 1 -type l -delete
  for entry in "$ROOT"/* "$ROOT"/.[!.]*; do
    case "$(basename "$entry")" in .catkin_ws|.git|'.[!.]*') continue ;; esac
    [ -e "$entry" ] && ln -sfn "$entry" "$pkg/$(basename "$entry")"
  done
}

build() {
  mkdir -p "$WS/src"
  link_package
  log "building $WS"
  (cd "$WS" && catkin_make -DPYTHON_EXECUTABLE=/usr/bin/python3 -DCATKIN_ENABLE_TESTING=ON >"$WS/build.log" 2>&1) \
    || { tail -n 40 "$WS/build.log" >&2; log "catkin_make failed (full log: $WS/build.log)"; exit 1; }
}

activate() {
  set +u
  # shellcheck disable=SC1091
  source "$WS/devel/setup.bash"
  set -u
  export PATH="/usr/bin:/bin:$PATH"
}

run_tests() {
  # catkin's run_tests empties build/test_results first, so the unit test results live beside it.
  local unit="$WS/build/unit_test_results" rostests="$WS/build/test_results/cc_log"
  rm -rf "$unit" && mkdir -p "$unit"
  log "unit tests (pytest, no roscore)"
  (cd "$ROOT" && python3 -m pytest -q -p no:cacheprovider --junitxml="$unit/pytest-unit.xml" test) || true
  log "rostests and launch file checks (catkin run_tests)"
  (cd "$WS" && catkin_make run_tests -DPYTHON_EXECUTABLE=/usr/bin/python3 >"$WS/run_tests.log" 2>&1) || true
  grep -E "^\[ROSTEST\]|^ SUMMARY|^ \* RESULT|^ \* TESTS|^ \* ERRORS|^ \* FAILURES" "$WS/run_tests.log" >&2 || true
  python3 "$ROOT/tools/test_summary.py" "$unit" "$rostests"
}

main() {
  local job=${1:-}
  case "$job" in
    setup|demo|test) ;;
    *) echo "usage: ./dev.sh demo|test|setup" >&2; exit 2 ;;
  esac
  install_missing
  build
  activate
  case "$job" in
    setup) log "ready: source $WS/devel/setup.bash" ;;
    demo) shift; exec rosrun cc_log demo.py "$@" ;;
    test) run_tests ;;
  esac
}

main "$@"
