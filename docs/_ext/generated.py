"""Pages generated when the site is built, so they cannot fall behind the code.

* ``_generated/cli.md``: every ``lipsync`` command's usage and options, from the argparse
  parsers the commands build (``lipsync.cli.build_parser``): a new option appears by itself.
* ``_generated/api.md``: every public name -- ``lipsync._EXPORTS`` (``from lipsync import
  NAME``) and the public submodules (``lipsync._SUBMODULES``) -- rendered by autodoc from the
  docstrings (numpydoc).
* ``_generated/bench.md``: the benchmark figures of ``bench/results.json`` as tables, or how
  to make that file when it is absent (it is machine-specific and not committed).

Each page is also a plain function returning Markdown (``cli_page``, ``api_page``,
``bench_page``), which the tests call without building the site.
"""

from __future__ import annotations

import argparse
import json
import os
import re
from pathlib import Path
from typing import List

ROOT = Path(__file__).resolve().parents[2]
OUT = Path(__file__).resolve().parents[1] / "_generated"


def _cell(text) -> str:
    return str(text).replace("|", "\\|").replace("\n", " ")


# --- CLI ---------------------------------------------------------------------------------------

def _subparsers(parser: argparse.ArgumentParser):
    for action in parser._actions:  # argparse keeps them here; there is no public accessor
        if isinstance(action, argparse._SubParsersAction):
            helps = {a.dest: a.help for a in action._choices_actions}
            for name, sub in action.choices.items():
                yield name, helps.get(name, ""), sub


def cli_page() -> str:
    """The CLI reference: one section per command, its usage and an options table."""
    os.environ["COLUMNS"] = "100"  # argparse wraps usage lines at the terminal's width
    from lipsync.cli import build_parser

    lines = ["# Command-line reference", "",
             "Generated from the argument parsers of `lipsync/cli/` when this site is built: every "
             "option of every command is here, with its default. Exit codes: 0 success, 2 bad input "
             "(the message names the file and, where it applies, the line), 130 Ctrl-C, 143 SIGTERM, "
             "1 anything else.", ""]
    for name, short, sub in _subparsers(build_parser()):
        short = _cell(short or "").rstrip(".")
        lines += [f"## lipsync {name}", "", short[:1].upper() + short[1:] + ".", ""]
        if sub.description:
            lines += [sub.description, ""]
        lines += ["```text", sub.format_usage().strip(), "```", "",
                  "| argument | meaning |", "| --- | --- |"]
        for action in sub._actions:
            if isinstance(action, argparse._HelpAction):
                continue
            if action.option_strings:
                arg = ", ".join(action.option_strings)
                if action.nargs != 0:
                    arg += " " + (action.metavar or action.dest.upper())
            else:
                arg = action.metavar or action.dest.upper()
            text = action.help or ""
            if action.choices and "one of" not in text and not action.metavar:
                text += f" (one of: {', '.join(map(str, action.choices))})"
            lines.append(f"| `{_cell(arg)}` | {_cell(text)} |")
        lines.append("")
    return "\n".join(lines) + "\n"


# --- API ---------------------------------------------------------------------------------------

def public_names():
    """(top-level names, public submodules) as ``lipsync`` declares them."""
    import lipsync

    return sorted(lipsync._EXPORTS), sorted(lipsync._SUBMODULES)


def api_page() -> str:
    """The API reference: autodoc directives for every public name."""
    import inspect

    import lipsync

    names, modules = public_names()
    lines = ["# API reference", "",
             "Everything `import lipsync` offers, from the docstrings (numpydoc). The names below "
             "are imported from the top level (`from lipsync import Bank`); the modules after "
             "them are the public submodules (`lipsync.morphing.warp`, ...). Generated when the site is "
             "built from `lipsync._EXPORTS` and `lipsync._SUBMODULES`.", "",
             "## Top-level names", "", "```{eval-rst}", ".. currentmodule:: lipsync", ""]
    for name in names:
        obj = getattr(lipsync, name)
        if inspect.isclass(obj):
            directive = "autoexception" if issubclass(obj, BaseException) else "autoclass"
            lines += [f".. {directive}:: {name}", "   :members:", ""]
        else:
            lines += [f".. autofunction:: {name}", ""]
    lines += ["```", "", "## Public submodules", "", "```{toctree}", ":maxdepth: 1", ""]
    lines += [f"api-lipsync.{module}" for module in modules]
    lines += ["```", ""]
    return "\n".join(lines) + "\n"


def module_page(module: str) -> str:
    """One public submodule: its docstring and its public members (``__all__`` where it has one).

    ``lipsync.NAME`` may be a module that moved into a room (``lipsync.warp`` is
    ``lipsync.morphing.warp``): it is documented where it lives, under both names."""
    import importlib

    import lipsync

    mod = importlib.import_module(f"lipsync.{module}")
    real = mod.__name__
    moved = [] if real == f"lipsync.{module}" else [f"(`lipsync.{module}` is `{real}`.)", ""]
    # names the top-level page documents (lipsync.Bank, ...) are not described twice
    top = sorted(n for n in lipsync._EXPORTS if getattr(mod, n, None) is getattr(lipsync, n))
    exclude = [f"   :exclude-members: {', '.join(top)}"] if top else []
    return "\n".join([f"# lipsync.{module}", ""] + moved + ["```{eval-rst}", f".. automodule:: {real}",
                                                           "   :members:"] + exclude + ["```", ""])


