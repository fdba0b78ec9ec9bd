# SPDX-License-Identifier: Apache-2.0
"""
Process entry helper shared by the node executables.

Executor
    ``rclpy.experimental.EventsExecutor`` where rclpy has it (rclpy >= 9), else
    ``SingleThreadedExecutor``; ``IPMC_EXECUTOR=single`` selects the latter.  On this
    machine the events executor handled one-sample messages at 80-90 us of CPU each
    against 360-400 us for the single-threaded one (README "ROS 2 interface").
    With ros-rclpy 9.1.2 the events executor's ``spin()`` never returns: an exception
    raised in a callback is logged and swallowed, and neither ``shutdown()`` from
    another thread nor a completed future ends it.  ``spin_once`` does return (and
    re-raises a callback's exception), so the nodes are spun by :func:`spin_until_signalled`,
    a ``spin_once`` loop with a 0.1 s timeout that checks the signal flag between calls.

Signals
    The process handles SIGINT and SIGTERM itself (rclpy's handlers are not
    installed, ``SignalHandlerOptions.NO``): the Python handler only records the
    signal, and the spin loop ends within ``SPIN_PERIOD_S`` once it is set, never in
    the middle of rcl calls.  So a signal at any moment exits 0 without a traceback.
    Why not rclpy's handlers: with them, a SIGTERM sent on the "ready" line left the
    process spinning forever in 4 of 5 runs (EventsExecutor; also seen with
    SingleThreadedExecutor), the context never shut down, and in 10 of 12 runs it
    raised ``RCLError`` ("the given context is not valid") out of the executor's
    wait-set set-up.  While the node is being built (parameters read, model files parsed,
    the filter designed) the handler raises instead, so a signal ends a slow start at once
    (exit 0), rather than after it.

Help
    ``-h`` / ``--help`` among the non-ROS arguments prints the node's usage and parameters
    and exits 0 without starting rclpy.

Teardown
    executor, node, context are destroyed in that order; there is no ``os._exit``
    (the SIGSEGV seen once at exit under load with rclpy's own signal handlers has
    not been seen since they are no longer installed).
"""
from __future__ import annotations

import contextlib
import os
import re
import signal
import sys

import rclpy
from rclpy.exceptions import ParameterException
from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor
from rclpy.signals import SignalHandlerOptions

from ..physics.parameters import read_yaml
from .params import ParameterError, node_help, params_files, ros_arguments, wants_help

__all__ = ['run', 'make_executor', 'executor_name', 'spin_until_signalled']

try:  # rclpy >= 9
    from rclpy.experimental import EventsExecutor
except ImportError:  # pragma: no cover - older rclpy
    EventsExecutor = None

try:
    from rclpy._rclpy_pybind11 import RCLError
except ImportError:  # pragma: no cover
    from rclpy.impl.implementation_singleton import rclpy_implementation as _impl
    RCLError = _impl.RCLError


class _InterruptedStart(Exception):
    """A signal arrived while the node was being built."""


_SHUTDOWN = (KeyboardInterrupt, ExternalShutdownException, _InterruptedStart)


def executor_name() -> str:
    """``events`` or ``single``: the executor :func:`make_executor` builds here."""
    default = 'single' if EventsExecutor is None else 'events'
    wanted = os.environ.get('IPMC_EXECUTOR', default).strip().lower()
    if wanted not in ('events', 'single'):
        raise ParameterError(f'environment variable IPMC_EXECUTOR={wanted!r}: expected '
                             "'events' or 'single'")
    return 'events' if wanted == 'events' and EventsExecutor is not None else 'single'


def make_executor(context=None):
    """Return the executor of the nodes (see the module docstring)."""
    if executor_name() == 'events':
        return EventsExecutor(context=context)
    return SingleThreadedExecutor(context=context)


def _stopping(context=None) -> bool:
    """Return True once a signal (or anyone) has shut the rclpy context down."""
    try:
        return not rclpy.ok(context=context)
    except Exception:  # noqa: BLE001 - a destroyed context is stopping too
        return True


#: Signals received (set by the handler, read by the guard timer).
_SIGNALLED: set = set()


#: True while the node is being built (parameters read, model files parsed, filter designed).
_STARTING = [False]


def _on_signal(signum, frame) -> None:
    _SIGNALLED.add(signum)
    if _STARTING[0]:       # reading a model file or designing a filter: stop it now
        _STARTING[0] = False
        raise _InterruptedStart(signum)


#: Longest wait of one ``spin_once`` call, s: the bound on the exit delay after a signal.
SPIN_PERIOD_S = 0.1


#: Exceptions a callback raises that end the spin as before: a shutdown, a configuration
#: error (exit 2), an rcl error (re-raised unless the context is stopping).
_ENDS_SPIN = _SHUTDOWN + (ParameterError, ParameterException, RCLError)


