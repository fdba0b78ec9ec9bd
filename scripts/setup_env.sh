#!/usr/bin/env bash
# Create .venv beside the repo and install everything the package, its nodes,
# the workbench and the tests need. Idempotent; quiet unless something fails.
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
venv="${IPMC_VENV:-$root/.venv}"
py="${PYTHON:-python3}"
if [ ! -x "$venv/bin/python" ]; then
  "$py" -m venv "$venv"
fi
stamp="$venv/.ipmc-installed"
want="$(cat "$root/setup.py" "$root/requirements-pypi-ros.txt" | sha256sum | cut -c1-16)"
if [ ! -f "$stamp" ] || [ "$(cat "$stamp")" != "$want" ]; then
  log="$venv/pip-install.log"
  if ! { "$venv/bin/python" -m pip install --upgrade pip \
         && "$venv/bin/python" -m pip install -r "$root/requirements-pypi-ros.txt" \
         && "$venv/bin/python" -m pip install -e "$root[test,workbench]"; } >"$log" 2>&1; then
    echo "setup_env: pip install failed; last lines of $log:" >&2
    tail -n 30 "$log" >&2
    exit 1
  fi
  echo "$want" > "$stamp"
fi
