"""The documentation cites only what exists: files, tests, modules, CLI commands and options.

Reads README.md, ARCHITECTURE.md and docs/*.md, and checks every repository path, test
name, `rafostrack.module` name and `rafostrack <command> --option` they cite against the
working tree and the click command tree; plus README's size limit, no `../` paths and no
issue-tracker numbers, and that docs/configuration.md is what scripts/config_reference.py
writes. Static reading only (no import of the tracker), so the tests take well under a second.
"""

from __future__ import annotations

import importlib.util
import itertools
import re
import sys
from functools import cache
from pathlib import Path

import click
import pytest

REPO = Path(__file__).resolve().parents[1]
DOCS = sorted([REPO / "README.md", REPO / "ARCHITECTURE.md", *(REPO / "docs").glob("*.md")])
README_MAX_BYTES = 15360
TOP_DIRS = ("rafostrack", "tests", "benchmarks", "scripts", "docs", "papers", "data")
PLACEHOLDER = re.compile(r"[<>*{}$]|\.\.\.|DIR|OUT|ROOT|MISSION|FILE")

CODE_SPAN = re.compile(r"`([^`\n]+)`")
LINK = re.compile(r"\]\(([^)\s]+)\)")
FENCE = re.compile(r"^```[^\n]*\n(.*?)^```", re.DOTALL | re.MULTILINE)
PATH = re.compile(r"(?<![\w./-])((?:" + "|".join(TOP_DIRS) + r")/[^\s`'\"),;]*)")
BARE_TEST_FILE = re.compile(r"^(test_\w+\.py)$")
TEST_ID = re.compile(r"^(tests/test_\w+\.py)::(test_\w+)$")
TEST_NAME = re.compile(r"^test_\w+$")
MODULE = re.compile(r"^rafostrack(?:\.\w+)+$")
# the mission directory's configuration file and the Parquet schema's metadata keys
NOT_MODULES = {"rafostrack.toml", "rafostrack.estimate", "rafostrack.config", "rafostrack.method", "rafostrack.version"}
PARENT = re.compile(r"(?:\.\./)+[^\s`'\")\]]*")  # a relative path upwards: it must stay inside the repository
MACHINE = re.compile(r"(?<![\w.])/(?:work|tmp|home|root|Users)/[^\s`'\")\]]*")  # an absolute path of one machine
ISSUE = re.compile(r"(?<![\w&/#(])#\d+\b|\bissues?\s+#?\d+|\bthe issue\b", re.IGNORECASE)


def _text(path: Path) -> str:
    return path.read_text(encoding="utf-8")


def _spans(text: str) -> list[str]:
    """Inline code spans, outside fenced blocks."""
    return CODE_SPAN.findall(FENCE.sub("", text))


@cache
def _test_functions() -> dict[str, set[str]]:
    """Test file name -> the names of the test functions it defines."""
    names = re.compile(r"^\s*(?:async\s+)?def (test_\w+)", re.MULTILINE)
    return {p.name: set(names.findall(_text(p))) for p in (REPO / "tests").glob("test_*.py")}


def cited_paths(text: str) -> set[str]:
    """Repository paths in code spans, fenced blocks and relative links (placeholders skipped)."""
    found = set()
    for chunk in [*_spans(text), *FENCE.findall(text)]:
        found |= {m.split("::")[0].rstrip(".,:;") for m in PATH.findall(chunk)}
    for target in LINK.findall(text):
        target = target.split("#")[0]
        if target and "://" not in target and not target.startswith("mailto:"):
            found.add(target)
    return {p for p in found if not PLACEHOLDER.search(p)}


def _exists(doc: Path, path: str) -> bool:
    """A path exists relative to the repository root (or, for a link, to the document)."""
    return (REPO / path).exists() or (doc.parent / path).exists()


def cited_tests(text: str) -> set[tuple[str | None, str]]:
    """(file or None, test name) pairs: `tests/test_x.py::test_y` and bare `test_y` spans."""
    found: set[tuple[str | None, str]] = set()
    for span in _spans(text):
        for part in re.split(r"[,\s]+", span):
            if m := TEST_ID.match(part):
                found.add((m.group(1), m.group(2)))
            elif TEST_NAME.match(part):
                found.add((None, part))
    return found


