#!/usr/bin/env bash
# Create .venv beside the repo and install everything the package, its nodes,
# the workbench and the tests need. Idempotent; prints a progress line at most every 2 s while it
# installs (full pip output in .venv/pip-install.log).
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
venv="${IPMC_VENV:-$root/.venv}"
py="${PYTHON:-python3}"
if [ ! -x "$venv/bin/python" ]; then
  echo "setup: creating $venv"
  "$py" -m venv "$venv"
fi
stamp="$venv/.ipmc-installed"
want="$(cat "$root/setup.py" "$root/requirements-pypi-ros.txt" | sha256sum | cut -c1-16)"
if [ -f "$stamp" ] && [ "$(cat "$stamp")" = "$want" ]; then
  exit 0
fi
log="$venv/pip-install.log"
: > "$log"
# step name, then pip arguments; pip's own lines go to the log, one summary line every >= 2 s here
step() {
  local name="$1"; shift
  echo "setup: $name"
  local last=$SECONDS
  set +e
  "$venv/bin/python" -m pip install --progress-bar off "$@" 2>&1 | tee -a "$log" | while IFS= read -r line; do
    case "$line" in
      Collecting*|Downloading*|Installing*|Building*)
        if [ $((SECONDS - last)) -ge 2 ]; then
          echo "setup:   ${line:0:100}"
          last=$SECONDS
        fi ;;
    esac
  done
  local rc=${PIPESTATUS[0]}
  set -e
  if [ "$rc" -ne 0 ]; then
    echo "setup_env: pip install failed ($name); last lines of $log:" >&2
    tail -n 30 "$log" >&2
    exit 1
  fi
}
step "1/3 pip" --upgrade pip
step "2/3 ROS 2 wheels (rclpy, messages, DDS)" -r "$root/requirements-pypi-ros.txt"
step "3/3 ipmc_sensor_ros with the workbench and test extras" -e "$root[test,workbench]"
echo "$want" > "$stamp"
echo "setup: done ($SECONDS s)"
