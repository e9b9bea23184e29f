"""The text of `cosim log info`: what ran, how it ended, what the file holds."""

from __future__ import annotations

from cosim.logs.reader import Log


def format_info(log: Log) -> str:
    size = log.path.stat().st_size
    state = "complete" if log.is_complete else "INCOMPLETE (cut short: no footer; read up to its last chunk)"
    lines = [
        f"log       {log.path} ({_size(size)}, {state})",
        f"scenario  {log.scenario_name or '(not recorded)'}",
        f"duration  {log.duration:.3f} s (t = {log.start_time:.3f} .. {log.end_time:.3f} s)",
    ]
    run = log.metadata.get("navcosim", {})
    for key, label in (("start", "start"), ("goal", "goal"), ("navcosim_version", "navcosim")):
        if key in run:
            lines.append(f"{label:<9} {run[key]}")
    if run.get("overrides"):
        # The attached scenario.toml is the file as given; the run applied these on top of it.
        lines.append(f"--set     {run['overrides']} (applied over the attached scenario.toml)")
    outcome = log.metadata.get("outcome")  # as written
    if outcome is None:
        lines.append("outcome   (none recorded: the run did not end normally)")
    else:
        lines.append("outcome   " + ", ".join(f"{key} {value}" for key, value in outcome.items()))
    fmus = log.fmus
    if fmus:
        lines.append("FMUs")
        for component, fmu in fmus.items():
            lines.append(
                f"  {component:<13} {fmu.get('model_name', '?'):<22} FMI {fmu.get('fmi_version', '?'):<4} "
                f"guid {fmu.get('guid', '?')}  by {fmu.get('generation_tool', '?')}"
            )
    lines.append("topics")
    width = max((len(topic.name) for topic in log.topics), default=10)
    type_width = max((len(topic.type) for topic in log.topics), default=10)
    for topic in log.topics:
        rate = f"{topic.rate:10.2f} Hz" if topic.rate else " " * 13
        lines.append(f"  {topic.name:<{width}}  {topic.type:<{type_width}}  {topic.count:>9} msgs {rate}")
    if log.components:
        lines.append(
            "signals   " + ", ".join(f"{name} ({len(log.signal_names(name))})" for name in log.components)
        )
    else:
        lines.append("signals   none (no /signals/<component> channels: not a navcosim run log)")
    if log.text_components:
        # String and Binary variables: /text_signals/<component>, a record when a value changes
        lines.append(
            "text      "
            + ", ".join(f"{name} ({len(log.text_signals(name).names)})" for name in log.text_components)
        )
    if log.attachments:
        lines.append("attached  " + ", ".join(log.attachments))
    return "\n".join(lines)


def _size(size: int) -> str:
    for unit in ("B", "kB", "MB", "GB"):
        if size < 1000 or unit == "GB":
            return f"{size:.0f} {unit}" if unit == "B" else f"{size:.1f} {unit}"
        size /= 1000
    return f"{size} B"
