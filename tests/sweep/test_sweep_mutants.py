"""The sweep-spec mutator (issue 26): hypothesis mutates `cosim sweep` command lines and sweep
files, and feeds each mutant to the real `cosim` entry point with `--dry-run`, each in a forked
child (`mutant_runner`): the sweep is checked and planned as a run would check and plan it (every
varied key's extremes validated against the scenario, every point made and given its run id),
and nothing runs on Dask.

Mutations: `--vary` texts with keys misspelt, unknown, empty or doubled, no `=`, value lists with
empty items, unbalanced brackets and quotes, other TOML types, huge strings; ranges with one to
four parts, START >= STOP, NaN, inf, 1e300, COUNT 0, negative, fractional, 2**63 or past the
limit, an interval under `--method grid`; grids past 100,000 points; `--samples`, `--seed`,
`--method`, `--workers` and `--scheduler` out of range, of the wrong type or excluding each other;
`--set` overrides; the scenario missing, a folder, not TOML. Sweep files with unknown sections
and keys, values of the wrong type, the scenario missing or outside, `[vary]` entries of every
shape (lists, empty lists, strings, tables with keys missing or extra, nested tables), the text
cut, nested deep, with a byte-order mark or bytes that are not UTF-8.

Whatever the mutant: exit 0 (the runs listed) or 2 (one line per problem), no traceback, no
hang. The mutants are derandomized and the counts by exit are printed at the end.
"""

from __future__ import annotations

import math
import random
import re
import sys
from pathlib import Path

import pytest
from hypothesis import HealthCheck, Phase, given, settings
from hypothesis import strategies as st

from cosim.cli import main

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from mutant_runner import Mutant, report, run_mutants, warm_up  # noqa: E402

REPO = Path(__file__).resolve().parents[2]
SCENARIOS = REPO / "scenarios"
SCENARIO = SCENARIOS / "warehouse_diff_drive_one_obstacle.toml"
MUTANTS = 320

# Keys that `--set` accepts, with a few values each passes (a base sweep is valid before mutation).
KEYS = {
    "lidar.noise": ["0.0", "0.02", "0.05"],
    "lidar.seed": ["0", "1", "2", "3"],
    "vfh.safety_distance": ["0.1", "0.3", "0.5"],
    "pure_pursuit.lookahead_distance": ["4.0", "8.0", "12.0"],
    "simulation.master": ["gauss-seidel", "jacobi"],
    "vfh.distance_limits": ["[3.5, 20.0]", "[2.0, 15.0]"],
    "simulation.stop_time": ["10", "60"],
}
NUMBERS = ["0", "-1", "1e300", "-1e300", "nan", "inf", "-inf", "1e999", "5e-324", "2", "3.5", "10",
           "9223372036854775808", "100001", "0x10", "1_000", "true", "'x'", "x", ""]  # fmt: skip
VALUES = ["", " ", "[", "]", "[[[", "{", "'", '"', "\"a,b\"", "[1,2", "{a = 1}", "2026-01-01", "true",
          "[]", "[3.5, 20.0]", "x" * 5000, "é", "a=b", "1,", ",", ":", "::", "0:1:2:3", "\\"]  # fmt: skip
hostile_text = st.one_of(
    st.sampled_from(NUMBERS),
    st.sampled_from(VALUES),
    st.floats().map(repr),
    st.integers(min_value=-(2**70), max_value=2**70).map(str),
    st.text(alphabet=st.characters(codec="utf-8", exclude_categories=("Cs",)), max_size=20),
)


def near_miss(key: str, choice: int) -> str:
    i = choice % max(len(key), 1)  # (a key an earlier mutation emptied: no character to drop)
    variants = [key[:i] + key[i + 1 :], key + "s", key.upper(), key.replace(".", "_"), "nosuch." + key,
                key.split(".")[0], "." + key, key + ".", key.replace("_", "-")]  # fmt: skip
    return variants[choice % len(variants)]


