# make run   set up and serve the appliance on http://127.0.0.1:8000 (embedded mode)
# make test  install what the tests need and run them all
# make run BIND=HOST:PORT  serve elsewhere (a port already in use is said as such)
PYTHON ?= python3
VENV := .venv
BIN := $(VENV)/bin
# The suite runs in two test processes (pytest-xdist): about 16 min on two cores. `make test PYTEST_PARALLEL=` runs it in one process.
PYTEST_PARALLEL ?= -n 2

.PHONY: run test lint bench bench-deps fleet fleet-secrets clean

# Quiet pip: what it does is said in one line before; its warnings and errors still show.
# --no-compile: Python compiles a module when first imported; compiling every file of every
# wheel at install time (pymavlink's dialects alone are 90 MB) doubled the install's time.
PIP := $(BIN)/pip install --quiet --disable-pip-version-check --progress-bar off --no-compile
# What is installed, stamped apart: `make run` installs the appliance alone (runtime), `make test`
# adds the test tools once (and again only when pyproject.toml changes); run after test
# installs nothing.
RUN_DEPS := $(VENV)/.run-deps
TEST_DEPS := $(VENV)/.test-deps

$(RUN_DEPS): pyproject.toml
	@./scripts/install-run-deps.sh $(PYTHON) --quiet
	@[ -x $(BIN)/python ] || { echo "robotide: creating the virtualenv in $(VENV)" && \
		$(PYTHON) -m venv $(VENV); }
	@echo "robotide: installing robotide into $(VENV) (runtime only, no test tools;" \
		"a few minutes the first time)..."
	@$(PIP) -e .
	@touch $@

$(TEST_DEPS): $(RUN_DEPS)
	@echo "robotide: installing the test tools into $(VENV)..."
	@$(PIP) -e '.[test]'
	@touch $@

run: $(RUN_DEPS)
	@./scripts/install-run-deps.sh $(PYTHON)
	@$(BIN)/robotide up $(if $(BIND),--bind $(BIND))

test: $(TEST_DEPS)
	./scripts/install-test-deps.sh
	./scripts/install-build-deps.sh
	$(PIP) -e '.[ldap]'
	$(BIN)/ruff check .
	$(BIN)/pytest $(PYTEST_PARALLEL)

lint: $(TEST_DEPS)
	$(BIN)/ruff check .
	$(BIN)/ruff format --check .

bench: $(TEST_DEPS)
	$(BIN)/python -m benchmarks

# The compose file's services as processes on this machine, on a PostgreSQL and a Redis of
# their own with passwords (in var/fleet: FLEET_DATA), not the machine's servers.
fleet: $(TEST_DEPS)
	./scripts/install-test-deps.sh --packages-only
	$(BIN)/python -m robotide.fleet

# The passwords of docker compose's postgres and redis, generated once into .env (mode 0600);
# kept if it is there. Needs python3 only, not the venv.
fleet-secrets:
	$(PYTHON) -m robotide.fleet secrets

# What benchmarks/gateway.py compares the router with: socat (the raw byte forwarder) and
# MAVProxy (a reference, in the venv only: not a test dependency).
bench-deps: $(TEST_DEPS)
	command -v socat >/dev/null || { apt-get update && apt-get install -y socat; }
	$(BIN)/pip install --quiet MAVProxy

clean:
	rm -rf $(VENV) var
