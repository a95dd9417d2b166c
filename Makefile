# rafostrack: `make demo` sets up and tracks the sample float; `make test` sets up and tests.
PYTHON ?= python3
VENV ?= .venv
BIN := $(VENV)/bin
# Two install stamps: $(RUNTIME) installs the package alone (all `make demo` needs);
# $(STAMP) adds the test and Dask extras (tests, lint, benchmarks, figures).
STAMP := $(VENV)/.installed
RUNTIME := $(VENV)/.installed-runtime
# The editable install puts the repository on sys.path with a .pth file, without a warning
# (pyproject.toml's `package-dir` says why).

.PHONY: demo test test-fast lint format bench sample clean

$(RUNTIME): pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip
	$(BIN)/python -m pip install --quiet -e .
	touch $(RUNTIME)

$(STAMP): $(RUNTIME)
	$(BIN)/python -m pip install --quiet -e '.[test,dask]'
	touch $(STAMP)

demo: $(RUNTIME)
	$(BIN)/rafostrack track data/samples/float767.csv --out out

# On every core, a test file's tests together in one worker (a file's fixtures are built once).
test: $(STAMP)
	$(BIN)/python -m pytest -n auto --dist loadfile

# The suite without the tests marked slow (each over ~5 s): a quick check while editing.
test-fast: $(STAMP)
	$(BIN)/python -m pytest -n auto --dist loadfile -m "not slow"

lint: $(STAMP)
	$(BIN)/ruff check rafostrack papers tests benchmarks scripts
	$(BIN)/ruff format --check rafostrack papers tests benchmarks scripts
	$(BIN)/mypy
	$(BIN)/lint-imports

format: $(STAMP)
	$(BIN)/ruff format rafostrack papers tests benchmarks scripts
	$(BIN)/ruff check --fix rafostrack papers tests benchmarks scripts

bench: $(STAMP)
	$(BIN)/python benchmarks/accuracy.py
	$(BIN)/python benchmarks/engines.py
	$(BIN)/python benchmarks/speed.py
	$(BIN)/python benchmarks/batch.py

sample: $(STAMP)
	$(BIN)/python scripts/make_sample.py data/samples

# The paper's figures redone (figures/REPORT.md): under 15 min on 2 cores; -quick under 3 min.
.PHONY: figures figures-quick
figures: $(STAMP)
	$(BIN)/python -m papers --out figures

figures-quick: $(STAMP)
	$(BIN)/python -m papers --quick --out figures

clean:
	rm -rf out $(VENV) build *.egg-info .pytest_cache .ruff_cache
