"""One PyTorch thread for a block of work (the one place this is done).

PyTorch's CPU kernels split some reductions by thread, and a few of their backward passes
(measured: EfficientNet-lite0's input gradient at 32 x 32 pixels with 2 threads, differing by
3e-4 from one call to the next on the same input) accumulate in whatever order the threads
finish. A result that must be the same bits in every process and on every replay (a Paparazzi
run, a training run, an adversarial image) is computed with one thread; at the sizes used here
it is no slower (the Gram loss at 128 x 128: 17 ms with one thread or two).
"""

from __future__ import annotations

from contextlib import contextmanager

__all__ = ["one_torch_thread"]


@contextmanager
def one_torch_thread():
    """Run the block with ``torch.set_num_threads(1)``; the caller's count is restored after."""
    import torch

    before = torch.get_num_threads()
    if before != 1:
        torch.set_num_threads(1)
    try:
        yield
    finally:
        if before != 1:
            torch.set_num_threads(before)
