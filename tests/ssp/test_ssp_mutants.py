"""The SSP mutator (issue 26): hypothesis mutates SSP archives in hostile ways and feeds each
mutant to the real `cosim` entry point (`cosim run X.ssp`, some `cosim system X.ssp`), each in a
forked child (`mutant_runner`), so that a crash or a hang is caught and counted, not suffered.

Bases: the project's own export of a shipped scenario (`cosim ssp export`, made here), the same
archive without its navcosim scenario annotation (so it runs FMU-only), and small SSDs built
here: one DifferentialDrive FMU fed by the system's own connector through an inline parameter
set, two FMUs joined through a linear transformation, and the same as SSP 2.0.

Mutations of the XML (SystemStructure.ssd or a .ssv): elements dropped, duplicated, renamed,
moved under another parent; attributes dropped, renamed, added in unknown namespaces, set to
wrong types and to huge, negative, NaN, 1e300 numbers or long names; connector kinds and types
swapped; connections dangling, looped, reversed; the text with entities (internal, external,
parameter: XXE), deep nesting, a byte-order mark, other encodings, garbage bytes, cut short.
Mutations of the zip: the SSD missing or in a folder, extra entries, `../` and absolute paths,
duplicate names, an FMU missing, empty, garbage or with no modelDescription.xml, the archive cut
short.

Whatever the mutant, the command must end, with exit 0, 1 or 2, no traceback, and on exit 2 one
line per problem. The mutants are derandomized (CI sees the same ones each time) and the counts
by exit are printed at the end.
"""

from __future__ import annotations

import copy
import io
import random
import re
import sys
import warnings
import xml.etree.ElementTree as ET
import zipfile
from pathlib import Path

import pytest
from hypothesis import HealthCheck, Phase, given, settings
from hypothesis import strategies as st

import cosim
from cosim.cli import main
from cosim.ssp import schema

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from mutant_runner import Mutant, report, run_mutants, warm_up  # noqa: E402

REPO = Path(__file__).resolve().parents[2]
SHIPPED = REPO / "scenarios" / "warehouse_diff_drive_one_obstacle.toml"
MUTANTS = 320
SSD = "SystemStructure.ssd"
SSP1 = "http://ssp-standard.org/SSP1"
NAMESPACES = (
    f'xmlns:ssd="{SSP1}/SystemStructureDescription" xmlns:ssc="{SSP1}/SystemStructureCommon" '
    f'xmlns:ssv="{SSP1}/SystemStructureParameterValues" xmlns:nc="urn:navcosim:ssp:1"'
)


def small_ssd(version: str = "1.0") -> str:
    """A root system whose input `speed` (0.5 from an inline binding) drives robot.v; robot.x
    drives a second robot's v through a linear transformation; experiment and macro step given."""
    return f"""<?xml version="1.0" encoding="UTF-8"?>
<ssd:SystemStructureDescription {NAMESPACES} version="{version}" name="line">
  <ssd:System name="root">
    <ssd:Connectors>
      <ssd:Connector name="speed" kind="input"><ssc:Real/></ssd:Connector>
      <ssd:Connector name="position" kind="output"><ssc:Real unit="m"/></ssd:Connector>
    </ssd:Connectors>
    <ssd:ParameterBindings><ssd:ParameterBinding><ssd:ParameterValues>
      <ssv:ParameterSet version="{version}" name="commands"><ssv:Parameters>
        <ssv:Parameter name="speed"><ssv:Real value="0.5"/></ssv:Parameter>
        <ssv:Parameter name="robot.wheel_radius"><ssv:Real value="0.1"/></ssv:Parameter>
      </ssv:Parameters></ssv:ParameterSet>
    </ssd:ParameterValues></ssd:ParameterBinding></ssd:ParameterBindings>
    <ssd:Elements>
      <ssd:Component name="robot" source="models/robot.fmu">
        <ssd:Connectors>
          <ssd:Connector name="v" kind="input"><ssc:Real/></ssd:Connector>
          <ssd:Connector name="x" kind="output"><ssc:Real unit="m"/></ssd:Connector>
        </ssd:Connectors>
        <ssd:Annotations><ssc:Annotation type="org.navcosim.component">
          <nc:Component period="0.1"/></ssc:Annotation></ssd:Annotations>
      </ssd:Component>
      <ssd:Component name="second" source="models/robot.fmu" implementation="CoSimulation">
        <ssd:Connectors>
          <ssd:Connector name="v" kind="input"><ssc:Real/></ssd:Connector>
          <ssd:Connector name="theta" kind="output"><ssc:Real unit="rad"/></ssd:Connector>
        </ssd:Connectors>
      </ssd:Component>
    </ssd:Elements>
    <ssd:Connections>
      <ssd:Connection startConnector="speed" endElement="robot" endConnector="v"/>
      <ssd:Connection startElement="robot" startConnector="x" endConnector="position"/>
      <ssd:Connection startElement="robot" startConnector="x" endElement="second" endConnector="v">
        <ssc:LinearTransformation factor="0.5" offset="0.1"/>
      </ssd:Connection>
    </ssd:Connections>
  </ssd:System>
  <ssd:DefaultExperiment startTime="0" stopTime="0.5">
    <ssd:Annotations><ssc:Annotation type="org.navcosim.simulation">
      <nc:Simulation macroStep="0.05"/></ssc:Annotation></ssd:Annotations>
  </ssd:DefaultExperiment>
</ssd:SystemStructureDescription>
""".encode()


