"""Build hook: a wheel (`pip install .`) ships the project's FMUs prebuilt in `cosim/_fmus/`.

Metadata lives in pyproject.toml; this file only adds the FMU build to `build_py`. An editable
install (`pip install -e .`, uv too) builds them on first use instead (`cosim.fmi.builtin`, with a
source-hash stamp), because an editable install is never rebuilt after a C edit.
"""

import importlib.util
import sys
from pathlib import Path

from setuptools import setup
from setuptools.command.build_py import build_py

ROOT = Path(__file__).resolve().parent


def _fmu_build_module():
    spec = importlib.util.spec_from_file_location("navcosim_fmu_build", ROOT / "fmus" / "build.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


class BuildPyWithFmus(build_py):
    def run(self):
        super().run()
        if getattr(self, "editable_mode", False):
            return
        build = _fmu_build_module()
        try:
            build.build_all(Path(self.build_lib) / "cosim" / "_fmus")
        except build.FmuBuildError as error:
            sys.exit(f"navcosim: cannot build the FMUs: {error}")


setup(cmdclass={"build_py": BuildPyWithFmus})