def cited_modules(text: str) -> set[str]:
    """Dotted `rafostrack.x.y` names in code spans (a call's arguments dropped)."""
    names = {span.split("(")[0].split()[0] for span in _spans(text) if span.startswith("rafostrack.")}
    names = {n.rstrip(".,:;") for n in names}
    return {n for n in names if MODULE.match(n) and n not in NOT_MODULES}


def _module_resolves(name: str) -> bool:
    """Walk the dotted name down packages and modules on disk; what is left must be one name
    defined in the last module's source (a function, class, constant or import)."""
    parts, where = name.split("."), REPO
    for k, part in enumerate(parts):
        if (where / part).is_dir() and (where / part / "__init__.py").exists():
            where = where / part
        elif (where / f"{part}.py").exists():
            source, rest = _text(where / f"{part}.py"), parts[k + 1 :]
            break
        else:
            source, rest = _text(where / "__init__.py"), parts[k:]
            break
    else:
        return True
    if not rest:
        return True
    if len(rest) > 2:
        return False
    name = re.escape(rest[0])
    pattern = rf"(def|class)\s+{name}\b|^\s*{name}\s*[:=]|import[^\n]*\b{name}\b|\b{name},|[\"']{name}[\"']"
    return re.search(pattern, source, re.MULTILINE) is not None


def cited_commands(text: str) -> list[list[str]]:
    """Each `rafostrack ...` command line as tokens, from code spans and fenced blocks (a
    fenced line's indented continuation lines joined, comments dropped)."""
    lines = [s for s in _spans(text) if s.startswith("rafostrack ")]
    for block in FENCE.findall(text):
        current: list[str] = []
        for line in block.splitlines():
            code = line.split(" #")[0]
            if code.startswith("rafostrack "):
                lines.append(" ".join(current)) if current else None
                current = [code]
            elif current and line.startswith((" ", "\t")) and code.strip():
                current.append(code.strip())
            else:
                lines.append(" ".join(current)) if current else None
                current = []
        if current:
            lines.append(" ".join(current))
    return [line.split() for line in lines]


@cache
def _cli() -> click.Group:
    """rafostrack.cli.main (its commands import the pipeline only when they run)."""
    from rafostrack.cli import main

    return main


def _options(command: click.Command) -> set[str]:
    opts = {"--help", "-h"}
    for param in command.params:
        opts |= {*param.opts, *param.secondary_opts}
    return opts


def command_problems(tokens: list[str]) -> list[str]:
    """What in one cited command line the CLI does not have: the command or an option."""
    main = _cli()
    words = [t for t in tokens[1:] if not t.startswith(("-", "[")) and re.fullmatch(r"[a-z]+", t)]
    flags = {m for t in tokens[1:] for m in re.findall(r"(?<![\w-])(--?[a-z][\w-]*)", t)}
    command = main.commands.get(words[0]) if words else None
    if words and command is None and not tokens[1].startswith("-"):
        return [f"no command {words[0]!r}"]
    allowed = _options(main) | (_options(command) if command else set())
    problems = [f"no option {flag}" for flag in sorted(flags) if flag not in allowed]
    return problems + _choice_problems(tokens, command)


def _choice_problems(tokens: list[str], command: click.Command | None) -> list[str]:
    """Values cited as `--option a` or `--option a|b|c` that the option's click.Choice does not offer."""
    params = {opt: p for p in (command.params if command else []) for opt in p.opts}
    problems = []
    for option, values in itertools.pairwise(tokens):
        param = params.get(option.strip("[]"))
        if param is not None and re.fullmatch(r"\[?[a-z_|]+\]?", values) and isinstance(param.type, click.Choice):
            cited = values.strip("[]").split("|")
            problems += [f"{option.strip('[]')} has no choice {v!r}" for v in cited if v not in param.type.choices]
    return problems


@pytest.mark.parametrize("doc", DOCS, ids=lambda p: p.name)
def test_cited_paths_exist(doc: Path) -> None:
    missing = sorted(p for p in cited_paths(_text(doc)) if not _exists(doc, p))
    assert not missing, f"{doc.name} cites paths that do not exist: {missing}"