# --- hostile values --------------------------------------------------------------------------------

NUMBERS = ["", "-1", "0", "-0", "1e300", "-1e300", "1e-320", "NaN", "nan", "INF", "-inf", "1e999",
           "18446744073709551616", "-9223372036854775809", "0x10", "1,5", " 1 ", "1e-300", "5e-324",
           "true", "abc", "0.05", "2", "100000", "1e9"]  # fmt: skip
NAMES = ["", " ", ".", "a.b", "robot", "vehicle", "x" * 5000, "é\u202e", "a b", "../x", "/abs",
         "speed", "v", "x", "1abc", "robot.x", "\t"]  # fmt: skip
KINDS = ["input", "output", "parameter", "calculatedParameter", "structuralParameter", "local",
         "inout", "", "Output", "bogus"]  # fmt: skip
TYPES = ["Real", "Integer", "Boolean", "String", "Enumeration", "Binary", "Float64", "Int8", "Bogus"]
NAMESPACE_URIS = [f"{SSP1}/SystemStructureDescription", f"{SSP1}/SystemStructureCommon",
                  f"{SSP1}/SystemStructureParameterValues", "http://ssp-standard.org/SSP2/x",
                  "urn:unknown", "urn:navcosim:ssp:1", ""]  # fmt: skip
ATTRIBUTES = ["name", "source", "kind", "value", "version", "startTime", "stopTime", "macroStep",
              "period", "factor", "offset", "startElement", "endElement", "startConnector",
              "endConnector", "implementation", "type", "unit", "prefix", "master", "scenario"]  # fmt: skip
hostile_text = st.one_of(
    st.sampled_from(NUMBERS),
    st.sampled_from(NAMES),
    st.sampled_from(KINDS),
    st.floats().map(repr),
    st.integers(min_value=-(2**70), max_value=2**70).map(str),
    st.text(alphabet=st.characters(codec="utf-8", exclude_categories=("Cs", "Cc")), max_size=30),
)


def qualified(element_tag: str) -> tuple[str, str]:
    namespace, _, local = (
        element_tag[1:].partition("}") if element_tag.startswith("{") else ("", "", element_tag)
    )
    return namespace, local


