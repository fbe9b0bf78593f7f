# scratch-bake: `make demo` bakes the bundled sample, `make test` runs the whole suite.
# Both create .venv and install the package from this repo (pinned by constraints.txt).
PYTHON ?= python3
VENV ?= .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed

.PHONY: demo test bench doc-tables fuzz clean

$(STAMP): pyproject.toml constraints.txt
	test -x $(BIN)/python || $(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install -q --upgrade pip
	$(BIN)/python -m pip install -q -c constraints.txt -e '.[dev]'
	touch $(STAMP)

# The real Scratch VM for the tests (scratch-vm + scratch-parser, pinned by vm/package-lock.json).
# Without npm the VM tests skip and say why.
vm/node_modules: vm/package.json vm/package-lock.json
	@if command -v npm >/dev/null 2>&1; then npm ci --prefix vm --no-audit --no-fund && touch vm/node_modules; \
	else echo "npm not found: the Scratch VM tests will be skipped"; fi

demo: $(STAMP)
	$(BIN)/bake demo --out bake-demo

test: $(STAMP) vm/node_modules
	$(BIN)/python -m pytest -q -ra

bench: $(STAMP) vm/node_modules
	$(BIN)/python -m pip install -q -c constraints.txt -e '.[dev,bench]'
	mkdir -p benchmarks/results
	set -e; for b in benchmarks/bench_*.py; do echo "== $$b"; $(BIN)/python $$b; done
	$(BIN)/python tools/doc_tables.py

# Re-render the docs' tables from benchmarks/results/*.json (what `make bench` wrote).
doc-tables: $(STAMP)
	$(BIN)/python tools/doc_tables.py

# Fuzz the OBJ/MTL, glTF and .sb3 readers with atheris (not part of `test`); FUZZ_SECONDS per reader.
fuzz: $(STAMP)
	$(BIN)/python -m pip install -q -c constraints.txt -e '.[dev,fuzz]'
	$(BIN)/python fuzz/run.py --seconds $${FUZZ_SECONDS:-120}

clean:
	rm -rf bake-demo bake-out .pytest_cache
