"""Worker processes that share the machine instead of oversubscribing it.

Every worker process that starts its own multi-threaded math library (BLAS, OpenMP) takes a
thread per core: N such workers on N cores run slower than one. Pools (batch `--jobs`, the
experiments) start their workers inside `single_threaded_math()`. Results do not depend on
this: the package's reductions avoid BLAS, so they are the same for any thread count.
"""

from __future__ import annotations

import contextlib
import os
from collections.abc import Iterator

MATH_THREAD_VARS = ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "VECLIB_MAXIMUM_THREADS")


@contextlib.contextmanager
def single_threaded_math() -> Iterator[None]:
    """While worker processes start, set the math libraries' thread counts to 1 in the
    environment they inherit, unless the user set them."""
    saved = {name: os.environ.get(name) for name in MATH_THREAD_VARS}
    for name in MATH_THREAD_VARS:
        os.environ.setdefault(name, "1")
    try:
        yield
    finally:
        for name, value in saved.items():
            if value is None:
                os.environ.pop(name, None)
            else:
                os.environ[name] = value
