# Fresh clone: `make demo` or `make test` creates .venv, installs the project, then runs.
PYTHON ?= python3
VENV := .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed
OUT ?= out/demo

.PHONY: demo test test-all lint format bench clean

$(STAMP): pyproject.toml constraints.txt
	test -x $(BIN)/python || $(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --upgrade pip
	$(BIN)/python -m pip install -c constraints.txt -e ".[dev]"
	touch $(STAMP)

demo: $(STAMP)
	$(BIN)/quad-sindy demo --out $(OUT)

lint: $(STAMP)
	$(BIN)/ruff check .
	$(BIN)/ruff format --check .

format: $(STAMP)
	$(BIN)/ruff format .
	$(BIN)/ruff check --fix .

test: lint
	MPLBACKEND=Agg $(BIN)/python -m pytest -q

test-all: lint
	MPLBACKEND=Agg $(BIN)/python -m pytest -q -m ""

bench: $(STAMP)
	$(BIN)/quad-sindy bench envs
	$(BIN)/quad-sindy bench surrogate

clean:
	rm -rf $(VENV) out .pytest_cache .ruff_cache