def spin_until_signalled(executor, context=None, node=None) -> None:
    """
    Spin ``executor`` until SIGINT/SIGTERM was received or the context shut down.

    Also until ``node`` says it is ``finalized`` (a managed node after the ``shutdown``
    transition: the executable then ends, exit status 0).  A loop of ``spin_once`` (see the
    module docstring for why not ``spin``).  Any other exception a callback raises past
    the node's own barrier (:mod:`.barrier`) is a defect: said on one line, counted on
    ``node``, and the node goes on.
    """
    while (not _SIGNALLED and not _stopping(context)
           and not getattr(node, 'finalized', False)):
        try:
            executor.spin_once(timeout_sec=SPIN_PERIOD_S)
        except _ENDS_SPIN:
            raise
        except Exception as exc:  # noqa: BLE001 - a callback's defect never ends the node
            if node is None or not hasattr(node, 'count_defect'):
                raise
            node.count_defect(exc)


def _report_configuration_error(name: str, exc: Exception, args) -> None:
    text = str(exc)
    hint = ''
    if "type 'INTEGER'" in text and "expecting type 'DOUBLE'" in text:
        hint = ' (write floating-point parameters with a decimal point, e.g. 1000.0)'
    elif 'is outside [' in text and any(f"parameter '{n}' = " in text
                                        for n in ('length_m', 'width_m', 'thickness_m')):
        hint = ' (lengths are in metres: is it in millimetres?)'
    files = params_files(args)
    source = f" (parameters files: {', '.join(files)})" if files and not any(
        f in text for f in files) else ''
    print(f'{name}: invalid parameter: {exc}{hint}{source}', file=sys.stderr)


def run(node_factory, name: str, args=None) -> int:
    """
    Init rclpy, build the node, spin until SIGINT/SIGTERM/shutdown; return the exit code.

    ``node_factory()`` builds the node (a ``Node`` or a ``LifecycleNode``).

    A signal at any moment gives 0 without a traceback.  A configuration error is
    printed on one line naming the parameter (no traceback) and gives 2.
    """
    args = list(sys.argv if args is None else args)
    if wants_help(args):
        try:
            print(node_help(name), flush=True)
        except BrokenPipeError:     # `--help | head`: the reader left; not an error
            os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 0
    # A shell starts background jobs with SIGINT ignored, and Python keeps an
    # inherited SIG_IGN: restore the default so SIGINT always stops the node.
    _SIGNALLED.clear()
    previous = {s: signal.signal(s, _on_signal) for s in (signal.SIGINT, signal.SIGTERM)}
    try:
        return _run(node_factory, name, args)
    finally:
        for s, handler in previous.items():
            signal.signal(s, handler)


@contextlib.contextmanager
def _interruptible():
    """
    Let a SIGINT/SIGTERM raise :class:`_InterruptedStart` inside the block (see ``_on_signal``).

    For the start: params files read, the node built (model files parsed, filter designed).
    """
    if _SIGNALLED:
        raise _InterruptedStart(min(_SIGNALLED))
    _STARTING[0] = True
    try:
        yield
    finally:
        _STARTING[0] = False


def _init(name: str, args) -> int | None:
    """Read the params files and init rclpy; return an exit code if the node must not start."""
    try:
        # rcl reports a params file it cannot parse as an RCLError traceback (exit 1)
        # without the line: read each file first (size-limited) for a one-line file:line error
        with _interruptible():
            for path in params_files(args):
                read_yaml(path, 'parameters file')
        rclpy.init(args=args, signal_handler_options=SignalHandlerOptions.NO)
    except _InterruptedStart:
        return 0
    except (ParameterError, RCLError) as exc:
        text = str(exc)
        if isinstance(exc, RCLError):  # "...Error: <what> at line_num 3, at /src/parse.c:435, ..."
            text = re.sub(r',? at /\S+:\d+', '', text).replace('failed to initialize rcl: ', '')
        print(f"{name}: invalid parameters file: {' '.join(text.split())}", file=sys.stderr)
        return 2
    return None


def _run(node_factory, name: str, args) -> int:
    early = _init(name, args)
    if early is not None:
        return early
    executor = node = None
    code = 0
    try:
        # The executor exists before the node logs "ready", so a signal sent on that
        # line finds a complete executor.
        executor = make_executor()
        with _interruptible():
            # the node gets the arguments rcl parsed for it (params files, -p, remaps) as
            # its own cli_args
            node = node_factory(cli_args=ros_arguments(args))
        node.get_logger().debug(f'executor: {type(executor).__name__}')
        executor.add_node(node)
        spin_until_signalled(executor, node.context, node)
    except _SHUTDOWN:
        pass
    except (ParameterError, ParameterException) as exc:
        if not _SIGNALLED:
            _report_configuration_error(name, exc, args)
            code = 2
    except RCLError:
        if not _stopping():
            raise
    finally:
        # signals only set the flag: the teardown cannot be interrupted
        if executor is not None:
            executor.shutdown()
        if node is not None:
            node.destroy_node()
        rclpy.try_shutdown()
    return code
