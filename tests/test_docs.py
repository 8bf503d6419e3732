"""The documentation, checked against the code it describes.

Conventions for README.md and docs/*.md:

* **Runnable blocks.** A fenced block whose info string is ``sh runnable`` or
  ``python runnable`` (GitHub highlights it by its first word) is run as written: sh with
  ``bash -e``, python with this interpreter, in an empty temporary folder, with this
  installation's console scripts (``quadsitl``, ``gcs-replay``, ``rerun``, ...) first on
  PATH, as an activated venv has them. Mark only quick, self-contained blocks (a few
  seconds; no network peers, nothing left running); long ones stay unmarked.
* **Options.** Every ``--option`` named in the docs must exist in the ``--help`` of the
  command it follows on the same line of a code block, in the same inline code span, or,
  in a block, on an earlier line (so a command's option list under it is checked against
  it): ``quadsitl SUB``, ``gcs-replay``, ``gcs-live``, ``python -m gcs_tools.relay``,
  ``python benchmarks/NAME.py`` (options read from its source: a benchmark runs before it
  parses). An option named with no command (a table row such as ``--gcs URL``) must exist
  in one of those commands. Options after other programs (``rerun``, ``mavproxy.py``,
  ``docker``, ``ray``, ...) are theirs and not checked.
* **Numbers.** The rotor speeds and the vehicle parameters the docs quote are the code's.

Failures name the document, the line and what is wrong.
"""

from __future__ import annotations

import argparse
import os
import re
import subprocess
import sys
import textwrap
from dataclasses import dataclass
from functools import cache
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
DOCS = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]
RUNNABLE = ("sh", "python")
TOOLS = ("gcs-replay", "gcs-live")  # console scripts besides quadsitl
FOREIGN = {
    "rerun",
    "mavproxy.py",
    "mavlogdump.py",
    "docker",
    "ray",
    "pip",
    "tensorboard",
    "make",
    "pytest",
    "git",
    "ruff",
    "mypy",
    "mavsdk_server",
    "wsl",
    "arducopter",  # ArduPilot's SITL binary and build tool (docs/autopilots.md)
    "waf",
}
OPTION = re.compile(r"(?<![\w-])--[a-z][a-z0-9]*(?:-[a-z0-9]+)*")


@dataclass
class Block:
    doc: Path
    line: int  # of the opening fence
    info: str
    text: str

    def __str__(self) -> str:
        return f"{self.doc.relative_to(ROOT)}:{self.line}"


def fenced_blocks(doc: Path) -> list[Block]:
    blocks, lines = [], doc.read_text().splitlines()
    start = None
    for number, line in enumerate(lines, 1):
        if line.lstrip().startswith("```"):
            if start is None:
                start, info, body = number, line.lstrip()[3:].strip(), []
            else:
                blocks.append(Block(doc, start, info, textwrap.dedent("\n".join(body))))
                start = None
        elif start is not None:
            body.append(line)
    return blocks


def runnable_blocks() -> list[Block]:
    return [
        block
        for doc in DOCS
        for block in fenced_blocks(doc)
        if block.info.split()[:2] in ([lang, "runnable"] for lang in RUNNABLE)
    ]


def test_some_blocks_are_marked_runnable():
    kinds = {block.info.split()[0] for block in runnable_blocks()}
    assert kinds == set(RUNNABLE), f"runnable blocks found: {kinds}"


@pytest.mark.parametrize("block", runnable_blocks(), ids=str)
def test_runnable_block_runs(block: Block, tmp_path):
    scripts = str(Path(sys.executable).parent)
    env = {
        **os.environ,
        "PATH": scripts + os.pathsep + os.environ.get("PATH", ""),
        "PYTHONPATH": str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", ""),
        "QUADSITL_RERUN_DIR": str(tmp_path),
    }
    command = ["bash", "-e", "-c"] if block.info.startswith("sh") else [sys.executable, "-c"]
    # 600 s: a hang guard, not a speed (a block that runs the physics compiles it first
    # where numba's cache is cold: 97 s seen on a loaded machine after a kernel change)
    result = subprocess.run(
        [*command, block.text], cwd=tmp_path, env=env, capture_output=True, text=True, timeout=600
    )
    assert result.returncode == 0, (
        f"{block}: the {block.info} block failed (exit {result.returncode}):\n"
        f"{block.text}\n--- output ---\n{result.stdout}{result.stderr}"
    )


