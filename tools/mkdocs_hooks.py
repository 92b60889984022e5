"""MkDocs hooks for the docs site (mkdocs.yml ``hooks:``); not part of the package.

Two jobs, both at build time so nothing can drift:

* ``reference/cli.md`` is generated from the ``amsfe`` argument parser
  (``amsfe_sym.apps.cli.get_argument_parser``): every command, every option, its default
  and its help, as the installed tool has them.
* A relative link from a page to a file of the repository outside ``docs/`` (a scenario, a
  robot spec, a sweep file) cannot be served by the site: it is shown as the file's path in
  the repository instead. A link to a file that exists nowhere is left alone, so
  ``mkdocs build --strict`` still fails on it.

    .venv/bin/mkdocs build --strict      # from the repository root
"""

from __future__ import annotations

import argparse
import os
import re
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parent.parent
CLI_PAGE = "reference/cli.md"
_REF = re.compile(r"\]\s?\[([^\]\[]+)\](?![(\[:])")
_LINK = re.compile(r"\[([^\]]+)\]\(([^)\s#]+)(#[^)\s]*)?\)")


def _cell(text: str) -> str:
    return text.replace("|", "\\|").replace("\n", " ")


def _option_rows(parser: argparse.ArgumentParser) -> list[str]:
    rows = ["| argument | default | meaning |", "|---|---|---|"]
    for a in parser._actions:
        if isinstance(a, argparse._HelpAction | argparse._SubParsersAction):
            continue
        if a.help == argparse.SUPPRESS:
            continue
        if a.option_strings:
            name = ", ".join(f"`{o}`" for o in a.option_strings)
            if a.nargs != 0:
                metavar = a.metavar or (a.dest.upper() if a.dest else "")
                name += f" `{metavar if isinstance(metavar, str) else ' '.join(metavar)}`"
        else:
            name = f"`{a.metavar or a.dest}`" + (" (optional)" if a.nargs in ("?", "*") else "")
        default = a.default
        shown = (
            "" if default in (None, False, argparse.SUPPRESS) or a.nargs == 0 else f"`{default}`"
        )
        choices = f" One of: {', '.join(map(str, a.choices))}." if a.choices else ""
        help_text = (a.help or "") % {"default": default} if a.help else ""
        rows.append(f"| {name} | {_cell(shown)} | {_cell(help_text + choices)} |")
    return rows


def cli_reference() -> str:
    """The page: every ``amsfe`` command and its options, from the parser itself."""
    from amsfe_sym.apps.cli import get_argument_parser

    parser = get_argument_parser()
    out = [
        "# Command reference (`amsfe`)",
        "",
        "Generated from the command's own argument parser when the site is built, so it is",
        "what `amsfe COMMAND --help` prints. Every command runs with no arguments (on the",
        "paper's 2-link robot or its scenario); where files go: "
        "[output paths](scenarios.md#output-paths-every-command).",
        "",
    ]
    (sub,) = (a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    helps = {c.dest: c.help for c in sub._choices_actions}
    for name, sp in sub.choices.items():
        line = (helps.get(name) or "").strip()
        out += [f"## `amsfe {name}`", "", line[:1].upper() + line[1:] + ".", ""]
        if sp.description:
            out += [sp.description.strip(), ""]
        usage = sp.format_usage().replace("usage: ", "").strip()
        out += ["```text", usage, "```", "", *_option_rows(sp), ""]
    return "\n".join(out)


def _present(nav: list[Any], docs_dir: Path) -> list[Any]:
    """The nav without the entries whose page is not in ``docs_dir`` (nor generated)."""
    out: list[Any] = []
    for item in nav:
        if isinstance(item, dict):
            ((title, value),) = item.items()
            if isinstance(value, list):
                kept = _present(value, docs_dir)
                if kept:
                    out.append({title: kept})
            elif value == CLI_PAGE or (docs_dir / value).exists():
                out.append(item)
        elif item == CLI_PAGE or (docs_dir / item).exists():
            out.append(item)
    return out


def on_config(config: Any) -> Any:
    """Pages another branch brings are in mkdocs.yml's nav before they exist."""
    if config["nav"]:
        config["nav"] = _present(config["nav"], Path(config["docs_dir"]))
    return config


def on_files(files: Any, config: Any) -> Any:
    """Adds the command reference. Also: text such as ``median [95% CI]`` after a bracketed
    interval reads as a Markdown reference link to mkdocs-autorefs (added by mkdocstrings
    after the hooks' ``on_config``); only the API's own cross-references are wanted."""
    from mkdocs.structure.files import File

    files.append(File.generated(config, CLI_PAGE, content=cli_reference()))
    return files


def on_page_markdown(markdown: str, page: Any, config: Any, files: Any) -> str:
    docs_dir = Path(config["docs_dir"]).resolve()
    here = (docs_dir / page.file.src_uri).parent

    def fix(m: re.Match[str]) -> str:
        text, target = m.group(1), m.group(2)
        if re.match(r"[a-z]+:", target) or target.startswith("/"):
            return m.group(0)
        path = Path(os.path.normpath(here / target))
        if path.is_relative_to(docs_dir) or not path.exists():
            return m.group(0)
        repo_path = path.relative_to(ROOT).as_posix()
        if repo_path in text:
            return text
        return f"{text} (`{repo_path}` in the repository)"

    # "[lo, hi] [95% CI]", "[a][unit]": text, not reference links (mkdocs-autorefs would
    # report them as missing cross-references)
    return _REF.sub(r"]\\[\1]", _LINK.sub(fix, markdown))


_AUTOREF = re.compile(r"<autoref ([^>]*)>(.*?)</autoref>", re.S)
_IDENTIFIER = re.compile(r'identifier="([^"]*)"')


def on_page_content(html: str, page: Any, config: Any, files: Any) -> str:
    """A docstring's "[u, v] [px]" is read by mkdocs-autorefs as a reference to an object
    ``px``; a cross-reference to the API is always a dotted path, so a target without a dot
    is put back as the text it was."""

    def text(m: re.Match[str]) -> str:
        ident = _IDENTIFIER.search(m.group(1))
        if ident is None or "." in ident.group(1):
            return m.group(0)
        return f"[{m.group(2)}][{ident.group(1)}]"

    return _AUTOREF.sub(text, html)
