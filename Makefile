# The whole set-up on a fresh machine: `make run` or `make test`.
PYTHON ?= python3
VENV   ?= .venv
BIN    := $(VENV)/bin

.PHONY: run test sweeps lint bench clean

$(BIN)/odocan: pyproject.toml
	test -x $(BIN)/python || $(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip
	$(BIN)/python -m pip install --quiet -e '.[test]'
	touch $@

run: $(BIN)/odocan
	$(BIN)/odocan run

# ruff over the whole tree; mypy over the files pyproject names (odocan, tests, examples).
lint: $(BIN)/odocan
	$(BIN)/ruff check .
	$(BIN)/mypy

# One pytest worker per core (pytest-xdist), a whole test file on one worker: the files keep their
# module fixtures, and every socket test already takes a fresh group and port (tests/udp_pair.py).
test: lint
	$(BIN)/python -m pytest -n auto --dist loadfile

# The tests with every case of every sweep (tests/sweeps.py), the grids `make test` samples.
sweeps: lint
	ODOCAN_SWEEPS=full $(BIN)/python -m pytest -n auto --dist loadfile

bench: $(BIN)/odocan
	for b in bench/*.py; do $(BIN)/python $$b || exit 1; done

clean:
	rm -rf $(VENV) .pytest_cache .mypy_cache .ruff_cache
