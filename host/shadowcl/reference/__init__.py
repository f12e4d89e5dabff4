"""Independent float64 NumPy implementations of every kernel: the oracles of the tests."""
