# One command to set up and run the main job, one to set up and run the tests.
# Both create ./.venv on first use (pip takes torch==2.13.0, a CPU build, from this machine).

PYTHON ?= python3
VENV := .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed

# Debian packages that ship the labelled real photographs the tests run the wire model on
# (perception/data/real_wires.json); installed with apt-get as root, else with sudo.
PHOTO_PACKAGES := lomiri-wallpapers-16.04 plasma-workspace-wallpapers
SUDO := $(if $(filter 0,$(shell id -u)),,sudo)

.PHONY: setup sim test lint photos

$(STAMP): pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(BIN)/pip install --quiet --upgrade pip
	$(BIN)/pip install --quiet -e ".[dev]"
	touch $(STAMP)

setup: $(STAMP)

# The main job: the most complete simulated flight available.
sim: $(STAMP)
	$(BIN)/wireavoid fly-pattern

photos:
	@installed=$$(dpkg-query -W -f='$${Status}\n' $(PHOTO_PACKAGES) 2>/dev/null \
	  | grep -cx 'install ok installed'); \
	[ "$$installed" = $(words $(PHOTO_PACKAGES)) ] || { \
	  $(SUDO) apt-get update -qq && \
	  $(SUDO) env DEBIAN_FRONTEND=noninteractive \
	    apt-get install -y -qq --no-install-recommends $(PHOTO_PACKAGES) >/dev/null; }

test: $(STAMP) photos
	$(BIN)/ruff check .
	$(BIN)/python -m pytest -q

lint: $(STAMP)
	$(BIN)/ruff check .
	$(BIN)/ruff format --check .
