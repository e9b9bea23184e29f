"""Shared infrastructure of `planner` and `cosim`, importing neither: `native.load` builds a C file
of either package into a shared library and loads it with ctypes, `native.errors` holds
`NavcosimError`, the base of every error a user can cause."""
