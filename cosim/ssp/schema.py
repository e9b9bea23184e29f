"""SSP 1.0 and 2.0 XML: namespaces, the normative schemas, parsing and validation with one-line errors.

The schemas in `schemas/` are the Modelica Association's normative SSP 1.0.1 XSD files, those in
`schemas/ssp-2.0/` its SSP 2.0 XSD 1.0 files (both BSD 2-clause, see their `LICENSE.txt`), used
unchanged. SSP 2.0 keeps the SSP 1 namespaces; a document is SSP 2.0 when its root's `version` is
"2.0" (SSP 2.0 tools also write 1.0 files, which its schemas accept too). Every file navcosim reads
or writes (SystemStructure.ssd, .ssv parameter sets, inline parameter sets) is checked against the
schemas of its own version.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from functools import cache
from pathlib import Path

from cosim.errors import CosimError, shorten_words

SCHEMA_DIR = Path(__file__).resolve().parent / "schemas"
SCHEMA_DIRS = {"1.0": SCHEMA_DIR, "2.0": SCHEMA_DIR / "ssp-2.0"}  # SSP version -> its schemas
NS = {
    "ssd": "http://ssp-standard.org/SSP1/SystemStructureDescription",
    "ssc": "http://ssp-standard.org/SSP1/SystemStructureCommon",
    "ssv": "http://ssp-standard.org/SSP1/SystemStructureParameterValues",
    "ssm": "http://ssp-standard.org/SSP1/SystemStructureParameterMapping",
    "ssb": "http://ssp-standard.org/SSP1/SystemStructureSignalDictionary",
    "nc": "urn:navcosim:ssp:1",  # navcosim's own annotations (ssc:Annotation type="org.navcosim.*")
}
SCHEMAS = {
    "ssd": "SystemStructureDescription.xsd",
    "ssv": "SystemStructureParameterValues.xsd",
    "ssm": "SystemStructureParameterMapping.xsd",
}
# Deepest element nesting of a file (20 nested systems take about 50): the schema check recurses
# through the document, a file nested thousands deep would exhaust Python's stack.
MAX_DEPTH = 100
for _prefix, _uri in NS.items():
    ET.register_namespace(_prefix, _uri)


def tag(qualified: str) -> str:
    """'ssd:System' -> '{http://...}System' (ElementTree's notation)."""
    prefix, _, local = qualified.partition(":")
    return f"{{{NS[prefix]}}}{local}"


@cache
def schema(kind: str, version: str = "1.0"):
    """The compiled normative schema `kind` ('ssd', 'ssv', 'ssm') of SSP `version` ('1.0', '2.0');
    compiled once per process."""
    import xmlschema

    return xmlschema.XMLSchema(str(SCHEMA_DIRS[version] / SCHEMAS[kind]))


def version_of(element: ET.Element) -> str:
    """The SSP version whose schemas check `element`: '2.0' for version="2.0", else '1.0' (whose
    schemas refuse any version they do not know)."""
    return "2.0" if (element.get("version") or "").strip() == "2.0" else "1.0"


def validate(element: ET.Element, kind: str, where: str) -> None:
    """Raise `CosimError` naming `where` and the first invalid element when `element` breaks the
    schema of its SSP version."""
    version = version_of(element)
    for error in schema(kind, version).iter_errors(element):
        reason = " ".join(str(error.reason or error.message).split())
        path = _short(error.path or "/")
        elem = getattr(error, "elem", None)
        if elem is not None and elem.get("name") is not None:
            path += f" (name '{elem.get('name')}')"
        message = f"{where}: not valid SSP {version} ({SCHEMAS[kind]}) at {path}: {reason}"
        raise CosimError(shorten_words(message, 2000))


def _short(path: str) -> str:
    """An XPath with the namespace URIs replaced by their usual prefixes."""
    for prefix, uri in NS.items():
        path = path.replace(f"{{{uri}}}", f"{prefix}:")
    return path


def parse(data: bytes, kind: str, where: str) -> ET.Element:
    """Parse and validate one XML document; `CosimError` names `where` and the line on bad XML."""
    try:
        root = ET.fromstring(data)
    except ET.ParseError as error:
        line, column = error.position
        raise CosimError(f"{where}: bad XML at line {line}, column {column}: {_reason(error)}") from None
    depth = _depth(root)
    if depth > MAX_DEPTH:
        raise CosimError(
            f"{where}: elements nest {depth} deep, more than the limit of {MAX_DEPTH} "
            "(systems inside systems: at most 20)"
        )
    validate(root, kind, where)
    return root


def _depth(root: ET.Element) -> int:
    """How deep the elements of `root` nest (root alone: 1), without recursion."""
    deepest, level = 0, [root]
    while level:
        deepest += 1
        level = [child for element in level for child in element]
    return deepest


def _reason(error: ET.ParseError) -> str:
    return str(error).split(":")[0]


def to_bytes(root: ET.Element) -> bytes:
    """An element as a UTF-8 XML document with a declaration, indented for readers."""
    ET.indent(root, space="  ")
    return ET.tostring(root, encoding="UTF-8", xml_declaration=True) + b"\n"


def annotations_of(element: ET.Element | None) -> dict[str, ET.Element]:
    """The `ssc:Annotation` children of an element's `Annotations`, by type: their content element."""
    found: dict[str, ET.Element] = {}
    if element is None:
        return found
    for block in (element.find(tag("ssd:Annotations")), element.find(tag("ssc:Annotations"))):
        if block is None:
            continue
        for annotation in block.findall(tag("ssc:Annotation")):
            content = list(annotation)
            found[annotation.get("type", "")] = content[0] if content else ET.Element("empty")
    return found


def number(element: ET.Element, attribute: str, where: str) -> float:
    """The attribute as a float; `CosimError` naming `where`, the element and the attribute if not."""
    text = element.get(attribute)
    try:
        return float(text)
    except (TypeError, ValueError):
        what = f"{local_name(element.tag)}.{attribute}"
        raise CosimError(f"{where}: {what} must be a number, got {text!r}") from None


def local_name(qualified: str) -> str:
    """'{namespace}Tag' -> 'Tag'."""
    return qualified.rpartition("}")[2]