def anchors(text: str) -> set[str]:
    """GitHub's anchors of the Markdown headings in `text` (lower case, punctuation dropped, spaces as -)."""
    headings = re.findall(r"^#{1,6}\s+(.+?)\s*$", FENCE.sub("", text), re.MULTILINE)
    return {re.sub(r"[^\w\- ]", "", h.lower()).replace(" ", "-") for h in headings}


@pytest.mark.parametrize("doc", DOCS, ids=lambda p: p.name)
def test_cited_anchors_exist(doc: Path) -> None:
    missing = []
    for target in LINK.findall(_text(doc)):
        path, _, anchor = target.partition("#")
        if not anchor or "://" in path:
            continue
        linked = doc if not path else doc.parent / path
        if linked.suffix == ".md" and linked.exists() and anchor not in anchors(_text(linked)):
            missing.append(target)
    assert not missing, f"{doc.name} links to headings that do not exist: {missing}"


@pytest.mark.parametrize("doc", DOCS, ids=lambda p: p.name)
def test_cited_tests_exist(doc: Path) -> None:
    tests = _test_functions()
    every = set().union(*tests.values())
    missing = sorted(
        f"{file}::{name}" if file else name
        for file, name in cited_tests(_text(doc))
        if (name not in tests.get(Path(file).name, set()) if file else name not in every)
    )
    bare = [s for s in _spans(_text(doc)) for p in re.split(r"[,\s]+", s) if BARE_TEST_FILE.match(p)]
    missing += sorted(f"tests/{p}" for p in bare if p not in tests)
    assert not missing, f"{doc.name} cites tests that do not exist: {missing}"


@pytest.mark.parametrize("doc", DOCS, ids=lambda p: p.name)
def test_cited_modules_exist(doc: Path) -> None:
    missing = sorted(n for n in cited_modules(_text(doc)) if not _module_resolves(n))
    assert not missing, f"{doc.name} cites rafostrack names that do not exist: {missing}"


@pytest.mark.parametrize("doc", DOCS, ids=lambda p: p.name)
def test_cited_cli_commands_and_options_exist(doc: Path) -> None:
    problems = {" ".join(t): p for t in cited_commands(_text(doc)) if (p := command_problems(t))}
    assert not problems, f"{doc.name} cites CLI commands or options that do not exist: {problems}"


@pytest.mark.parametrize("doc", DOCS, ids=lambda p: p.name)
def test_no_parent_paths_or_issue_numbers(doc: Path) -> None:
    text = _text(doc)
    outside = [p for p in PARENT.findall(text) if not (doc.parent / p).resolve().is_relative_to(REPO)]
    assert not outside, f"{doc.name} cites paths outside the repository: {outside}"
    assert not ISSUE.findall(text), f"{doc.name} cites the issue tracker: {ISSUE.findall(text)}"
    assert not MACHINE.findall(text), f"{doc.name} cites one machine's paths: {MACHINE.findall(text)}"


def test_readme_is_short() -> None:
    size = len((REPO / "README.md").read_bytes())
    assert size <= README_MAX_BYTES, f"README.md is {size} bytes; at most {README_MAX_BYTES} (move detail to docs/)"


def test_checks_catch_what_they_should() -> None:
    """The extractors find a missing path, test, module, command and option, and an issue number."""
    text = (
        "See `rafostrack/nowhere.py` and `tests/test_cli.py::test_no_such_test`, `rafostrack.nowhere.thing`,\n"
        "```sh\nrafostrack track F.csv --particles 10\n    --no-such-flag\nrafostrack nocommand\n```\nas in #12."
    )
    assert "rafostrack/nowhere.py" in cited_paths(text)
    assert ("tests/test_cli.py", "test_no_such_test") in cited_tests(text)
    assert not _module_resolves("rafostrack.nowhere.thing") and _module_resolves("rafostrack.sim.stress")
    commands = cited_commands(text)
    assert command_problems(commands[0]) == ["no option --no-such-flag"]
    assert command_problems(commands[1]) == ["no command 'nocommand'"]
    assert command_problems("rafostrack simulate D [--scenario synthetic|stress]".split()) == [
        "--scenario has no choice 'stress'"
    ]
    assert PARENT.findall("see ../shared/x.txt") == ["../shared/x.txt"]
    assert MACHINE.findall("--out /work/scratch/x and /tmp/y not rafostrack/io/x.py") == ["/work/scratch/x", "/tmp/y"]
    assert anchors("## Leg fits (`rafostrack legs`)\n### Scale: a, b") == {"leg-fits-rafostrack-legs", "scale-a-b"}
    assert ISSUE.findall(text) == ["#12"] and not ISSUE.findall("[Outputs](#outputs), `# # # degC`")


