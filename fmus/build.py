"""Build the project's FMUs: C sources -> standard FMI 2.0 and FMI 3.0 co-simulation `.fmu` archives.

Every folder under `fmus/` holding a `modelDescription.xml` (FMI 2.0) is an FMU. Its `*.c` files are
compiled together with the shared C of `fmus/common/` and one FMI version's glue into
`binaries/<platform>/<modelIdentifier>.so` (the FMI 2.0 glue and fmu_state.c hold nothing of a
model: compiled once per process, they are linked into every FMI 2.0 FMU), and packed with the
model description and all sources (declared in `<SourceFiles>` for FMI 2.0 and in
`sources/buildDescription.xml`, so any FMI tool can rebuild the binary) into `<Name>.fmu`. The
FMI 3.0 FMU of the same model gets its description derived from the FMI 2.0 one
(`fmus/common/model_description.py`: arrays instead of scalars) and goes into the `fmi3/` folder
beside the FMI 2.0 ones.

Standalone on purpose (standard library only): `setup.py` imports it in pip's isolated build
environment, and `cosim.fmi.builtin` imports it from a source checkout. Run
`python3 fmus/build.py [OUT_DIR] [--fmi 2|3]` (both versions by default).
"""

from __future__ import annotations

import atexit
import hashlib
import importlib.util
import os
import platform
import re
import shutil
import subprocess
import sys
import tempfile
import threading
import zipfile
from functools import cache
from pathlib import Path
from types import ModuleType
from typing import TYPE_CHECKING

if TYPE_CHECKING:  # imported where a description is parsed: a run that finds its FMUs built parses none
    import xml.etree.ElementTree as ElementTree

FMUS_ROOT = Path(__file__).resolve().parent
COMPILE_FLAGS = ["-std=c99", "-O2", "-fPIC", "-shared", "-Wall", "-Wextra", "-Werror", "-fvisibility=hidden"]
# libm must be linked explicitly: a Python host has it loaded, other FMI hosts do not, and
# --no-undefined turns a forgotten library into a link error instead of a load failure elsewhere.
LINK_FLAGS = ["-lm", "-Wl,--no-undefined"]
# The shared C of `common/` (the FMI glue fmi2_glue.c or fmi3_glue.c: argument checks, copying
# values by reference, no arithmetic on the model's values but the new time t + h, one IEEE addition
# at any optimisation level; fmu_state.c: FMU state copies) is compiled at -Og into objects first,
# both by one compiler call (for FMI 2.0 once per process, see SHARED_GLUE): the glue at -O2 was
# ~80 % of each FMU's compile time (0.21 s of CPU against 0.095 s at -Og; a first run builds four
# FMUs), and a warm run's CPU time is the same with either (measured: ratio 1.00; at -O0 it is 4 %
# more). The model's own sources stay at -O2.
GLUE_FLAGS = ["-Og", "-c"]
GENERATION_TOOL = "navcosim fmus/build.py"
FMI_VERSIONS = (2, 3)
FMI3_SUBDIR = "fmi3"  # FMI 3.0 FMUs go to <out>/fmi3/<Name>.fmu, beside the FMI 2.0 <out>/<Name>.fmu

ACCESS_UNKNOWN, ACCESS_READ_ONLY, ACCESS_FIXED, ACCESS_ANY_TIME = 0, 1, 2, 3
TYPE_TAGS = ("Real", "Integer", "Boolean", "String", "Enumeration")
ACCESS_NAMES = ("ACCESS_UNKNOWN", "ACCESS_READ_ONLY", "ACCESS_FIXED", "ACCESS_ANY_TIME")


class FmuBuildError(Exception):
    """An FMU could not be built (no compiler, bad model description, compile error). One line."""


def platform_folder(fmi_version: int = 2) -> tuple[str, str]:
    """The binaries folder name (FMI 2.0 `linux64`, FMI 3.0 `x86_64-linux`) and shared-library
    suffix of this machine."""
    bits = "64" if sys.maxsize > 2**32 else "32"
    system = platform.system()
    if system not in ("Linux", "Darwin"):
        raise FmuBuildError(f"building FMUs on {system} is not supported (Linux and macOS are)")
    suffix = ".so" if system == "Linux" else ".dylib"
    if fmi_version == 3:
        machine = platform.machine().lower()
        architecture = {"amd64": "x86_64", "arm64": "aarch64"}.get(machine, machine)
        return f"{architecture}-{system.lower()}", suffix
    return f"{system.lower()}{bits}", suffix