class Mutator:
    """Mutations of one archive: `files` (member -> bytes, in order), with XML trees to edit."""

    def __init__(self, data, files: list[tuple[str, bytes]], index: int):
        self.data = data
        # Hypothesis draws the same seed now and then; with the mutant's index each mutant differs,
        # and the same run of the test still makes the same mutants.
        self.rnd = random.Random(f"{data.draw(st.integers(0, 2**64 - 1), label='seed')}/{index}")
        # Drawn up front, so every example draws the same things from hypothesis.
        self.texts = data.draw(st.lists(hostile_text, min_size=4, max_size=4), label="texts")
        self.files = list(files)
        self.notes: list[str] = []
        self.text_edits: dict[str, list] = {}  # member -> text edits applied after the tree edits
        self.trees: dict[str, ET.Element] = {}
        self.zip_edit: str | None = None
        self.long = False  # a name or value of LONG characters or more was written

    def choice(self, options):
        return self.rnd.choice(list(options))

    def hostile(self) -> str:
        return self.text(self.choice(self.texts))

    def text(self, value: str) -> str:
        self.long |= len(value) >= LONG
        return value

    def xml_members(self) -> list[str]:
        return [name for name, _ in self.files if name.endswith((".ssd", ".ssv"))]

    def tree(self, member: str) -> ET.Element:
        if member not in self.trees:
            self.trees[member] = ET.fromstring(dict(self.files)[member])
        return self.trees[member]

    def pick_member(self) -> str:
        members = self.xml_members()
        return SSD if SSD in members and self.rnd.random() < 0.8 else self.choice(members)

    def elements(self, member: str) -> list[tuple[ET.Element, ET.Element]]:
        """(parent, child) pairs of the member's tree."""
        root = self.tree(member)
        return [(parent, child) for parent in root.iter() for child in parent]

    # --- XML structure -----------------------------------------------------------------------
    def drop_element(self):
        member = self.pick_member()
        pairs = self.elements(member)
        if pairs:
            parent, child = self.choice(pairs)
            parent.remove(child)
            self.notes.append(f"{member}: drop {qualified(child.tag)[1]}")

    def duplicate_element(self):
        member = self.pick_member()
        pairs = self.elements(member)
        if pairs:
            parent, child = self.choice(pairs)
            index = list(parent).index(child)
            for _ in range(self.choice([1, 1, 2, 200])):
                parent.insert(index, copy.deepcopy(child))
            self.notes.append(f"{member}: duplicate {qualified(child.tag)[1]}")

    def rename_element(self):
        member = self.pick_member()
        pairs = self.elements(member)
        if pairs:
            _, child = self.choice(pairs)
            namespace, local = qualified(child.tag)
            kind = self.rnd.randrange(4)
            if kind == 0:
                local = self.choice(["Component", "System", "Connector", "Connection", "Real", "Integer",
                                     "ParameterSet", "Parameter", "Annotation", "DefaultExperiment",
                                     "SignalDictionary", "Bogus", local.lower(), local + "s"])  # fmt: skip
            elif kind == 1:
                namespace = self.choice(NAMESPACE_URIS)
            elif kind == 2:
                local = local[:-1] or "x"
            else:
                namespace, local = (
                    self.choice(NAMESPACE_URIS),
                    self.text(self.choice(["Real", "Bogus", "x" * 3000])),
                )
            child.tag = f"{{{namespace}}}{local}" if namespace else local
            self.notes.append(f"{member}: rename element to {child.tag[:80]}")

    def move_element(self):
        member = self.pick_member()
        pairs = self.elements(member)
        if len(pairs) > 1:
            parent, child = self.choice(pairs)
            parent.remove(child)
            target = self.choice([element for element in self.tree(member).iter()])
            target.append(child)
            self.notes.append(f"{member}: move {qualified(child.tag)[1]} under {qualified(target.tag)[1]}")

    def nest_element(self):
        """An element wrapped in many levels of itself or of an unknown element."""
        member = self.pick_member()
        pairs = self.elements(member)
        if pairs:
            parent, child = self.choice(pairs)
            depth = self.choice([2, 50, 3000])
            wrapper_tag = self.choice([child.tag, parent.tag, "{urn:unknown}Deep"])
            self.text_edits.setdefault(member, []).append(
                ("nest", qualified(child.tag)[1], depth, wrapper_tag)
            )
            self.notes.append(f"{member}: nest {qualified(child.tag)[1]} {depth} deep")

    # --- attributes ----------------------------------------------------------------------------
    def attributed(self, member: str) -> list[ET.Element]:
        return [element for element in self.tree(member).iter() if element.attrib]

    def drop_attribute(self):
        member = self.pick_member()
        elements = self.attributed(member)
        if elements:
            element = self.choice(elements)
            name = self.choice(sorted(element.attrib))
            del element.attrib[name]
            self.notes.append(f"{member}: drop {qualified(element.tag)[1]}@{name}")

    def rename_attribute(self):
        member = self.pick_member()
        elements = self.attributed(member)
        if elements:
            element = self.choice(elements)
            name = self.choice(sorted(element.attrib))
            new = self.choice([*ATTRIBUTES, name.upper(), name + "_", "{urn:unknown}" + name])
            element.attrib[new] = element.attrib.pop(name)
            self.notes.append(f"{member}: rename {qualified(element.tag)[1]}@{name} -> {new}")

    def set_attribute(self):
        member = self.pick_member()
        elements = self.attributed(member) or list(self.tree(member).iter())
        element = self.choice(elements)
        existing = sorted(element.attrib)
        name = self.choice(existing) if existing and self.rnd.random() < 0.8 else self.choice(ATTRIBUTES)
        value = self.text(self.choice([self.hostile(), self.hostile(), "x" * self.choice([300, 100_000])]))
        element.set(name, value)
        self.notes.append(f"{member}: {qualified(element.tag)[1]}@{name} = {value[:40]!r}")

    def add_attribute(self):
        member = self.pick_member()
        element = self.choice(list(self.tree(member).iter()))
        name = self.choice([*ATTRIBUTES, "{urn:unknown}extra", "{http://www.w3.org/XML/1998/namespace}lang",
                            "bogus"])  # fmt: skip
        element.set(name, self.hostile())
        self.notes.append(f"{member}: add {qualified(element.tag)[1]}@{name}")

    def number(self):
        """A number attribute (time, step, period, factor, value) made extreme."""
        member = self.pick_member()
        names = ("startTime", "stopTime", "macroStep", "period", "factor", "offset", "value")
        found = [(e, n) for e in self.tree(member).iter() for n in names if n in e.attrib]
        if found:
            element, name = self.choice(found)
            element.set(name, self.choice(NUMBERS))
            self.notes.append(f"{member}: {qualified(element.tag)[1]}@{name} = {element.get(name)!r}")

    # --- SSP meaning -----------------------------------------------------------------------------
    def connector(self):
        root = self.tree(SSD) if SSD in self.xml_members() else None
        connectors = [] if root is None else list(root.iter(schema.tag("ssd:Connector")))
        if not connectors:
            return self.set_attribute()
        connector = self.choice(connectors)
        kind = self.rnd.randrange(3)
        if kind == 0:
            connector.set("kind", self.choice(KINDS))
        elif kind == 1:
            for child in list(connector):
                namespace, _ = qualified(child.tag)
                child.tag = f"{{{namespace}}}{self.choice(TYPES)}"
        else:
            connector.set("name", self.text(self.choice(NAMES)))
        self.notes.append(f"connector {connector.get('name', '')[:20]!r}: {connector.attrib}"[:160])

    def connection(self):
        root = self.tree(SSD) if SSD in self.xml_members() else None
        parents = [] if root is None else list(root.iter(schema.tag("ssd:Connections")))
        if not parents:
            return self.set_attribute()
        parent = parents[0]
        connections = list(parent)
        kind = self.rnd.randrange(6)
        base = (
            copy.deepcopy(self.choice(connections))
            if connections
            else ET.Element(schema.tag("ssd:Connection"))
        )
        if kind == 0:  # dangling: an element or connector that does not exist
            base.set(self.choice(["startElement", "endElement"]), self.text(self.choice(NAMES)))
        elif kind == 1:
            base.set(self.choice(["startConnector", "endConnector"]), self.text(self.choice(NAMES)))
        elif kind == 2:  # reversed
            for a, b in (("startElement", "endElement"), ("startConnector", "endConnector")):
                first, second = base.get(a), base.get(b)
                for name, value in ((a, second), (b, first)):
                    if value is None:
                        base.attrib.pop(name, None)
                    else:
                        base.set(name, value)
        elif kind == 3:  # a loop onto itself
            base.set("endElement", base.get("startElement", ""))
            base.set("endConnector", base.get("startConnector", ""))
        elif kind == 4:  # a transformation of another kind, or with extreme numbers
            transform = self.choice(
                ["LinearTransformation", "BooleanMappingTransformation", "IntegerMappingTransformation",
                 "EnumerationMappingTransformation"]
            )  # fmt: skip
            element = ET.SubElement(base, schema.tag(f"ssc:{transform}"))
            if transform == "LinearTransformation":
                element.set("factor", self.choice(NUMBERS))
                element.set("offset", self.choice(NUMBERS))
        parent.append(base)
        self.notes.append(f"connection #{kind}: {base.attrib}"[:200])

    # --- the text ----------------------------------------------------------------------------------
    def xml_text(self):
        member = self.pick_member()
        edit = self.choice(
            ["xxe", "xxe_parameter", "entity", "laughs", "bom", "utf16", "latin1", "garbage", "cut",
             "doctype", "comment", "cdata", "pi", "nul", "empty"]
        )  # fmt: skip
        self.text_edits.setdefault(member, []).append((edit, self.rnd.random()))
        self.notes.append(f"{member}: text {edit}")

    # --- the zip -----------------------------------------------------------------------------------
    def archive(self):
        self.zip_edit = self.choice(["no_ssd", "ssd_in_folder", "extra", "dotdot", "absolute", "duplicate",
                                     "duplicate_ssd", "cut", "fmu_missing", "fmu_empty", "fmu_garbage",
                                     "fmu_no_description", "directory_entry", "backslash",
                                     "member_garbage", "empty_zip"])  # fmt: skip
        self.cut = self.rnd.random()
        self.notes.append(f"zip {self.zip_edit}")

    MUTATIONS = (
        "drop_element", "duplicate_element", "rename_element", "move_element", "nest_element",
        "drop_attribute", "rename_attribute", "set_attribute", "set_attribute", "add_attribute",
        "number", "number", "number", "number", "connector", "connector", "connection", "connection",
        "connection", "xml_text", "archive", "archive",
    )  # fmt: skip

    # --- writing ----------------------------------------------------------------------------------
    def member_bytes(self, member: str, data: bytes) -> bytes:
        if member in self.trees:
            data = ET.tostring(self.trees[member], encoding="UTF-8", xml_declaration=True)
        for edit in self.text_edits.get(member, []):
            data = apply_text_edit(data, edit)
        return data

    def write(self, path: Path) -> None:
        files = [(name, self.member_bytes(name, data)) for name, data in self.files]
        edit = self.zip_edit
        fmus = [name for name, _ in files if name.endswith(".fmu")]
        fmu = self.choice(fmus) if fmus else None
        if edit == "no_ssd":
            files = [(n, d) for n, d in files if n != SSD]
        elif edit == "ssd_in_folder":
            files = [(f"resources/{n}" if n == SSD else n, d) for n, d in files]
        elif edit == "extra":
            files += [("resources/extra.bin", bytes(range(256)) * 4), ("readme", b""), ("x.ssd", b"<a/>")]
        elif edit == "dotdot":
            files.append(
                (
                    self.choice(
                        ["../evil.txt", "resources/../../evil.txt", "../" * 50 + "tmp/navcosim-mutant-e"]
                    ),
                    b"e",
                )
            )
        elif edit == "absolute":
            files.append((self.choice(["/tmp/navcosim-mutant-evil.txt", "//server/x", "C:/x.txt"]), b"e"))
        elif edit == "duplicate" and fmu:
            files.append((fmu, b"second copy, not an FMU"))
        elif edit == "duplicate_ssd":
            files.append((SSD, small_ssd()))
        elif edit == "fmu_missing" and fmu:
            files = [(n, d) for n, d in files if n != fmu]
        elif edit == "fmu_empty" and fmu:
            files = [(n, b"" if n == fmu else d) for n, d in files]
        elif edit == "fmu_garbage" and fmu:
            files = [(n, (d[: int(len(d) * self.cut)] if n == fmu else d)) for n, d in files]
        elif edit == "fmu_no_description" and fmu:
            files = [(n, (without_description(d) if n == fmu else d)) for n, d in files]
        elif edit == "directory_entry":
            files.append(("resources/", b""))
        elif edit == "backslash" and fmu:
            files = [(n.replace("/", "\\") if n == fmu else n, d) for n, d in files]
        elif edit == "member_garbage":
            member = self.choice([n for n, _ in files])
            files = [(n, b"\xff\xfe garbage \x00" if n == member else d) for n, d in files]
        elif edit == "empty_zip":
            files = []
        buffer = io.BytesIO()
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # zipfile warns of duplicate names: they are the point
            with zipfile.ZipFile(buffer, "w", zipfile.ZIP_STORED) as archive:
                for name, data in files:
                    archive.writestr(name, data)
        data = buffer.getvalue()
        if edit == "cut":
            data = data[: int(len(data) * self.cut)]
        path.write_bytes(data)