def test_configuration_reference_is_current() -> None:
    """docs/configuration.md is what scripts/config_reference.py writes from default.toml."""
    generator = _load("scripts/config_reference.py")
    wanted = generator.render(generator.DEFAULTS.read_text())
    current = (REPO / "docs" / "configuration.md").read_text()
    assert current == wanted, "docs/configuration.md is stale: run python scripts/config_reference.py"


def _load(relative: str):
    """A script of the repository (not a package module) loaded by path."""
    spec = importlib.util.spec_from_file_location(Path(relative).stem, REPO / relative)
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module
    spec.loader.exec_module(module)
    return module


def test_report_sections_replace_only_their_own_text() -> None:
    """benchmarks/report.py: a section is replaced between its markers, appended when absent."""
    report = _load("benchmarks/report.py")
    text = "intro\n<!-- a:start -->\nold a\n<!-- a:end -->\nmiddle\n<!-- b:start -->\nold b\n<!-- b:end -->\n"
    once = report.replace_section(text, "a", "new a")
    assert once == text.replace("old a", "new a")
    assert report.replace_section(once, "a", "new a") == once
    appended = report.replace_section(text, "c", "c body")
    assert appended.startswith(text.rstrip("\n")) and appended.endswith("<!-- c:start -->\nc body\n<!-- c:end -->\n")


def test_validation_sections_are_stamped() -> None:
    """docs/validation.md holds the three benchmark sections, each stamped with date, commit and command."""
    text = (REPO / "docs" / "validation.md").read_text()
    for name, script in (("robustness", "robustness"), ("accuracy", "accuracy"), ("speed", "speed")):
        body = re.search(rf"<!-- {name}:start -->\n(.*?)<!-- {name}:end -->", text, re.DOTALL)
        assert body is not None, f"no {name} section"
        stamp = r"_Written \d{4}-\d{2}-\d{2} at commit `[0-9a-f]+(\+dirty)?` by `python benchmarks/%s\.py[^`]*`\._"
        assert re.match(stamp % script, body.group(1)), f"the {name} section is not stamped"
        assert re.search(r"^\|(---:?\|)+$", body.group(1), re.MULTILINE), f"the {name} section has no table"


# A timing written by hand: seconds, minutes or hours near a core count or per float.
DURATION = r"\d+(?:\.\d+)?(?:-\d+(?:\.\d+)?)? ?(?:s|min|minutes|hours)\b"
HAND_TIMING = re.compile(
    rf"{DURATION}[^.;\n]{{0,30}}?(?:\bcores?\b|per (?:\S+ )?float)|\bcores?\b[^.;\n]{{0,30}}?{DURATION}|core-hours"
)


def test_speed_figures_come_from_the_benchmarks() -> None:
    """The user guide's timings ("8.7-9.0 s on two cores") were hand-written, not what a user
    sees: it points to validation.md's speed section, which the benchmark writes with the
    machine and its load; README says how long `make test` takes and that `make test-fast` exists."""
    for written in ("the sample float on two cores: 8.7-9.0 s", "~15-25 s per 2-year float", "~7-10 core-hours"):
        assert HAND_TIMING.findall(written), written
    assert not HAND_TIMING.findall("the arrivals support 90.2 s on 7 of 9 floats")
    guide = (REPO / "docs" / "user-guide.md").read_text()
    assert not HAND_TIMING.findall(guide), HAND_TIMING.findall(guide)
    assert "validation.md#speed-the-2-year-sample-float-and-an-archive-float" in guide
    assert "load average" in _load("benchmarks/report.py").machine()
    readme = (REPO / "README.md").read_text()
    assert re.search(r"`make test` runs the suite, about \d+ minutes on a \d-core machine; `make test-fast`", readme)