def output_dir(out_dir: Path, fmi_version: int) -> Path:
    """Where `build_all(out_dir)` puts the FMUs of `fmi_version`."""
    return Path(out_dir) if fmi_version == 2 else Path(out_dir) / FMI3_SUBDIR


def find_compiler() -> str:
    """The C compiler: $CC, else cc, gcc or clang on PATH."""
    candidates = [os.environ["CC"]] if os.environ.get("CC") else ["cc", "gcc", "clang"]
    for candidate in candidates:
        found = shutil.which(candidate)
        if found:
            return found
    tried = ", ".join(candidates)
    raise FmuBuildError(f"no C compiler found (tried {tried}): install gcc (apt-get install gcc) or set CC")


def fmi_header_dir(common_dir: Path, fmi_version: int = 2) -> Path:
    """The FMI standard headers of `fmi_version` shipped by fmpy, else our own minimal declarations
    (`fmus/common/fmi2/`, `fmus/common/fmi3/`)."""
    own = common_dir / f"fmi{fmi_version}"
    # Found without importing fmpy (~0.1 s with numpy in a fresh process, in the build thread that
    # would hold the interpreter before the first compiler starts).
    spec = importlib.util.find_spec("fmpy")
    if spec is None or not spec.origin:
        return own
    shipped = Path(spec.origin).parent / "c-code"
    return shipped if (shipped / f"fmi{fmi_version}Functions.h").is_file() else own


def fmi2_header_dir(common_dir: Path) -> Path:
    return fmi_header_dir(common_dir, 2)


@cache
def description_module(common_dir: Path) -> ModuleType:
    """`model_description.py` of the source tree (the shared writer and the FMI 3.0 derivation)."""
    path = Path(common_dir) / "model_description.py"
    spec = importlib.util.spec_from_file_location(f"navcosim_model_description_{abs(hash(path))}", path)
    if spec is None or spec.loader is None:
        raise FmuBuildError(f"cannot load {path}")
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module  # dataclasses look their module up while the file executes
    spec.loader.exec_module(module)
    return module


def model_dirs(source_root: Path = FMUS_ROOT) -> list[Path]:
    """Every FMU source folder under `source_root`, sorted by name."""
    return sorted(p.parent for p in source_root.glob("*/modelDescription.xml"))


def fmu_names(source_root: Path = FMUS_ROOT) -> list[str]:
    return [d.name for d in model_dirs(source_root)]


def source_files(model_dir: Path, fmi_version: int = 2) -> list[Path]:
    """The files an FMU is built from: its folder, the shared C and headers of `common/` (of the
    glues and FMI header folders, only that version's), the description writer and this script."""
    common_dir = model_dir.parent / "common"
    other = [f"fmi{v}" for v in FMI_VERSIONS if v != fmi_version]
    files = [p for p in sorted(model_dir.rglob("*")) if p.is_file()]
    for path in sorted(common_dir.rglob("*")):
        foreign = path.name in {f"{o}_glue.c" for o in other} or any(o in path.parts for o in other)
        if path.is_file() and path.suffix in (".c", ".h") and not foreign:
            files.append(path)
    return files + [common_dir / "model_description.py", Path(__file__).resolve()]


def source_hash(model_dir: Path, fmi_version: int = 2) -> str:
    """SHA-256 over the FMU's sources, the compiler and the header folder: a change means rebuild."""
    digest = hashlib.sha256(f"FMI {fmi_version}".encode())
    for path in source_files(model_dir, fmi_version):
        if "__pycache__" in path.parts or not path.is_file():
            continue
        digest.update(path.name.encode() + b"\0" + path.read_bytes() + b"\0")
    digest.update(str(fmi_header_dir(model_dir.parent / "common", fmi_version)).encode())
    digest.update(os.environ.get("CC", "").encode())
    return digest.hexdigest()


def _variables(root: ElementTree.Element) -> list[tuple[str, int, str, str, str]]:
    """(name, value reference, type, causality, variability) of every ScalarVariable."""
    variables = []
    for element in root.iter("ScalarVariable"):
        kinds = [child.tag for child in element if child.tag in TYPE_TAGS]
        if len(kinds) != 1:
            raise FmuBuildError(f"variable {element.get('name')!r} has no single type element")
        variables.append(
            (
                element.get("name", ""),
                int(element.get("valueReference", "-1")),
                "Integer" if kinds[0] == "Enumeration" else kinds[0],
                element.get("causality", "local"),
                element.get("variability", "continuous"),
            )
        )
    return variables


