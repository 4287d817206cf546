# Set-up and the project's two everyday commands. Everything installs into ./.venv.
PYTHON ?= python3
VENV := .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed

.PHONY: demo test test-unit hil multihost lint bench clean

demo: $(STAMP)  ## The paper's scenario, 4 robot processes over Zenoh in real time: table, JSON, plots.
	$(BIN)/heft demo --out out/paper-results.json --plot out/plots

test: $(STAMP) lint  ## Lint, then every test: unit, integration and browser, then on vcan, then multi-host.
	$(BIN)/python -m pytest -q -n auto tests/unit
	$(BIN)/python -m pytest -q tests/integration tests/browser
	$(MAKE) --no-print-directory hil
	$(MAKE) --no-print-directory multihost

hil: $(STAMP)  ## tests/hil on real vcan (in User-Mode Linux if this kernel has none).
	@if $(BIN)/heft vcan --check; then \
	  $(BIN)/heft vcan --timeout 1200 -- $(BIN)/python -m pytest -q tests/hil -p no:cacheprovider; \
	else \
	  $(BIN)/python -m pytest -q tests/hil -rs; \
	fi

multihost: $(STAMP)  ## tests/multihost: network namespaces as hosts, mutual TLS (root).
	$(BIN)/python -m pytest -q -s tests/multihost -p no:cacheprovider

test-unit: $(STAMP)  ## The unit tests only (tests/unit: no Zenoh, no network), on every CPU.
	$(BIN)/python -m pytest -q -n auto tests/unit

lint: $(STAMP)
	$(BIN)/ruff check .
	$(BIN)/ruff format --check .

bench: $(STAMP)  ## Accuracy, step durations and speed: in one process, then over Zenoh.
	$(BIN)/heft bench accuracy; status=$$?; $(BIN)/heft bench zenoh && exit $$status

$(STAMP): pyproject.toml dashboard/package-lock.json
	@$(PYTHON) -c 'import sys; assert sys.version_info >= (3, 11), "Python >= 3.11 is needed"'
	@command -v npm >/dev/null || { echo "npm is needed (the dashboard's uPlot): apt-get install npm" >&2; exit 1; }
	$(PYTHON) -m venv $(VENV)
	$(BIN)/pip install --quiet --upgrade pip
	$(BIN)/pip install --quiet -e '.[test]'
	npm ci --prefix dashboard --no-audit --no-fund --loglevel=error
	touch $(STAMP)

clean:
	rm -rf $(VENV) out .pytest_cache .ruff_cache *.egg-info dashboard/node_modules