def toml_string(text: str) -> str:
    return '"' + text.replace("\\", "\\\\").replace('"', '\\"').replace("\n", "\\n") + '"'


class Mutator:
    """A sweep as parts (dimensions, method, options); mutations edit them; `argv` writes them."""

    def __init__(self, data, index: int, files: Path):
        self.rnd = random.Random(f"{data.draw(st.integers(0, 2**64 - 1), label='seed')}/{index}")
        self.texts = data.draw(st.lists(hostile_text, min_size=4, max_size=4), label="texts")
        self.files = files
        self.index = index
        self.notes: list[str] = []
        keys = self.rnd.sample(sorted(KEYS), self.rnd.choice([1, 1, 2, 3]))
        self.method = self.rnd.choice(["grid", "grid", "random", "lhs"])
        self.samples = None if self.method == "grid" else str(self.rnd.randint(1, 6))
        self.seed = self.rnd.choice([None, None, str(self.rnd.randint(0, 9))])
        self.vary = [f"{key}={self.base_values(key)}" for key in keys]
        self.overrides = ["simulation.stop_time=5"] if self.rnd.random() < 0.5 else []
        self.scenario = str(self.rnd.choice([SCENARIO, SCENARIOS / "warehouse_apf.toml"]))
        self.options: list[str] = []
        self.file: dict | None = None  # a sweep file: {"sweep": {...}, "vary": {...}}
        self.file_edit: str | None = None

    def choice(self, options):
        return self.rnd.choice(list(options))

    def hostile(self) -> str:
        return self.choice(self.texts)

    def base_values(self, key: str) -> str:
        values = KEYS[key]
        numbers = all(re.fullmatch(r"-?[\d.]+", value) for value in values)
        if numbers and self.rnd.random() < 0.5:
            low, high = float(values[0]), float(values[-1])
            if key == "lidar.seed":
                low, high = int(low), int(high)
            if self.method == "grid":
                return f"{low}:{high}:{self.rnd.randint(1, 4)}"
            return f"{low}:{high}" if self.rnd.random() < 0.5 else f"{low}:{high}:{self.rnd.randint(1, 4)}"
        return ",".join(self.rnd.sample(values, self.rnd.randint(1, len(values))))

    # --- mutations ---------------------------------------------------------------------------------
    def vary_key(self):
        if not self.vary:
            return self.vary_more()
        index = self.rnd.randrange(len(self.vary))
        key, _, values = self.vary[index].partition("=")
        new = self.choice([near_miss(key, self.rnd.randint(0, 50)), "", " ", "a..b", "k" * 3000, "=",
                           "obstacles.0.radius", "obstacles.99.radius", "scenario.name", "simulation",
                           "map.file", "vehicle.fmu", "simulation.macro_step"])  # fmt: skip
        self.vary[index] = f"{new}={values}"
        self.notes.append(f"vary key {key} -> {new[:30]!r}")

    def vary_values(self):
        if not self.vary:
            return self.vary_more()
        index = self.rnd.randrange(len(self.vary))
        key, _, values = self.vary[index].partition("=")
        kind = self.rnd.randrange(6)
        if kind == 0:  # a list with a hostile item
            items = values.split(",")
            items[self.rnd.randrange(len(items))] = self.hostile()
            values = ",".join(items)
        elif kind == 1:  # a range with hostile parts
            # A count from NUMBERS only: a valid one of tens of thousands of points is slow, not wrong.
            parts = [self.choice(NUMBERS + [self.hostile()]) for _ in range(self.choice([1, 2, 2, 3, 3, 4]))]
            values = ":".join(parts[:2] + [self.choice(NUMBERS) for _ in parts[2:]])
        elif kind == 2:  # a grid past the limit, or a count of every kind
            values = f"0:1:{self.choice(['100001', '0', '-3', '2.5', 'x', str(2**63), '1e5', '99999999'])}"
        elif kind == 3:
            values = self.choice(VALUES)
        elif kind == 4:  # no '=' at all, or nothing after it
            self.vary[index] = self.choice([key, f"{key}=", f"={values}", ""])
            self.notes.append(f"vary {self.vary[index][:40]!r}")
            return
        else:
            values = self.hostile()
        self.vary[index] = f"{key}={values}"
        self.notes.append(f"vary {key}={values[:40]!r}")

    def vary_more(self):
        kind = self.rnd.randrange(4)
        if kind == 0 and self.vary:  # the same key twice
            self.vary.append(self.choice(self.vary))
        elif kind == 1:  # a grid of many keys whose product passes the limit
            keys = ("lidar.noise", "vfh.safety_distance", "pure_pursuit.lookahead_distance")
            self.vary = [f"{key}=0:1:{self.choice([50, 100])}" for key in keys]
            self.method, self.samples = "grid", None
        elif kind in (0, 2):  # nothing to vary
            self.vary = []
        else:
            self.vary.append(f"lidar.seed={','.join(str(i) for i in range(self.choice([2, 300])))}")
        self.notes.append(f"vary more #{kind}")

    def method_options(self):
        kind = self.rnd.randrange(6)
        if kind == 0:
            self.method = self.choice(["grid", "random", "lhs", "Grid", "sobol", ""])
        elif kind == 1:
            self.samples = self.choice([*NUMBERS, None])
        elif kind == 2:
            self.seed = self.choice(NUMBERS + [self.hostile()])
        elif kind == 3:
            self.options += self.choice([["--workers", "0"], ["--workers", "-1"], ["--workers", "x"],
                                         ["--workers", "2", "--scheduler", "tcp://127.0.0.1:9"],
                                         ["--scheduler", "tcp://127.0.0.1:9"], ["--resume"],
                                         ["--out", str(self.files / "a_file")], ["--out", ""]])  # fmt: skip
        elif kind == 4:
            self.method, self.samples = self.choice([("grid", "4"), ("random", None), ("lhs", "0")])
        else:
            self.options.append(self.choice(["--method", "--samples", "--vary", "--seed"]))  # no value
        self.notes.append(f"method {self.method} samples {self.samples!r} seed {self.seed!r} {self.options}")

    def override(self):
        key = self.choice([*KEYS, "nosuch.key", "simulation", "", "lidar.noise.x", "k" * 2000])
        value = self.choice(NUMBERS + VALUES + [self.hostile()])
        self.overrides.append(self.choice([f"{key}={value}", key, f"={value}"]))
        self.notes.append(f"--set {key[:30]}={value[:30]!r}")

    def scenario_path(self):
        (self.files / "a_folder.toml").mkdir(exist_ok=True)
        (self.files / "not_toml.toml").write_bytes(b"\xff\xfe[[[ not toml")
        (self.files / "empty.toml").write_bytes(b"")
        self.scenario = self.choice([str(self.files / "missing.toml"), str(self.files / "a_folder.toml"),
                                     str(self.files / "not_toml.toml"), str(self.files / "empty.toml"),
                                     "s" * 5000 + ".toml", "", str(SCENARIOS / "maps" / "warehouse.yaml"),
                                     "/dev/null"])  # fmt: skip
        self.notes.append(f"scenario {self.scenario[-40:]!r}")

    def sweep_file(self):
        """The sweep written as a file, then mutated there."""
        if self.file is not None:
            return self.file_mutation()
        vary = {}
        for text in self.vary:
            key, _, values = text.partition("=")
            vary[key] = values
        sweep = {"scenario": self.scenario, **({"method": self.method} if self.method else {})}
        if self.samples is not None:
            sweep["samples"] = int(self.samples) if self.samples.lstrip("-").isdigit() else self.samples
        self.file = {"sweep": sweep, "vary": vary}
        self.vary = self.vary if self.rnd.random() < 0.2 else []
        self.method = self.samples = None
        self.notes.append("sweep file")
        for _ in range(self.choice([1, 1, 2])):
            self.file_mutation()

    def file_mutation(self):
        sweep, vary = self.file["sweep"], self.file["vary"]
        kind = self.rnd.randrange(10)
        if kind == 0:
            key = self.choice(["bogus", "scenarios", "Method", "workers", "scheduler", "out", "set"])
            sweep[key] = self.choice(
                [1, -1, "x", True, [1], {"a": 1}, 1e300, ["lidar.noise=0.1"], "../" * 40]
            )
        elif kind == 1:
            sweep[self.choice(["scenario", "method", "samples", "seed"])] = self.choice(
                [1, 2.5, True, [], {}, "", "../" * 40 + "etc/passwd", "/dev/null", -5, 2**63 - 1]
            )
        elif kind == 2:
            if sweep:
                del sweep[self.choice(list(sweep))]
        elif kind == 3 and vary:
            key = self.choice(list(vary))
            vary[key] = self.choice(
                [[], [1, 2], [math.nan], ["a", 1, True], {"start": 0, "stop": 1},
                 {"start": 0, "stop": 1, "count": 3}, {"start": 0}, {"start": 1, "stop": 0},
                 {"start": 0, "stop": 1, "count": "3"}, {"start": 0, "stop": 1, "step": 1},
                 {"start": math.inf, "stop": 1}, {"nested": {"deeper": [1]}}, 1, True, "0:1:3", "",
                 [[1, 2], [3]], {"start": 0, "stop": 1, "count": 10**9}]
            )  # fmt: skip
        elif kind == 4:
            self.file["vary"] = self.choice([[], "x", 1, {}])
        elif kind == 5:
            self.file[self.choice(["extra", "scenario", "simulation"])] = {"a": 1}
        elif kind == 6:
            self.file["sweep"] = self.choice([[], "x", 1])
        else:
            self.file_edit = self.choice(["cut", "nest", "bom", "bytes", "crlf", "duplicate"])
            self.cut = self.rnd.random()
        self.notes.append(f"sweep file #{kind} {self.file_edit or ''}")

    MUTATIONS = (
        "vary_key", "vary_values", "vary_values", "vary_values", "vary_more", "method_options",
        "method_options", "override", "scenario_path", "sweep_file", "sweep_file",
    )  # fmt: skip

    # --- writing ----------------------------------------------------------------------------------
    def argv(self, work: Path) -> list[str]:
        target = self.scenario
        if self.file is not None:
            path = work / f"sweep_{self.index}.toml"
            self.write_file(path)
            target = str(path)
        argv = ["sweep", target, "--dry-run", "--out", str(work / f"out_{self.index}")]
        argv += [f"--vary={text}" for text in self.vary]  # `=`: a text that starts with '-' stays a value
        argv += [f"--set={text}" for text in self.overrides]
        if self.method is not None:
            argv.append(f"--method={self.method}")
        if self.samples is not None:
            argv.append(f"--samples={self.samples}")
        if self.seed is not None:
            argv.append(f"--seed={self.seed}")
        return argv + self.options

    def write_file(self, path: Path) -> None:
        text = toml_text(self.file)
        edit = self.file_edit
        if edit == "cut":
            text = text[: int(len(text) * self.cut)]
        elif edit == "nest":
            text += "deep = " + "[" * 1500 + "]" * 1500 + "\n"
        elif edit == "bom":
            text = "\ufeff" + text
        elif edit == "crlf":
            text = text.replace("\n", "\r\n")
        elif edit == "duplicate":
            text += "\n[sweep]\nmethod = 'grid'\n"
        data = text.encode()
        if edit == "bytes":
            data = data[:10] + b"\xff\xfe\x00" + data[10:]
        path.write_bytes(data)


