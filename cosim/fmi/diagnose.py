"""Say what is wrong with a broken FMU archive in words a user can act on.

fmpy reports a `<ModelStructure>` entry that points past `<ModelVariables>` (a deleted
ScalarVariable) as "list index out of range"; a modelIdentifier with no binary of that name is
easily mistaken for a missing platform. These helpers look at the archive again and name the
entry, the variable or the file.
"""

from __future__ import annotations

import zipfile
from pathlib import Path
from xml.etree import ElementTree

from cosim.errors import shorten

_XML_LIMIT = 50 * 1024 * 1024  # bytes of modelDescription.xml worth parsing a second time


def dangling_reference(path: Path) -> str | None:
    """The first `<ModelStructure>` reference to a variable that `<ModelVariables>` lacks, as a
    phrase ("<Outputs> <Unknown index=\"19\"> refers to variable 19 of 18"), or None."""
    try:
        with zipfile.ZipFile(path) as archive:
            if archive.getinfo("modelDescription.xml").file_size > _XML_LIMIT:
                return None
            root = ElementTree.fromstring(archive.read("modelDescription.xml"))
    except (OSError, KeyError, zipfile.BadZipFile, ElementTree.ParseError):
        return None
    variables = root.find("ModelVariables")
    structure = root.find("ModelStructure")
    if variables is None or structure is None:
        return None
    if root.get("fmiVersion", "").startswith("3"):
        # FMI 3.0 refers to variables by valueReference.
        known = {element.get("valueReference") for element in variables}
        for entry in structure:
            for attribute in ("valueReference", "dependencies"):
                for reference in (entry.get(attribute) or "").split():
                    if reference not in known:
                        return (
                            f'<ModelStructure> <{entry.tag} {attribute}="{shorten(reference)}"> refers to '
                            f"valueReference {shorten(reference)}, which no variable of <ModelVariables> has"
                        )
        return None
    count = sum(1 for element in variables if element.tag == "ScalarVariable")
    for group in structure:
        for unknown in group:
            for attribute in ("index", "dependencies"):
                for index in (unknown.get(attribute) or "").split():
                    if not index.isdigit() or not 1 <= int(index) <= count:
                        return (
                            f'<ModelStructure> <{group.tag}> <Unknown {attribute}="{shorten(index)}"> '
                            f"refers to ScalarVariable {shorten(index)}, but <ModelVariables> holds {count} "
                            "(a ScalarVariable was removed, or the indices are out of date)"
                        )
    return None


def missing_binary(path: Path, names: list[str], platform: str, model_identifier: str, suffix: str) -> str:
    """Why `binaries/<platform>/<modelIdentifier><suffix>` is not in the archive, in one line."""
    folder = f"binaries/{platform}/"
    present = sorted(n[len(folder) :] for n in names if n.startswith(folder) and n != folder)
    if present:
        return (
            f"FMU '{path}': <CoSimulation modelIdentifier=\"{shorten(model_identifier)}\"> needs "
            f"{folder}{shorten(model_identifier)}{suffix}, which is missing; {folder} holds: "
            f"{shorten(', '.join(present))}"
        )
    platforms = sorted({n.split("/")[1] for n in names if n.startswith("binaries/") and n.count("/") >= 2})
    return (
        f"FMU '{path}' has no binary for this platform ({platform}); "
        f"it has: {shorten(', '.join(platforms)) or 'none'}"
    )
