"""Stage 1, the co-simulation core: the `Component` interface, `System` (components, connections,
rates), the `Master` that steps it on an integer time base, and the compiled kernel (C)."""
