"""Optional compilation of the closed loop's per-tick arithmetic.

A kernel is a plain Python function of floats and float arrays written as
scalar loops (the subset of Python that numba compiles).  When numba is
installed (``pip install 'robstiff-drake[fast]'``: numba ships wheels for
Linux, macOS and Windows, no compiler needed) it is compiled on its first
call and cached on disk (numba's ``cache=True``: the next process loads it
in milliseconds); without numba, or with the environment variable
ROBSTIFF_NO_JIT set, ``available()`` is false and the callers keep their
vectorised numpy reference, which is what every kernel is tested against
(tests/test_jit_kernels.py, to round-off).  A kernel whose compilation
fails (a platform numba does not support) falls back the same way, with
one warning.
"""

import contextlib
import inspect
import os
import types
import warnings

DISABLE_ENV = "ROBSTIFF_NO_JIT"

# ("on": available()'s answer, kept until "failed" or "off" changes; None: to be worked out again)
_STATE = {"numba": None, "checked": False, "failed": False, "on": None}


def _numba():
    if not _STATE["checked"]:
        _STATE["checked"] = True
        if not os.environ.get(DISABLE_ENV):
            try:
                import numba
                _STATE["numba"] = numba
            except ImportError:
                pass
    return _STATE["numba"]


def available():
    """True when kernels run compiled (numba importable, not disabled, no
    compilation has failed).  Asked by every compiled system's update, so
    kept: a dictionary look-up (0.04 us, where working it out takes 0.09)."""
    on = _STATE["on"]
    if on is None:
        on = _STATE["on"] = _numba() is not None and not _STATE["failed"] and not _STATE.get("off")
    return on


@contextlib.contextmanager
def disabled():
    """Within: ``available()`` is false (the callers run their numpy
    references), as with ROBSTIFF_NO_JIT set."""
    was = _STATE.get("off", False)
    _STATE["off"], _STATE["on"] = True, None
    try:
        yield
    finally:
        _STATE["off"], _STATE["on"] = was, None


class Kernel:
    """A function compiled with numba on its first call (``py_func``: the
    Python original, run as it is when numba is not there)."""

    def __init__(self, fn):
        self.py_func = fn
        self.__name__ = fn.__name__
        self.__doc__ = fn.__doc__
        self._impl = None

    def __call__(self, *args):
        impl = self._impl
        if impl is None:
            impl = self._impl = self._compile()
        try:
            return impl(*args)
        except Exception as e:  # (numba's typing and lowering errors: fall back, once)
            if impl is self.py_func:
                raise
            _STATE["failed"], _STATE["on"] = True, None
            warnings.warn(f"robstiff: compiled kernel {self.__name__} failed ({type(e).__name__}: {e}); "
                          f"running the numpy reference instead", RuntimeWarning, stacklevel=2)
            self._impl = self.py_func
            return self.py_func(*args)

    def compiled(self):
        """The compiled function itself (numba's dispatcher, compiled or
        loaded now), to call without this wrapper's cost (about 0.1 us a
        call), or this Kernel where nothing is compiled (``available()``
        false, or its compilation failed).  The dispatcher has no fallback:
        hold it for the argument types that a call through the Kernel has
        already run (a warm-up), and call it only while ``available()``."""
        if not available():
            return self
        impl = self._impl if self._impl is not None else self._compile()
        self._impl = impl
        return self if impl is self.py_func else impl

    def _compile(self):
        numba = _numba()
        if numba is None or _STATE["failed"]:
            return self.py_func
        fn = self.py_func
        # a kernel that calls other kernels calls their compiled versions (numba sees them through the globals)
        inner = _called(fn)
        if inner:
            scope = dict(fn.__globals__)
            for name, value in inner.items():
                if value._impl is None:
                    value._impl = value._compile()
                scope[name] = value._impl
            fn = types.FunctionType(fn.__code__, scope, fn.__name__, fn.__defaults__, fn.__closure__)
            fn.__qualname__, fn.__module__ = self.py_func.__qualname__, self.py_func.__module__
        compiled = numba.njit(cache=True, nogil=True)(fn)
        if inner:
            _stamp_with_callees(compiled, self)
        return compiled


def _called(fn):
    """{name: Kernel} of the kernels the function ``fn`` calls."""
    return {name: value for name, value in fn.__globals__.items()
            if name in fn.__code__.co_names and isinstance(value, Kernel)}


def _source_files(k, seen=None):
    """The source files of kernel ``k`` and of every kernel it calls, sorted."""
    seen = set() if seen is None else seen
    if id(k) not in seen:
        seen.add(id(k))
        yield inspect.getsourcefile(k.py_func)
        for inner in _called(k.py_func).values():
            yield from _source_files(inner, seen)


def _stamp_with_callees(compiled, k):
    """numba's disk cache of a kernel is fresh while the kernel's own file
    is unchanged (its modification time and size); a kernel that calls
    kernels of other files would keep their old code after they change.
    The stamp of its cache is made that of every file involved, so that
    editing any of them compiles it again.  (numba's cache internals: if
    they are not there, the cache stays keyed on the kernel's own file.)"""
    try:
        cache_file = compiled._cache._cache_file
        stamps = [cache_file._source_stamp]
        for path in sorted(set(_source_files(k)) - {inspect.getsourcefile(k.py_func)}):
            st = os.stat(path)
            stamps.append((path, st.st_mtime, st.st_size))
        cache_file._source_stamp = tuple(stamps)
    except (AttributeError, OSError, TypeError):
        pass


def kernel(fn):
    """Decorator: ``fn`` as a Kernel."""
    return Kernel(fn)
