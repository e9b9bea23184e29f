"""Stage 2, FMI: `FmuComponent` (FMI 1.0/2.0/3.0 through fmpy; its description, port layout and
generated step code in `description`, `layout`, `codegen`), `IsolatedFmuComponent` (the same in a
child process), archive limits, the project FMUs' build and lookup, and FMU inspection."""
