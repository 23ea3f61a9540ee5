# Two entry points for a fresh machine (see README.md). Both set the kit up first.
VENV ?= .venv
PROFILE ?= smoke

.PHONY: setup smoke reproduce test test-all bench

setup:
	bash scripts/setup.sh

# main job: every notebook of the profile, figures into figures/
smoke: setup
	$(VENV)/bin/airpose reproduce --profile $(PROFILE)

reproduce: smoke

# the test suite without the slow end-to-end runs (CI's smoke reproduction runs those)
test: setup
	$(VENV)/bin/python -m pytest -q -m "not slow"

test-all: setup
	$(VENV)/bin/python -m pytest -q

bench: setup
	$(VENV)/bin/python benchmarks/body_model.py
