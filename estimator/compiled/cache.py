"""Numba's on-disk cache, keyed by every project source a kernel compiles in.

Numba's cache (``@njit(cache=True)``) checks only the file that defines a kernel. But a
kernel inlines the functions it calls and freezes the module-level constants it reads,
from other files too: ``coop_gym.envs.kernels.step.step_env`` compiles in the person
(``coop_gym.model.dynamics``), the filter and the judgment, and
``estimator.identification.identify`` the multiple-model steps. After an edit there Numba would
keep running the old machine code.

:func:`guard_kernel_cache` fixes this for every cached kernel of a module: before the
first cache load in a process it hashes the sources of the module and of every project
module it imports, directly or not (:func:`project_sources`, read from the import
statements with ``ast``), and flushes the module's kernels' cache when the hash differs
from the one stamped beside the cache. Nothing is read or written at import time: the
check runs lazily, once per module and process, when Numba first looks in the cache
(i.e. at the first call of one of its kernels). Keying Numba's cache directory by the
hash instead would need the sources read at import.

Where no cache folder is writable (a read-only install: the package folder, ``HOME`` and
``NUMBA_CACHE_DIR`` all read-only), Numba refuses ``cache=True`` at decoration time ("no locator
available"). For the modules that use the guard, :class:`_UncachedLocator` is then the last
resort: their kernels compile in memory (``NullCache``), with one :class:`KernelCacheWarning` per
process. A cache that fails later (a folder that turns read-only, a full disk) likewise warns
once and the kernels run uncached; a run never stops for its cache.
"""

from __future__ import annotations

import ast
import hashlib
import importlib
import os
import sys
import threading
import warnings
from pathlib import Path
from types import ModuleType
from typing import Any

from numba.core.caching import CacheImpl, FunctionCache, NullCache, _CacheLocator
from numba.core.runtime import rtsys

from estimator.compiled import background

__all__ = ["KernelCacheWarning", "guard_kernel_cache", "guarded_kernels", "project_sources", "source_digest"]

_STAMP_SUFFIX = ".sources.sha256"


def _project_root(module_name: str) -> Path:
    """The directory holding the top-level package of ``module_name``."""
    module = sys.modules.get(module_name) or importlib.import_module(module_name)
    depth = module_name.count(".") + (1 if Path(module.__file__ or "").name == "__init__.py" else 0)
    return Path(module.__file__ or "").resolve().parents[depth]


def _module_file(root: Path, name: str) -> Path | None:
    base = root.joinpath(*name.split("."))
    for candidate in (base.with_suffix(".py"), base / "__init__.py"):
        if candidate.is_file():
            return candidate
    return None


def _imported_names(path: Path, name: str) -> set[str]:
    """Dotted names imported anywhere in ``path`` (module ``name``), function-local imports included."""
    package = name if path.name == "__init__.py" else name.rpartition(".")[0]
    names: set[str] = set()
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"), str(path))):
        if isinstance(node, ast.Import):
            names.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                parent = package.rsplit(".", node.level - 1)[0] if node.level > 1 else package
                base = f"{parent}.{base}" if base else parent
            names.add(base)
            # ``from package import module`` imports a module, not a name.
            names.update(f"{base}.{alias.name}" for alias in node.names)
    return names


def project_sources(module_name: str) -> list[Path]:
    """Source files of ``module_name`` and of every project module it imports, transitively.

    A project module is one whose file lies under the same root as ``module_name``'s
    package (so NumPy, Numba ... are not followed). Parent packages' ``__init__`` files
    are not included unless imported by name.
    """
    root = _project_root(module_name)
    first = _module_file(root, module_name)
    if first is None:
        raise ValueError(f"no source file for module {module_name!r} under {root}")
    seen = {module_name: first}
    pending = [module_name]
    while pending:
        name = pending.pop()
        for imported in _imported_names(seen[name], name):
            if imported not in seen and (path := _module_file(root, imported)) is not None:
                seen[imported] = path
                pending.append(imported)
    return sorted(seen.values())


