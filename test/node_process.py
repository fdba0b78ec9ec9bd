# SPDX-License-Identifier: Apache-2.0
"""A node executable started as a process, read up to its "ready" line, then signalled."""
from __future__ import annotations

import os
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def start_until_ready(argv: list, domain: int, **env_extra) -> tuple:
    """Start ``python argv`` on ROS domain ``domain``; return (process, its lines to "ready")."""
    env = dict(os.environ, PYTHONPATH=str(ROOT), ROS_DOMAIN_ID=str(domain), **env_extra)
    proc = subprocess.Popen([sys.executable, *argv], stdout=subprocess.PIPE,
                            stderr=subprocess.STDOUT, env=env, text=True)
    lines = []
    deadline = time.monotonic() + 60.0
    for line in proc.stdout:
        lines.append(line)
        if 'ready' in line or time.monotonic() > deadline:
            break
    return proc, lines


def signal_and_wait(proc, sig, lines: list, timeout_s: float = 20.0) -> tuple:
    """Send ``sig``; return (exit status or None if it did not exit, the whole output)."""
    proc.send_signal(sig)
    try:
        out, _ = proc.communicate(timeout=timeout_s)
    except subprocess.TimeoutExpired:
        proc.kill()
        out, _ = proc.communicate()
        return None, ''.join(lines) + out
    return proc.returncode, ''.join(lines) + out
