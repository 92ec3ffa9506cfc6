# Everything a fresh machine needs: `make demo` runs the main job, `make test` the tests.
VENV   ?= .venv
PY     := $(VENV)/bin/python
PIP    := $(VENV)/bin/pip
STAMP  := $(VENV)/.installed

.PHONY: demo test lint bench clean install

# pip's own lines (Collecting, Installing, Successfully installed) are the progress: the
# first run installs for a minute or two, and a silent one looks hung.
$(STAMP): pyproject.toml
	@echo "scanplan: setting up $(VENV) (first run only, 1-2 minutes)"
	python3 -m venv $(VENV)
	@echo "scanplan: [1/3] pip"
	$(PIP) install -q --upgrade pip
	@echo "scanplan: [2/3] torch 2.13.0, CPU build"
	# The CPU build of torch lies on disk here; install it first or pip fetches a CUDA build.
	$(PIP) install --progress-bar on torch==2.13.0
	@echo "scanplan: [3/3] scanplan and its dependencies"
	$(PIP) install --progress-bar on -e '.[dev]'
	@echo "scanplan: $(VENV) ready"
	touch $(STAMP)

install: $(STAMP)

demo: $(STAMP)
	$(VENV)/bin/scanplan demo -o out/demo

# One worker per core, each test file on one worker (its module fixtures built once).
test: $(STAMP)
	$(PY) -m pytest -q -n auto --dist loadfile

lint: $(STAMP)
	$(VENV)/bin/ruff check src tests benchmarks
	$(VENV)/bin/ruff format --check src tests benchmarks
	$(VENV)/bin/mypy
	$(VENV)/bin/lint-imports --no-cache

bench: $(STAMP)
	for f in benchmarks/*.py; do $(PY) $$f || exit 1; done

clean:
	rm -rf $(VENV) out .pytest_cache
