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
    fleet = log.fleet_outcome
    if fleet is not None:
        lines += fleet_lines(fleet)
    elif outcome is None:
        lines.append("outcome   (none recorded: the run did not end normally)")
    else:
        lines.append("outcome   " + ", ".join(f"{key} {value}" for key, value in outcome.items()))
    fmus = log.fmus
    if fmus:
        lines.append("FMUs")
        name_width = max(13, *(len(component) for component in fmus))  # a fleet's: robot1:pure_pursuit
        for component, fmu in fmus.items():
            lines.append(
                f"  {component:<{name_width}} {fmu.get('model_name', '?'):<22} "
                f"FMI {fmu.get('fmi_version', '?'):<4} "
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
    elif log.fleet_outcome is not None:
        lines.append("signals   none (a fleet's log of navcosim 3f13a1e or older: poses on /<robot>/odom)")
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


def fleet_lines(fleet: dict) -> list[str]:
    """A fleet's outcome (`Log.fleet_outcome`): a row per robot, the fleet's line, each collision."""
    rows = [("  robot", "status", "goals", "time [s]", "distance [m]", "clearance walls [m]",
             "clearance robots [m]", "deadlocked")]  # fmt: skip
    for name, robot in fleet.get("robots", {}).items():
        rows.append(
            (
                f"  {name}", str(robot.get("status")), f"{robot.get('goals_reached')}/{robot.get('goals')}",
                _number(robot.get("completion_time"), 2), _number(robot.get("distance"), 2),
                _number(robot.get("min_clearance_walls"), 3), _number(robot.get("min_clearance_robots"), 3),
                "-" if robot.get("deadlocked_at") is None else f"since {robot['deadlocked_at']:.2f} s",
            )
        )  # fmt: skip
    widths = [max(len(row[i]) for row in rows) for i in range(len(rows[0]))]
    lines = ["fleet"]
    lines += ["  ".join(cell.ljust(w) for cell, w in zip(row, widths, strict=True)).rstrip() for row in rows]
    lines.append("  " + fleet_line(fleet))
    lines += [f"  collision: {text}" for _, text in collision_texts(fleet)]
    return lines


def fleet_line(fleet: dict) -> str:
    """The fleet's line: how it ended, makespan, throughput, collisions, deadlocks."""
    makespan = fleet.get("makespan")
    return (
        f"fleet: {fleet.get('reason')} at t = {_number(fleet.get('time'), 2)} s; makespan "
        f"{'-' if makespan is None else f'{makespan:.2f} s'}; throughput "
        f"{_number(fleet.get('throughput_per_hour'), 1)} goals/h; "
        f"collisions {len(fleet.get('collisions', []))}; "
        f"deadlocks {len(fleet.get('deadlocks', []))}"
    )


def collision_texts(fleet: dict) -> list[tuple[dict, str]]:
    """Every collision of a fleet outcome, robot-robot then wall, as (record, one line)."""
    texts = []
    for contact in fleet.get("collisions", []):
        (a, b), (ca, cb) = contact["robots"], contact["centers"]
        texts.append(
            (
                contact,
                f"{a} and {b} collide at t = {contact['time']:.3f} s at ({ca[0]:.3f}, {ca[1]:.3f}) "
                f"and ({cb[0]:.3f}, {cb[1]:.3f})",
            )
        )
    for name, robot in fleet.get("robots", {}).items():
        if robot.get("collision"):
            t, x, y = robot["collision"]
            record = {"robots": [name], "time": t, "centers": [[x, y]]}
            texts.append((record, f"{name} hits a wall or obstacle at t = {t:.3f} s at ({x:.3f}, {y:.3f})"))
    return texts


def _number(value, digits: int) -> str:
    return "-" if value is None else f"{value:.{digits}f}"


def _size(size: int) -> str:
    for unit in ("B", "kB", "MB", "GB"):
        if size < 1000 or unit == "GB":
            return f"{size:.0f} {unit}" if unit == "B" else f"{size:.1f} {unit}"
        size /= 1000
    return f"{size} B"
