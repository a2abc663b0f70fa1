"""The first calls of a kernel that is not compiled yet run as Python while a background process compiles it.

Compiling the env's kernels is most of a fresh install's first step (``python bench/cold_start.py
--kernels`` lists them and their seconds), and most of that is Numba's own Python code (typing
and lowering), which no reshaping of the kernels shortens enough. The kernels' Python source,
though, is the same maths and runs as it is: ``NUMBA_DISABLE_JIT=1`` runs it draw for draw like
the machine code (``tests/compiled/test_disable_jit.py``). So a kernel called with a signature
that is not in Numba's disk cache

1. asks a background process (``python -m estimator.compiled.background``, one per process, started
   at the first such call) to compile it into the cache, and
2. runs as its *Python twin* (:func:`python_twin`: its ``py_func`` whose kernels, intrinsics and
   libm-bound names are replaced by their Python twins) until that process reports it done;
3. the call after that loads the machine code from the cache, as a warm start does.

Results are the same either way (``tests/compiled/test_background.py``); only the first calls
are slower, on this core, while the compile runs on another (``python bench/cold_start.py``
reports the first step and when the kernels are compiled). The background process compiles
what it was asked and exits when its requests are done, also after this process has ended (so
the next start is warm); processes sharing a cache folder compile one at a time (a lock file
there).

Not used -- the kernel compiles in this process as Numba does -- where it cannot help: with
``COOP_GYM_BACKGROUND_COMPILE=0``, on a single core (the compile would take the core the Python
twins run on), for batches too large to step as Python (:data:`MAX_PYTHON_ELEMENTS`), for
kernels without a disk cache (:mod:`estimator.compiled.cache` runs those uncached) and in the
background process itself. :func:`wait` blocks until the kernels asked for so far are compiled
(a benchmark timing the compiled step calls it first).
"""

from __future__ import annotations

import base64
import contextlib
import importlib
import os
import pickle
import subprocess
import sys
import threading
import types
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import numpy as np
from numba import config
from numba.core.dispatcher import Dispatcher

__all__ = ["ENV_SWITCH", "MAX_PYTHON_ELEMENTS", "enabled", "install", "python_twin", "run_as_python", "wait"]

ENV_SWITCH = "COOP_GYM_BACKGROUND_COMPILE"
"""Environment variable: ``0`` compiles every kernel in the calling process, as Numba does."""

MAX_PYTHON_ELEMENTS = 1 << 20
"""Calls with a larger array argument compile in the calling process instead of running as Python:
~10,000 envs' state rows, whose Python step takes about as long as the compile (the make_vec row
of ``python bench/cold_start.py`` times a Python step of 1024 envs)."""

IDLE_EXIT_S = 30.0
"""A background process with no request for this long exits (a process's kernels are usually asked
for within its first steps; a later one starts another)."""

_LOCK_NAME = "coop_gym-compile.lock"

_replacements: dict[int, Any] = {}  # id(compiled object) -> its Python twin
_keep_alive: list[Any] = []  # the compiled objects keyed by id above


def run_as_python(compiled: Any, python: Any) -> Any:
    """Declare ``python`` the twin of ``compiled`` (an intrinsic, a kernel, a NumPy function) in Python runs.

    Returns the one to bind now: ``python`` under ``NUMBA_DISABLE_JIT=1``, else ``compiled``. A
    Python twin of a kernel (:func:`python_twin`) sees ``python`` wherever its module has ``compiled``.
    """
    _replacements[id(compiled)] = python
    _keep_alive.append(compiled)
    return python if getattr(config, "DISABLE_JIT", False) else compiled


_twins: dict[int, Callable[..., Any]] = {}
_twin_globals: dict[int, dict[str, Any]] = {}
_twins_lock = threading.RLock()


def python_twin(kernel: Any) -> Callable[..., Any]:
    """``kernel`` as Python: its ``py_func`` over its module's globals with every compiled name replaced.

    Kernels become their Python twins (so a twin never enters the dispatcher again) and the
    objects declared with :func:`run_as_python` their declared twins.
    """
    with _twins_lock:
        twin = _twins.get(id(kernel))
        if twin is None:
            twin = _replacements.get(id(kernel))
        if twin is None:
            py_func = kernel.py_func
            twin = types.FunctionType(
                py_func.__code__,
                _python_globals(py_func.__globals__),
                py_func.__name__,
                py_func.__defaults__,
                py_func.__closure__,
            )
            twin.__kwdefaults__ = py_func.__kwdefaults__
            twin.__qualname__ = py_func.__qualname__
        _twins[id(kernel)] = twin
        _keep_alive.append(kernel)
        return twin