# --- benchmarks --------------------------------------------------------------------------------

def bench_page(results: Path = ROOT / "bench" / "results.json") -> str:
    """The benchmark figures of ``results`` as one table per figure."""
    lines = ["# Benchmark figures", ""]
    if not results.is_file():
        return "\n".join(lines + [
            "No `bench/results.json` was there when this site was built. It is written by",
            "",
            "```sh",
            "make bench                                   # every figure (about 15 minutes on 2 cores)",
            "python -m lipsync.bench --only frame          # one figure",
            "```",
            "",
            "and then `make docs` shows its tables here. The file is not committed: the figures are "
            "this machine's (cores, CPU, load), and the pages that quote figures say which run and "
            "machine they come from ([How it works](../how-it-works.md)).", ""]) + "\n"
    data = json.loads(results.read_text(encoding="utf-8"))
    meta = data.get("meta", {})
    lines += [f"From `bench/results.json`: {meta.get('seconds', '?')} s on {meta.get('cpu_count', '?')} cores, "
              f"Python {meta.get('python', '?')}, numpy {meta.get('numpy', '?')}. Regenerate with `make bench` "
              "(or `python -m lipsync.bench --only NAME`), then `make docs`.", ""]
    figures: dict = {}
    for row in data.get("results", []):
        figures.setdefault(row.get("figure", "?"), []).append(row)
    for figure, rows in figures.items():
        columns: List[str] = []
        for row in rows:
            columns += [k for k in row if k != "figure" and k not in columns]
        lines += [f"## {figure}", "", "| " + " | ".join(_cell(c) for c in columns) + " |",
                  "|" + " --- |" * len(columns)]
        for row in rows:
            lines.append("| " + " | ".join(_cell(row.get(c, "")) for c in columns) + " |")
        lines.append("")
    return "\n".join(lines) + "\n"


# --- Sphinx hook -------------------------------------------------------------------------------

def _write(name: str, text: str) -> None:
    OUT.mkdir(exist_ok=True)
    path = OUT / name
    if not path.is_file() or path.read_text(encoding="utf-8") != text:  # unchanged: no rebuild
        path.write_text(text, encoding="utf-8")


def generate(app=None) -> None:
    _write("cli.md", cli_page())
    _write("api.md", api_page())
    for module in public_names()[1]:
        _write(f"api-lipsync.{module}.md", module_page(module))
    _write("bench.md", bench_page())


_UNDERLINE = re.compile(r"^(-{3,}|={3,})$")


def _module_sections_as_rubrics(app, what, name, obj, options, lines) -> None:
    """Module docstrings' numpydoc-style headings (``Examples`` over dashes) as rubrics:
    numpydoc leaves module docstrings to docutils, whose sections would give every module
    page a duplicate ``examples`` label."""
    if what != "module":
        return
    for i in range(len(lines) - 1):
        if lines[i].strip() and _UNDERLINE.match(lines[i + 1].strip()) and \
                len(lines[i + 1].strip()) >= len(lines[i].strip()) and not lines[i].startswith(" "):
            lines[i], lines[i + 1] = f".. rubric:: {lines[i].strip()}", ""


def _resolve(target: str, module: str, cls: str):
    """The object a Python reference names, looked up as Python would (or None)."""
    import importlib

    target = target.lstrip("~.")
    candidates = [target]
    for base in (f"{module}.{cls}" if module and cls else None, module, "lipsync"):
        if base:
            candidates.append(f"{base}.{target}")
    if module == "lipsync":  # the top-level names' docstrings speak from their own modules
        import sys

        candidates += [f"{m}.{target}" for m in sorted(sys.modules) if m.startswith("lipsync.")]
    for dotted in candidates:
        parts = dotted.split(".")
        for cut in range(len(parts), 0, -1):
            try:
                obj = importlib.import_module(".".join(parts[:cut]))
            except ImportError:
                continue
            try:
                for attr in parts[cut:]:
                    obj = getattr(obj, attr)
            except AttributeError:
                break
            return obj
    return None


def _existing_but_undocumented(app, env, node, contnode):
    """A docstring's reference to a real object the API reference does not list (a private
    helper, an internal module) is shown as code, without a link; a reference to a name
    that does not exist stays a warning, which ``make docs`` (-W -n) turns into a failure."""
    if node.get("refdomain") != "py":
        return None
    if _resolve(node.get("reftarget", ""), node.get("py:module") or "", node.get("py:class") or "") is None:
        return None
    return contnode


def setup(app):
    app.connect("builder-inited", generate)
    app.connect("autodoc-process-docstring", _module_sections_as_rubrics)
    app.connect("missing-reference", _existing_but_undocumented)
    return {"parallel_read_safe": True, "parallel_write_safe": True}