def _access(causality: str, variability: str) -> int:
    if causality == "input" or (causality == "parameter" and variability == "tunable"):
        return ACCESS_ANY_TIME
    if causality == "parameter":
        return ACCESS_FIXED
    return ACCESS_READ_ONLY


def _c_string(text: str) -> str:
    """`text` as a C string literal ('?' escaped: -std=c99 still reads trigraphs)."""
    escaped = text.replace("\\", "\\\\").replace('"', '\\"').replace("?", "\\?")
    return f'"{escaped}"'


def variable_table(model_description: Path, root: ElementTree.Element | None = None) -> str:
    """C source of `variable_table.h`: per type, the access and the name of each value reference
    (`root`: the description's parsed root, when the caller has it)."""
    if root is None:
        import xml.etree.ElementTree as ElementTree

        root = ElementTree.parse(model_description).getroot()
    lines = [f"/* Generated by {GENERATION_TOOL} from modelDescription.xml; do not edit. */"]
    variables = _variables(root)
    for type_name in ("Real", "Integer", "Boolean"):
        table: dict[int, int] = {}
        names: dict[int, str] = {}
        for name, vr, kind, causality, variability in variables:
            if kind != type_name:
                continue
            if vr < 0 or vr > 1_000_000:
                raise FmuBuildError(f"{model_description}: {name!r} has value reference {vr} out of range")
            if vr in table:
                raise FmuBuildError(f"{model_description}: {type_name} value reference {vr} used twice")
            table[vr] = _access(causality, variability)
            names[vr] = _c_string(name)
        size = max(table, default=-1) + 1
        entries = ", ".join(ACCESS_NAMES[table.get(vr, ACCESS_UNKNOWN)] for vr in range(size))
        name_entries = ", ".join(names.get(vr, "NULL") for vr in range(size))
        upper, lower = type_name.upper(), type_name.lower()
        lines.append(f"#define {upper}_TABLE_SIZE {size}u")
        # C forbids an empty array: a type without variables gets one unknown entry.
        lines.append(f"static const unsigned char {lower}_access[] = {{{entries or 'ACCESS_UNKNOWN'}}};")
        lines.append(f"static const char *const {lower}_names[] = {{{name_entries or 'NULL'}}};")
    return "\n".join(lines) + "\n"


def fmi3_variable_table(variables: list) -> str:
    """C source of `fmi3_variable_table.h` from the FMI 3.0 variables (`Fmi3Variable`s): per value
    reference the type, access, elements and name; the elements as the model's value references."""
    types = {"Float64": "TYPE_FLOAT64", "Int32": "TYPE_INT32", "Boolean": "TYPE_BOOLEAN"}
    rows, elements = [], []
    for variable in variables:
        if variable.causality == "independent":
            rows.append(f"    {{TYPE_INDEPENDENT, ACCESS_READ_ONLY, 0u, 1u, {_c_string(variable.name)}}},")
            continue
        access = ACCESS_NAMES[_access(variable.causality, variable.variability)]
        first = len(elements)
        elements += variable.elements
        rows.append(
            f"    {{{types[variable.type]}, {access}, {first}u, {len(variable.elements)}u, "
            f"{_c_string(variable.name)}}}, /* value reference {variable.value_reference} */"
        )
    lines = [
        f"/* Generated by {GENERATION_TOOL} from modelDescription.xml (FMI 3.0 form); do not edit. */",
        f"#define VARIABLE_COUNT {len(variables)}u",
        f"#define ELEMENT_COUNT {max(len(elements), 1)}u",
        "static const VariableInfo variables[VARIABLE_COUNT] = {",
        *rows,
        "};",
        # C forbids an empty array: a model with only `time` gets one unused element.
        "static const unsigned model_references[ELEMENT_COUNT] = {"
        + (", ".join(f"{r}u" for r in elements) or "0u")
        + "};",
    ]
    return "\n".join(lines) + "\n"


