# Every target sets itself up: a fresh machine needs only python3.
PY      ?= python3
VENV    := .venv
BIN     := $(VENV)/bin
STAMP   := $(VENV)/.installed

.PHONY: test demo bench fuzz docs-images clean install

$(STAMP): pyproject.toml setup.py
	$(PY) -m venv $(VENV)
	$(BIN)/pip install -q --upgrade pip
	$(BIN)/pip install -q -e '.[test]'
	touch $(STAMP)

install: $(STAMP)

test: $(STAMP)
	$(BIN)/python -m pytest -q -p no:cacheprovider

demo: $(STAMP)
	$(BIN)/lipsync render samples/hello.phn --audio samples/hello.wav -o demo.mp4
	@echo "wrote demo.mp4"

bench: $(STAMP)
	$(BIN)/python -m lipsync.bench

fuzz: $(STAMP)
	HYPOTHESIS_PROFILE=fuzz $(BIN)/python -m pytest -q -p no:cacheprovider tests/test_fuzz.py

clean:
	rm -rf $(VENV) build *.egg-info .pytest_cache demo.mp4

# The README's pictures, from the default subject.
docs-images: $(STAMP)
	$(BIN)/lipsync morph visemes/toon X D --frames 5 -o docs/strip.png
	$(BIN)/lipsync preview visemes/toon -o docs/preview.png
