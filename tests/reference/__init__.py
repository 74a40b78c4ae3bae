"""Independent plain-NumPy float64 reference implementations used by the test-suite."""