def _python_globals(namespace: dict[str, Any]) -> dict[str, Any]:
    # One twin namespace per module, filled after it is registered: kernels may call each other.
    twin_namespace = _twin_globals.get(id(namespace))
    if twin_namespace is None:
        twin_namespace = _twin_globals[id(namespace)] = dict(namespace)
        for name, value in namespace.items():
            if id(value) in _replacements:
                twin_namespace[name] = _replacements[id(value)]
            elif isinstance(value, Dispatcher):
                twin_namespace[name] = python_twin(value)
    return twin_namespace


def _ignoring_float_warnings(function: Callable[..., Any]) -> Callable[..., Any]:
    # Machine code never warns; NumPy scalars do (an overflow to inf, a 0/0) where it gives the same value.
    def call(*args: Any) -> Any:
        with np.errstate(all="ignore"):
            return function(*args)

    return call


def _usable_cores() -> int:
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # not on Linux
        return os.cpu_count() or 1


_CORES = _usable_cores()


def enabled() -> bool:
    """Whether an uncompiled kernel runs as Python while a background process compiles it."""
    return os.environ.get(ENV_SWITCH, "1") != "0" and _CORES >= 2


class _Compiler:
    """The background process of this process: requests in on its stdin, ``done N`` lines out."""

    def __init__(self) -> None:
        environment = {**os.environ, ENV_SWITCH: "0"}
        # The same modules as here, wherever they were imported from (a checkout, a test's folder).
        environment["PYTHONPATH"] = os.pathsep.join(path for path in sys.path if path)
        self.process = subprocess.Popen(
            [sys.executable, "-m", __name__],
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            stderr=subprocess.DEVNULL,
            env=environment,
        )
        self.sent = 0
        self.finished: set[int] = set()
        self.changed = threading.Condition()
        threading.Thread(target=self._read, name="coop_gym-compile-reader", daemon=True).start()

    def request(self, kernel: Any, signature: tuple[Any, ...]) -> int:
        assert self.process.stdin is not None
        line = base64.b64encode(pickle.dumps((kernel.py_func.__module__, kernel.py_func.__qualname__, signature)))
        self.process.stdin.write(line + b"\n")
        self.process.stdin.flush()
        with self.changed:
            if self.sent < 0:  # the process has ended
                raise OSError("the background compile process has ended")
            self.sent += 1
            return self.sent

    def _read(self) -> None:
        assert self.process.stdout is not None
        for line in self.process.stdout:
            with self.changed:
                self.finished.add(int(line.split()[1]))
                self.changed.notify_all()
        with self.changed:  # the process ended: whatever it did not compile compiles here
            self.finished.update(range(1, self.sent + 1))
            self.sent = -1
            self.changed.notify_all()

    def ended(self) -> bool:
        with self.changed:
            return self.sent < 0

    def is_done(self, number: int) -> bool:
        with self.changed:
            return self.sent < 0 or number in self.finished

    def wait(self, timeout: float | None) -> bool:
        with self.changed:
            return self.changed.wait_for(lambda: self.sent < 0 or len(self.finished) >= self.sent, timeout)


_compiler: _Compiler | None = None
_requests: dict[tuple[int, tuple[Any, ...]], tuple[_Compiler, int]] = {}  # (id(kernel), signature) -> request
_state_lock = threading.Lock()


def _forget_compiler() -> None:
    # A forked child has no reader thread: it asks a process of its own when it needs one.
    global _compiler, _state_lock
    _compiler = None
    _requests.clear()
    _state_lock = threading.Lock()


if hasattr(os, "register_at_fork"):
    os.register_at_fork(after_in_child=_forget_compiler)


