"""Stage 1, the co-simulation core: the `Component` interface, `System` (components, connections,
rates, step order), algebraic loops (`loops`: found and iterated), the `Master` that steps a system
on an integer time base (`timebase`), and the compiled kernel (C)."""
