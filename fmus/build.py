"""Build the project's FMUs: C sources -> standard FMI 2.0 co-simulation `.fmu` archives.

Every folder under `fmus/` holding a `modelDescription.xml` is an FMU. Its `*.c` files are compiled
together with the glue in `fmus/common/` into `binaries/<platform>/<modelIdentifier>.so`, and packed
with the model description and all sources (so any FMI tool can rebuild it) into `<Name>.fmu`.

Standalone on purpose (standard library only): `setup.py` imports it in pip's isolated build
environment, and `cosim.fmus` imports it from a source checkout. Run `python3 fmus/build.py [OUT_DIR]`.
"""

from __future__ import annotations

import hashlib
import os
import platform
import re
import shutil
import subprocess
import sys
import tempfile
import xml.etree.ElementTree as ElementTree
import zipfile
from pathlib import Path

FMUS_ROOT = Path(__file__).resolve().parent
COMPILE_FLAGS = ["-std=c99", "-O2", "-fPIC", "-shared", "-Wall", "-Wextra", "-Werror", "-fvisibility=hidden"]
# libm must be linked explicitly: a Python host has it loaded, other FMI hosts do not, and
# --no-undefined turns a forgotten library into a link error instead of a load failure elsewhere.
LINK_FLAGS = ["-lm", "-Wl,--no-undefined"]
GENERATION_TOOL = "navcosim fmus/build.py"

ACCESS_UNKNOWN, ACCESS_READ_ONLY, ACCESS_FIXED, ACCESS_ANY_TIME = 0, 1, 2, 3
TYPE_TAGS = ("Real", "Integer", "Boolean", "String", "Enumeration")
ACCESS_NAMES = ("ACCESS_UNKNOWN", "ACCESS_READ_ONLY", "ACCESS_FIXED", "ACCESS_ANY_TIME")


class FmuBuildError(Exception):
    """An FMU could not be built (no compiler, bad model description, compile error). One line."""


def platform_folder() -> tuple[str, str]:
    """The FMI 2.0 binaries folder name and shared-library suffix of this machine."""
    bits = "64" if sys.maxsize > 2**32 else "32"
    system = platform.system()
    if system == "Linux":
        return f"linux{bits}", ".so"
    if system == "Darwin":
        return f"darwin{bits}", ".dylib"
    raise FmuBuildError(f"building FMUs on {system} is not supported (Linux and macOS are)")


def find_compiler() -> str:
    """The C compiler: $CC, else cc, gcc or clang on PATH."""
    candidates = [os.environ["CC"]] if os.environ.get("CC") else ["cc", "gcc", "clang"]
    for candidate in candidates:
        found = shutil.which(candidate)
        if found:
            return found
    tried = ", ".join(candidates)
    raise FmuBuildError(f"no C compiler found (tried {tried}): install gcc (apt-get install gcc) or set CC")


def fmi2_header_dir(common_dir: Path) -> Path:
    """The FMI 2.0 standard headers shipped by fmpy, else our own minimal declarations."""
    try:
        import fmpy
    except ImportError:
        return common_dir / "fmi2"
    shipped = Path(fmpy.__file__).parent / "c-code"
    return shipped if (shipped / "fmi2Functions.h").is_file() else common_dir / "fmi2"


def model_dirs(source_root: Path = FMUS_ROOT) -> list[Path]:
    """Every FMU source folder under `source_root`, sorted by name."""
    return sorted(p.parent for p in source_root.glob("*/modelDescription.xml"))


def fmu_names(source_root: Path = FMUS_ROOT) -> list[str]:
    return [d.name for d in model_dirs(source_root)]


def source_files(model_dir: Path) -> list[Path]:
    """The files an FMU is built from: its folder, the glue, and this build script."""
    common_dir = model_dir.parent / "common"
    files = [p for p in sorted(model_dir.rglob("*")) if p.is_file()]
    files += [p for p in sorted(common_dir.rglob("*")) if p.is_file() and p.suffix in (".c", ".h")]
    return files + [Path(__file__).resolve()]