# --- options ---------------------------------------------------------------------------


def _options(text: str) -> set[str]:
    return set(OPTION.findall(text))


@cache
def command_options() -> dict[str, set[str]]:
    """Each command the docs may name -> the options its --help lists."""
    from quadsitl.cli import _build_parser

    parser = _build_parser()
    known = {"quadsitl": _options(parser.format_help())}
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for name, sub in action.choices.items():
                known[f"quadsitl {name}"] = _options(sub.format_help())
    for name, argv in (
        ("gcs-replay", ["-m", "gcs_tools.replay"]),
        ("gcs-live", ["-m", "gcs_tools.live"]),
        ("gcs_tools.relay", ["-m", "gcs_tools.relay"]),
    ):
        help_text = subprocess.run(
            [sys.executable, *argv, "--help"], capture_output=True, text=True, timeout=60, cwd=ROOT
        ).stdout
        assert "usage:" in help_text, f"{name} --help printed no usage"
        known[name] = _options(help_text)
    for script in sorted((ROOT / "benchmarks").glob("*.py")):
        added = re.findall(r"add_argument\(\s*\"(--[a-z0-9-]+)\"", script.read_text())
        known[f"benchmarks/{script.name}"] = set(added) | {"--help"}
    return known


def _command_at(words: list[str], i: int, current: str | None) -> str | None:
    """The command that the word at ``i`` starts (or ``current`` if it starts none)."""
    word, following = (words[j].strip("`[](),;:") if j < len(words) else "" for j in (i, i + 1))
    if word == "quadsitl":
        sub = f"quadsitl {following}"
        return sub if sub in command_options() else "quadsitl"
    if word in TOOLS:
        return word
    if word.startswith("benchmarks/") and word.endswith(".py"):
        return word
    if word == "-m" and following.startswith("gcs_tools."):
        return following
    if word == "-m" and following == "quadsitl.cli":
        sub = f"quadsitl {words[i + 2].strip('`[](),;:')}" if i + 2 < len(words) else ""
        return sub if sub in command_options() else "quadsitl"
    if word.rsplit("/", 1)[-1] in FOREIGN:  # also by path: build/sitl/bin/arducopter
        return "foreign"
    return current


@dataclass
class Mention:
    doc: Path
    line: int
    option: str
    command: str | None  # None: named with no command

    def problem(self) -> str | None:
        known = command_options()
        if self.command == "foreign":
            return None
        if self.command is None:
            if any(self.option in options for options in known.values()):
                return None
            return f"{self.option} is an option of no command"
        if self.command not in known:
            return None  # a benchmark script without options, checked elsewhere
        if self.option in known[self.command]:
            return None
        return f"{self.option} is not in `{self.command} --help`"


def _scan(
    doc: Path, text: str, first_line: int, current: str | None
) -> tuple[list[Mention], str | None]:
    """Options in ``text`` (one code span or one block line) with their commands, and the
    command in force at its end."""
    mentions = []
    words = text.split()
    offsets, position = [], 0
    for word in words:
        position = text.index(word, position)
        offsets.append(position)
        position += len(word)
    for i, word in enumerate(words):
        current = _command_at(words, i, current)
        for option in OPTION.findall(word):
            line = first_line + text.count("\n", 0, offsets[i])
            mentions.append(Mention(doc, line, option, current))
    return mentions, current


