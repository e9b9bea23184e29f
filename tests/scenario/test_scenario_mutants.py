"""The scenario mutator (issue 10): hypothesis mutates the shipped scenarios, and composed ones with
`[components.*]` and `[[connections]]`, in hostile ways, and feeds each mutant to the real `cosim`
entry point (`cosim.cli.main`, in-process; a few through a subprocess).

Whatever the mutant, the command must end the way the README promises: no traceback, exit 0, 1 or
2, and exit 2 with one line per problem, each naming the scenario file (and the key, where the
problem has one) or the `--set` override, with quoted values cut short (no 1 MB echo).

Mutations: keys deleted, renamed to near misses, added; values replaced by other TOML types
(booleans, strings, arrays, tables, dates) or extreme numbers (0, negative, 1e300, nan, inf,
2**63, 5e-324); huge strings; map paths that are missing, directories, symbolic-link loops, 5000
characters long, hold a NUL byte, or point at a hostile map YAML; FMU paths that are missing,
empty, not a zip, a directory; connections duplicated, swapped, looped, misnamed; template
components replaced or left out ([system] remove); obstacles of odd shapes; `--set` overrides,
well and badly formed; the TOML text itself cut or nested deep.

Most mutants are only loaded and described (`cosim system`); about one in eight is run for 0.05 s
(`cosim run --set simulation.stop_time=0.05 --no-plot`). The examples are derandomized, so CI sees
the same mutants every time. The counts (mutants, exit codes) are printed at the end.
"""

from __future__ import annotations

import collections
import contextlib
import copy
import datetime
import io
import json
import math
import os
import re
import subprocess
import sys
import tomllib
from pathlib import Path

import pytest
from hypothesis import HealthCheck, Phase, given, settings
from hypothesis import strategies as st

from cosim.cli import main

REPO = Path(__file__).resolve().parents[2]
SCENARIOS = REPO / "scenarios"
SHIPPED = sorted(
    p for p in SCENARIOS.glob("*.toml") if not p.name.startswith("fleet_")
)  # fleets: tests/fleet
MAP_YAML = SCENARIOS / "maps" / "warehouse.yaml"
MAP_PGM = SCENARIOS / "maps" / "warehouse.pgm"
MUTANTS = 320
# An error line beyond the file name: a composition problem may list up to 12 of an FMU's own
# variable names, so it is longer than a loading problem, but at most this long.
LINE_LIMIT = 1000
WORD_LIMIT = 200  # characters without a space: whatever the user wrote is quoted cut short
HUGE = 1_000_000  # characters of a huge string value

# A composed scenario: a second differential drive fed by the mixer, through a scale and offset.
GHOST = {
    "components": {
        "ghost": {
            "fmu": "DifferentialDrive",
            "wheel_radius": 0.1,
            "track_width": 0.5,
            "wheel_speed_left": 0.0,
            "wheel_speed_right": 0.0,
        },
    },
    "connections": [
        {"from": "mixer.v", "to": "ghost.v", "scale": 0.5, "offset": 0.1},
        {"from": "mixer.omega", "to": "ghost.omega"},
    ],
}


def base_scenarios() -> list[tuple[str, dict]]:
    """(name, parsed TOML) of every shipped scenario, its map path absolute, and two composed ones."""
    bases = []
    for path in SHIPPED:
        raw = tomllib.loads(path.read_text())
        raw["map"]["file"] = str((SCENARIOS / raw["map"]["file"]).resolve())
        bases.append((path.stem, raw))
    for stem in ("warehouse_diff_drive_one_obstacle", "warehouse_bicycle_three_obstacles"):
        composed = copy.deepcopy(dict(bases)[stem])
        composed.update(copy.deepcopy(GHOST))
        bases.append((f"{stem}+ghost", composed))
    return bases


BASES = base_scenarios()


# --- a TOML writer (the mutants are dictionaries; the CLI reads files) ---------------------------


def toml_key(key: str) -> str:
    return key if re.fullmatch(r"[A-Za-z0-9_-]+", key) else json.dumps(key)


