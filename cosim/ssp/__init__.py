"""Stage 7, SSP: reading and validating SSP 1.0 and 2.0 archives (`read`, `schema`, and `experiment`
for their time and macro step), writing them (`write`),
running any SSP's system and logging every signal (`run`), and exporting a scenario as an SSP that
runs as that scenario (`export`). It sits below navigation because an export is built from the
robot template and an exported archive runs as its scenario."""
