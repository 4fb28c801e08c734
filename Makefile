# The two set-up commands of the README. Each installs what it needs first (idempotently).
PY ?= python3

.PHONY: demo test install bench

demo:
	@scripts/install.sh
	$(PY) -m invface.cli demo --overwrite

test:
	@scripts/install.sh test
	$(PY) -m pytest -q tests

bench:
	@scripts/install.sh
	$(PY) bench/template.py
