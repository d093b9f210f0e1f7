"""One BLAS thread for the identification's small dense algebra.

OpenBLAS splits even a 256 x 256 eigendecomposition over every core; on a
machine whose cores are busy with other work the threads wait for each
other and the call runs 10-30 times slower than on one thread (measured
here: 0.03 s against 0.6-0.9 s).  The diagnosis's matrices are small
(hundreds of columns) and many, so it runs with one BLAS thread
(threadpoolctl, the maintained way to set it at run time).
"""

from contextlib import nullcontext


def single_blas_thread():
    """A context in which BLAS uses one thread (no-op without threadpoolctl)."""
    try:
        from threadpoolctl import threadpool_limits
    except ImportError:  # pragma: no cover - a dependency; keep working without it
        return nullcontext()
    return threadpool_limits(limits=1, user_api="blas")
