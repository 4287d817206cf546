# Set-up and the project's two everyday commands. Everything installs into ./.venv.
PYTHON ?= python3
VENV := .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed

.PHONY: demo test test-quick lint bench clean

demo: $(STAMP)  ## The paper's scenario, 4 robot processes over Zenoh in real time: table, JSON, plots.
	$(BIN)/heft demo --out out/paper-results.json --plot out/plots

test: $(STAMP) lint  ## Lint, then run the whole test suite.
	$(BIN)/python -m pytest -q

test-quick: $(STAMP) lint  ## Lint, then the tests not marked slow (no Zenoh, no processes).
	$(BIN)/python -m pytest -q -m "not slow"

lint: $(STAMP)
	$(BIN)/ruff check .
	$(BIN)/ruff format --check .

bench: $(STAMP)  ## Accuracy, step durations and speed: in one process, then over Zenoh.
	$(BIN)/heft bench
	$(BIN)/heft bench --transport zenoh

$(STAMP): pyproject.toml
	@$(PYTHON) -c 'import sys; assert sys.version_info >= (3, 11), "Python >= 3.11 is needed"'
	$(PYTHON) -m venv $(VENV)
	$(BIN)/pip install --quiet --upgrade pip
	$(BIN)/pip install --quiet -e '.[test]'
	touch $(STAMP)

clean:
	rm -rf $(VENV) out .pytest_cache .ruff_cache *.egg-info
