"""Test support shared across the test layers: synthetic signals, specs, row matching."""