def without_description(fmu: bytes) -> bytes:
    out = io.BytesIO()
    try:
        with zipfile.ZipFile(io.BytesIO(fmu)) as source, zipfile.ZipFile(out, "w") as target:
            for info in source.infolist():
                if info.filename != "modelDescription.xml":
                    target.writestr(info, source.read(info))
    except zipfile.BadZipFile:
        return fmu
    return out.getvalue()


def apply_text_edit(data: bytes, edit: tuple) -> bytes:
    kind = edit[0]
    declaration = re.match(rb"<\?xml[^>]*\?>", data)
    head = declaration.group(0) if declaration else b""
    body = data[len(head) :]
    if kind == "nest":
        _, local, depth, wrapper_tag = edit
        namespace, wrapper = qualified(wrapper_tag)
        start = re.search(rb"<(\w+:)?" + local.encode() + rb"[\s/>]", body)
        if start is None:
            return data
        opening = f'<w:{wrapper} xmlns:w="{namespace}">' if namespace else f"<{wrapper}>"
        closing = f"</w:{wrapper}>" if namespace else f"</{wrapper}>"
        end = body.find(b">", start.start())
        # Wrap the element's start tag's position; the wrappers close right after the element's
        # own start tag, so an element with content becomes malformed only where that is the point.
        inner = body[start.start() : end + 1]
        self_closing = inner.endswith(b"/>")
        wrapped = opening.encode() * depth + inner + (closing.encode() * depth if self_closing else b"")
        return head + body[: start.start()] + wrapped + body[end + 1 :]
    fraction = edit[1]
    if kind in ("xxe", "xxe_parameter", "entity", "laughs", "doctype"):
        root = re.search(rb"<(\w+:)?(\w+)", body)
        name = root.group(0)[1:].decode() if root else "x"
        declarations = {
            "xxe": '<!ENTITY e SYSTEM "file:///etc/passwd">',
            "xxe_parameter": '<!ENTITY % p SYSTEM "http://127.0.0.1:9/x.dtd"> %p;',
            "entity": '<!ENTITY e "robot">',
            "laughs": '<!ENTITY a "aaaaaaaaaa">'
            + "".join(f'<!ENTITY {chr(98 + i)} "{("&" + chr(97 + i) + ";") * 10}">' for i in range(9)),
            "doctype": "",
        }[kind]
        use = {"xxe": "&e;", "entity": "&e;", "laughs": "&j;"}.get(kind, "")
        doctype = f"<!DOCTYPE {name} [{declarations}]>".encode()
        # The entity is used in an attribute value (a name) and in text.
        body = body.replace(b'name="', f'name="{use}'.encode(), 1) if use and kind != "xxe" else body
        if use:
            close = body.rfind(b"</")
            body = body[:close] + use.encode() + body[close:] if close > 0 else body
        return head + b"\n" + doctype + body
    if kind == "bom":
        return b"\xef\xbb\xbf" + data
    if kind == "utf16":
        return data.decode("utf-8", "replace").encode("utf-16")
    if kind == "latin1":
        return data.replace(b'encoding="UTF-8"', b'encoding="ISO-8859-1"').replace(
            b'name="', 'name="\xe9'.encode(), 1
        )
    if kind == "garbage":
        at = int(len(data) * fraction)
        return data[:at] + b"\xff\x00\x80<&" + data[at:]
    if kind == "cut":
        return data[: int(len(data) * fraction)]
    if kind == "comment":
        return data.replace(b"><", b"><!-- c --><", 50)
    if kind == "cdata":
        return data.replace(b"><", b"><![CDATA[x]]><", 3)
    if kind == "pi":
        return data.replace(b"><", b"><?navcosim x?><", 5)
    if kind == "nul":
        return data.replace(b'name="', b'name="\x00', 1)
    if kind == "empty":
        return b""
    raise ValueError(kind)