def toml_value(value) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, int):
        return str(value)
    if isinstance(value, float):
        if math.isnan(value):
            return "nan"
        if math.isinf(value):
            return "inf" if value > 0 else "-inf"
        return repr(value)
    if isinstance(value, str):  # a basic string: JSON's escapes are TOML's, but for DEL
        return json.dumps(value, ensure_ascii=False).replace("\x7f", "\\u007f")
    if isinstance(value, datetime.date | datetime.time):
        return value.isoformat()
    if isinstance(value, list):
        return "[" + ", ".join(toml_value(item) for item in value) + "]"
    if isinstance(value, dict):
        return "{" + ", ".join(f"{toml_key(k)} = {toml_value(v)}" for k, v in value.items()) + "}"
    raise TypeError(type(value))


def is_table_array(value) -> bool:
    return isinstance(value, list) and value and all(isinstance(item, dict) for item in value)


def toml_text(raw: dict) -> str:
    """`raw` as TOML: top-level sections as [tables], lists of tables as [[arrays]]."""
    lines = [f"{toml_key(k)} = {toml_value(v)}" for k, v in raw.items() if not isinstance(v, dict)
             and not is_table_array(v)]  # fmt: skip

    def table(name: str, body: dict) -> None:
        lines.append(f"\n[{name}]")
        nested = []
        for key, value in body.items():
            if isinstance(value, dict) and value and all(isinstance(v, dict) for v in value.values()):
                nested.append((key, value))  # e.g. [components.ghost]
            else:
                lines.append(f"{toml_key(key)} = {toml_value(value)}")
        for key, value in nested:
            for sub, sub_body in value.items():
                table(f"{name}.{toml_key(key)}.{toml_key(sub)}", sub_body)

    for key, value in raw.items():
        if isinstance(value, dict):
            table(toml_key(key), value)
        elif is_table_array(value):
            for item in value:
                lines.append(f"\n[[{toml_key(key)}]]")
                lines.extend(f"{toml_key(k)} = {toml_value(v)}" for k, v in item.items())
    return "\n".join(lines) + "\n"


# --- hostile values and mutations ----------------------------------------------------------------

EXTREME_NUMBERS = [
    0, 0.0, -0.0, -1, -1.5, 1e300, -1e300, math.nan, math.inf, -math.inf, 2**63, 2**63 - 1, -(2**63),
    2**64, 10**400, 5e-324, 1e-300, 1e-9, 1.5e-9, 1e9, 1e20, 0.1, 7, 1000000,
]  # fmt: skip
ODD_TYPES = [
    True, False, "", "1.5", "nan", "DifferentialDrive", "x" * 5000, [], [1.0], [1.0, 2.0, 3.0],
    [[1.0, 2.0]], ["a", "b"], [True, False], {}, {"a": 1}, {"x": {"y": [1, 2]}},
    datetime.date(2026, 1, 1), datetime.datetime(2026, 1, 1, 12, 0), datetime.time(12, 0),
]  # fmt: skip
hostile_value = st.one_of(
    st.sampled_from(EXTREME_NUMBERS),
    st.sampled_from(ODD_TYPES),
    st.floats(allow_nan=True, allow_infinity=True),
    st.integers(min_value=-(2**70), max_value=2**70),
    st.text(alphabet=st.characters(codec="utf-8", exclude_categories=("Cs",)), max_size=40),
    st.just("y" * HUGE),
    st.lists(st.floats(allow_nan=False, width=32), max_size=5),
)


def near_miss(key: str, choice: int) -> str:
    """A name close to `key`: a letter dropped, doubled, swapped, upper-cased, or - for _."""
    if not key:
        return "x"
    i = choice % len(key)
    variants = [
        key[:i] + key[i + 1 :],
        key[:i] + key[i] + key[i:],
        key[:i] + key[i + 1 : i + 2] + key[i : i + 1] + key[i + 2 :],
        key.upper(),
        key.replace("_", "-") if "_" in key else key + "s",
        key + "_",
    ]
    variant = variants[choice % len(variants)]
    return variant if variant != key else key + "x"


def paths_of(raw, prefix=()) -> list[tuple]:
    """Every key path in `raw` (tables and list items included)."""
    found = []
    items = raw.items() if isinstance(raw, dict) else enumerate(raw) if isinstance(raw, list) else ()
    for key, value in items:
        found.append((*prefix, key))
        found.extend(paths_of(value, (*prefix, key)))
    return found


