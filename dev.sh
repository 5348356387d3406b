#!/usr/bin/env bash
# Set up cc_log on this machine and run one of its jobs.
#
#   ./dev.sh demo     install what is missing, build, run the demo
#   ./dev.sh test     install what is missing, build, run every test (unit tests and rostests)
#   ./dev.sh setup    install what is missing and build only
#   ./dev.sh packages the Debian packages setup installs when missing (package.xml's keys, the toolchain, Dask)
#                     (setup also installs the MCAP library from PyPI: PIP_EXTRAS)
#
# Setup installs the Debian packages cc_log needs when they are missing (quick when they are present) and
# builds a catkin workspace in .catkin_ws/ whose src/cc_log points at this repository (entry by entry). Afterwards
# `source .catkin_ws/devel/setup.bash` makes rosrun, roslaunch and rostest find cc_log.
set -euo pipefail

ROOT=$(cd "$(dirname "$(readlink -f "${BASH_SOURCE[0]}")")" && pwd)
WS="$ROOT/.catkin_ws"
# Debian's ROS lives in the system interpreter; another python3 first on PATH cannot see it.
export PATH="/usr/bin:/bin:$PATH"

# What building needs besides package.xml's keys: catkin_make configures a C/C++ project and runs make.
BUILD_TOOLCHAIN=(g++ make cmake)
# Optional extras without a rosdep key (ros/rosdistro's rosdep/python.yaml has no dask or zstandard key): Dask,
# which the fleet commands (cclog collect / learn / replay over many bags) run on; they ask for it in one line when
# missing; zstandard, the zstd chunks of `cclog export --to mcap` (lz4 without it).
OPTIONAL_EXTRAS=(python3-dask python3-distributed python3-pip python3-zstandard)
# Optional extras only on PyPI (Debian 12 has no package): the MCAP library, which `cclog export --to mcap`
# writes with (it says how to install it in one line when missing). pip puts them in /usr/local for /usr/bin/python3.
PIP_EXTRAS=(mcap mcap-ros1-support)
PIP_EXTRAS_IMPORT='import mcap, mcap_ros1'

log() { printf '[dev.sh] %s\n' "$*" >&2; }

# The rosdep keys package.xml declares (every kind of dependency), one a line; comments are left out.
package_keys() {
  perl -0777 -ne 's/<!--.*?-->//gs;
    print "$1\n" while /<(?:buildtool_|buildtool_export_|build_|build_export_|exec_|test_|doc_)?depend(?:\s[^>]*)?>\s*([^<\s]+)\s*</g' \
    "$ROOT/package.xml" | sort -u
}

# The Debian 12 packages of one rosdep key. The one place keys are mapped: a key added to package.xml is
# installed from here, and a key this does not know stops setup with a line naming it.
debian_packages_of() {
  local key=$1 name=${1//_/-}
  case "$key" in
    catkin|rosbash|rosout) echo "$key" ;;
    message_generation|message_runtime) echo "ros-$name" ;;
    genpy|roslib|rospy|rosbag|roslz4|rosgraph|roslaunch|rostest|rosnode|rostopic|rosparam|rosservice|rosmsg)
      echo "python3-$name" ;;
    diagnostic_updater) echo python3-diagnostic-updater ;;
    *_msgs|*_srvs) echo "ros-$name python3-$name" ;;     # message definitions and their Python classes
    python3-catkin-lint) echo catkin-lint ;;
    python3-*|xz-utils|jq) echo "$key" ;;                 # rosdep's Debian rule: the same name
    *) return 1 ;;
  esac
}

debian_packages() {
  local key packages unknown=()
  printf '%s\n' "${BUILD_TOOLCHAIN[@]}" "${OPTIONAL_EXTRAS[@]}"
  for key in $(package_keys); do
    if packages=$(debian_packages_of "$key"); then printf '%s\n' $packages; else unknown+=("$key"); fi
  done
  if [ ${#unknown[@]} -gt 0 ]; then
    log "package.xml: no Debian package known for rosdep key(s) ${unknown[*]}: add them to debian_packages_of in dev.sh"
    return 1
  fi
}

install_pip_extras() {
  /usr/bin/python3 -c "$PIP_EXTRAS_IMPORT" 2>/dev/null && return 0
  log "installing ${PIP_EXTRAS[*]} (PyPI)"
  local sudo=()
  [ "$(id -u)" -eq 0 ] || sudo=(sudo)
  if ! "${sudo[@]}" /usr/bin/python3 -m pip install -q --root-user-action=ignore --break-system-packages \
      "${PIP_EXTRAS[@]}" >&2; then
    log "optional ${PIP_EXTRAS[*]} not installed (pip failed): cclog export --to mcap says how to install it"
  fi
}

install_missing() {
  local missing=() list pkg
  list=$(debian_packages) || exit 1
  for pkg in $list; do
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
  # Every test is registered in CMakeLists.txt: the launch file check, each unit test file (pytest) and each
  # rostest, one after the other (-j1: they share the cores and some of them measure rates). Progress: the name
  # of each test file as it starts; the whole output is in run_tests.log.
  local results="$WS/build/test_results/cc_log"
  log "every test (catkin_make run_tests; log: $WS/run_tests.log)"
  (cd "$WS" && catkin_make run_tests -j1 -DPYTHON_EXECUTABLE=/usr/bin/python3 2>&1) | tee "$WS/run_tests.log" \
    | awk '/run_tests.py: execute commands/ {
        getline; n = split($NF, part, "/"); name = part[n]
        if (name !~ /[.](py|test)$/) name = "launch file check"
        print "[dev.sh]   " name; fflush() }' >&2 || true
  python3 "$ROOT/tools/test_summary.py" "$results"
}

main() {
  local job=${1:-}
  case "$job" in
    setup|demo|test) ;;
    packages) debian_packages; exit ;;
    *) echo "usage: ./dev.sh demo|test|setup|packages" >&2; exit 2 ;;
  esac
  install_missing
  install_pip_extras
  build
  activate
  case "$job" in
    setup) log "ready: source $WS/devel/setup.bash" ;;
    demo) shift; exec rosrun cc_log demo.py "$@" ;;
    test) run_tests ;;
  esac
}

main "$@"
