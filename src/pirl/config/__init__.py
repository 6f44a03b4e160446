"""The bottom layer: facts and settings every other layer reads (nothing here imports upward)."""