def parent_of(raw, path):
    node = raw
    for part in path[:-1]:
        node = node[part]
    return node


class Mutator:
    """Mutations of one parsed scenario; `files` makes hostile files in the test's directory."""

    def __init__(self, data, raw: dict, files: Path):
        self.data = data
        self.rnd = data.draw(st.randoms(use_true_random=False), label="choices")
        self.raw = raw
        self.files = files
        self.overrides: list[str] = []
        self.text_edit = None
        self.notes: list[str] = []

    def choice(self, options, label=None):
        return self.rnd.choice(list(options))

    def hostile(self, label):
        """A hostile value: an extreme number, another TOML type, or one hypothesis makes up."""
        kind = self.rnd.randrange(4)
        if kind == 0:
            return self.rnd.choice(EXTREME_NUMBERS)
        if kind == 1:
            return self.rnd.choice(ODD_TYPES)
        return self.data.draw(hostile_value, label=label)

    def pick_path(self):
        return self.choice(paths_of(self.raw))

    # Each mutation returns nothing and edits self.raw / self.overrides / self.text_edit.
    def delete_key(self):
        path = self.pick_path()
        parent = parent_of(self.raw, path)
        del parent[path[-1]]
        self.notes.append(f"delete {path}")

    def rename_key(self):
        path = self.pick_path()
        parent = parent_of(self.raw, path)
        if isinstance(parent, list):
            return self.delete_key()
        new = near_miss(str(path[-1]), self.rnd.randint(0, 60))
        parent[new] = parent.pop(path[-1])
        self.notes.append(f"rename {path} -> {new}")

    def add_key(self):
        tables = [p for p in paths_of(self.raw) if isinstance(parent_of(self.raw, p)[p[-1]], dict)]
        target = self.choice([(), *tables])
        node = parent_of(self.raw, (*target, None)) if target else self.raw
        node = node if not target else parent_of(self.raw, target)[target[-1]]
        existing = [str(k) for k in node] or ["key"]
        name = near_miss(self.choice(existing), self.rnd.randint(0, 60))
        name = self.choice([name, "z" * 3000, "", "a.b", "[x]"])
        node[name] = self.hostile("value")
        self.notes.append(f"add {target}.{name[:30]}")

    def replace_value(self):
        path = self.pick_path()
        value = self.hostile("value")
        parent_of(self.raw, path)[path[-1]] = value
        self.notes.append(f"replace {path} = {str(value)[:40]}")

    def scale_number(self):
        numbers = [p for p in paths_of(self.raw) if isinstance(parent_of(self.raw, p)[p[-1]], int | float)
                   and not isinstance(parent_of(self.raw, p)[p[-1]], bool)]  # fmt: skip
        if not numbers:
            return self.replace_value()
        path = self.choice(numbers)
        factor = self.choice([0, -1, 1e-12, 1e6, 1e300, 1 + 1e-9, 2**63])
        parent = parent_of(self.raw, path)
        try:
            parent[path[-1]] = parent[path[-1]] * factor
        except OverflowError:
            parent[path[-1]] = math.inf
        self.notes.append(f"scale {path} by {factor}")

    def map_path(self):
        choice = self.rnd.randint(0, 10)
        files = self.files
        loop = files / "loop.yaml"
        if not loop.is_symlink():
            os.symlink(files / "loop2.yaml", loop)
            os.symlink(loop, files / "loop2.yaml")
        (files / "a_directory.yaml").mkdir(exist_ok=True)
        options = [
            str(files / "missing.yaml"),
            str(files / "a_directory.yaml"),
            str(loop),
            "m" * 5000 + ".yaml",
            "maps/\0warehouse.yaml",
            str(MAP_PGM),  # an image without its YAML
            "/dev/null",
            str(SCENARIOS / "warehouse_apf.toml"),  # not a map at all
            "",
            "../" * 300 + "etc/passwd",
            None,  # a hostile YAML beside a copy of the image
        ]
        path = options[choice]
        if path is None:
            path = str(self.hostile_yaml())
        self.raw.setdefault("map", {})["file"] = path
        self.notes.append(f"map file {path[:60]!r}")

    def hostile_yaml(self) -> Path:
        lines = {
            "image": str(MAP_PGM),
            "resolution": "0.1",
            "origin": "[0.0, 0.0, 0.0]",
            "negate": "0",
            "occupied_thresh": "0.65",
            "free_thresh": "0.196",
        }
        key = self.choice(sorted(lines))
        bad = self.choice(["", "-1", "0", "1e300", "nan", "inf", "[1, 2]", "{a: 1}", "x" * 5000,
                           "/nonexistent.pgm", str(self.files), "true", "[nan, 0, 0]", None])  # fmt: skip
        if bad is None:
            del lines[key]
        else:
            lines[key] = bad
        path = self.files / f"hostile_{abs(hash((key, bad))) % 10**8}.yaml"
        path.write_text("".join(f"{k}: {v}\n" for k, v in lines.items()))
        self.notes.append(f"yaml {key}: {str(bad)[:40]}")
        return path

    def fmu_path(self):
        files = self.files
        (files / "empty.fmu").write_bytes(b"")
        (files / "text.fmu").write_text("not a zip archive\n")
        (files / "dir.fmu").mkdir(exist_ok=True)
        options = [
            str(files / "missing.fmu"),
            str(files / "empty.fmu"),
            str(files / "text.fmu"),
            str(files / "dir.fmu"),
            "DifferentialDrivee",
            "Bicycle",
            "VectorFieldHistogram",
            "f" * 5000 + ".fmu",
            "/dev/null/x.fmu",
            "",
        ]
        sections = [
            s for s in ("vehicle", "pure_pursuit", "vfh", "mixer") if isinstance(self.raw.get(s), dict)
        ]
        ghost = (
            self.raw.get("components", {}).get("ghost")
            if isinstance(self.raw.get("components"), dict)
            else None
        )
        if isinstance(ghost, dict):
            sections.append("ghost")
        if not sections:
            return self.replace_value()
        section = self.choice(sections)
        fmu = self.choice(options)
        (ghost if section == "ghost" else self.raw[section])["fmu"] = fmu
        self.notes.append(f"{section}.fmu = {fmu[:60]!r}")

    def connections(self):
        connections = self.raw.get("connections")
        if not isinstance(connections, list) or not connections:
            connections = self.raw["connections"] = [{"from": "mixer.v", "to": "vehicle.v"}]
        choice = self.rnd.randint(0, 11)
        first = connections[0] if isinstance(connections[0], dict) else {}
        endpoints = ["mixer.v", "ghost.v", "vehicle.x", "vehicle.v", "ghost.x", "vehicel.x", "mixer",
                     "a.b.c", "", ".", "mixer.", ".v", "planner.waypoints", "lidar.ranges[1]",
                     "ghost.wheel_radius", "mixer.v" * 1000]  # fmt: skip
        if choice == 0:
            connections.append(copy.deepcopy(first))  # duplicate
        elif choice == 1:
            connections.append({"from": first.get("to"), "to": first.get("from")})  # swapped
        elif choice == 2:
            connections.append({"from": "ghost.x", "to": "ghost.v"})  # a loop through one component
        elif choice == 3:
            connections.append({"from": "vehicle.x", "to": "vehicle.v"})  # direct feed-back
        elif choice == 4:
            connections.append({"from": "vehicle.theta", "to": "mixer.v_in"})  # replaces a template link
        elif choice == 5:
            connections[0] = self.choice([[], "mixer.v", 1, {}, [{"from": "a"}]])
        elif choice == 6:
            self.raw["connections"] = self.choice([{}, "x", 1, [1, 2]])
        else:
            connections.append(
                {
                    "from": self.choice(endpoints),
                    "to": self.choice(endpoints),
                    **({"scale": self.hostile("scale")} if choice == 8 else {}),
                    **({"offset": self.hostile("offset")} if choice == 9 else {}),
                }
            )
        self.notes.append(f"connections #{choice}")

    def components(self):
        components = self.raw.setdefault("components", {})
        if not isinstance(components, dict):
            return self.replace_value()
        choice = self.rnd.randint(0, 7)
        name = self.choice(["extra", "vehicle", "planner", "lidar", "pure_pursuit", "mixer", "9bad", "a-b",
                            "é", "x" * 300])  # fmt: skip
        table = [
            {"fmu": "DifferentialDrive"},  # inputs neither connected nor held
            {"fmu": "PurePursuit", "rate": 20.0},
            {"fmu": "Bicycle", "rate": 3.0},  # not a whole number of macro steps
            {"fmu": "DifferentialDrive", "v": 0.0, "omega": 0.0, "wheel_speed_left": 0.0,
             "wheel_speed_right": 0.0, "isolation": self.choice(["none", "thread", 1])},
            {"fmu": "DifferentialDrive", "nan_outputs": self.choice([["x"], "x", [1]])},
            {"fmu": "AvoidanceMixer", "no_such_variable": 1.0},
            "DifferentialDrive",
            {},
        ][choice]  # fmt: skip
        components[name] = table
        self.notes.append(f"component {name[:20]} #{choice}")

    def obstacles(self):
        obstacles = self.raw.get("obstacles")
        if not isinstance(obstacles, list):
            obstacles = self.raw["obstacles"] = []
        shape = self.choice(
            [
                {"type": "polygon", "vertices": [[0, 0], [1, 1], [2, 2]]},  # collinear
                {"type": "polygon", "vertices": [[30, 30], [30, 30], [30, 30]]},
                {"type": "polygon", "vertices": [[30, 30], [40, 40], [30, 40], [40, 30]]},  # bow-tie
                {"type": "polygon", "vertices": [[30 + math.cos(a / 1000), 30 + math.sin(a / 1000)]
                                                 for a in range(0, 6283, 3)]},  # 2095 vertices
                {"type": "polygon", "vertices": [[1e300, 0], [0, 1e300], [-1e300, 0]]},
                {"type": "circle", "center": [6.0, 6.0], "radius": 1.0},  # on the start
                {"type": "circle", "center": [50.0, 30.0], "radius": 1e300},
                {"type": "circle", "center": [50.0, 30.0], "radius": 5e-324},
                {"type": "rectangle", "center": [50.0, 30.0], "size": [1e308, 1e308], "yaw": 1e300},
                {"type": "rectangle", "center": [50.0, 30.0], "size": [0.0, 1.0]},
                {"type": "circle", "radius": 1.0, "path": [[30, 30], [30, 30]], "speed": 1.0},
                {"type": "circle", "radius": 1.0, "path": [[30, 30], [40, 30]], "speed": 1e-300},
                {"type": "circle", "center": [30, 30], "radius": 1.0, "velocity": [0.0, 0.0],
                 "start_time": 1e300},
                {"type": "circle", "center": [30, 30], "radius": 1.0, "velocity": [70.0, 70.1]},
                {"type": "circle", "radius": 1.0, "path": [[30, 30], [40, 30]], "speed": 1.0,
                 "motion": "pingpong"},
                {"type": "triangle", "center": [30, 30]},
                {"type": "circle", "center": [30, 30, 0], "radius": 1.0},
                {"type": "circle", "center": [math.nan, 30], "radius": 1.0},
                "circle",
                [],
            ],
        )  # fmt: skip
        count = self.choice([1, 1, 2, 1001] if len(str(shape)) < 200 else [1, 2])  # text of at most 0.2 MB
        obstacles.extend(copy.deepcopy(shape) for _ in range(count))
        self.notes.append(f"obstacle {str(shape)[:60]} x{count}")

    def system_remove(self):
        """`[system] remove`: template components left out, some of them needed, some unknown."""
        names = ["vfh", "mixer", "pure_pursuit", "planner", "lidar", "vehicle", "ghost", "vhf", "", "vfh"]
        removed = self.rnd.sample(names, self.rnd.randint(0, 3))
        self.raw["system"] = {"remove": self.choice([removed, removed, "vfh", [1], {}])}
        self.notes.append(f"[system] remove = {self.raw['system']['remove']}")

    def override(self):
        paths = [".".join(str(part) for part in path) for path in paths_of(self.raw) if len(path) <= 3]
        key = self.choice(paths + ["nosuch.key", "simulation", "obstacles.99.radius",
                                                 "obstacles.x.radius", "scenario.name.deeper", "", "a..b",
                                                 "k" * 3000])  # fmt: skip
        if self.rnd.random() < 0.5:
            value = self.choice(["0", "-1", "1e300", "nan", "inf", "true", "[1, 2]", "{a = 1}", "",
                                 "'x'", "[[[[", "9" * 5000, "2026-01-01", "x" * 100_000, "= =",
                                 "[" * 2000])  # fmt: skip
        else:
            value = self.hostile("override value")
            value = value if isinstance(value, str) and len(value) > 100 else toml_value(value)
        form = self.choice(["{k}={v}"] * 6 + ["{k}", "={v}", "{k} = {v}"])
        self.overrides.append(form.format(k=key, v=value))
        self.notes.append(f"--set {key[:30]}=…")

    def text(self):
        self.text_edit = self.choice(["cut", "nest", "duplicate", "bom", "bytes", "crlf"])
        if self.text_edit == "cut":
            self.cut = self.rnd.random()
        self.notes.append(f"text {self.text_edit}")

    MUTATIONS = (
        "delete_key", "rename_key", "add_key", "replace_value", "replace_value", "scale_number",
        "map_path", "fmu_path", "connections", "components", "system_remove", "obstacles", "override",
        "override", "text",
    )  # fmt: skip

    def write(self, path: Path) -> None:
        text = toml_text(self.raw)
        edit = self.text_edit
        if edit == "cut":
            text = text[: int(len(text) * self.cut)]
        elif edit == "nest":
            text += "deep = " + "[" * 1200 + "]" * 1200 + "\n"
        elif edit == "duplicate":
            text += "\n[simulation]\nstop_time = 1.0\n"
        elif edit == "bom":
            text = "\ufeff" + text
        elif edit == "crlf":
            text = text.replace("\n", "\r\n")
        data = text.encode("utf-8")
        if edit == "bytes":
            data = data[:40] + b"\xff\xfe\x00" + data[40:]
        path.write_bytes(data)


