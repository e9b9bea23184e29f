"""Placeholder replaced below."""

SCENARIO_ANNOTATION = "org.navcosim.scenario"
