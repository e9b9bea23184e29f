"""The FMU build: every project FMU validates, loads in a C host, and rebuilds after a C edit."""

from __future__ import annotations

import importlib.util
import os
import shutil
import subprocess
import sys
import zipfile
from pathlib import Path

import pytest
from fmpy import read_model_description
from fmpy.validation import validate_fmu
from fmu_harness import copy_sources

from cosim.cli import main
from cosim.errors import CosimError
from cosim.fmi import builtin as fmus
from cosim.fmi.inspect import FMPY_HEADERS, fmpy_problems, required_functions, validate
from native import load as native

REPO = Path(__file__).resolve().parents[2]
NAMES = fmus.known_names()
HOST_SOURCE = Path(__file__).resolve().parents[1] / "c_host" / "host.c"
# (input, value, output, expected after 3 steps of 0.1 s) where the closed form is simple.
HOST_CHECKS = {
    "DifferentialDrive": ("v", 1.5, "x", 0.45),
    "Bicycle": ("v", 2.0, "x", 0.6),
}


def test_every_project_fmu_is_found():
    assert {"DifferentialDrive", "Bicycle"} <= set(NAMES)
    assert NAMES == sorted(p.parent.name for p in (REPO / "fmus").glob("*/modelDescription.xml"))


@pytest.mark.parametrize("name", NAMES)
def test_fmu_passes_fmpy_validation_and_ours(name):
    assert validate(fmus.builtin_fmu(name)) == []


@pytest.mark.parametrize("name", ["DifferentialDrive", "Bicycle"])
def test_fmpy_validate_fmu_itself_finds_no_problem(name):
    """fmpy's own entry point (too slow on 2000 structured names to run on every FMU)."""
    assert validate_fmu(str(fmus.builtin_fmu(name))) == []


def test_fast_name_check_catches_what_fmpy_catches(tmp_path):
    """The one-parse-per-name-shape check still rejects an illegal structured name."""
    with zipfile.ZipFile(fmus.builtin_fmu("DifferentialDrive")) as archive:
        text = archive.read("modelDescription.xml").decode()
    text = text.replace('variableNamingConvention="flat"', 'variableNamingConvention="structured"')
    for bad_name in ("track width", "wheel_speed_min[1,]"):
        broken = tmp_path / "Broken.fmu"
        with zipfile.ZipFile(broken, "w") as archive:
            archive.writestr("modelDescription.xml", text.replace('name="track_width"', f'name="{bad_name}"'))
        slow, fast = validate_fmu(str(broken)), fmpy_problems(broken)
        assert len(slow) == len(fast) == 1 and "is not a legal variable name" in fast[0]


@pytest.mark.parametrize("name", NAMES)
def test_fmu_archive_layout(name):
    path = fmus.builtin_fmu(name)
    identifier = read_model_description(str(path)).coSimulation.modelIdentifier
    with zipfile.ZipFile(path) as archive:
        members = set(archive.namelist())
    assert f"binaries/linux64/{identifier}.so" in members
    assert {"modelDescription.xml", "sources/buildDescription.xml", "sources/fmi2_glue.c"} <= members
    assert {"sources/model.c", "sources/config.h", "sources/model.h", "sources/fmi2Functions.h"} <= members


@pytest.fixture(scope="module")
def c_host(tmp_path_factory) -> Path:
    compiler = shutil.which("cc") or shutil.which("gcc")
    executable = tmp_path_factory.mktemp("host") / "host"
    command = [compiler, "-std=c99", "-Wall", "-Wextra", "-Werror", f"-I{FMPY_HEADERS}", str(HOST_SOURCE)]
    subprocess.run([*command, "-o", str(executable), "-ldl", "-lm"], check=True)
    return executable


@pytest.mark.slow
@pytest.mark.parametrize("name", NAMES)
def test_binary_runs_in_a_c_host(name, c_host, tmp_path):
    path = fmus.builtin_fmu(name)
    description = read_model_description(str(path))
    with zipfile.ZipFile(path) as archive:
        archive.extractall(tmp_path)
    library = tmp_path / "binaries" / "linux64" / f"{description.coSimulation.modelIdentifier}.so"
    arguments = [str(c_host), str(library), description.guid]
    if name in HOST_CHECKS:
        vr = {v.name: v.valueReference for v in description.modelVariables}
        input_name, value, output_name, expected = HOST_CHECKS[name]
        arguments += [str(vr[input_name]), repr(value), str(vr[output_name]), repr(expected), "3", "0.1"]
    result = subprocess.run(arguments, capture_output=True, text=True)
    assert result.stdout.strip() == "ok", result.stdout + result.stderr


