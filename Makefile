# make run   set up and serve the appliance on http://127.0.0.1:8000 (embedded mode)
# make test  install what the tests need and run them all
PYTHON ?= python3
VENV := .venv
BIN := $(VENV)/bin

.PHONY: run test lint bench bench-deps fleet clean

$(BIN)/robotide: pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(BIN)/pip install --quiet --upgrade pip
	$(BIN)/pip install --quiet -e '.[test]'
	touch $@

run: $(BIN)/robotide
	./scripts/install-run-deps.sh
	$(BIN)/robotide up $(if $(BIND),--bind $(BIND))

test: $(BIN)/robotide
	./scripts/install-test-deps.sh
	$(BIN)/ruff check .
	$(BIN)/pytest

lint: $(BIN)/robotide
	$(BIN)/ruff check .
	$(BIN)/ruff format --check .

bench: $(BIN)/robotide
	$(BIN)/python -m benchmarks

# What benchmarks/gateway.py compares the router with: socat (the raw byte forwarder) and
# MAVProxy (a reference, in the venv only: not a test dependency).
# The compose file's services as processes on this machine (its PostgreSQL and Redis).
fleet: $(BIN)/robotide
	./scripts/install-test-deps.sh
	$(BIN)/python -m robotide.fleet

bench-deps: $(BIN)/robotide
	command -v socat >/dev/null || { apt-get update && apt-get install -y socat; }
	$(BIN)/pip install --quiet MAVProxy

clean:
	rm -rf $(VENV) var
