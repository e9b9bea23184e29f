"""Stage 4, scenarios: the TOML schema, validation with errors that name the file and key, and the
typed `Scenario` the later stages build from."""
