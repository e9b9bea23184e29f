"""Stage 6, the robot pipeline as a system: the planner component, the navigation template that
turns a scenario into a `System`, outcome checks, and the run loop that records it."""
