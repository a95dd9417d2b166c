"""Worker processes that share the machine instead of oversubscribing it.

Every worker process that starts its own multi-threaded math library (BLAS, OpenMP, numba's
parallel kernels) takes a thread per core: N such workers on N cores run slower than one.
Pools (batch `--jobs`, the experiments) start their workers inside `single_threaded_math()`,
by spawn or forkserver (a forked worker keeps its parent's numba threads). Results do not
depend on this: the package's reductions avoid BLAS, and its parallel kernels give every
particle its own arithmetic, so they are the same for any thread count.
"""

from __future__ import annotations

import contextlib
import os
from collections.abc import Iterator

# NUMBA_NUM_THREADS: the compiled kernels' own threads (read when numba is imported: a worker
# started by spawn or forkserver, as the batch's are, imports it afresh).
MATH_THREAD_VARS = (
    "OMP_NUM_THREADS",
    "OPENBLAS_NUM_THREADS",
    "MKL_NUM_THREADS",
    "VECLIB_MAXIMUM_THREADS",
    "NUMBA_NUM_THREADS",
)


@contextlib.contextmanager
def environment(values: dict[str, str], *, keep_existing: bool = False) -> Iterator[None]:
    """Set environment variables (those already set stay, with `keep_existing`) for the
    duration, then restore the environment as it was."""
    saved = {name: os.environ.get(name) for name in values}
    for name, value in values.items():
        if not (keep_existing and name in os.environ):
            os.environ[name] = value
    try:
        yield
    finally:
        for name, old in saved.items():
            if old is None:
                os.environ.pop(name, None)
            else:
                os.environ[name] = old


def single_threaded_math() -> contextlib.AbstractContextManager[None]:
    """While worker processes start, set the math libraries' thread counts to 1 in the
    environment they inherit, unless the user set them."""
    return environment(dict.fromkeys(MATH_THREAD_VARS, "1"), keep_existing=True)