def model_binding(fmi_version: int, root: ElementTree.Element | None = None) -> str:
    """C source of `model_binding.h` (included by each model's model.c): for FMI 2.0 the object
    `fmi2_model` (fmi2_model.h) through which the glue, compiled once for every model, reaches this
    model's identity, data size and variable table; for FMI 3.0 nothing (that glue includes config.h
    and the generated table itself and is compiled with each model)."""
    lines = [f"/* Generated by {GENERATION_TOOL} from modelDescription.xml; do not edit. */"]
    if fmi_version != 2:
        return "\n".join(lines) + "\n"
    assert root is not None
    reals = [vr for _, vr, kind, _, _ in _variables(root) if kind == "Real"]
    watched = ", ".join(f"MODEL_WATCHES_REAL({vr}) != 0" for vr in range(max(reals, default=-1) + 1))
    lines += [
        '#include "config.h"',
        '#include "fmi2_model.h"',
        '#include "variable_table.h"',
        "#ifdef MODEL_WATCHES_REAL",
        f"static const unsigned char real_watched[] = {{{watched or '0'}}};",
        "#define REAL_WATCHED real_watched",
        "#define REAL_CHANGED model_real_changed",
        "#else",
        "#define REAL_WATCHED NULL",
        "#define REAL_CHANGED NULL",
        "#endif",
        "const Fmi2Model fmi2_model = {",
        "    MODEL_IDENTIFIER,",
        "    MODEL_GUID,",
        "    sizeof(ModelData),",
        '    {"Real", real_access, real_names, REAL_TABLE_SIZE},',
        '    {"Integer", integer_access, integer_names, INTEGER_TABLE_SIZE},',
        '    {"Boolean", boolean_access, boolean_names, BOOLEAN_TABLE_SIZE},',
        "    REAL_WATCHED,",
        "    REAL_CHANGED,",
        "};",
    ]
    return "\n".join(lines) + "\n"


def _read_identity(model_dir: Path) -> tuple[str, str, str, ElementTree.Element]:
    """(modelName, modelIdentifier, guid, root) of the description, checked against config.h and
    against the sources the build compiles."""
    import xml.etree.ElementTree as ElementTree

    description = model_dir / "modelDescription.xml"
    try:
        root = ElementTree.parse(description).getroot()
    except ElementTree.ParseError as error:
        raise FmuBuildError(f"{description}: not valid XML ({error})") from None
    cosimulation = root.find("CoSimulation")
    if root.get("fmiVersion") != "2.0" or cosimulation is None:
        raise FmuBuildError(f"{description}: not an FMI 2.0 co-simulation model description")
    identifier, guid = cosimulation.get("modelIdentifier", ""), root.get("guid", "")
    config = (model_dir / "config.h").read_text() if (model_dir / "config.h").is_file() else ""
    for macro, expected in (("MODEL_IDENTIFIER", identifier), ("MODEL_GUID", guid)):
        match = re.search(rf'#define\s+{macro}\s+"([^"]*)"', config)
        if match is None or match.group(1) != expected:
            config_path = model_dir / "config.h"
            raise FmuBuildError(f'{config_path}: {macro} must be "{expected}" as in modelDescription.xml')
    # FMI 2.0 tools rebuild the binary from <SourceFiles>: it must list exactly what we compile.
    declared = [f.get("name", "") for f in cosimulation.findall("SourceFiles/File")]
    compiled = [path.name for path in description_module(model_dir.parent / "common").c_sources(model_dir, 2)]
    if sorted(declared) != sorted(compiled):
        raise FmuBuildError(
            f"{description}: <SourceFiles> lists {', '.join(declared) or 'nothing'} but the FMU is built "
            f"from {', '.join(compiled)} (regenerate it: make_model_description.py)"
        )
    return root.get("modelName", identifier), identifier, guid, root


def _build_description(identifier: str, sources: list[str]) -> str:
    files = "\n".join(f'      <SourceFile name="{name}"/>' for name in sources if name.endswith(".c"))
    return (
        '<?xml version="1.0" encoding="UTF-8"?>\n'
        '<fmiBuildDescription fmiVersion="3.0">\n'
        f'  <BuildConfiguration modelIdentifier="{identifier}">\n'
        '    <SourceFileSet language="C99">\n'
        f"{files}\n"
        "    </SourceFileSet>\n"
        '    <Library name="m"/>\n'
        "  </BuildConfiguration>\n"
        "</fmiBuildDescription>\n"
    )


def _compile(command: list[str], model_dir: Path, run_compiler, cwd: Path | None = None) -> None:
    if run_compiler is None:
        result = subprocess.run(command, capture_output=True, text=True, cwd=cwd)
    else:
        result = run_compiler(command, cwd=cwd)
    if result.returncode != 0:
        errors = [line for line in result.stderr.splitlines() if " error: " in line]
        first = errors[0] if errors else result.stderr.strip()
        raise FmuBuildError(f"compiling {model_dir.name} failed: {first}")