@pytest.mark.slow
def test_c_host_detects_a_wrong_output(c_host, tmp_path):
    """The host's check can fail: a wrong expectation is reported."""
    path = fmus.builtin_fmu("DifferentialDrive")
    with zipfile.ZipFile(path) as archive:
        archive.extractall(tmp_path)
    library = tmp_path / "binaries" / "linux64" / "DifferentialDrive.so"
    guid = read_model_description(str(path)).guid
    result = subprocess.run(
        [str(c_host), str(library), guid, "10", "1.5", "20", "0.5", "3", "0.1"], capture_output=True
    )
    assert result.returncode == 1


def test_all_fmi2_functions_are_required():
    names = required_functions("2.0")
    assert len(names) == 44 and "fmi2GetDirectionalDerivative" in names and "fmi2DoStep" in names
    assert len(required_functions("3.0")) > 60


def _build_module(source_root: Path):
    spec = importlib.util.spec_from_file_location("copied_fmu_build", source_root / "build.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_c_edit_is_rebuilt_on_next_use(tmp_path):
    sources = copy_sources(REPO / "fmus", tmp_path / "fmus")
    cache_dir = tmp_path / "cache"
    first = fmus.build_if_stale("DifferentialDrive", sources, cache_dir)
    first_bytes = first.read_bytes()
    assert fmus.build_if_stale("DifferentialDrive", sources, cache_dir).read_bytes() == first_bytes

    model = sources / "DifferentialDrive" / "model.c"
    model.write_text(model.read_text().replace("m->wheel_radius = 0.05;", "m->wheel_radius = 0.07;"))
    rebuilt = fmus.build_if_stale("DifferentialDrive", sources, cache_dir)
    assert rebuilt.read_bytes() != first_bytes
    import fmpy

    result = fmpy.simulate_fmu(
        str(rebuilt),
        start_values={"input_mode": 1, "wheel_speed_left": 10.0, "wheel_speed_right": 10.0},
        stop_time=1.0,
    )
    assert result["x"][-1] == pytest.approx(0.7, abs=1e-12)  # r = 0.07 m, 10 rad/s, 1 s


def test_glue_compiles_against_our_minimal_fmi2_header(tmp_path):
    """pip's isolated wheel build has no fmpy: the fallback header must build the same FMUs."""
    build = _build_module(REPO / "fmus")
    for name in ("DifferentialDrive", "Bicycle"):
        path = build.build_fmu(REPO / "fmus" / name, tmp_path, header_dir=REPO / "fmus" / "common" / "fmi2")
        assert validate(path) == []


def test_fmi2_glue_is_compiled_once_without_any_model_and_linked_into_each_fmu(tmp_path):
    """The FMI 2.0 glue and fmu_state.c hold nothing of a model: one compiler call builds them,
    with no model folder or generated table on its include path, and each FMU links those objects
    yet answers its own GUID, variables and equations (fmpy instantiates with the description's
    GUID and the glue checks it)."""
    import fmpy

    sources = copy_sources(REPO / "fmus", tmp_path / "fmus")
    glue = sources / "common" / "fmi2_glue.c"
    glue.write_text(glue.read_text() + f"/* {tmp_path.name} */\n")  # not the process's compiled glue
    build = _build_module(sources)
    commands: list[list[str]] = []

    def run_compiler(command, cwd=None):
        commands.append(command)
        return subprocess.run(command, capture_output=True, text=True, cwd=cwd)

    built = {
        name: build.build_fmu(sources / name, tmp_path / "out", run_compiler=run_compiler)
        for name in ("DifferentialDrive", "Bicycle")
    }
    glue_calls = [c for c in commands if str(glue) in c]
    assert len(glue_calls) == 1 and str(sources / "common" / "fmu_state.c") in glue_calls[0]
    includes = [flag for flag in glue_calls[0] if flag.startswith("-I")]
    assert f"-I{sources / 'common'}" in includes and len(includes) == 2
    model_calls = [c for c in commands if c not in glue_calls]
    assert len(model_calls) == 2
    objects = [[part for part in c if part.endswith(".o")] for c in model_calls]
    assert objects[0] == objects[1] and len(objects[0]) == 2
    wheels = {"input_mode": 1, "wheel_speed_left": 10.0, "wheel_speed_right": 10.0}  # r = 0.05 m
    checks = {"DifferentialDrive": (wheels, "x", 0.5), "Bicycle": ({"v": 2.0}, "x", 2.0)}  # 1 s straight
    for name, (start_values, output, expected) in checks.items():
        result = fmpy.simulate_fmu(str(built[name]), start_values=start_values, stop_time=1.0)
        assert result[output][-1] == pytest.approx(expected, abs=1e-12)


def test_glue_objects_removed_are_compiled_again_for_the_next_build(tmp_path):
    """A process that removes its compiled glue objects (`remove_glue_folder`: at its exit, or
    before it ends with `os._exit`, as the sweep's fork server and workers do) forgets them: the next
    build compiles them again into a new folder and makes a working FMU."""
    import fmpy

    sources = copy_sources(REPO / "fmus", tmp_path / "fmus")
    glue = sources / "common" / "fmi2_glue.c"
    glue.write_text(glue.read_text() + f"/* {tmp_path.name} */\n")  # not the process's compiled glue
    build = _build_module(sources)
    folders: list[Path] = []

    def run_compiler(command, cwd=None):
        if str(glue) in command:
            folders.append(Path(cwd))
        return subprocess.run(command, capture_output=True, text=True, cwd=cwd)

    build.build_fmu(sources / "Bicycle", tmp_path / "first", run_compiler=run_compiler)
    assert len(folders) == 1 and folders[0].is_dir()
    build.remove_glue_folder()
    assert not folders[0].exists()
    path = build.build_fmu(sources / "Bicycle", tmp_path / "second", run_compiler=run_compiler)
    assert len(folders) == 2 and folders[1].is_dir() and folders[1].parent != folders[0].parent
    result = fmpy.simulate_fmu(str(path), start_values={"v": 2.0}, stop_time=1.0)
    assert result["x"][-1] == pytest.approx(2.0, abs=1e-12)  # 1 s straight at 2 m/s
    build.remove_glue_folder()


def test_build_error_is_one_line(tmp_path):
    sources = copy_sources(REPO / "fmus", tmp_path / "fmus")
    model = sources / "Bicycle" / "model.c"
    model.write_text(model.read_text() + "\nint unused_and_broken(void) { return undefined_name; }\n")
    with pytest.raises(
        CosimError, match=r"building FMU Bicycle: compiling Bicycle failed: .*undefined_name"
    ) as error:
        fmus.build_if_stale("Bicycle", sources, tmp_path / "cache")
    assert "\n" not in str(error.value)


def test_missing_compiler_is_one_line(tmp_path, monkeypatch):
    sources = copy_sources(REPO / "fmus", tmp_path / "fmus")
    monkeypatch.setenv("CC", "no-such-compiler-navcosim")
    with pytest.raises(CosimError, match="no C compiler found"):
        fmus.build_if_stale("Bicycle", sources, tmp_path / "cache")


def test_unknown_name_lists_known_ones():
    with pytest.raises(CosimError, match="unknown project FMU 'Unicycle'; known: .*DifferentialDrive"):
        fmus.builtin_fmu("Unicycle")


def test_cli_fmu_path_info_validate(capsys, tmp_path):
    assert main(["fmu", "path", "Bicycle"]) == 0
    assert capsys.readouterr().out.strip() == str(fmus.builtin_fmu("Bicycle"))
    assert main(["fmu", "info", "DifferentialDrive"]) == 0
    out = capsys.readouterr().out
    assert "FMI version:     2.0" in out and "{0a1ebf92-88de-4ee3-9d6b-a0fca9cd1c6b}" in out
    assert any(
        line.split()[:6] == ["wheel_radius", "parameter", "fixed", "Real", "m", "0.05"]
        for line in out.splitlines()
    )
    assert main(["fmu", "validate", "Bicycle"]) == 0


def test_cli_bad_files_exit_2(capsys, tmp_path):
    not_zip = tmp_path / "a.fmu"
    not_zip.write_text("hello")
    no_description = tmp_path / "b.fmu"
    with zipfile.ZipFile(no_description, "w") as archive:
        archive.writestr("other.txt", "x")
    for argument, message in ((not_zip, "not a zip"), (no_description, "no modelDescription.xml")):
        for action in ("info", "validate"):
            assert main(["fmu", action, str(argument)]) == 2
            err = capsys.readouterr().err
            assert message in err and err.count("\n") == 1
    assert main(["fmu", "info", "NoSuchThing"]) == 2


def test_validate_reports_a_missing_binary(tmp_path, capsys):
    broken = tmp_path / "Broken.fmu"
    with (
        zipfile.ZipFile(fmus.builtin_fmu("DifferentialDrive")) as source,
        zipfile.ZipFile(broken, "w") as target,
    ):
        for item in source.infolist():
            if not item.filename.startswith("binaries/"):
                target.writestr(item, source.read(item))
    assert main(["fmu", "validate", str(broken)]) == 1
    assert "binaries/linux64/DifferentialDrive.so is missing" in capsys.readouterr().out


def _age(path: Path, seconds: float) -> None:
    """Move `path`'s modification time `seconds` into the past (as if written that long ago)."""
    status = path.stat()
    os.utime(path, ns=(status.st_atime_ns, status.st_mtime_ns - int(seconds * 1e9)))


def test_up_to_date_fmu_is_found_without_reading_its_sources(tmp_path, monkeypatch):
    """The freshness check compares the files' times and sizes with the stamp: no hash, no build."""
    sources = copy_sources(REPO / "fmus", tmp_path / "fmus")
    cache_dir = tmp_path / "cache"
    built = fmus.build_if_stale("DifferentialDrive", sources, cache_dir)
    for path in sources.rglob("*"):
        if path.is_file():
            _age(path, 60)  # sources older than the stamp: no racy window
    fmus.build_if_stale("DifferentialDrive", sources, cache_dir)  # renews the recorded times
    build = fmus._build_module(sources)

    def refuse(*_args, **_kwargs):
        raise AssertionError("the fresh check read the sources or built")

    monkeypatch.setattr(build, "source_hash", refuse)
    monkeypatch.setattr(build, "build_fmu", refuse)
    assert fmus.build_if_stale("DifferentialDrive", sources, cache_dir) == built


def test_same_size_c_edit_after_the_racy_window_is_rebuilt(tmp_path):
    """An edit that keeps the file's size, long after the build, changes its time: rebuilt."""
    sources = copy_sources(REPO / "fmus", tmp_path / "fmus")
    cache_dir = tmp_path / "cache"
    for path in sources.rglob("*"):
        if path.is_file():
            _age(path, 120)
    first_bytes = fmus.build_if_stale("DifferentialDrive", sources, cache_dir).read_bytes()
    _age(cache_dir / "DifferentialDrive.stamp", 60)  # the build was a minute ago
    model = sources / "DifferentialDrive" / "model.c"
    text = model.read_text()
    model.write_text(text.replace("m->wheel_radius = 0.05;", "m->wheel_radius = 0.07;"))
    assert len(model.read_text()) == len(text)
    rebuilt = fmus.build_if_stale("DifferentialDrive", sources, cache_dir)
    assert rebuilt.read_bytes() != first_bytes
    import fmpy

    result = fmpy.simulate_fmu(
        str(rebuilt),
        start_values={"input_mode": 1, "wheel_speed_left": 10.0, "wheel_speed_right": 10.0},
        stop_time=1.0,
    )
    assert result["x"][-1] == pytest.approx(0.7, abs=1e-12)  # r = 0.07 m, 10 rad/s, 1 s


def test_touched_source_renews_the_stamp_without_a_rebuild(tmp_path, monkeypatch):
    sources = copy_sources(REPO / "fmus", tmp_path / "fmus")
    cache_dir = tmp_path / "cache"
    built = fmus.build_if_stale("DifferentialDrive", sources, cache_dir)
    _age(sources / "DifferentialDrive" / "model.c", 30)  # same bytes, another time
    build = fmus._build_module(sources)

    def refuse(*_args, **_kwargs):
        raise AssertionError("rebuilt for a time-only change")

    monkeypatch.setattr(build, "build_fmu", refuse)
    assert fmus.build_if_stale("DifferentialDrive", sources, cache_dir) == built
    recorded = (cache_dir / "DifferentialDrive.stamp").read_text()
    status = (sources / "DifferentialDrive" / "model.c").stat()
    assert f"{status.st_mtime_ns} {status.st_size} " in recorded


@pytest.mark.parametrize("version", [2, 3])
def test_stamp_environment_names_the_headers_the_build_uses(version):
    """The cheap check finds the FMI headers without importing fmpy: the folder the build picks."""
    build = fmus._build_module(REPO / "fmus")
    headers = build.fmi_header_dir(REPO / "fmus" / "common", version)
    assert fmus._environment_line(REPO / "fmus" / "Bicycle", version).startswith(f"env {headers} CC=")


def test_a_co_simulation_only_fmi2_fmu_need_not_export_model_exchange_functions(tmp_path, capsys):
    """PythonFMU's FMUs are FMI 2.0 co-simulation only and export none of the Model Exchange
    functions; FMI 2.0 asks for the common and the co-simulation functions only, and fmpy's
    validation does not ask for them either. FMI 3.0 asks for every function whatever the interfaces."""
    import ctypes
    import platform

    from fixtures.pythonfmu_fixtures import pythonfmu_fmu

    fmu = pythonfmu_fmu("first_order_lag")
    description = read_model_description(str(fmu))
    assert description.modelExchange is None and description.coSimulation is not None
    identifier = description.coSimulation.modelIdentifier
    with zipfile.ZipFile(fmu) as archive:
        library = Path(archive.extract(f"binaries/linux64/{identifier}.so", tmp_path))
    binary = ctypes.CDLL(str(library))
    assert platform.system() == "Linux"
    assert not hasattr(binary, "fmi2GetDerivatives") and hasattr(binary, "fmi2DoStep")
    # fmpy's verdict (it notes this model's empty InitialUnknowns) is ours, and nothing more.
    assert validate(fmu) == validate_fmu(str(fmu))
    cs, me = set(required_functions("2.0", ("cs",))), set(required_functions("2.0", ("me",)))
    assert "fmi2DoStep" in cs - me and "fmi2GetDerivatives" in me - cs and "fmi2Instantiate" in cs & me
    assert required_functions("3.0", ("cs",)) == required_functions("3.0")


def test_prepare_builds_stale_fmus_and_builtin_fmu_waits_for_them(tmp_path, monkeypatch):
    monkeypatch.setenv("NAVCOSIM_FMU_CACHE", str(tmp_path / "cache"))
    lines: list[str] = []
    fmus.prepare(["Bicycle", "Bicycle", "NoSuchFmu"], 2, kernels=(), announce=lines.append)
    assert lines == ["building FMUs Bicycle (first use or changed sources) ..."]
    path = fmus.builtin_fmu("Bicycle")
    assert path == tmp_path / "cache" / "Bicycle.fmu" and validate(path) == []
    assert fmus._pending == {}
    fmus.prepare(["Bicycle"], 2, kernels=(), announce=lines.append)  # up to date: nothing to say
    assert len(lines) == 1 and fmus.builtin_fmu("Bicycle") == path and fmus._fresh == set()


@pytest.mark.slow
def test_first_run_says_what_it_builds_and_builds_what_the_run_loads(tmp_path):
    """A run with empty FMU and kernel caches prints one line per build step on stderr and compiles
    exactly the kernels the run loads (`RUN_KERNELS`); the next run prints neither line."""
    environment = dict(
        os.environ, NAVCOSIM_FMU_CACHE=str(tmp_path / "fmus"), NAVCOSIM_NATIVE_CACHE=str(tmp_path / "native")
    )
    code = (
        "import sys\n"
        "from cosim.cli import main\n"
        "from native import load as native\n"
        "code = main(sys.argv[1:])\n"
        "print('loaded', ' '.join(sorted(str(path) for path in native._loaded)))\n"
    )
    scenario = str(REPO / "scenarios" / "warehouse_diff_drive_one_obstacle.toml")
    command = [sys.executable, "-c", code, "run", scenario, "--no-plot", "--out", str(tmp_path / "run.mcap")]
    first = subprocess.run(command, capture_output=True, text=True, env=environment, cwd=REPO, timeout=600)
    assert first.returncode == 0, first.stderr
    steps = [line for line in first.stderr.splitlines() if "(first use or changed sources)" in line]
    assert len(steps) == 2
    assert steps[0].startswith("compiling kernels distance, world, astar, costmap, kernel ")
    fmu_names = (
        "PurePursuit, VectorFieldHistogram, AvoidanceMixer, DifferentialDrive"  # as the run reads them
    )
    assert steps[1].startswith(f"building FMUs {fmu_names} ")
    loaded = first.stdout.splitlines()[-1].split()[1:]
    assert sorted(loaded) == sorted(str(path.resolve()) for path in fmus.RUN_KERNELS)
    built = sorted(path.name for path in (tmp_path / "native").iterdir())
    assert built == sorted(native.library_name(path.resolve()) for path in fmus.RUN_KERNELS)
    again = subprocess.run(command, capture_output=True, text=True, env=environment, cwd=REPO, timeout=600)
    assert again.returncode == 0 and "first use" not in again.stderr


def test_a_free_build_thread_takes_the_queued_build_of_lowest_rank():
    """The build pool runs queued builds by rank (equal ranks in the order they came), not in the
    order they were queued: a first run queues its FMUs after kernels it needs later. A build's
    exception reaches whoever waits for it."""
    import threading

    pool = fmus._NeedOrderedPool(1)
    release, ran = threading.Event(), []
    first = pool.submit((9, 0), release.wait)  # holds the only thread while the others queue
    futures = [
        pool.submit(rank, ran.append, label) for rank, label in [((2, 0), "c"), ((1, 5), "b"), ((0, 1), "a2")]
    ]
    futures.append(fmus._Ranked(pool, (0, 0)).submit(ran.append, "a1"))
    failed = pool.submit((1, 9), int, "not a number")
    release.set()
    assert first.result(timeout=30) is True
    assert [future.result(timeout=30) for future in futures] == [None] * 4
    assert ran == ["a1", "a2", "b", "c"]
    with pytest.raises(ValueError, match="not a number"):
        failed.result(timeout=30)


def test_a_run_needs_the_early_kernels_before_its_fmus(tmp_path, monkeypatch):
    """`prepare` ranks the kernels given first that are in `BEFORE_FMUS` before the FMUs, and the
    other kernels after them in the order given, whichever call queued them."""
    monkeypatch.setattr(fmus, "_pending", {})
    monkeypatch.setattr(native, "_pending", {})
    monkeypatch.setattr(native, "_loaded", {})
    monkeypatch.setenv("NAVCOSIM_FMU_CACHE", str(tmp_path / "fmus"))
    monkeypatch.setenv("NAVCOSIM_NATIVE_CACHE", str(tmp_path / "native"))
    queued: list[tuple[tuple, str]] = []

    class Recording:
        def submit(self, rank, function, *arguments):
            queued.append((rank, getattr(arguments[0], "stem", arguments[0])))
            from concurrent.futures import Future

            return Future()

    monkeypatch.setattr(fmus, "_builders", Recording())
    fmus.prepare((), kernels=fmus.RUN_KERNELS)
    fmus.prepare(["PurePursuit", "DifferentialDrive"], 2, kernels=())
    order = [name for _, name in sorted(queued)]
    assert order == ["distance", "world", "astar", "PurePursuit", "DifferentialDrive", "costmap", "kernel"]
    assert [path.stem for path in fmus.RUN_KERNELS] == ["distance", "world", "astar", "costmap", "kernel"]
    queued.clear()
    monkeypatch.setattr(native, "_pending", {})
    native_dir = fmus.BEFORE_FMUS[0].parent  # planner/native: `cosim plan compare` gives its own order
    fmus.prepare((), kernels=[native_dir / "hybrid.c", native_dir / "astar.c", native_dir / "distance.c"])
    assert [name for _, name in sorted(queued)] == ["hybrid", "astar", "distance"]
