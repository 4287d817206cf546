# Set-up and the project's two everyday commands. Everything installs into ./.venv.
PYTHON ?= python3
VENV := .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed

.PHONY: demo test lint bench clean

demo: $(STAMP)  ## Run the paper's scenario: table of estimates vs truth, results JSON, plots.
	$(BIN)/heft run simulator/scenarios/paper.toml --out out/paper-results.json --plot out/plots

test: $(STAMP) lint  ## Lint, then run the whole test suite.
	$(BIN)/python -m pytest -q

lint: $(STAMP)
	$(BIN)/ruff check .
	$(BIN)/ruff format --check .

bench: $(STAMP)  ## Print accuracy, step durations and speed on the paper's scenario.
	$(BIN)/heft bench

$(STAMP): pyproject.toml
	@$(PYTHON) -c 'import sys; assert sys.version_info >= (3, 11), "Python >= 3.11 is needed"'
	$(PYTHON) -m venv $(VENV)
	$(BIN)/pip install --quiet --upgrade pip
	$(BIN)/pip install --quiet -e '.[test]'
	touch $(STAMP)

clean:
	rm -rf $(VENV) out .pytest_cache .ruff_cache *.egg-info
