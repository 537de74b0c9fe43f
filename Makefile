# Two commands do all the set-up on a fresh machine: `make demo` and `make test`.
PYTHON ?= python3
VENV   := .venv
PY     := $(VENV)/bin/python
STAMP  := $(VENV)/.installed

.PHONY: demo test test-cuda test-slow bench notebooks clean

$(STAMP): pyproject.toml setup.py
	test -x $(PY) || $(PYTHON) -m venv $(VENV)
	$(PY) -m pip install -q --upgrade pip 'setuptools>=77'
	$(PY) -m pip install -q -e '.[test]'
	touch $(STAMP)

demo: $(STAMP)
	$(VENV)/bin/pbr render -o out/cornell.exr --png out/cornell.png

test: $(STAMP)
	$(PY) -m pytest -q $(PYTEST_ARGS)

# The quick suite on the GPU (CUDA/OptiX); stops at once if CUDA is unusable.
test-cuda: $(STAMP)
	PBR_TEST_BACKEND=cuda $(PY) -m pytest -q $(PYTEST_ARGS)

test-slow: $(STAMP)
	$(PY) -m pytest -q --runslow $(PYTEST_ARGS)

bench: $(STAMP)
	$(PY) -m pip install -q -e '.[test,bench]'
	$(PY) benchmarks/bench_cornell.py

# Jupyter Lab on notebooks/ (installs the 'notebooks' extra first).
notebooks: $(STAMP)
	$(PY) -m pip install -q -e '.[test,notebooks]'
	$(VENV)/bin/jupyter lab notebooks

clean:
	rm -rf out .pytest_cache
