"""Scenario files to plain data: pyyaml's safe loader, stricter.

What a scenario file may be, checked before any value is looked at:

- at most ``MAX_FILE_BYTES`` (1 MB; the paper's scenarios are 2 kB) of UTF-8 text;
- YAML that pyyaml's safe loader reads (no Python tags);
- no key twice in one mapping (YAML 1.1 keeps the last one silently; a duplicated
  ``north_m`` is a mistake, never a choice). Merge keys (``<<``) may still be overridden;
- nested at most ``MAX_DEPTH`` levels (a scenario uses four);
- YAML 1.2's floats: ``1e3`` is the number 1000, as in JSON, not the string ``'1e3'``.

Every refusal is a :class:`~ezcompanion.errors.ConfigError` whose field is the key path
(``vehicle.north_m``) or ``scenario`` for the file as a whole, and whose message is one line.
"""

from __future__ import annotations

import re
from pathlib import Path
from typing import Any

import yaml

from ezcompanion.errors import ConfigError

__all__ = ["MAX_DEPTH", "MAX_FILE_BYTES", "read_yaml", "read_yaml_file"]

MAX_FILE_BYTES = 1_000_000
MAX_DEPTH = 16


class _StrictLoader(yaml.SafeLoader):
    """The safe loader with YAML 1.2's float syntax and a nesting limit in its scanner (the
    scanner's work grows with the square of the nesting, the composer recurses on it); the
    duplicate check walks the composed nodes."""

    def fetch_flow_collection_start(self, TokenClass: Any) -> None:
        if self.flow_level >= MAX_DEPTH:
            raise yaml.scanner.ScannerError(
                None, None, f"nests deeper than {MAX_DEPTH} levels", self.get_mark()
            )
        super().fetch_flow_collection_start(TokenClass)  # type: ignore[misc]

    def add_indent(self, column: int) -> bool:
        if len(self.indents) >= MAX_DEPTH:
            raise yaml.scanner.ScannerError(
                None, None, f"nests deeper than {MAX_DEPTH} levels", self.get_mark()
            )
        return bool(super().add_indent(column))  # type: ignore[misc]


_StrictLoader.add_implicit_resolver(
    "tag:yaml.org,2002:float",
    re.compile(r"^[-+]?[0-9][0-9_]*(?:\.[0-9_]*)?[eE][-+]?[0-9]+$"),
    list("-+0123456789"),
)


def read_yaml_file(path: str | Path) -> Any:
    """Read and parse a YAML file; errors name ``scenario`` and the path."""
    path = Path(path)
    try:
        with path.open("rb") as handle:
            raw = handle.read(MAX_FILE_BYTES + 1)
    except OSError as exc:
        raise ConfigError("scenario", str(path), f"cannot be read: {exc.strerror}") from None
    if len(raw) > MAX_FILE_BYTES:
        raise ConfigError("scenario", str(path), f"is larger than {MAX_FILE_BYTES} bytes")
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError as exc:
        bad = f"byte {raw[exc.start]:#04x} at offset {exc.start}"
        raise ConfigError("scenario", str(path), f"is not UTF-8 text ({bad})") from None
    return read_yaml(text, source=str(path))


def read_yaml(text: str, *, source: str = "<text>") -> Any:
    """Parse YAML text strictly (see the module's docstring)."""
    loader: _StrictLoader | None = None
    try:
        loader = _StrictLoader(text)
        node = loader.get_single_node()
        if node is None:
            return None
        _check_nodes(node, source)
        return loader.construct_document(node)
    except ConfigError:
        raise
    except yaml.MarkedYAMLError as exc:
        where = exc.problem_mark or exc.context_mark
        at = f" at line {where.line + 1}, column {where.column + 1}" if where else ""
        problem = " ".join(str(exc.problem or exc.context or "cannot be parsed").split())
        raise ConfigError("scenario", source, f"is not valid YAML: {problem}{at}") from None
    except yaml.YAMLError as exc:
        raise ConfigError("scenario", source, f"is not valid YAML: {_one_line(exc)}") from None
    except RecursionError:
        raise ConfigError("scenario", source, f"nests deeper than {MAX_DEPTH} levels") from None
    except ValueError as exc:  # e.g. an integer of more than 4300 digits
        raise ConfigError("scenario", source, f"holds a value that cannot be read: "
                          f"{_one_line(exc)}") from None  # fmt: skip
    finally:
        if loader is not None:
            loader.dispose()


def _one_line(exc: BaseException) -> str:
    return " ".join(str(exc).split())[:200]


def _check_nodes(root: yaml.Node, source: str) -> None:
    """Refuse duplicate keys and deep nesting; iterative, each node once (aliases share)."""
    seen: set[int] = set()
    stack: list[tuple[yaml.Node, str, int]] = [(root, "", 0)]
    while stack:
        node, path, depth = stack.pop()
        if id(node) in seen:
            continue
        seen.add(id(node))
        if depth > MAX_DEPTH:
            raise ConfigError(path or "scenario", source, f"nests deeper than {MAX_DEPTH} levels")
        if isinstance(node, yaml.SequenceNode):
            stack.extend((item, f"{path}[{i}]", depth + 1) for i, item in enumerate(node.value))
        elif isinstance(node, yaml.MappingNode):
            lines: dict[str, int] = {}
            for key_node, value_node in node.value:  # a scalar key as written (1 and 1.0 differ)
                if key_node.tag == "tag:yaml.org,2002:merge":
                    stack.append((value_node, path, depth + 1))
                    continue
                key = key_node.value if isinstance(key_node, yaml.ScalarNode) else "?"
                child = f"{path}.{key}" if path else str(key)
                line = key_node.start_mark.line + 1
                if isinstance(key_node, yaml.ScalarNode) and key in lines:
                    given = value_node.value if isinstance(value_node, yaml.ScalarNode) else "..."
                    raise ConfigError(
                        child, given, f"is given twice, at lines {lines[key]} and {line}"
                    )
                lines[key] = line
                stack.append((value_node, child, depth + 1))
