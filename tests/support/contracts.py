"""docs/CONTRACTS.md read as data, and checks of a folder against it: the files it holds,
each table's columns (names, order, kinds) and each JSON file's fields (see the page's
conventions: `/` between keys, `[]` every element of a list, `<name>` every key of an
object whose keys are data — or, as a column, the columns a run adds, named by the
caller —, `object: NAME` a block, `?` a field that may be absent)."""

from __future__ import annotations

import json
import re
from dataclasses import dataclass, field
from pathlib import Path

import pandas as pd
import pyarrow as pa
import pyarrow.parquet as pq

DOC = Path(__file__).resolve().parents[2] / "docs" / "CONTRACTS.md"
_CELL = re.compile(r"^`([^`]+)`$")


@dataclass
class Node:
    """A JSON value's contract: its kinds, whether it may be absent, a block it is laid out
    as, its keys' contracts (a `<name>` key: every key) and, for `[]`, its elements'."""

    kinds: set[str] = field(default_factory=set)
    optional: bool = False
    block: str | None = None
    children: dict[str, "Node"] = field(default_factory=dict)
    each: "Node | None" = None


@dataclass
class Contract:
    files: dict[str, list[str]] = field(default_factory=dict)  # folder → file patterns
    columns: dict[tuple[str, str], list[tuple[str, str]]] = field(default_factory=dict)  # (folder, file) → (name, kind)
    fields: dict[tuple[str, str], Node] = field(default_factory=dict)  # (folder, file) → the root
    blocks: dict[str, Node] = field(default_factory=dict)


def _rows(lines: list[str], start: int) -> list[list[str]]:
    """The body rows (cells) of the markdown table whose header is at `start`."""
    out = []
    for line in lines[start + 2 :]:
        if not line.startswith("|"):
            break
        out.append([c.strip() for c in line.strip().strip("|").split(" | ")])
    return out


def _name(cell: str) -> str:
    m = _CELL.match(cell)
    assert m, f"CONTRACTS.md: {cell!r} is not a `name`"
    return m.group(1)


def _add(root: Node, path: str, kind: str) -> None:
    node = root
    for segment in path.split("/"):
        each = segment.endswith("[]")
        node = node.children.setdefault(segment.removesuffix("[]"), Node())
        if each:
            node.kinds.add("list")
            node.each = node.each or Node(kinds={"object"})
            node = node.each
    text = kind.strip()
    node.optional = text.endswith("?")
    for part in text.rstrip("?").split(" or "):
        word, _, block = part.partition(": ")
        node.kinds.add(word.strip())
        node.block = block.strip() or node.block


def parse(text: str | None = None) -> Contract:
    lines = (DOC.read_text() if text is None else text).splitlines()
    contract = Contract()
    folder = file = None
    for i, line in enumerate(lines):
        if line.startswith("## "):
            folder, file = line[3:].split()[0].lower(), None
        elif line.startswith("### "):
            file = _name(line[4:].removeprefix("block ").strip())
            if line.startswith("### block "):
                contract.blocks[file] = Node(kinds={"object"})
        elif line.startswith("Columns as `") and folder and file:
            contract.columns[folder, file] = contract.columns[folder, line.split("`")[1]]
        elif line.startswith("Fields as `") and folder and file:
            contract.fields[folder, file] = contract.fields[folder, line.split("`")[1]]
        elif line.startswith("| file |") and folder:
            contract.files[folder] = [_name(r[0]) for r in _rows(lines, i)]
        elif line.startswith("| column |") and folder and file:
            contract.columns[folder, file] = [(_name(r[0]), r[1]) for r in _rows(lines, i)]
        elif line.startswith("| field |") and folder and file:
            root = contract.blocks[file] if folder == "blocks" else contract.fields.setdefault((folder, file), Node({"object"}))
            for r in _rows(lines, i):
                _add(root, _name(r[0]), r[1])
    return contract


def _pattern(name: str) -> re.Pattern:
    """`<id>`: a task id (`label-` and 16 hex digits); any other `<name>`: a name part."""
    body = re.escape(name).replace("<id>", "[^/]*-[0-9a-f]{16}")
    return re.compile("^" + re.sub(r"<[^>]+>", "[^/.]+", body) + "$")


def file_pattern(names: list[str], actual: str) -> str | None:
    """The one documented file name `actual` matches (<id> etc. stand for any name part)."""
    hits = [n for n in names if _pattern(n).match(actual)]
    assert len(hits) <= 1, f"{actual} matches several documented files: {hits}"
    return hits[0] if hits else None


