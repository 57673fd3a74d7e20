PY ?= python3.11
VENV := .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed
# The exact versions, with their sha256 hashes, that the install step installs (docs/installing.md).
LOCK := requirements.lock
# `make lock`: pip-compile in a throwaway venv, the tools pinned too. By default it resolves the
# newest versions pyproject.toml allows; `make lock LOCK_UPGRADE=` keeps the current pins (only what
# pyproject.toml added or dropped moves) and `make lock LOCK_UPGRADE='-P numpy'` moves one package.
LOCK_TOOLS ?= pip==26.3 pip-tools==7.6.2
LOCK_UPGRADE ?= --upgrade

.PHONY: run test test-all lint bench robustness clean indirect-variants lock docs-figures

VARIANTS := $(sort $(wildcard configs/indirect_variants/*.yaml))

# Installs exactly the lock (pip, setuptools and wheel included), then hcid itself with that
# setuptools; pip check fails if the lock misses a dependency of pyproject.toml. Then the engine's
# kernels are compiled into numba's cache, so that the first run costs what a warm one does
# (docs/benchmarks.md, "issue 47 (4)").
$(STAMP): pyproject.toml $(LOCK)
	test -x $(BIN)/python || $(PY) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --require-hashes --no-deps -r $(LOCK)
	$(BIN)/python -m pip install --quiet --no-deps --no-build-isolation -e .
	$(BIN)/python -m pip check
	OPENBLAS_NUM_THREADS=1 $(BIN)/python -c "from hcid.pipeline.parallel import compile_before_fork as c; c()"
	touch $(STAMP)

# The lock's inputs: pyproject.toml with the dev and dask extras, plus pip and the build-system
# requirements (read from pyproject.toml). Then `make test`: the golden digests and numbers.
lock:
	set -e; tmp=$$(mktemp -d); trap 'rm -rf "$$tmp"' EXIT; \
	$(PY) -m venv "$$tmp"; \
	"$$tmp/bin/python" -m pip install --quiet $(LOCK_TOOLS); \
	build=$$("$$tmp/bin/python" -c "import tomllib; \
		print(*tomllib.load(open('pyproject.toml', 'rb'))['build-system']['requires'], sep='\n')"); \
	printf 'pip\n%s\n' "$$build" | \
	CUSTOM_COMPILE_COMMAND='make lock' "$$tmp/bin/pip-compile" --quiet $(LOCK_UPGRADE) \
		--generate-hashes --allow-unsafe --extra dev --extra dask --strip-extras \
		--no-emit-index-url --no-emit-find-links --output-file $(LOCK) pyproject.toml -
	@echo "$(LOCK) written: now make test (golden digests and numbers), then commit it."

run: $(STAMP)
	$(BIN)/hcid run configs/paper.yaml
	$(BIN)/hcid report runs/paper

# The indirect method's stage-1 variants (docs/methodology.md (stage-1 variants)): FB only, indirect
# only, 50 realizations each (about 6 minutes on 2 idle cores), then their comparison report.
indirect-variants: $(STAMP)
	for c in $(VARIANTS); do \
		$(BIN)/hcid identify $$c --method indirect --jobs 2 --quiet && $(BIN)/hcid sweep-w $$c || exit 1; \
	done
	$(BIN)/python -m hcid.report.variants runs/indirect_variants $(VARIANTS)

# Two pytest workers (pytest-xdist), each test file on one of them (its module fixtures made once),
# after the engine's kernels are compiled once into numba's cache (not by both workers at once).
test: $(STAMP)
	OPENBLAS_NUM_THREADS=1 $(BIN)/python -c "from hcid.pipeline.parallel import compile_before_fork as c; c()"
	OPENBLAS_NUM_THREADS=1 OMP_NUM_THREADS=1 $(BIN)/python -m pytest -q -n 2 --dist loadfile -m "not slow" tests
	OPENBLAS_NUM_THREADS=1 $(BIN)/python -m pytest -q -p no:cacheprovider --doctest-modules hcid
	NUMBA_DISABLE_JIT=1 OPENBLAS_NUM_THREADS=1 $(BIN)/python -m pytest -q -p no:cacheprovider -n 2 \
		tests/test_arx_engine.py tests/test_arx_grid.py

# Every figure and answer line the README and docs quote, made again on this machine (named first)
# and checked against the README (benchmarks/docs_figures.py; the paper study is reused from runs/paper).
docs-figures: $(STAMP)
	OPENBLAS_NUM_THREADS=1 $(BIN)/python benchmarks/docs_figures.py

test-all: $(STAMP)
	OPENBLAS_NUM_THREADS=1 OMP_NUM_THREADS=1 $(BIN)/python -m pytest -q -n 2 --dist loadfile tests

lint: $(STAMP)
	$(BIN)/ruff check hcid tests benchmarks configs
	$(BIN)/ruff format --check hcid tests benchmarks configs

bench: $(STAMP)
	$(BIN)/python benchmarks/arx_engine.py
	$(BIN)/python benchmarks/fit_hc.py
	$(BIN)/python benchmarks/cold_start.py

robustness: $(STAMP)
	$(BIN)/python tests/robustness/battery.py
	$(BIN)/python tests/robustness/concurrency.py

clean:
	rm -rf $(VENV) runs/*/ .pytest_cache build *.egg-info
	find . -name __pycache__ -type d -prune -exec rm -rf {} +
