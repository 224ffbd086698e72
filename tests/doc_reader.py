"""Reading README.md and docs/*.md as a user would copy from them: the commands of their
shell and indented blocks, their Python blocks, the commands named inline; and what a
Makefile target or a shell script runs. Used by tests/test_docs_commands.py (which says
what is done with each)."""

from __future__ import annotations

import ast
import re
import shlex
import textwrap
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
DOCS = ("README.md", *sorted(str(p.relative_to(ROOT)) for p in (ROOT / "docs").glob("*.md")))
SHELL_FENCES = {"", "sh", "shell", "bash", "console", "text"}


@dataclass(frozen=True)
class DocCommand:
    """One command of a doc: where it is, as written (normalised) and split as a shell would."""

    doc: str
    line: int
    text: str
    argv: tuple[str, ...]

    @property
    def program(self) -> str:
        return self.argv[0]


@dataclass(frozen=True)
class PythonBlock:
    doc: str
    line: int
    source: str


# --- reading the Markdown -------------------------------------------------------------------


def _is_project_command(argv: list[str]) -> bool:
    if not argv:
        return False
    head, rest = argv[0], argv[1:]
    if head in ("ezcompanion", "sitl-stub", "make"):
        return True
    if head in ("python", "python3"):
        return bool(rest) and (
            rest[0] == "-m" or rest[0].startswith(("bench/", "docs/", "sitl_stub", "ezcompanion"))
        )
    return head == "sh" and bool(rest) and rest[0].startswith("docs/")


def words_of(text: str) -> list[str]:
    """The words of the first command of a shell line: split as sh would, comments dropped,
    up to a redirection, a pipe or a ``;``/``&&`` (a word of its own; ``a|b`` is a usage
    line's choice)."""
    words = []
    for word in shlex.split(text, comments=True):
        if re.match(r"\d?[<>]|[;|&]+$", word):
            break
        words.append(word)
    return words


def _split(text: str) -> list[str]:
    """``text``'s command (``words_of``) without ``$``, ``.venv/bin/`` or a leading
    ``NAME=value``."""
    argv = words_of(text)
    if argv[:1] == ["$"]:
        argv = argv[1:]
    while argv and re.fullmatch(r"[A-Z_]+=\S*", argv[0]):
        argv = argv[1:]
    if argv:
        argv[0] = argv[0].removeprefix(".venv/bin/")
    return argv


def _logical_lines(lines: list[tuple[int, str]]) -> Iterator[tuple[int, str]]:
    """(first line number, text) with ``\\`` continuations joined."""
    pending: tuple[int, str] | None = None
    for number, raw in lines:
        line = raw.strip()
        start, text = pending if pending is not None else (number, "")
        text = f"{text} {line}".strip()
        if line.endswith("\\"):
            pending = (start, text[:-1].rstrip())
            continue
        pending = None
        yield start, text
    if pending is not None:
        yield pending


def _blocks(doc: str) -> Iterator[tuple[str, list[tuple[int, str]]]]:
    """(language, numbered lines) of each fenced block (language as labelled) and each
    indented block (language ``indented``) of ``doc``."""
    lines = (ROOT / doc).read_text(encoding="utf-8").splitlines()
    fence: str | None = None
    body: list[tuple[int, str]] = []
    previous_blank = True
    for number, line in enumerate(lines, start=1):
        if fence is not None:
            if line.strip().startswith("```"):
                yield fence, body
                fence, body = None, []
            else:
                body.append((number, line))
            continue
        if line.strip().startswith("```"):
            if body:
                yield "indented", body
                body = []
            fence = line.strip()[3:].strip()
            continue
        indented = line.startswith("    ") and line.strip()
        if indented and (body or previous_blank):
            body.append((number, line))
        elif body and not line.strip():
            body.append((number, line))  # a blank line inside an indented block
        elif body:
            yield "indented", [b for b in body if b[1].strip()]
            body = []
        previous_blank = not line.strip()
    if body:
        yield ("indented" if fence is None else fence), [b for b in body if b[1].strip()]


def doc_commands() -> list[DocCommand]:
    """Every project command in the shell and indented blocks of the docs, in order."""
    found: list[DocCommand] = []
    for doc in DOCS:
        for language, body in _blocks(doc):
            if language != "indented" and language not in SHELL_FENCES:
                continue
            for number, text in _logical_lines(body):
                try:
                    argv = _split(text)
                except ValueError:  # not shell (a formula, a config line)
                    continue
                if _is_project_command(argv):
                    found.append(DocCommand(doc, number, " ".join(argv), tuple(argv)))
    return found


