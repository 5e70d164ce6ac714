# robocal — every target creates the virtual environment it needs.
PYTHON ?= python3
VENV   := .venv
BIN    := $(VENV)/bin
STAMP  := $(VENV)/.installed

.PHONY: venv demo test lint bench reprocess clean chromium bytecode

$(STAMP): pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(BIN)/pip install --quiet --upgrade pip
	$(BIN)/pip install --quiet -e '.[test]'
	touch $(STAMP)

venv: $(STAMP)

# robocal's own modules byte-compiled, as a (non-editable) pip install does: this checkout is installed
# editable, and where PYTHONDONTWRITEBYTECODE is set every process would compile them again (≈ 0.15 s
# of each command's and each worker's start).  Only stale files are recompiled.
bytecode: $(STAMP)
	@$(BIN)/python -m compileall -q pipeline >/dev/null

demo: $(STAMP) bytecode
	$(BIN)/robocal run recordings/arc-welder-touch.mcap --out runs/demo

# the suite on TEST_WORKERS processes (pytest-xdist), one test file per unit of work, the heaviest
# first (tests/ci_time.py); TEST_WORKERS=0 runs it in this process alone
TEST_WORKERS ?= 2
test: $(STAMP) bytecode chromium lint
	$(BIN)/python -m pytest -q -n $(TEST_WORKERS) --dist loadfile --no-loadscope-reorder

# pyflakes rules only: undefined names, unused imports/variables, syntax errors
lint: $(STAMP)
	$(BIN)/ruff check --select F,E9 pipeline tests benchmarks

reprocess: $(STAMP) bytecode
	$(BIN)/robocal reprocess recordings/ --out runs/reprocess

bench: $(STAMP) bytecode
	for f in benchmarks/bench_*.py; do $(BIN)/python $$f || exit 1; done

# headless Chromium for the report test (Debian package), installed where it is missing
# (non-fatal: without it the report test skips, saying why)
chromium:
	@command -v chromium >/dev/null 2>&1 || (export DEBIAN_FRONTEND=noninteractive; \
	  apt-get update -qq && apt-get install -y -qq chromium >/dev/null) || \
	  echo "warning: could not install Debian chromium; the report's browser test will be skipped"
	@command -v xvfb-run >/dev/null 2>&1 && ls /usr/share/vulkan/icd.d/lvp_icd.* >/dev/null 2>&1 || \
	  (export DEBIAN_FRONTEND=noninteractive; apt-get install -y -qq xvfb xauth mesa-vulkan-drivers >/dev/null) || \
	  echo "warning: could not install xvfb and mesa-vulkan-drivers; the rerun viewer screenshot test will be skipped"

clean:
	rm -rf $(VENV) runs .pytest_cache
