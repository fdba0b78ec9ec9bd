# SPDX-License-Identifier: Apache-2.0
"""
Single-threaded BLAS for the fits (:func:`single_threaded_blas`).

The fits here do many small matrix products (thousands of rows x tens of
columns); a multi-threaded OpenBLAS spins its threads on every one of them, and
on a shared 2-core machine (or with the worker processes of ``diagnose``) that
oversubscription made a mains-line search 30x slower (31 s vs 1.0 s for 10
records, measured).  Uses ``threadpoolctl`` when installed, else OpenBLAS's own
``*_set_num_threads`` found in the loaded libraries; without either it does nothing.
"""
from __future__ import annotations

import contextlib
import ctypes

__all__ = ['single_threaded_blas']

_SETTERS = ('scipy_openblas_set_num_threads64_', 'scipy_openblas_set_num_threads',
            'openblas_set_num_threads64_', 'openblas_set_num_threads')
_GETTERS = ('scipy_openblas_get_num_threads64_', 'scipy_openblas_get_num_threads',
            'openblas_get_num_threads64_', 'openblas_get_num_threads')


def _openblas_libraries():
    try:
        with open('/proc/self/maps') as f:
            paths = {line.split()[-1] for line in f if 'openblas' in line.lower() and '/' in line}
    except OSError:
        return []
    libs = []
    for p in sorted(paths):
        try:
            libs.append(ctypes.CDLL(p))
        except OSError:
            continue
    return libs


def _pairs():
    out = []
    for lib in _openblas_libraries():
        for s, g in zip(_SETTERS, _GETTERS):
            if hasattr(lib, s) and hasattr(lib, g):
                out.append((getattr(lib, s), getattr(lib, g)))
                break
    return out


@contextlib.contextmanager
def single_threaded_blas():
    """Run the block with one BLAS thread, restoring the previous count afterwards."""
    try:
        from threadpoolctl import threadpool_limits
    except ImportError:
        threadpool_limits = None
    if threadpool_limits is not None:
        with threadpool_limits(limits=1, user_api='blas'):
            yield
        return
    pairs = _pairs()
    before = [int(g()) for _, g in pairs]
    for s, _ in pairs:
        s(1)
    try:
        yield
    finally:
        for (s, _), n in zip(pairs, before):
            s(n)