# --- the contract ----------------------------------------------------------------------------------

FILE_LEVEL = re.compile(
    r"(TOML syntax error|TOML nested too deeply|TOML value not readable|cannot read|no such scenario file)"
)


def check_outcome(code: int, err: str, scenario: Path, out: Path | None, what: str) -> None:
    """The README's contract for one mutant's exit code and stderr."""
    assert "Traceback" not in err, f"{what}\n{err[:3000]}"
    assert code in (0, 1, 2), f"{what}: exit {code}\n{err[:3000]}"
    if code != 2:
        return
    lines = err.splitlines()
    errors = [line for line in lines if line.startswith("cosim: error: ")]
    assert errors, f"{what}: exit 2 without an error line\n{err[:3000]}"
    assert errors == lines[-len(errors) :], f"{what}: the error lines come last\n{err[:3000]}"
    for line in errors:
        assert len(line) < LINE_LIMIT + len(str(scenario)), f"{what}: {len(line)} characters: {line[:500]}"
        body = line.removeprefix("cosim: error: ")
        longest = max(body.replace(str(scenario), "").split(), key=len, default="")
        assert len(longest) <= WORD_LIMIT, f"{what}: an echo of {len(longest)} characters: {line[:500]}"
        if body.startswith("--set "):
            continue
        if body.startswith(f"{scenario}: "):
            problem = body.removeprefix(f"{scenario}: ")
            # A key ([section].key, [[obstacles]][2].radius) or a whole-file problem.
            assert problem.startswith("[") or FILE_LEVEL.match(problem), f"{what}: no key named: {line}"
            continue
        # A failed FMU during a run names the FMU; the log up to the failure is kept.
        assert out is not None and "log (up to the failure)" in line, f"{what}: names no file: {line}"
    if len(errors) > 1:  # several problems at once: only the composition reports them so
        assert all(f"{scenario}: " in line for line in errors), f"{what}\n{err[:3000]}"
    if out is not None and not any("log (up to the failure)" in line for line in errors):
        assert not out.exists(), f"{what}: a log for bad input"


