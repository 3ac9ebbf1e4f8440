"""The documentation site's generated pages and the README front page (issue 31, part 1).

``make docs`` builds the site with warnings as errors; these tests check, without building
it, what the generators put in: every public name in the API reference, every command and
option in the CLI reference, the benchmark tables from a results file.
"""

from __future__ import annotations

import json
import re
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "docs" / "_ext"))

import generated  # noqa: E402  (docs/_ext/generated.py)


def test_every_public_name_is_in_the_api_reference():
    import lipsync

    page = generated.api_page()
    documented = set(re.findall(r"^\.\. auto(?:class|function|exception):: (\w+)$", page, re.M))
    assert documented == set(lipsync._EXPORTS)
    assert {"write_video", "render_clip", "Bank", "Animator", "LiveAnimator"} <= documented
    listed = set(re.findall(r"^api-lipsync\.(\w+)$", page, re.M))
    assert listed == set(lipsync._SUBMODULES)
    import importlib

    for module in lipsync._SUBMODULES:
        real = importlib.import_module(f"lipsync.{module}").__name__  # where a moved module lives
        assert f".. automodule:: {real}\n   :members:" in generated.module_page(module)


def test_the_cli_reference_has_every_command_and_option():
    from lipsync.cli import _COMMAND_MODULES, build_parser

    page = generated.cli_page()
    commands = re.findall(r"^## lipsync (\S+)$", page, re.M)
    assert commands == [m.replace("_", "-") for m in _COMMAND_MODULES]
    for name, _, sub in generated._subparsers(build_parser()):
        section = page.split(f"## lipsync {name}\n", 1)[1].split("\n## lipsync ", 1)[0]
        for action in sub._actions:
            for option in action.option_strings:
                if option not in ("-h", "--help"):
                    assert f"`{option}" in section or f", {option}" in section, (name, option)
    assert "--shapes" in page and "--allow-mismatch" in page and "DIR_OR_NAME" in page


def test_the_benchmark_page_renders_results_or_says_how_to_make_them(tmp_path):
    assert "make bench" in generated.bench_page(tmp_path / "absent.json")
    results = tmp_path / "results.json"
    results.write_text(json.dumps({"meta": {"seconds": 12.5, "cpu_count": 2, "python": "3.11", "numpy": "2.1"},
                                   "results": [{"figure": "frame", "size": "512x512", "flow_ms": 0.91},
                                               {"figure": "frame", "size": "1280x720", "flow_ms": 3.31},
                                               {"figure": "align", "case": "a|b", "speed": 26.8}]}))
    page = generated.bench_page(results)
    assert "## frame\n\n| size | flow_ms |\n| --- | --- |\n| 512x512 | 0.91 |\n| 1280x720 | 3.31 |" in page
    assert "| a\\|b | 26.8 |" in page and "12.5 s on 2 cores" in page


def test_the_readme_is_a_front_page():
    text = (ROOT / "README.md").read_text(encoding="utf-8")
    assert len(text.splitlines()) <= 220
    assert "make test" in text and "make demo" in text and "make docs" in text and "pip install" in text
    assert "X-Lipsync-Token" in text
    for link in re.findall(r"\]\((docs/[^)#]+)", text):          # every page it links exists
        assert (ROOT / link).is_file(), link


def test_every_page_is_in_the_site_and_the_feature_pages_have_a_place():
    index = (ROOT / "docs" / "index.md").read_text(encoding="utf-8")
    entries = set(re.findall(r"^([\w/-]+)$", index, re.M))
    pages = {p.stem for p in (ROOT / "docs").glob("*.md")} - {"index"}
    assert pages <= entries, pages - entries
    assert {"dub", "make-a-subject", "phonetics", "languages", "live", "blender"} <= entries
    serve = (ROOT / "docs" / "serve.md").read_text(encoding="utf-8")
    assert "X-Lipsync-Token" in serve and "token=" in serve
