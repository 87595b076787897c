"""Long arrays read in blocks, so that no temporary grows with a run's length."""

#: Samples read at once: a block's temporaries stay near 1 MB whatever the run's length [samples].
BLOCK = 1 << 14


def blocks(n, size=BLOCK):
    """Slices ``[0, size), [size, 2·size), …`` that cover ``range(n)`` in order (the last one shorter)."""
    return (slice(lo, lo + size) for lo in range(0, n, size))