def source_digest(module_name: str, sources: list[Path] | None = None) -> str:
    """SHA-256 over the relative paths and contents of :func:`project_sources` (or of ``sources``)."""
    root = _project_root(module_name)
    digest = hashlib.sha256()
    for path in project_sources(module_name) if sources is None else sources:
        digest.update(path.relative_to(root).as_posix().encode())
        digest.update(b"\0")
        digest.update(path.read_bytes())
    return digest.hexdigest()


def guarded_kernels(module_name: str) -> list[Any]:
    """The disk-cached Numba kernels defined in ``module_name``."""
    module = sys.modules[module_name]
    return [
        value
        for value in vars(module).values()
        if isinstance(getattr(value, "_cache", None), FunctionCache)
        and getattr(getattr(value, "py_func", None), "__module__", None) == module_name
    ]


class _SourceGuard:
    """Checks a module's source digest against its stamp once, before the first cache load."""

    def __init__(self, module_name: str, kernels: list[Any]) -> None:
        self.module_name = module_name
        self.kernels = kernels
        self.checked = False
        self._lock = threading.Lock()

    def check(self) -> None:
        if self.checked:
            return
        with self._lock:
            if self.checked:
                return
            self.checked = True
            try:
                stamp = Path(self.kernels[0]._cache.cache_path) / f"{self.module_name}{_STAMP_SUFFIX}"
                previous = stamp.read_text().splitlines() if stamp.exists() else []
                if _unchanged(previous[1:]):
                    return
                sources = project_sources(self.module_name)
                digest = source_digest(self.module_name, sources)
                if previous[:1] != [digest]:
                    for kernel in self.kernels:
                        kernel._cache.flush()
                temporary = stamp.with_name(f"{stamp.name}.{os.getpid()}")
                temporary.write_text("\n".join([digest, *_file_stamps(sources)]))
                os.replace(temporary, stamp)
            except OSError:  # a read-only cache: Numba compiles as usual
                pass


def _file_stamps(paths: list[Path]) -> list[str]:
    """``mtime_ns size path`` of each file: what tells, without reading them, that the sources are the stamped ones."""
    return [f"{(status := path.stat()).st_mtime_ns} {status.st_size} {path}" for path in paths]


def _unchanged(file_stamps: list[str]) -> bool:
    """Whether every file of a stamp still has its recorded modification time and size.

    The digest's sources are found by parsing every one of them, part of each process start's
    import of coop_gym (which ``python bench/cold_start.py`` times on its own,
    ``bench/results/cold_start.json``); a file's times and size are what Numba's own cache trusts
    for the file that defines a kernel, so an unchanged set needs no parsing. Any difference -- an
    edit, a moved checkout, a missing file -- means the digest is computed again from the contents.
    """
    if not file_stamps:
        return False
    try:
        return _file_stamps([Path(line.split(" ", 2)[2]) for line in file_stamps]) == file_stamps
    except (OSError, IndexError):
        return False


class KernelCacheWarning(RuntimeWarning):
    """Numba's disk cache is unusable here: kernels compile in memory at every process start."""


_warned = threading.Event()


def _warn_uncached(reason: str, filename: str = __file__, lineno: int = 1) -> None:
    """Warn once per process that kernels run without a disk cache (at ``filename:lineno``)."""
    if _warned.is_set():
        return
    _warned.set()
    warnings.warn_explicit(
        f"{reason}: compiling Numba kernels without a disk cache (slower start, same results); "
        "set NUMBA_CACHE_DIR to a writable folder to cache them",
        KernelCacheWarning,
        filename,
        lineno,
    )


_PACKAGE = __name__.rpartition(".")[0]
"""``estimator.compiled``: a kernel module built on it imports something from it."""


def _built_on_compiled(py_func: Any) -> bool:
    """Whether the (still executing) module of ``py_func`` has imported anything from ``compiled``."""
    for value in list(getattr(py_func, "__globals__", {}).values()):
        name = value.__name__ if isinstance(value, ModuleType) else getattr(value, "__module__", None)
        if isinstance(name, str) and (name == _PACKAGE or name.startswith(_PACKAGE + ".")):
            return True
    return False