def _in_cache(kernel: Any, signature: tuple[Any, ...]) -> bool:
    """Whether Numba's disk cache holds ``kernel`` for ``signature`` (after the source guard's check)."""
    cache = kernel._cache
    cache.source_guard.check()
    if not getattr(cache, "_enabled", False):
        return False
    key = cache._index_key(signature, kernel.targetctx.codegen())
    try:
        return key in cache._cache_file._load_index()
    except Exception:  # an unreadable index: Numba's own load decides
        return True


_numba_compile_for_args: Any = Dispatcher._compile_for_args  # type: ignore[attr-defined]


def _compile_for_args(kernel: Any, *args: Any) -> Callable[..., Any]:
    """The dispatcher's ``_compile_for_args``: what runs a call that matches no compiled signature."""
    if not enabled() or max((arg.size for arg in args if isinstance(arg, np.ndarray)), default=0) > MAX_PYTHON_ELEMENTS:
        return _numba_compile_for_args(kernel, *args)
    global _compiler
    try:
        signature = tuple(kernel.typeof_pyval(arg) for arg in args)
    except Exception:  # Numba's own call reports an argument it cannot type
        return _numba_compile_for_args(kernel, *args)
    key = (id(kernel), signature)
    with _state_lock:
        request = _requests.get(key)
        if request is None:
            if _in_cache(kernel, signature):
                return _numba_compile_for_args(kernel, *args)
            try:
                if _compiler is None or _compiler.ended():
                    _compiler = _Compiler()
                request = _requests[key] = (_compiler, _compiler.request(kernel, signature))
            except Exception:  # no process, or a signature it cannot be sent: compile here
                return _numba_compile_for_args(kernel, *args)
        elif request[0].is_done(request[1]):
            del _requests[key]
            request = None
    if request is None:  # compiled by now (or the background process ended): load it, or compile here
        return _numba_compile_for_args(kernel, *args)
    return _ignoring_float_warnings(python_twin(kernel))


def install(kernel: Any) -> None:
    """Route ``kernel``'s uncompiled calls through :func:`_compile_for_args` (a disk-cached, guarded kernel)."""
    kernel._compile_for_args = lambda *args, **kws: _compile_for_args(kernel, *args, **kws)


def wait(timeout: float | None = None) -> bool:
    """Block until the background process has compiled every kernel asked for so far; False on timeout."""
    compiler = _compiler
    return True if compiler is None else compiler.wait(timeout)


@contextlib.contextmanager
def _compile_lock(kernel: Any) -> Iterator[None]:
    """One compiling process at a time per cache folder (the later ones then load what it wrote)."""
    try:
        import fcntl
    except ImportError:  # Windows: compile side by side
        yield
        return
    folder = Path(kernel._cache.cache_path)
    folder.mkdir(parents=True, exist_ok=True)
    with open(folder / _LOCK_NAME, "a") as handle:
        fcntl.flock(handle, fcntl.LOCK_EX)
        try:
            yield
        finally:
            fcntl.flock(handle, fcntl.LOCK_UN)


def _requests_in(idle_exit_s: float) -> Iterator[bytes]:
    """The request lines on stdin, until its end or, where ``select`` works on pipes, ``idle_exit_s`` without one."""
    if os.name != "posix":
        yield from sys.stdin.buffer
        return
    import select

    fd = sys.stdin.fileno()
    pending = b""
    while True:
        if not select.select([fd], [], [], idle_exit_s)[0]:
            return  # idle: free the memory; the asking process starts another when it needs one
        chunk = os.read(fd, 1 << 16)
        if not chunk:
            return
        *lines, pending = (pending + chunk).split(b"\n")
        yield from lines


def _serve() -> None:
    """The background process: compile each request into the disk cache, report ``done N``, exit when idle."""
    for number, line in enumerate(_requests_in(IDLE_EXIT_S), start=1):
        try:
            module_name, qualname, signature = pickle.loads(base64.b64decode(line))
            kernel: Any = importlib.import_module(module_name)
            for part in qualname.split("."):
                kernel = getattr(kernel, part)
            with _compile_lock(kernel):
                kernel.compile(signature)
        except Exception:  # the asking process compiles it and meets the error itself
            pass
        sys.stdout.write(f"done {number}\n")
        sys.stdout.flush()


if __name__ == "__main__":
    _serve()
