# Set-up and the project's two everyday commands. Everything installs into ./.venv.
PYTHON ?= python3
VENV := .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed

.PHONY: demo test test-quick hil multihost lint bench clean

demo: $(STAMP)  ## The paper's scenario, 4 robot processes over Zenoh in real time: table, JSON, plots.
	$(BIN)/heft demo --out out/paper-results.json --plot out/plots

test: $(STAMP) lint  ## Lint, then the whole test suite (hardware-in-the-loop on vcan, then multi-host).
	$(BIN)/python -m pytest -q -m "not hil and not multihost"
	$(MAKE) --no-print-directory hil
	$(MAKE) --no-print-directory multihost

hil: $(STAMP)  ## The hardware-in-the-loop tests, on real vcan (in User-Mode Linux if this kernel has none).
	@if $(BIN)/heft vcan --check; then \
	  $(BIN)/heft vcan --timeout 1200 -- $(BIN)/python -m pytest -q -m hil -p no:cacheprovider; \
	else \
	  $(BIN)/python -m pytest -q -m hil -rs; \
	fi

multihost: $(STAMP)  ## The team across network namespaces as hosts, over mutual TLS (needs root).
	$(BIN)/python -m pytest -q -s -m multihost -p no:cacheprovider

test-quick: $(STAMP) lint  ## Lint, then the tests not marked slow (no Zenoh, no processes).
	$(BIN)/python -m pytest -q -m "not slow and not hil and not multihost"

lint: $(STAMP)
	$(BIN)/ruff check .
	$(BIN)/ruff format --check .

bench: $(STAMP)  ## Accuracy, step durations and speed: in one process, then over Zenoh.
	$(BIN)/heft bench
	$(BIN)/heft bench --transport zenoh

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