def mentions(doc: Path) -> list[Mention]:
    found: list[Mention] = []
    text = doc.read_text()
    text = re.sub(r"\]\([^)]*\)", lambda m: "]" + " " * (len(m.group()) - 1), text)  # links
    lines = text.split("\n")
    prose: list[str] = []
    in_block, block_language, current = False, "", None
    for number, line in enumerate(lines, 1):
        if line.lstrip().startswith("```"):
            in_block, block_language, current = not in_block, line.lstrip()[3:].strip(), None
            prose.append("")
            continue
        if in_block:
            prose.append("")
            if not block_language.startswith("python"):
                in_line, current = _scan(doc, line, number, current)
                found += in_line
        else:
            prose.append(line)
    body = "\n".join(prose)
    end, current = 0, None
    for span in re.finditer(r"`([^`]+)`", body):
        # `ray start`'s `--port`/`--head`: the command of the span before
        carried = current if body[end : span.start()].strip() in ("'s", "/") else None
        first = body.count("\n", 0, span.start()) + 1
        in_span, current = _scan(doc, span.group(1), first, carried)
        found += in_span
        end = span.end()
    outside = re.sub(r"`[^`]+`", lambda m: re.sub(r"[^\n]", " ", m.group()), body)
    for match in OPTION.finditer(outside):
        found.append(Mention(doc, outside.count("\n", 0, match.start()) + 1, match.group(), None))
    return found


@pytest.mark.parametrize("doc", DOCS, ids=lambda d: str(d.relative_to(ROOT)))
def test_every_option_named_in_the_docs_exists(doc: Path):
    problems = [
        f"{doc.relative_to(ROOT)}:{m.line}: {problem}"
        for m in mentions(doc)
        if (problem := m.problem()) is not None
    ]
    assert not problems, "options named in the docs that the commands lack:\n" + "\n".join(problems)


def test_a_misnamed_option_is_caught_with_its_line(tmp_path):
    doc = tmp_path / "doc.md"
    doc.write_text(
        "Run `quadsitl sim --rerun-sav x` or\n\n```sh\nquadsitl train --task hover\n"
        "  --bogus-flag    explained here\nrerun --headless\n```\n`--gcs` and `--nowhere`\n"
    )
    problems = sorted((m.line, m.option, m.problem()) for m in mentions(doc) if m.problem())
    assert problems == [
        (1, "--rerun-sav", "--rerun-sav is not in `quadsitl sim --help`"),
        (5, "--bogus-flag", "--bogus-flag is not in `quadsitl train --help`"),
        (8, "--nowhere", "--nowhere is an option of no command"),
    ]


# --- numbers ---------------------------------------------------------------------------


def test_rotor_speeds_quoted_in_the_docs_are_the_papers_airframe():
    from quadsitl.physics import PAPER

    expected = {"Ω_max": PAPER.max_rotor_speed, "Ω_h": PAPER.hover_rotor_speed}
    pattern = re.compile(r"(Ω_max|Ω_h)(?: = [^≈|]*≈)?\s+(\d+(?:\.\d+)?)\s+rad/s")
    wrong = [
        f"{doc.relative_to(ROOT)}:{text.count(chr(10), 0, match.start()) + 1}: "
        f"{match.group(1)} {match.group(2)} rad/s, the code has {expected[match.group(1)]:.1f}"
        for doc in DOCS
        for text in [doc.read_text()]
        for match in pattern.finditer(text)
        if abs(float(match.group(2)) - expected[match.group(1)]) > 0.05
    ]
    checked = sum(len(pattern.findall(doc.read_text())) for doc in DOCS)
    assert checked >= 3, f"only {checked} rotor speeds found: has the wording changed?"
    assert not wrong, "\n".join(wrong)


def test_parameter_table_of_mavlink_md_is_the_codes():
    from quadsitl.flight_software.params import PARAMETERS

    doc = ROOT / "docs" / "mavlink.md"
    specs = {spec.name: spec for spec in PARAMETERS}
    rows = {}
    for number, line in enumerate(doc.read_text().splitlines(), 1):
        match = re.match(r"\| `([A-Z0-9_]+)`(?: \(\*int\*\))? \| ([^|]+) \| ([^|]+) \|", line)
        if match and match.group(1) in specs:
            rows[match.group(1)] = (number, match.group(2).strip(), match.group(3).strip())
    wrong = sorted(set(specs) - set(rows))
    problems = [f"docs/mavlink.md: parameter {name} is missing from the table" for name in wrong]
    for name, (number, default, span) in rows.items():
        spec = specs[name]
        if float(default) != spec.default:
            problems.append(
                f"docs/mavlink.md:{number}: {name} default {default}, code {spec.default:g}"
            )
        if "…" in span:
            low, high = (float(x.replace(",", "")) for x in span.split("…"))
            if (low, high) != (spec.minimum, spec.maximum):
                problems.append(
                    f"docs/mavlink.md:{number}: {name} range {span}, "
                    f"code {spec.minimum:g} … {spec.maximum:g}"
                )
    assert not problems, "\n".join(problems)