def check_files(contract: Contract, folder: str, root: Path) -> list[str]:
    """Every file under `root` is documented and every documented file is there."""
    names = contract.files[folder]
    actual = sorted(str(p.relative_to(root)) for p in root.rglob("*") if p.is_file())
    errors = [f"{a}: not in CONTRACTS.md ({folder} folder)" for a in actual if file_pattern(names, a) is None]
    seen = {file_pattern(names, a) for a in actual}
    return errors + [f"{n}: documented, not written" for n in names if n not in seen]


def _arrow_kind(t: pa.DataType) -> str:
    if pa.types.is_string(t) or pa.types.is_large_string(t):
        return "text"
    if pa.types.is_boolean(t):
        return "true/false"
    if pa.types.is_integer(t):
        return "integer"
    if pa.types.is_floating(t):
        return "number"
    return "time" if pa.types.is_timestamp(t) else str(t)


def check_table(contract: Contract, folder: str, name: str, path: Path, expand: dict[str, list[str]] | None = None) -> list[str]:
    """A parquet file's columns (names, order, kinds) or a CSV file's column names are the
    documented ones, a documented `<name>` column standing for the columns `expand` gives
    it (none if it gives none)."""
    documented: list[tuple[str, str]] = []
    for column, kind in contract.columns[folder, name]:
        documented += [(c, kind) for c in (expand or {}).get(column, [])] if column.startswith("<") else [(column, kind)]
    if path.suffix == ".parquet":
        actual = [(f.name, _arrow_kind(f.type)) for f in pq.read_schema(path)]
        ok = actual == documented
    else:  # CSV: names only, the text says nothing of kinds
        actual = [(c, "") for c in pd.read_csv(path, nrows=0).columns]
        ok = [c for c, _ in actual] == [c for c, _ in documented]
    return [] if ok else [f"{path.name}: columns {actual}, documented {documented}"]


def _kind_of(value: object) -> str:
    if value is None:
        return "null"
    if isinstance(value, bool):
        return "true/false"
    if isinstance(value, int):
        return "integer"
    if isinstance(value, float):
        return "number"
    return {str: "text", list: "list", dict: "object"}.get(type(value), type(value).__name__)


def check_value(contract: Contract, node: Node, value: object, where: str) -> list[str]:
    """`value` against `node` (see `Node`); the errors, each naming the path."""
    kind = _kind_of(value)
    if node.kinds and not (kind in node.kinds or (kind == "integer" and "number" in node.kinds)):
        return [f"{where}: {kind}, documented {' or '.join(sorted(node.kinds))}"]
    errors: list[str] = []
    if node.each is not None and isinstance(value, list):
        for i, item in enumerate(value):
            errors += check_value(contract, node.each, item, f"{where}[{i}]")
    children = dict(contract.blocks[node.block].children) if node.block else {}
    children |= node.children
    if not children or not isinstance(value, dict):
        return errors
    wild = [k for k in children if k.startswith("<")]
    if wild:
        for key, item in value.items():
            errors += check_value(contract, children[wild[0]], item, f"{where}/{key}")
        return errors
    for key in value:
        if key not in children:
            errors.append(f"{where}/{key}: written, not in CONTRACTS.md")
    for key, child in children.items():
        if key in value:
            errors += check_value(contract, child, value[key], f"{where}/{key}")
        elif not child.optional:
            errors.append(f"{where}/{key}: documented, not written")
    return errors


def check_json(contract: Contract, folder: str, name: str, path: Path) -> list[str]:
    return check_value(contract, contract.fields[folder, name], json.loads(path.read_text()), path.name)


def check_folder(contract: Contract, folder: str, root: Path, expand: dict[str, list[str]] | None = None) -> list[str]:
    """Files, tables and JSON fields of the folder `root` against the contract (`expand`:
    the columns each `<name>` column stands for, `check_table`)."""
    errors = check_files(contract, folder, root)
    for path in sorted(p for p in root.rglob("*") if p.is_file()):
        name = file_pattern(contract.files[folder], str(path.relative_to(root)))
        if (folder, name) in contract.columns:
            errors += check_table(contract, folder, name, path, expand)
        elif (folder, name) in contract.fields:
            errors += check_json(contract, folder, name, path)
    return errors