COUNTS: collections.Counter = collections.Counter()


def run_cli(argv: list[str]) -> tuple[int, str, str]:
    stdout, stderr = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(stdout), contextlib.redirect_stderr(stderr):
        try:
            code = main(argv)
        except SystemExit as exit_:  # argparse
            code = exit_.code
        except BaseException as error:  # a traceback a user would see
            import traceback

            code = f"Traceback: {traceback.format_exc()}"
            raise AssertionError(f"{argv[:2]} raised {error!r}\n{code[-3000:]}") from error
    return code, stdout.getvalue(), stderr.getvalue()


@pytest.mark.slow
def test_scenario_mutants(tmp_path_factory):
    files = tmp_path_factory.mktemp("hostile_files")
    work = tmp_path_factory.mktemp("mutants")
    counter = iter(range(10**9))

    @settings(
        max_examples=MUTANTS,
        derandomize=True,
        deadline=None,
        database=None,
        suppress_health_check=list(HealthCheck),
        phases=[Phase.explicit, Phase.generate],  # no shrinking: the notes name the mutant
    )
    @given(data=st.data())
    def mutant(data):
        mutator = Mutator(data, None, files)
        name, base = mutator.choice(BASES)
        mutator.raw = copy.deepcopy(base)
        for _ in range(mutator.rnd.choice([1, 1, 2, 3])):
            getattr(mutator, mutator.choice(Mutator.MUTATIONS))()
        number = next(counter)
        scenario = work / f"mutant_{number}.toml"
        mutator.write(scenario)
        run = mutator.rnd.randrange(8) == 0
        # `--set=VALUE` keeps argparse from reading a value that starts with '-' as an option.
        sets = [f"--set={override}" for override in mutator.overrides]
        out = None
        if run:
            out = work / f"mutant_{number}.mcap"
            argv = ["run", str(scenario), *sets, "--set=simulation.stop_time=0.05", "--no-plot", "--quiet",
                    "--out", str(out)]  # fmt: skip
        else:
            argv = ["system", str(scenario), *sets]
        code, _, err = run_cli(argv)
        what = f"mutant {number} of {name} ({'; '.join(mutator.notes)}), {' '.join(argv[:1])}"
        check_outcome(code, err, scenario, out, what)
        COUNTS["mutants"] += 1
        COUNTS[f"{argv[0]} exit {code}"] += 1
        COUNTS[f"exit {code}"] += 1

    mutant()
    summary = ", ".join(f"{key}: {COUNTS[key]}" for key in sorted(COUNTS))
    print(f"\nscenario mutants: {summary}")
    assert COUNTS["mutants"] >= 300
    # The mutator reaches past validation too: some mutants load and build, some run.
    assert COUNTS["exit 0"] + COUNTS["exit 1"] > 0 and COUNTS["exit 2"] > 0


