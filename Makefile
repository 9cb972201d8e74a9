# Quick start: `make demo` runs the main job, `make test` runs the tests.
# Both create .venv on first use (Python 3.11, pip; torch pinned by constraints.txt).
PYTHON ?= $(shell command -v python3.11 || command -v python3)
VENV   ?= .venv
BIN     = $(VENV)/bin
STAMP   = $(VENV)/.installed

.PHONY: demo test lint conform conform-baseline bench install clean

install: $(STAMP)

# constraints.txt's pins (torch 2.13.0 CPU among them) are wheels for Python 3.11: another
# Python would resolve other packages (CUDA torch on 3.12), so it is refused here.
$(STAMP): pyproject.toml constraints.txt
	@$(PYTHON) -c 'import sys; sys.exit(sys.version_info[:2] != (3, 11))' || { \
		echo "make: $(PYTHON) is not Python 3.11, which constraints.txt's pins are for;" \
		"install python3.11 or run make PYTHON=/path/to/python3.11" >&2; exit 1; }
	$(PYTHON) -m venv $(VENV)
	$(BIN)/pip install --quiet --upgrade pip
	$(BIN)/pip install --quiet -c constraints.txt -e '.[test,fast,lint]'
	touch $(STAMP)

demo: $(STAMP)
	$(BIN)/exohil demo

# The test files run in parallel, one process per core (at most four); a file's tests stay
# together, so its module fixtures are built once.
test: $(STAMP)
	$(BIN)/python -m pytest -n auto --maxprocesses 4 --dist loadfile -rs

lint: $(STAMP)
	$(BIN)/ruff check .
	$(BIN)/mypy

# The conformance gate CI runs: reference ENNet, held-out fixture on the emulator, ci profile;
# its accuracy must not regress from the figures stored in conformance/baselines/ci.json.
GATE = --target emulator:fixtures/paper_protocol_heldout.mcap \
	--model fixtures/models/ennet.npz --profile ci
conform: $(STAMP)
	$(BIN)/exohil conform $(GATE) --baseline conformance/baselines/ci.json \
		--out conformance-report

# Store the gate's figures as the new baseline (only after a change meant to move them;
# conformance/baselines/README.md). A failing gate stores nothing.
conform-baseline: $(STAMP)
	$(BIN)/exohil conform $(GATE) --out conformance-baseline
	cp conformance-baseline/conformance.json conformance/baselines/ci.json.partial
	mv conformance/baselines/ci.json.partial conformance/baselines/ci.json

bench: $(STAMP)
	$(BIN)/python -m benchmarks

clean:
	rm -rf $(VENV) build *.egg-info conformance-report conformance-baseline demo-report .tox .hypothesis \
		.mypy_cache .ruff_cache .pytest_cache
