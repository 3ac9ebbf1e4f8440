# Every target sets itself up: a fresh machine needs only python3.
PY      ?= python3
VENV    := .venv
BIN     := $(VENV)/bin
STAMP   := $(VENV)/.installed

.PHONY: test test-browser demo bench fuzz docs-images clean install

# The compiled frame kernel is built by the editable install: a changed source rebuilds it.
# compileall: an editable install leaves no bytecode, and where PYTHONDONTWRITEBYTECODE is
# set every run would compile the package again (~0.1 s of each lipsync start-up).
$(STAMP): pyproject.toml setup.py lipsync/_flowkernel.c
	$(PY) -m venv $(VENV)
	$(BIN)/pip install -q --upgrade pip
	$(BIN)/pip install -q -e '.[test]'
	$(BIN)/python -m compileall -q lipsync
	touch $(STAMP)

install: $(STAMP)

test: $(STAMP)
	$(BIN)/python -m pytest -q -p no:cacheprovider

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
	$(BIN)/python -m pytest -q -s -p no:cacheprovider tests/test_browser_editor.py

fuzz: $(STAMP)
	HYPOTHESIS_PROFILE=fuzz $(BIN)/python -m pytest -q -p no:cacheprovider tests/test_fuzz.py tests/test_hostile_inputs.py tests/test_json_limits.py

clean:
	rm -rf $(VENV) build *.egg-info .pytest_cache demo.mp4

# The README's pictures, from the default subject.
docs-images: $(STAMP)
	$(BIN)/lipsync morph visemes/toon X D --frames 5 -o docs/strip.png
	$(BIN)/lipsync preview visemes/toon -o docs/preview.png
	$(BIN)/python -m lipsync.editor.browser visemes/toon docs/editor.png
	$(BIN)/python tools/face_overlay.py docs/face-lines.jpg
	$(BIN)/python tools/atlas_picture.py docs/atlas.jpg
	$(BIN)/python tools/real_strip.py docs/strip-real.png
