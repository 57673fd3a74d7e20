PY ?= python3.11
VENV := .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed

.PHONY: run test test-all lint bench robustness clean indirect-variants

VARIANTS := $(sort $(wildcard configs/indirect_variants/*.yaml))

$(STAMP): pyproject.toml
	test -x $(BIN)/python || $(PY) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip
	$(BIN)/python -m pip install --quiet -e '.[dev,dask]'
	touch $(STAMP)

run: $(STAMP)
	$(BIN)/hcid run configs/paper.yaml
	$(BIN)/hcid report runs/paper

# The indirect method's stage-1 variants (README "The indirect method's W_FP"): FB only, indirect
# only, 50 realizations each (about 6 minutes on 2 idle cores), then their comparison report.
indirect-variants: $(STAMP)
	for c in $(VARIANTS); do \
		$(BIN)/hcid identify $$c --method indirect --jobs 2 --quiet && $(BIN)/hcid sweep-w $$c || exit 1; \
	done
	$(BIN)/python -m hcid.report.variants runs/indirect_variants $(VARIANTS)

test: $(STAMP)
	OPENBLAS_NUM_THREADS=1 OMP_NUM_THREADS=1 $(BIN)/python -m pytest -q -m "not slow" tests
	OPENBLAS_NUM_THREADS=1 $(BIN)/python -m pytest -q -p no:cacheprovider --doctest-modules hcid
	NUMBA_DISABLE_JIT=1 OPENBLAS_NUM_THREADS=1 $(BIN)/python -m pytest -q -p no:cacheprovider \
		tests/test_arx_engine.py tests/test_arx_grid.py

test-all: $(STAMP)
	OPENBLAS_NUM_THREADS=1 OMP_NUM_THREADS=1 $(BIN)/python -m pytest -q tests

lint: $(STAMP)
	$(BIN)/ruff check hcid tests benchmarks configs
	$(BIN)/ruff format --check hcid tests benchmarks configs

bench: $(STAMP)
	$(BIN)/python benchmarks/arx_engine.py
	$(BIN)/python benchmarks/fit_hc.py

robustness: $(STAMP)
	$(BIN)/python tests/robustness/battery.py
	$(BIN)/python tests/robustness/concurrency.py

clean:
	rm -rf $(VENV) runs/*/ .pytest_cache build *.egg-info
	find . -name __pycache__ -type d -prune -exec rm -rf {} +