def toml_value(value) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, int):
        return str(value)
    if isinstance(value, float):
        return "nan" if math.isnan(value) else ("inf" if value == math.inf else repr(value))
    if isinstance(value, str):
        return toml_string(value)
    if isinstance(value, list):
        return "[" + ", ".join(toml_value(item) for item in value) + "]"
    if isinstance(value, dict):
        return "{" + ", ".join(f"{toml_string(k)} = {toml_value(v)}" for k, v in value.items()) + "}"
    raise TypeError(type(value))


def toml_text(raw: dict) -> str:
    lines = []
    for section, body in raw.items():
        if isinstance(body, dict):
            lines.append(f"[{section}]")
            lines += [f"{toml_string(key)} = {toml_value(value)}" for key, value in body.items()]
        else:
            lines.insert(0, f"{section} = {toml_value(body)}")
    return "\n".join(lines) + "\n"


@pytest.mark.slow
def test_sweep_mutants(tmp_path_factory):
    files = tmp_path_factory.mktemp("hostile_files")
    work = tmp_path_factory.mktemp("sweep_mutants")
    (files / "a_file").write_text("a file where a folder should be\n")
    mutants: list[Mutant] = []

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
        index = len(mutants)
        mutator = Mutator(data, index, files)
        for _ in range(mutator.choice([0, 1, 1, 1, 2, 3])):
            getattr(mutator, mutator.choice(Mutator.MUTATIONS))()
        argv = mutator.argv(work)
        mutants.append(Mutant(argv, f"mutant {index} ({'; '.join(mutator.notes)})"))

    mutant()
    base = ["sweep", str(SCENARIO), "--dry-run", "--vary=lidar.noise=0:0.1", "--vary=lidar.seed=0,1"]
    warm_up([*base, "--method=lhs", "--samples=3"], [*base, "--method=random", "--samples=3"])
    outcomes = run_mutants(mutants, work / "children")
    counts, failures = report("sweep mutants", outcomes)
    assert not failures, f"{len(failures)} mutants broke the contract:\n" + "\n".join(failures[:10])
    assert counts["mutants"] >= 300
    assert counts["exit 1"] == 0  # a dry run fails no run: it runs none
    assert counts["exit 0"] > 0 and counts["exit 2"] > 0
    # A dry run writes nothing: no mutant's sweep folder exists.
    assert not list(work.glob("out_*"))


