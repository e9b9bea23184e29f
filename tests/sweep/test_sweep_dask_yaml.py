"""Dask's configuration files read with libyaml's parser while Dask is imported
(`cosim.sweep.warm.yaml_parsed_in_c`): the same values as PyYAML's pure-Python parser gives, and
PyYAML as it was after the block."""

from __future__ import annotations

from pathlib import Path

import pytest

yaml = pytest.importorskip("yaml")
if not hasattr(yaml, "CSafeLoader"):
    pytest.skip("PyYAML without libyaml: the block changes nothing", allow_module_level=True)


def _dask_yaml_files() -> list[Path]:
    """The YAML files Dask reads when imported: its and distributed's defaults (and their schemas,
    read when a configuration is validated), and any of the user's in Dask's configuration paths."""
    import dask
    import dask.config
    import distributed

    files = [Path(dask.__file__).parent / name for name in ("dask.yaml", "dask-schema.yaml")]
    files += [Path(distributed.__file__).parent / n for n in ("distributed.yaml", "distributed-schema.yaml")]
    for folder in map(Path, dask.config.paths):
        if folder.is_dir():
            files += sorted(folder.glob("*.y*ml"))
    return files


def test_dasks_configuration_parses_the_same_with_libyaml():
    files = _dask_yaml_files()
    assert len(files) >= 4
    for path in files:
        text = path.read_text()
        assert yaml.load(text, Loader=yaml.CSafeLoader) == yaml.load(text, Loader=yaml.SafeLoader), path


def test_safe_load_is_libyamls_inside_the_block_only():
    from cosim.sweep.warm import yaml_parsed_in_c

    pure = yaml.SafeLoader
    assert pure is not yaml.CSafeLoader
    with yaml_parsed_in_c():
        assert yaml.SafeLoader is yaml.CSafeLoader
        assert yaml.safe_load("a: [1, 2.5, yes, ~]") == {"a": [1, 2.5, True, None]}
        with pytest.raises(yaml.YAMLError):
            yaml.safe_load("a: [1, 2")
    assert yaml.SafeLoader is pure
    with pytest.raises(RuntimeError), yaml_parsed_in_c():
        raise RuntimeError("given back on an error too")
    assert yaml.SafeLoader is pure
