"""Named numpy arrays in one block of shared memory, visible to the master and its workers.

The parallel backend passes coupling values and output history between processes through
these arrays instead of pickled messages: a write by one process is a plain store that the
others see after the next synchronisation point.
"""

from __future__ import annotations

from multiprocessing import shared_memory

import numpy as np

ALIGN = 64  # bytes: one cache line, so that arrays written by different workers never share one

Layout = dict[str, tuple[tuple[int, ...], str]]  # array name -> (shape, numpy dtype string)


def _offsets(layout: Layout) -> tuple[dict[str, int], int]:
    """Byte offset of each array in the block, and the block size."""
    offsets: dict[str, int] = {}
    size = 0
    for name, (shape, dtype) in layout.items():
        offsets[name] = size
        nbytes = int(np.prod(shape, dtype=np.int64)) * np.dtype(dtype).itemsize
        size += -(-max(nbytes, 1) // ALIGN) * ALIGN
    return offsets, max(size, ALIGN)


class SharedArrays:
    """A set of named numpy arrays living in one `multiprocessing.shared_memory` block.

    The creating process owns the block and must call `unlink()` when done.  Pickling an
    instance (start methods spawn and forkserver) sends only the block name and layout;
    unpickling attaches to the same memory.  Under fork the views are simply inherited.
    """

    def __init__(self, layout: Layout, name: str | None = None):
        self.layout = dict(layout)
        offsets, size = _offsets(self.layout)
        self.owner = name is None
        self.shm = shared_memory.SharedMemory(name=name, create=self.owner, size=size if self.owner else 0)
        self.arrays: dict[str, np.ndarray] = {}
        for key, (shape, dtype) in self.layout.items():
            self.arrays[key] = np.ndarray(shape, dtype=dtype, buffer=self.shm.buf, offset=offsets[key])
        if self.owner:
            for a in self.arrays.values():
                a.fill(0)

    def __getitem__(self, key: str) -> np.ndarray:
        return self.arrays[key]

    def __getstate__(self) -> tuple[Layout, str]:
        return self.layout, self.shm.name

    def __setstate__(self, state: tuple[Layout, str]) -> None:
        layout, name = state
        self.__init__(layout, name)  # type: ignore[misc]

    def close(self) -> None:
        """Drop this process's views and mapping (the block itself stays until unlinked)."""
        self.arrays = {}
        try:
            self.shm.close()
        except BufferError:
            pass  # a view is still referenced somewhere; the mapping goes with the process

    def unlink(self) -> None:
        """Close, and if this process created the block, remove it from the system."""
        self.close()
        if self.owner:
            try:
                self.shm.unlink()
            except FileNotFoundError:
                pass
