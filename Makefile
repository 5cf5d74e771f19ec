# The two set-up commands (see README): make demo, make test.
PYTHON ?= $(shell command -v python3.11 || command -v python3)
VENV := .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed
DEV_STAMP := $(VENV)/.installed-dev

.PHONY: demo test bench bench-quick lint clean

$(BIN)/python:
	$(PYTHON) -m venv $(VENV)

# the demo needs amrvio alone; lint and test add the dev tools and the cluster extra (Ray)
$(STAMP): $(BIN)/python pyproject.toml constraints.txt
	$(BIN)/python -m pip install --quiet --upgrade pip
	$(BIN)/python -m pip install --quiet -c constraints.txt -e .
	touch $(STAMP)

$(DEV_STAMP): $(STAMP)
	$(BIN)/python -m pip install --quiet -c constraints.txt -e '.[dev]'
	touch $(DEV_STAMP)

demo: $(STAMP)
	$(BIN)/python -m amrvio.demo --out demo_out

lint: $(DEV_STAMP)
	$(BIN)/ruff check amrvio tests bench examples
	$(BIN)/mypy

# -rfEs lists failures, errors and every skip with its reason; tests/skip_policy.py fails the run on a skip it does not allow.
# Any non-zero pytest status fails make, including 5 (no test collected).
test: lint
	$(BIN)/python -m pytest -n 2 -rfEs tests

bench: $(DEV_STAMP)
	$(BIN)/python -m bench.run --out bench/results

# The headline figures (diagnostics throughput and truth) in under 5 minutes; the other sections
# of bench/results keep their last full run.
bench-quick: $(STAMP)
	$(BIN)/python -m bench.run --out bench/results --quick --headline

clean:
	rm -rf $(VENV) demo_out .mypy_cache .pytest_cache .ruff_cache