def test_sim_option_defaults_of_mavlink_md_are_the_codes():
    from quadsitl.cli import _build_parser

    parser = _build_parser()
    sim = next(
        action.choices["sim"]
        for action in parser._actions
        if isinstance(action, argparse._SubParsersAction)
    )
    defaults = {
        option: action.default for action in sim._actions for option in action.option_strings
    }
    doc = ROOT / "docs" / "mavlink.md"
    problems = []
    for number, line in enumerate(doc.read_text().splitlines(), 1):
        match = re.match(r"\| `(--[a-z-]+)[^`]*` \| `?([^|`]+)`? \|", line)
        if not match or match.group(1) not in defaults:
            continue
        documented, default = match.group(2).strip(), defaults[match.group(1)]
        if documented in ("–", "off") or default in (None, False, []):
            continue
        if str(default) != documented and _number(documented) != default:
            problems.append(
                f"docs/mavlink.md:{number}: {match.group(1)} default {documented}, code {default}"
            )
    assert not problems, "\n".join(problems)


def _number(text: str) -> float | None:
    try:
        return float(text)
    except ValueError:
        return None


def test_telemetry_rates_of_mavlink_md_are_the_codes():
    from quadsitl.simulator.telemetry import DEFAULT_RATES, mav

    doc = ROOT / "docs" / "mavlink.md"
    text = doc.read_text()
    section = text.index("## Telemetry (per link")
    first = text.count("\n", 0, section) + 1
    problems, checked = [], 0
    for number, line in enumerate(text[section:].splitlines(), first):
        if line.startswith("## ") and number > first:
            break
        match = re.match(r"\| ([A-Z_, ]+) \| ([\d.]+) \|", line)
        if not match:
            continue
        rate = float(match.group(2))
        for name in match.group(1).split(","):
            code = DEFAULT_RATES.get(getattr(mav, f"MAVLINK_MSG_ID_{name.strip()}", -1))
            checked += 1
            if code != rate:
                problems.append(
                    f"docs/mavlink.md:{number}: {name.strip()} at {rate:g} Hz, code {code}"
                )
    assert checked >= 10, f"only {checked} telemetry rows found: has the table changed?"
    assert not problems, "\n".join(problems)


def test_airframe_table_of_the_readme_is_the_papers():
    from quadsitl.physics import PAPER

    row = next(
        line
        for line in (ROOT / "README.md").read_text().splitlines()
        if line.startswith("| `paper`")
    )
    cells = [cell.strip() for cell in row.strip("|").split("|")]
    numbers = [float(re.match(r"[\d.e-]+", cell).group()) for cell in cells[2:4] + cells[5:]]
    expected = [
        PAPER.mass,
        PAPER.arm_length,
        PAPER.thrust_coeff,
        PAPER.torque_coeff,
        round(PAPER.hover_rotor_speed, 1),
        round(PAPER.max_rotor_speed, 1),
    ]
    assert numbers == expected, f"README.md airframe row {numbers}, code {expected}"
    inertia = tuple(float(x.strip(",")) for x in cells[4].split()[:3])
    assert inertia == PAPER.inertia, f"README.md inertia {inertia}, code {PAPER.inertia}"


def test_the_readmes_command_list_has_every_subcommand():
    """README's "Command line" block names each subcommand `quadsitl --help` lists."""
    block = (ROOT / "README.md").read_text().split("## Command line", 1)[1].split("```")[1]
    listed = {line.split()[1] for line in block.splitlines() if line.startswith("quadsitl ")}
    subcommands = {name.split()[1] for name in command_options() if name.startswith("quadsitl ")}
    missing = subcommands - listed
    assert not missing, f"missing from README's command list: {sorted(missing)}"