def source_hash(model_dir: Path) -> str:
    """SHA-256 over the FMU's sources, the compiler and the header folder: a change means rebuild."""
    digest = hashlib.sha256()
    for path in source_files(model_dir):
        if "__pycache__" in path.parts:
            continue
        digest.update(path.name.encode() + b"\0" + path.read_bytes() + b"\0")
    digest.update(str(fmi2_header_dir(model_dir.parent / "common")).encode())
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


def variable_table(model_description: Path) -> str:
    """C source of `variable_table.h`: per type, the access and the name of each value reference."""
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


def _read_identity(model_dir: Path) -> tuple[str, str, str]:
    """(modelName, modelIdentifier, guid) of the description, checked against config.h."""
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
    return root.get("modelName", identifier), identifier, guid


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


def build_fmu(model_dir: Path, out_dir: Path, header_dir: Path | None = None) -> Path:
    """Compile and pack the FMU of `model_dir` into `out_dir/<Name>.fmu`; returns its path.

    The archive is written to a temporary file in `out_dir` and renamed into place, so a reader
    (or a second build running at the same time) never sees a half-written `.fmu`.
    """
    model_dir, out_dir = Path(model_dir), Path(out_dir)
    common_dir = model_dir.parent / "common"
    header_dir = header_dir or fmi2_header_dir(common_dir)
    _, identifier, _ = _read_identity(model_dir)
    folder, suffix = platform_folder()
    compiler = find_compiler()
    out_dir.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory(prefix=f".{model_dir.name}-", dir=out_dir) as temp:
        generated = Path(temp) / "generated"
        generated.mkdir()
        (generated / "variable_table.h").write_text(variable_table(model_dir / "modelDescription.xml"))
        sources = sorted(common_dir.glob("*.c")) + sorted(model_dir.glob("*.c"))
        binary = Path(temp) / f"{identifier}{suffix}"
        includes = [f"-I{include_dir}" for include_dir in (generated, model_dir, common_dir, header_dir)]
        command = [compiler, *COMPILE_FLAGS, *includes]
        command += [str(s) for s in sources] + ["-o", str(binary), *LINK_FLAGS]
        result = subprocess.run(command, capture_output=True, text=True)
        if result.returncode != 0:
            errors = [line for line in result.stderr.splitlines() if " error: " in line]
            first = errors[0] if errors else result.stderr.strip()
            raise FmuBuildError(f"compiling {model_dir.name} failed: {first}")
        packed: dict[str, Path] = {}
        headers = [*sorted(common_dir.glob("*.h")), *sorted(model_dir.glob("*.h"))]
        headers += sorted(header_dir.glob("fmi2*.h"))
        for path in [*sources, *headers, generated / "variable_table.h"]:
            if path.name in packed:
                raise FmuBuildError(f"{model_dir.name}: two source files named {path.name!r}")
            packed[path.name] = path
        archive = Path(temp) / f"{model_dir.name}.fmu"
        with zipfile.ZipFile(archive, "w", zipfile.ZIP_DEFLATED) as fmu:
            fmu.write(model_dir / "modelDescription.xml", "modelDescription.xml")
            fmu.write(binary, f"binaries/{folder}/{identifier}{suffix}")
            for name, path in sorted(packed.items()):
                fmu.write(path, f"sources/{name}")
            fmu.writestr("sources/buildDescription.xml", _build_description(identifier, sorted(packed)))
        target = out_dir / f"{model_dir.name}.fmu"
        os.replace(archive, target)
    return target


def build_all(out_dir: Path, source_root: Path = FMUS_ROOT) -> list[Path]:
    """Build every FMU under `source_root` into `out_dir`."""
    return [build_fmu(model_dir, out_dir) for model_dir in model_dirs(source_root)]


def main(argv: list[str]) -> int:
    out_dir = Path(argv[0]) if argv else FMUS_ROOT.parent / "build" / "fmus"
    try:
        for path in build_all(out_dir):
            print(path)
    except FmuBuildError as error:
        print(f"fmus/build.py: error: {error}", file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
