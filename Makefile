# demcli: `make run` and `make test` set up everything on a fresh machine (Python 3.11 + pip).
PYTHON ?= python3
VENV   ?= .venv
BIN    := $(VENV)/bin
STAMP  := $(VENV)/.installed
TEST_JOBS ?= 2

.PHONY: run test test-nojit stress bench smoke validate hashes guard clean-jit clean

$(STAMP): pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip
	$(BIN)/python -m pip install --quiet -e '.[dev]'
	touch $(STAMP)

## run: set up, then run the quickstart case end to end
run: $(STAMP)
	$(BIN)/demcli run cases/quickstart.yaml

## test: set up, then run the test suite
test: $(STAMP)
	$(BIN)/python -m pytest -q -n auto --maxprocesses=$(TEST_JOBS) --dist loadfile

## stress: the long stability variants
stress: $(STAMP)
	DEMCLI_STRESS=1 $(BIN)/python -m pytest -q tests/stability

## bench: throughput against the peer codes (see bench/README.md)
bench: $(STAMP)
	$(BIN)/python bench/run_bench.py

## smoke: every case file for a few steps
smoke: $(STAMP)
	$(BIN)/python -m pytest -q tests/test_cases.py

## validate: the Chung & Ooi benchmarks and the analytic checks against their references -> docs/validation.md (~2 min)
validate: $(STAMP)
	$(BIN)/python -m demcli validate

## hashes: record the smoke cases' state hashes (before a change that must keep results)
hashes: $(STAMP)
	$(BIN)/python tests/guards/smoke_hashes.py record

## guard: compare the smoke cases' states with the recorded hashes (after such a change)
guard: $(STAMP)
	$(BIN)/python tests/guards/smoke_hashes.py compare

## clean-jit: drop numba's compiled-kernel caches (each set of kernel sources has its own folder)
clean-jit:
	find . -name '__pycache__' -type d -path '*demcli*' -exec sh -c 'rm -f "$$1"/*.nbi "$$1"/*.nbc' _ {} \;
	rm -rf .numba_cache "$${XDG_CACHE_HOME:-$$HOME/.cache}/demcli/numba"

clean: clean-jit
	rm -rf runs $(VENV)