# FMI versions whose shared C (glue and fmu_state.c) holds nothing of a model (the glue reaches it
# through the `model_binding.h` each model.c includes, see fmi2_model.h): compiled once per process
# into objects that every FMU of that version links.
SHARED_GLUE = (2,)
_glue_objects: dict[str, list[Path]] = {}  # by process id and source digest
_glue_locks: dict[str, threading.Lock] = {}
_glue_guard = threading.Lock()
_glue_folder: list[tuple[int, str]] = []  # (pid, folder) of this process's compiled glue objects
_glue_exit: list[bool] = []  # the exit handler that removes them, once registered


def remove_glue_folder() -> None:
    """Remove this process's compiled glue objects, and forget them: a later build compiles them
    again (at its exit; or before, by a process that ends without its exit handlers:
    `cosim.fmi.builtin.remove_build_scratch`)."""
    pid = os.getpid()
    with _glue_guard:
        for owner, folder in _glue_folder:
            if owner == pid:  # not from a forked child: the parent still links the objects
                shutil.rmtree(folder, ignore_errors=True)
        _glue_folder[:] = [entry for entry in _glue_folder if entry[0] != pid]
        for key in [key for key in _glue_objects if key.startswith(f"{pid}-")]:
            del _glue_objects[key]


def _glue_objects_of(
    compiler: str, shared: list[Path], headers_from: Path, model_dir: Path, run_compiler
) -> list[Path]:
    """The shared C `shared` (the glue and fmu_state.c) compiled (at GLUE_FLAGS) into objects, once
    per process for a given compiler, header folder and content of those files and the shared
    headers; concurrent callers wait for the first."""
    common_dir = shared[0].parent
    digest = hashlib.sha256(f"{compiler}\0{headers_from}\0{COMPILE_FLAGS}{GLUE_FLAGS}".encode())
    for path in [*shared, *sorted(common_dir.glob("*.h"))]:
        digest.update(path.name.encode() + b"\0" + path.read_bytes() + b"\0")
    key = f"{os.getpid()}-{digest.hexdigest()[:32]}"  # a forked child compiles its own
    with _glue_guard:
        lock = _glue_locks.setdefault(key, threading.Lock())
    with lock:
        if key in _glue_objects:
            return _glue_objects[key]
        with _glue_guard:
            if not _glue_folder or _glue_folder[0][0] != os.getpid():
                if not _glue_exit:  # (a forked child has its parent's)
                    atexit.register(remove_glue_folder)
                    _glue_exit.append(True)
                _glue_folder[:] = [(os.getpid(), tempfile.mkdtemp(prefix="navcosim-glue-"))]
            folder = Path(_glue_folder[0][1]) / key
        folder.mkdir()
        compile_flags = [flag for flag in COMPILE_FLAGS if flag != "-shared"]
        includes = [f"-I{common_dir}", f"-I{headers_from}"]
        command = [compiler, *compile_flags, *GLUE_FLAGS, *includes, *map(str, shared)]
        _compile(command, model_dir, run_compiler, cwd=folder)  # `-c` writes the objects into `cwd`
        _glue_objects[key] = [folder / f"{source.stem}.o" for source in shared]
        return _glue_objects[key]


