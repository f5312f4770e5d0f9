# make run   set up and serve the appliance on http://127.0.0.1:8000 (embedded mode)
# make test  install what the tests need and run them all
PYTHON ?= python3
VENV := .venv
BIN := $(VENV)/bin
# The suite runs in two test processes (pytest-xdist): about 16 min on two cores. `make test PYTEST_PARALLEL=` runs it in one process.
PYTEST_PARALLEL ?= -n 2

.PHONY: run test lint bench bench-deps fleet fleet-secrets clean

$(BIN)/robotide: pyproject.toml
	./scripts/install-run-deps.sh $(PYTHON) --quiet
	$(PYTHON) -m venv $(VENV)
	$(BIN)/pip install --quiet --upgrade pip
	$(BIN)/pip install --quiet -e '.[test]'
	touch $@

run: $(BIN)/robotide
	./scripts/install-run-deps.sh $(PYTHON)
	$(BIN)/robotide up $(if $(BIND),--bind $(BIND))

test: $(BIN)/robotide
	./scripts/install-test-deps.sh
	./scripts/install-build-deps.sh
	$(BIN)/pip install --quiet -e '.[ldap]'
	$(BIN)/ruff check .
	$(BIN)/pytest $(PYTEST_PARALLEL)

lint: $(BIN)/robotide
	$(BIN)/ruff check .
	$(BIN)/ruff format --check .

bench: $(BIN)/robotide
	$(BIN)/python -m benchmarks

# The compose file's services as processes on this machine, on a PostgreSQL and a Redis of
# their own with passwords (in var/fleet: FLEET_DATA), not the machine's servers.
fleet: $(BIN)/robotide
	./scripts/install-test-deps.sh --packages-only
	$(BIN)/python -m robotide.fleet

# The passwords of docker compose's postgres and redis, generated once into .env (mode 0600);
# kept if it is there. Needs python3 only, not the venv.
fleet-secrets:
	$(PYTHON) -m robotide.fleet secrets

# What benchmarks/gateway.py compares the router with: socat (the raw byte forwarder) and
# MAVProxy (a reference, in the venv only: not a test dependency).
bench-deps: $(BIN)/robotide
	command -v socat >/dev/null || { apt-get update && apt-get install -y socat; }
	$(BIN)/pip install --quiet MAVProxy

clean:
	rm -rf $(VENV) var