def test_dry_run_lists_every_point_and_writes_nothing(tmp_path, capsys):
    out = tmp_path / "sweep"
    argv = ["sweep", str(SCENARIO), "--vary", "lidar.seed=0:3:4", "--vary", "lidar.noise=0.02,0.05",
            "--out", str(out), "--dry-run"]  # fmt: skip
    assert main(argv) == 0
    lines = capsys.readouterr().out.splitlines()
    assert lines[0].startswith("warehouse_diff_drive_one_obstacle: 8 runs (grid)")
    points = [line.split("  ", 1)[1] for line in lines[1:]]
    assert points == [f"lidar.seed={s} lidar.noise={n}" for s in range(4) for n in ("0.02", "0.05")]
    assert len({line.split()[0] for line in lines[1:]}) == 8  # a run id each
    assert not out.exists()
    assert main([*argv, "--vary", "lidar.nois=0,1"]) == 2
    assert "[lidar].nois: unknown key (did you mean 'noise'?)" in capsys.readouterr().err


def test_dry_run_lists_each_replicate_with_the_seed_the_sweep_gives_it(tmp_path, capsys):
    from cosim.sweep.spec import replicate_seeds

    argv = ["sweep", str(SCENARIO), "--vary", "lidar.noise=0.02,0.05", "--replicates", "3",
            "--out", str(tmp_path / "sweep"), "--dry-run"]  # fmt: skip
    assert main(argv) == 0  # the replicate and seed columns once broke the listing (zip strict)
    lines = capsys.readouterr().out.splitlines()[1:]
    assert len(lines) == 6
    for noise, group in zip(("0.02", "0.05"), (lines[:3], lines[3:]), strict=True):
        seeds = [int(line.rsplit("lidar.seed=", 1)[1]) for line in group]
        assert seeds == replicate_seeds((f"lidar.noise={noise}",), 3) and len(set(seeds)) == 3
        assert [line.split()[2] for line in group] == ["replicate=0", "replicate=1", "replicate=2"]


if __name__ == "__main__":
    sys.exit(pytest.main([__file__, "-q", "-s"]))
