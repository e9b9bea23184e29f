"""Build hook: a wheel (`pip install .`) ships the project's FMUs prebuilt in `cosim/_fmus/` and its
C kernels (`native/load.py`) prebuilt in `cosim/_native/` and `planner/_native/`.

Metadata lives in pyproject.toml; this file only adds those builds to `build_py`. An editable
install (`pip install -e .`, uv too) builds them on first use instead (`cosim.fmi.builtin` and
`native.load`, keyed by a hash of the sources), because an editable install is never rebuilt
after a C edit.
"""

import importlib.util
import sys
from pathlib import Path

from setuptools import setup
from setuptools.command.build_py import build_py

ROOT = Path(__file__).resolve().parent


def _module(name: str, path: Path):
    spec = importlib.util.spec_from_file_location(name, path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


class BuildPyWithFmus(build_py):
    def run(self):
        super().run()
        if getattr(self, "editable_mode", False):
            return
        build = _module("navcosim_fmu_build", ROOT / "fmus" / "build.py")
        try:
            build.build_all(Path(self.build_lib) / "cosim" / "_fmus")
        except build.FmuBuildError as error:
            sys.exit(f"navcosim: cannot build the FMUs: {error}")
        native = _module("navcosim_native", ROOT / "native" / "load.py")
        try:
            native.build_all({ROOT / name: Path(self.build_lib) / name for name in ("cosim", "planner")})
        except native.NativeBuildError as error:
            sys.exit(f"navcosim: cannot build the C kernels: {error}")


setup(cmdclass={"build_py": BuildPyWithFmus})