def python_blocks() -> list[PythonBlock]:
    return [
        PythonBlock(doc, body[0][0], textwrap.dedent("\n".join(line for _, line in body)))
        for doc in DOCS
        for language, body in _blocks(doc)
        if language == "python" and body
    ]


def inline_commands() -> list[tuple[str, list[str]]]:
    """(doc, argv) of every inline code span that starts an ``ezcompanion`` or ``sitl-stub``
    command (spans may wrap a line)."""
    found = []
    for doc in DOCS:
        text = (ROOT / doc).read_text(encoding="utf-8")
        text = re.sub(r"```.*?```", "", text, flags=re.S)  # fenced blocks are checked above
        for span in re.findall(r"(?<!`)`([^`]+)`(?!`)", text):
            words = " ".join(span.split()).split(" ")
            if words and words[0].removeprefix(".venv/bin/") in ("ezcompanion", "sitl-stub"):
                found.append((doc, [words[0].removeprefix(".venv/bin/"), *words[1:]]))
    return found


# --- what make and sh run ---------------------------------------------------------------------


def _make_rules() -> tuple[dict[str, str], dict[str, tuple[list[str], list[str]]]]:
    """The Makefile's variables and its rules (target: prerequisites, recipe lines)."""
    variables: dict[str, str] = {}
    rules: dict[str, tuple[list[str], list[str]]] = {}
    current: list[str] | None = None
    for line in (ROOT / "Makefile").read_text(encoding="utf-8").splitlines():
        if line.startswith("\t") and current is not None:
            current.append(line.strip())
            continue
        current = None
        if m := re.fullmatch(r"([A-Z_]+)\s*[:?]?=\s*(.*)", line):
            variables[m[1]] = m[2].strip()
        elif (m := re.fullmatch(r"([^\s:#.][^:]*):(?!=)(.*)", line)) and not line.startswith("."):
            current = []
            for target in m[1].split():
                rules[target] = (m[2].split(), current)
    return variables, rules


def _expand(text: str, variables: dict[str, str]) -> str:
    while m := re.search(r"\$\((\w+)\)", text):
        text = text.replace(m[0], variables[m[1]])
    return text


def make_recipe(target: str) -> list[str]:
    """Every recipe line ``make target`` runs (its prerequisites' first), expanded."""
    variables, rules = _make_rules()
    rules = {_expand(t, variables): r for t, r in rules.items()}
    assert target in rules, f"the Makefile has no target {target!r}"
    lines: list[str] = []
    seen: set[str] = set()

    def visit(name: str) -> None:
        if name in seen or name not in rules:
            return
        seen.add(name)
        prerequisites, recipe = rules[name]
        for each in prerequisites:
            visit(_expand(each, variables))
        lines.extend(_expand(r.lstrip("@"), variables) for r in recipe)

    visit(target)
    return lines


def script_commands(script: Path) -> list[list[str]]:
    """The ``ezcompanion`` commands of a shell script, ``$BIN`` and ``$OUT`` at their
    defaults, ``$WHERE`` (an optional scheduler) empty, continuations joined."""
    text = script.read_text(encoding="utf-8")
    defaults = dict(re.findall(r"^(\w+)=\$\{\1:-([^}]*)\}$", text, flags=re.M))
    numbered = list(enumerate(text.splitlines(), start=1))
    found = []
    for _, line in _logical_lines(numbered):
        line = line.replace("$WHERE", "")
        for name, value in defaults.items():
            line = line.replace(f"${name}", value)
        argv = words_of(line)
        if argv and argv[0].endswith("/ezcompanion"):
            found.append(["ezcompanion", *argv[1:]])
    return found


def bench_flags(script: Path) -> set[str]:
    """The ``--flags`` a benchmark's ``argparse`` declares (read from its source)."""
    flags = set()
    for node in ast.walk(ast.parse(script.read_text(encoding="utf-8"))):
        is_add = isinstance(node, ast.Call) and getattr(node.func, "attr", "") == "add_argument"
        if is_add:
            flags |= {
                a.value for a in node.args
                if isinstance(a, ast.Constant) and str(a.value).startswith("--")
            }  # fmt: skip
    return flags


COMMANDS = doc_commands()