# --- the bases -----------------------------------------------------------------------------------


def members_of(archive: Path) -> list[tuple[str, bytes]]:
    with zipfile.ZipFile(archive) as zipped:
        return [(info.filename, zipped.read(info)) for info in zipped.infolist()]


def without_scenario(files: list[tuple[str, bytes]]) -> list[tuple[str, bytes]]:
    """The exported archive as a plain FMU system: the navcosim scenario annotation taken out."""
    text = dict(files)[SSD]
    root = ET.fromstring(text)
    for block in root.findall(schema.tag("ssd:Annotations")):
        root.remove(block)
    data = ET.tostring(root, encoding="UTF-8", xml_declaration=True)
    return [(name, data if name == SSD else content) for name, content in files if "navcosim/" not in name]


@pytest.fixture(scope="module")
def bases(tmp_path_factory) -> list[tuple[str, list[tuple[str, bytes]], bool]]:
    """(name, archive members, whether it runs a scenario whose own stop time is long)."""
    folder = tmp_path_factory.mktemp("ssp_bases")
    exported = folder / "exported.ssp"
    assert main(["ssp", "export", str(SHIPPED), "--out", str(exported)]) == 0
    files = members_of(exported)
    robot = cosim.builtin_fmu("DifferentialDrive").read_bytes()
    small = [(SSD, small_ssd("1.0")), ("models/robot.fmu", robot)]
    small_2 = [(SSD, small_ssd("2.0")), ("models/robot.fmu", robot)]
    return [("exported", files, True), ("exported-fmu-only", without_scenario(files), True),
            ("small", small, False), ("small-2.0", small_2, False)]  # fmt: skip


