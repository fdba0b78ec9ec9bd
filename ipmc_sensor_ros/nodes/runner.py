"""Process entry helper shared by the node executables."""
from __future__ import annotations

import os
import re
import signal
import sys

import rclpy
from rclpy.exceptions import ParameterException
from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor

from rclpy._rclpy_pybind11 import RCLError

from ..physics.parameters import ParameterError, read_yaml
from .params import ConfigurationError, params_files

__all__ = ["run"]


def run(node_factory, name: str, args=None) -> int:
    """Run the node (see :func:`_run`), then leave the process without interpreter
    teardown.  After the orderly shutdown (executor, node, rclpy context), the
    remaining finalisers of the DDS middleware's native objects run in an
    unspecified order at interpreter exit; under load this crashed the process
    (SIGSEGV, about once in a full test run) after a clean SIGINT.  Output is
    flushed first, so nothing printed is lost."""
    code = _run(node_factory, name, args)
    if os.environ.get("IPMC_NODE_NO_HARD_EXIT") != "1":  # opt-out for in-process callers
        sys.stdout.flush()
        sys.stderr.flush()
        os._exit(code)
    return code


def _run(node_factory, name: str, args=None) -> int:
    """Init rclpy, build the node, spin until SIGINT/shutdown; return the exit code.

    SIGINT (Ctrl-C, ``ros2 run``/launch shutdown) gives 0.  A configuration error
    is printed on one line naming the parameter (no traceback) and gives 2.
    """
    # A shell starts background jobs with SIGINT ignored, and Python keeps an
    # inherited SIG_IGN: restore the default so SIGINT always stops the node.
    signal.signal(signal.SIGINT, signal.default_int_handler)
    try:
        # rcl reports a params file it cannot parse as an RCLError traceback (exit 1)
        # without the line: read each file first for a one-line file:line error
        for path in params_files(args):
            read_yaml(path, "parameters file")
        rclpy.init(args=args)
    except (ParameterError, RCLError) as exc:
        text = str(exc)
        if isinstance(exc, RCLError):   # "...Error: <what> at line_num 3, at /src/parse.c:435, ..."
            text = re.sub(r",? at /\S+:\d+", "", text).replace("failed to initialize rcl: ", "")
        print(f"{name}: invalid parameters file: {' '.join(text.split())}", file=sys.stderr)
        return 2
    # The executor exists before the node logs "ready", so a SIGINT sent on that
    # line cannot interrupt the executor's construction (rclpy then prints an
    # "Exception ignored in Executor.__del__" traceback).
    executor = SingleThreadedExecutor()
    try:
        node = node_factory()
    except (KeyboardInterrupt, ExternalShutdownException):
        executor.shutdown()
        rclpy.try_shutdown()
        return 0
    except (ConfigurationError, ParameterException) as exc:
        text = str(exc)
        hint = ""
        if "type 'INTEGER'" in text and "expecting type 'DOUBLE'" in text:
            hint = " (write floating-point parameters with a decimal point, e.g. 1000.0)"
        elif "out of range" in text and any(f"Parameter {n} out of range" in text
                                            for n in ("length_m", "width_m", "thickness_m")):
            hint = " (lengths are in metres: is it in millimetres?)"
        files = params_files()
        source = f" (parameters files: {', '.join(files)})" if files and not any(
            f in str(exc) for f in files) else ""
        print(f"{name}: invalid parameter: {exc}{hint}{source}", file=sys.stderr)
        executor.shutdown()
        rclpy.try_shutdown()
        return 2
    try:
        executor.add_node(node)
        executor.spin()
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        executor.shutdown()
        node.destroy_node()
        rclpy.try_shutdown()
    return 0