def build_fmu(
    model_dir: Path, out_dir: Path, header_dir: Path | None = None, fmi_version: int = 2, run_compiler=None
) -> Path:
    """Compile and pack the FMI `fmi_version` FMU of `model_dir` into `out_dir/<Name>.fmu`; returns
    its path. `run_compiler(command, cwd=folder)` runs the compiler as `subprocess.run(command,
    capture_output=True, text=True, cwd=folder)` does (the default); `cosim.fmi.builtin` passes one
    that is safe in a thread of a process that forks.

    The archive is written to a temporary file in `out_dir` and renamed into place, so a reader
    (or a second build running at the same time) never sees a half-written `.fmu`.
    """
    model_dir, out_dir = Path(model_dir), Path(out_dir)
    if fmi_version not in FMI_VERSIONS:
        raise FmuBuildError(f"FMI version {fmi_version} is not built (2 and 3 are)")
    common_dir = model_dir.parent / "common"
    headers_from = header_dir or fmi_header_dir(common_dir, fmi_version)
    _, identifier, _, root = _read_identity(model_dir)
    descriptions = description_module(common_dir)
    folder, suffix = platform_folder(fmi_version)
    compiler = find_compiler()
    out_dir.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory(prefix=f".{model_dir.name}-", dir=out_dir) as temp:
        generated = Path(temp) / "generated"
        generated.mkdir()
        if fmi_version == 2:
            description = model_dir / "modelDescription.xml"
            table = generated / "variable_table.h"
            table.write_text(variable_table(description, root))
        else:
            description = generated / "modelDescription.xml"
            try:
                description.write_text(
                    descriptions.fmi3_model_description((model_dir / "modelDescription.xml").read_text())
                )
                variables = descriptions.fmi3_variables(root)
            except descriptions.DescriptionError as error:
                raise FmuBuildError(f"{model_dir.name}: no FMI 3.0 form: {error}") from None
            table = generated / "fmi3_variable_table.h"
            table.write_text(fmi3_variable_table(variables))
        binding = generated / "model_binding.h"
        binding.write_text(model_binding(fmi_version, root))
        sources = descriptions.c_sources(model_dir, fmi_version)
        binary = Path(temp) / f"{identifier}{suffix}"
        includes = [f"-I{include_dir}" for include_dir in (generated, model_dir, common_dir, headers_from)]
        if fmi_version in SHARED_GLUE:
            shared = [source for source in sources if source.parent == common_dir]
            objects = _glue_objects_of(compiler, shared, headers_from, model_dir, run_compiler)
        else:
            compile_flags = [flag for flag in COMPILE_FLAGS if flag != "-shared"]
            shared = [source for source in sources if source.parent == common_dir]
            objects = [Path(temp) / f"{source.stem}.o" for source in shared]  # `-c` writes them into `cwd`
            if shared:
                command = [compiler, *compile_flags, *GLUE_FLAGS, *includes, *map(str, shared)]
                _compile(command, model_dir, run_compiler, cwd=Path(temp))
        command = [compiler, *COMPILE_FLAGS, *includes]
        command += [str(s) for s in sources if s not in shared] + [str(o) for o in objects]
        _compile([*command, "-o", str(binary), *LINK_FLAGS], model_dir, run_compiler)
        packed: dict[str, Path] = {}
        headers = [*sorted(common_dir.glob("*.h")), *sorted(model_dir.glob("*.h"))]
        headers += sorted(headers_from.glob(f"fmi{fmi_version}*.h"))
        for path in [*sources, *headers, table, binding]:
            if path.name in packed:
                raise FmuBuildError(f"{model_dir.name}: two source files named {path.name!r}")
            packed[path.name] = path
        archive = Path(temp) / f"{model_dir.name}.fmu"
        # Deflate level 1: half the CPU of the default level 6 (~3 ms an FMU of a first run) for an
        # archive ~7 % larger.
        with zipfile.ZipFile(archive, "w", zipfile.ZIP_DEFLATED, compresslevel=1) as fmu:
            fmu.write(description, "modelDescription.xml")
            fmu.write(binary, f"binaries/{folder}/{identifier}{suffix}")
            for name, path in sorted(packed.items()):
                fmu.write(path, f"sources/{name}")
            fmu.writestr("sources/buildDescription.xml", _build_description(identifier, sorted(packed)))
        target = out_dir / f"{model_dir.name}.fmu"
        os.replace(archive, target)
    return target


def build_all(
    out_dir: Path, source_root: Path = FMUS_ROOT, fmi_versions: tuple[int, ...] = FMI_VERSIONS
) -> list[Path]:
    """Build every FMU under `source_root`: FMI 2.0 into `out_dir`, FMI 3.0 into `out_dir/fmi3`."""
    return [
        build_fmu(model_dir, output_dir(out_dir, version), fmi_version=version)
        for version in fmi_versions
        for model_dir in model_dirs(source_root)
    ]


def main(argv: list[str]) -> int:
    versions = FMI_VERSIONS
    if "--fmi" in argv:
        position = argv.index("--fmi")
        choice = argv[position + 1] if position + 1 < len(argv) else ""
        if choice not in ("2", "3"):
            print("fmus/build.py: error: --fmi takes 2 or 3", file=sys.stderr)
            return 2
        versions = (int(choice),)
        argv = argv[:position] + argv[position + 2 :]
    out_dir = Path(argv[0]) if argv else FMUS_ROOT.parent / "build" / "fmus"
    try:
        for path in build_all(out_dir, fmi_versions=versions):
            print(path)
    except FmuBuildError as error:
        print(f"fmus/build.py: error: {error}", file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
