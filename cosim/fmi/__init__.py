"""Stage 2, FMI: `FmuComponent` (FMI 2.0/3.0 through fmpy), the project FMUs' build and lookup, and
FMU inspection."""