LONG = 300  # characters of a name or value that an error message should not echo whole
ECHO = ("an error line of", "a long name echoed whole (left to the SSP hardening of names)")


def known_problem(mutator: Mutator) -> tuple[str, str] | None:
    return ECHO if mutator.long else None


@pytest.mark.slow
def test_ssp_mutants(bases, tmp_path_factory):
    work = tmp_path_factory.mktemp("ssp_mutants")
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
        number = len(mutants)
        mutator = Mutator(data, [], number)
        name, files, long_run = mutator.choice(bases)
        mutator.files = list(files)
        for _ in range(mutator.choice([1, 1, 1, 2, 3])):
            getattr(mutator, mutator.choice(Mutator.MUTATIONS))()
        archive = work / f"mutant_{number}.ssp"
        mutator.write(archive)
        if mutator.rnd.randrange(4) == 0:
            argv = ["system", str(archive)]
        else:
            argv = ["run", str(archive), "--out", str(work / f"mutant_{number}.mcap"), "--quiet", "--no-plot"]
        if long_run or mutator.rnd.random() < 0.5:
            argv.append("--set=simulation.stop_time=0.05")
        what = f"mutant {number} of {name} ({'; '.join(mutator.notes)})"
        mutants.append(Mutant(argv, what, known_problem(mutator)))

    mutant()
    warm = work / "warm"
    warm.mkdir()
    for name, files, _ in bases:
        archive = warm / f"{name}.ssp"
        with zipfile.ZipFile(archive, "w") as zipped:
            for member, data in files:
                zipped.writestr(member, data)
        out = ["--out", str(warm / f"{name}.mcap"), "--quiet", "--no-plot", "--set=simulation.stop_time=0.05"]
        warm_up(["run", str(archive), *out], ["system", str(archive)])
    outcomes = run_mutants(mutants, work / "children")
    counts, failures = report("SSP mutants", outcomes)
    assert not failures, f"{len(failures)} mutants broke the contract:\n" + "\n".join(failures[:10])
    # No member with ../ or an absolute name was written outside the folder it was unpacked to.
    escaped = [*work.rglob("evil.txt"), *Path("/tmp").glob("navcosim-mutant-e*")]
    assert not escaped, escaped
    assert counts["mutants"] >= 300
    # The mutator reaches past validation too: some mutants run.
    assert counts["exit 0"] + counts["exit 1"] > 0 and counts["exit 2"] > 0


@pytest.mark.parametrize("start", ["-1", "-9223372036854775809", "NaN"])
def test_a_start_time_before_zero_is_one_line(start, tmp_path, capsys):
    """Found by the mutator: a negative DefaultExperiment startTime overflowed the log's clock."""
    archive = tmp_path / "start.ssp"
    with zipfile.ZipFile(archive, "w") as zipped:
        zipped.writestr(SSD, small_ssd().replace(b'startTime="0"', f'startTime="{start}"'.encode()))
        zipped.write(cosim.builtin_fmu("DifferentialDrive"), "models/robot.fmu")
    assert main(["run", str(archive), "--out", str(tmp_path / "log.mcap"), "--quiet", "--no-plot"]) == 2
    error = capsys.readouterr().err
    assert error.count("\n") == 1 and "start time must be a finite number of seconds >= 0" in error, error
    assert not (tmp_path / "log.mcap").exists()


if __name__ == "__main__":
    sys.exit(pytest.main([__file__, "-q", "-s"]))
