# Set-up is two commands: `make demo` and `make test`. Both create .venv when missing.
PYTHON ?= python3
VENV   := .venv
BIN    := $(VENV)/bin
STAMP  := $(VENV)/.installed
DEVSTAMP := $(VENV)/.installed-dev

.PHONY: demo test lint typecheck pytest browser clean

$(BIN)/python:
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip

$(STAMP): pyproject.toml | $(BIN)/python
	$(BIN)/python -m pip install --quiet -e .
	touch $@

$(DEVSTAMP): pyproject.toml | $(BIN)/python
	$(BIN)/python -m pip install --quiet -e '.[dev]'
	touch $@ $(STAMP)

demo: $(STAMP)
	$(BIN)/mast demo

lint: $(DEVSTAMP)
	$(BIN)/ruff check src tests benchmarks
	$(BIN)/ruff format --check src tests benchmarks

typecheck: $(DEVSTAMP)
	$(BIN)/mypy --strict src/mast

# The run report's render test opens report.html in headless Chromium: installed here
# (Debian's chromium) when missing and we are root; otherwise a note, and that test skips.
browser:
	@command -v chromium >/dev/null 2>&1 || command -v chromium-browser >/dev/null 2>&1 || \
	if [ "$$(id -u)" = 0 ] && command -v apt-get >/dev/null 2>&1; then \
		echo "installing chromium (apt-get) for the HTML report render test"; \
		{ apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq chromium >/dev/null; } || \
		echo "note: chromium could not be installed; the HTML report render test will skip"; \
	else \
		echo "note: no chromium and not root (or no apt-get): install chromium to run the HTML report render test"; \
	fi

# Two to four processes, a test file to each (its module fixtures built once), but the
# heaviest tests spread and sent first (tests/conftest.py: SPREAD).
pytest: $(DEVSTAMP) browser
	$(BIN)/python -m pytest -n auto --maxprocesses 4 --dist loadscope

test: lint typecheck pytest

clean:
	rm -rf $(VENV) build .mypy_cache .pytest_cache .ruff_cache
