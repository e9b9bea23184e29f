"""Stage 7, SSP: reading and validating SSP archives (`read`, `schema`), writing them (`write`),
running any SSP's system and logging every signal (`run`), and exporting a scenario as an SSP that
runs as that scenario (`export`). It sits below navigation because an export is built from the
robot template and an exported archive runs as its scenario."""
