"""The topic table (cosim.scenario.topics) is what the recorder writes and what docs/logs.md lists."""

from __future__ import annotations

import re
from pathlib import Path

from cosim.scenario.topics import REMAPPABLE_TOPICS, TOPIC_TYPES, TOPICS

DOCS = Path(__file__).resolve().parents[2] / "docs" / "logs.md"


def _documented_topics() -> dict[str, str]:
    """Topic -> type of the first table in docs/logs.md (`| `/a`, `/b` | `type` | ... |` rows)."""
    topics = {}
    for line in DOCS.read_text().splitlines():
        cells = [cell.strip() for cell in line.strip().strip("|").split("|")]
        if len(cells) < 3 or not cells[0].startswith("`/"):
            continue
        kind = cells[1].strip("`")
        for name in re.findall(r"`(/[^`]+)`", cells[0]):
            topics[name] = kind
    return topics


def test_docs_list_every_topic_with_its_type():
    documented = _documented_topics()
    signals = {
        name: kind for name, kind in documented.items() if name.startswith(("/signals/", "/text_signals/"))
    }
    assert len(signals) == 2, "docs/logs.md no longer documents /signals/ and /text_signals/<component>"
    assert {name: kind for name, kind in documented.items() if name not in signals} == TOPIC_TYPES


def test_every_topic_is_remappable_by_its_name_without_the_slash():
    assert REMAPPABLE_TOPICS == tuple(topic.name.removeprefix("/") for topic in TOPICS)
    assert len(set(REMAPPABLE_TOPICS)) == len(TOPICS)


def test_a_run_log_holds_the_table_types(tmp_path):
    from mcap.reader import make_reader

    from cosim.navigation.run import run_scenario
    from cosim.scenario.load import load_scenario

    scenario = DOCS.parents[1] / "scenarios" / "warehouse_diff_drive_one_obstacle.toml"
    out = tmp_path / "run.mcap"
    # With the sensors that are off unless their section is there.
    overrides = ["simulation.stop_time=1.0", "output.plot=false", "imu={}", "bumper={}"]
    run_scenario(load_scenario(scenario, overrides), out)
    with out.open("rb") as stream:
        summary = make_reader(stream).get_summary()
    written = {
        channel.topic: summary.schemas[channel.schema_id].name
        for channel in summary.channels.values()
        if not channel.topic.startswith("/signals/")
    }
    assert written == TOPIC_TYPES  # a robot run with obstacles writes every topic of the table
