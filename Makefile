# Every target sets itself up: a fresh machine needs only python3.
PY      ?= python3
VENV    := .venv
BIN     := $(VENV)/bin
STAMP   := $(VENV)/.installed

.PHONY: test test-browser test-blender demo bench fuzz docs docs-images clean install

# The compiled frame kernel is built by the editable install: a changed source rebuilds it.
# compileall: an editable install leaves no bytecode, and where PYTHONDONTWRITEBYTECODE is
# set every run would compile the package again (~0.1 s of each lipsync start-up).
$(STAMP): pyproject.toml setup.py lipsync/morphing/_flowkernel.c
	$(PY) -m venv $(VENV)
	$(BIN)/pip install -q --upgrade pip
	$(BIN)/pip install -q -e '.[test]'
	$(BIN)/python -m compileall -q lipsync
	touch $(STAMP)

install: $(STAMP)

# On both cores of CI's machine (pytest-xdist). --dist loadfile: a test file runs whole in
# one worker, so its module fixtures are made once and its tests keep their order;
# tests/conftest.py orders the heaviest files first (xdist's own reorder, by test count, off). TEST_WORKERS=0 runs in one process.
TEST_WORKERS ?= 2
test: $(STAMP)
	$(BIN)/python -m pytest -q -p no:cacheprovider -n $(TEST_WORKERS) --dist loadfile --no-loadscope-reorder

demo: $(STAMP)
	$(BIN)/lipsync render samples/hello.phn --audio samples/hello.wav -o demo.mp4
	@echo "wrote demo.mp4"

bench: $(STAMP)
	$(BIN)/python -m lipsync.bench

# The editor in real headless Chromium (also part of `make test` when chromium is present).
# Installs Debian's chromium and chromium-driver first, only if they are missing.
test-browser: $(STAMP)
	@if [ ! -x /usr/bin/chromium ] || [ ! -x /usr/bin/chromedriver ]; then \
		apt-get update && apt-get install -y chromium chromium-driver; fi
	$(BIN)/python -m pytest -q -s -p no:cacheprovider tests/test_browser_editor.py tests/test_serve_mic_browser.py \
		tests/test_timing_editor_browser.py

# The Blender add-on in real headless Blender (also part of `make test` when blender is
# present). Installs Debian's blender first, only if it is missing.
test-blender: $(STAMP)
	@if ! command -v blender >/dev/null; then apt-get update && apt-get install -y blender; fi
	$(BIN)/python -m pytest -q -s -p no:cacheprovider tests/test_blender.py

fuzz: $(STAMP)
	HYPOTHESIS_PROFILE=fuzz $(BIN)/python -m pytest -q -p no:cacheprovider tests/test_fuzz.py tests/test_hostile_inputs.py tests/test_json_limits.py

# The documentation site (docs/, Sphinx + MyST + numpydoc), offline, warnings as errors:
# a broken link, reference or page fails. The CLI and API references and the benchmark page
# are generated at build time (docs/_ext/generated.py). Open docs/_build/html/index.html.
DOCS_STAMP := $(VENV)/.docs-installed
$(DOCS_STAMP): $(STAMP)
	$(BIN)/pip install -q -e '.[test,docs]'
	touch $(DOCS_STAMP)

docs: $(DOCS_STAMP)
	$(BIN)/python -m sphinx -b html -W --keep-going -n -q docs docs/_build/html
	@echo "wrote docs/_build/html/index.html"

clean:
	rm -rf $(VENV) build *.egg-info .pytest_cache demo.mp4 docs/_build docs/_generated

# The README's pictures, from the default subject.
docs-images: $(STAMP)
	$(BIN)/lipsync morph visemes/toon X D --frames 5 -o docs/strip.png
	$(BIN)/lipsync preview visemes/toon -o docs/preview.png
	$(BIN)/python -m lipsync.editor.browser visemes/toon docs/editor.png
	$(BIN)/python -m lipsync.timing_editor.browser tests/data/grid-s1-audio/bram2n.flac tests/data/grid-s1-audio/bram2n.align docs/timing-editor.png
	$(BIN)/python tools/face_overlay.py docs/face-lines.jpg
	$(BIN)/python tools/atlas_picture.py docs/atlas.jpg
	$(BIN)/python tools/real_strip.py docs/strip-real.png
	$(BIN)/python tools/dub_strip.py docs/strip-dub.png
	$(BIN)/python tools/samples_strip.py docs/strip-samples.png docs/mouth-samples.png