SUBPROCESS_MUTANTS = [
    ("simulation.stop_time", 1e300),
    ("vfh.robot_radius", "x" * HUGE),
    ("map.file", "m" * 5000),
]  # three: each process spends seconds importing


@pytest.mark.slow
def test_mutants_through_a_subprocess(tmp_path):
    """The installed program's way: a fresh interpreter, signal handlers on, stderr a real pipe."""
    stem = "warehouse_diff_drive_one_obstacle"
    processes = []
    for index, (key, value) in enumerate(SUBPROCESS_MUTANTS):
        raw = copy.deepcopy(dict(BASES)[stem])
        section, item = key.split(".")
        raw[section][item] = value
        scenario = tmp_path / f"mutant_{index}.toml"
        scenario.write_text(toml_text(raw))
        out = tmp_path / f"mutant_{index}.mcap"
        command = [sys.executable, "-m", "cosim", "run", str(scenario), "--out", str(out), "--no-plot"]
        process = subprocess.Popen(command, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        processes.append((scenario, out, key, process))
    for scenario, out, key, process in processes:
        _, err = process.communicate()
        check_outcome(process.returncode, err, scenario, out, f"subprocess {key}")
        assert process.returncode == 2, err
        assert len(err.splitlines()) == 1 and f"{key.split('.')[1]}" in err, err[:1000]


if __name__ == "__main__":
    sys.exit(pytest.main([__file__, "-q", "-s"]))
