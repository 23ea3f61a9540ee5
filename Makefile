# Entry points for a fresh machine (see README.md). Each sets the kit up first.
VENV ?= .venv
PROFILE ?= smoke

.PHONY: setup demo smoke reproduce report test test-all test-browser bench lint

setup:
	bash scripts/setup.sh

# the first command: every notebook on the cpu profile's shipped networks and data rendered here,
# nothing trained; exits 1 unless the run agrees with results/cpu/ within its tolerances
demo: setup
	$(VENV)/bin/airpose reproduce --profile demo --require-agreement

# the training path at tiny sizes: every notebook of the profile, figures into figures/
smoke: setup
	$(VENV)/bin/airpose reproduce --profile $(PROFILE)

reproduce: smoke

# the last reproduction of the profile as static HTML: runs/<profile>/report/index.html
# (fails if a notebook has an error output or a catalogue figure is missing)
report: setup
	$(VENV)/bin/airpose report --profile $(PROFILE)

# the test suite without the slow end-to-end runs (CI's smoke reproduction runs those)
test: setup
	$(VENV)/bin/python -m pytest -q -m "not slow"

# JupyterLab in headless Chromium: notebook 07's 3D view (run after `make smoke`, which caches
# the estimates it shows; installs Debian's chromium when root and the browser extra)
test-browser: setup
	bash scripts/setup_browser.sh
	AIRPOSE_REQUIRE_BROWSER=1 $(VENV)/bin/python -m pytest -q -m browser tests/browser

# pyflakes, import order and bugbear (pyproject.toml [tool.ruff]); CI runs it after the tests
lint: setup
	$(VENV)/bin/ruff check .

test-all: setup
	$(VENV)/bin/python -m pytest -q

bench: setup
	$(VENV)/bin/python benchmarks/body_model.py