class _UncachedLocator(_CacheLocator):
    """Numba's last-resort cache locator, for the kernels of modules built on this package.

    Chosen only when every locator of Numba's own found no writable folder, and only for a module
    that imports from ``compiled`` (every project module with kernels does; the others are left
    to Numba's error). It reads and writes nothing: :func:`guard_kernel_cache`, which every such
    module's kernels pass through (tests/compiled/test_cache.py), replaces their cache by Numba's
    ``NullCache``.
    """

    def __init__(self, py_file: str) -> None:
        self._py_file = py_file

    def ensure_cache_path(self) -> None:
        raise OSError(f"no writable cache folder for {self._py_file}")

    def get_cache_path(self) -> str:
        return os.path.join(os.path.dirname(self._py_file), "__pycache__")

    def get_source_stamp(self) -> None:
        return None

    def get_disambiguator(self) -> str:
        return ""

    @classmethod
    def from_function(cls, py_func: Any, py_file: str) -> _UncachedLocator | None:
        if not _built_on_compiled(py_func):
            return None
        _warn_uncached(
            "no writable Numba cache folder (package, NUMBA_CACHE_DIR, user cache)",
            py_file,
            py_func.__code__.co_firstlineno,
        )
        return cls(py_file)


_NUMBA_LOCATORS: list[Any] = CacheImpl._locator_classes
if _UncachedLocator not in _NUMBA_LOCATORS:
    _NUMBA_LOCATORS.append(_UncachedLocator)


def _uncached(kernel: Any) -> bool:
    """Replace the cache of a kernel that got :class:`_UncachedLocator` by ``NullCache``; True if so."""
    if isinstance(kernel._cache._impl.locator, _UncachedLocator):
        kernel._cache = NullCache()
        return True
    return False


def _load_overload(cache: Any, sig: Any, target_context: Any) -> Any:
    """Numba's ``Cache.load_overload`` without its first step, a refresh of the target context.

    That refresh imports every implementation registry of Numba (SciPy's BLAS among them:
    0.4-0.9 s of each warm start, most of it) so that a compile can find them; rebuilding a
    cached kernel needs only the runtime its allocations call into. A compile later in the
    process refreshes the context itself (``numba.core.compiler.compile_extra``).
    """
    rtsys.initialize(target_context)
    with cache._guard_against_spurious_io_errors():
        return cache._load_overload(sig, target_context)


def guard_kernel_cache(module_name: str, *, compile_here: tuple[str, ...] = ()) -> None:
    """Flush the cached kernels of ``module_name`` whenever a project source they depend on changes.

    Call at the end of a module that defines ``@njit(cache=True)`` kernels:
    ``guard_kernel_cache(__name__)``. No file is touched until a kernel is first called.
    Uncompiled kernels run as Python while a background process compiles them
    (:mod:`estimator.compiled.background`), except those named in ``compile_here``: kernels
    whose one call can be long (a filter over a whole recorded sequence), which would run
    far longer as Python than their compile takes, compile in the calling process.
    """
    defined = guarded_kernels(module_name)
    unknown = sorted(set(compile_here) - {kernel.__name__ for kernel in defined})
    if unknown:
        raise ValueError(f"compile_here names no kernel of {module_name}: {', '.join(map(repr, unknown))}")
    kernels = [kernel for kernel in defined if not _uncached(kernel)]
    if not kernels:
        return
    guard = _SourceGuard(module_name, kernels)
    for kernel in kernels:
        cache = kernel._cache
        if getattr(cache, "source_guard", None) is not None:
            continue
        original_save = cache.save_overload

        def load_overload(sig: Any, target_context: Any, _cache: Any = cache) -> Any:
            guard.check()
            try:
                return _load_overload(_cache, sig, target_context)
            except OSError as exc:  # an unreadable cache: compile instead
                _cache.disable()
                _warn_uncached(f"cannot read Numba's cache at {_cache.cache_path} ({exc})")
                return None

        def save_overload(sig: Any, data: Any, _cache: Any = cache, _original: Any = original_save) -> None:
            try:
                _original(sig, data)
            except OSError as exc:  # a cache folder that turned read-only, a full disk ...
                _cache.disable()
                _warn_uncached(f"cannot write Numba's cache at {_cache.cache_path} ({exc})")

        cache.load_overload = load_overload
        cache.save_overload = save_overload
        cache.source_guard = guard
        if kernel.__name__ not in compile_here:
            background.install(kernel)
