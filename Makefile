# make run   set up and serve the appliance on http://127.0.0.1:8000 (embedded mode)
# make test  install what the tests need and run them all
PYTHON ?= python3
VENV := .venv
BIN := $(VENV)/bin

.PHONY: run test lint bench fleet clean

$(BIN)/robotide: pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(BIN)/pip install --quiet --upgrade pip
	$(BIN)/pip install --quiet -e '.[test]'
	touch $@

run: $(BIN)/robotide
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

clean:
	rm -rf $(VENV) var
