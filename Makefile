# Two commands: `make run` (the viewer on the default sample scene) and `make test`.
# Both set up what is missing: Debian packages (when root), a .venv, the package in editable mode.
PY      ?= python3
VENV    := .venv
BIN     := $(VENV)/bin
SCENE   ?= sample_models/cornell_box.glb
XVFB    := xvfb-run -a -s "-screen 0 1280x800x24"

.PHONY: run test lint setup clean bench

setup: .stamp-venv

.stamp-apt:
	@if [ "$$(id -u)" = 0 ] && command -v apt-get >/dev/null && ! command -v xvfb-run >/dev/null; then \
	  echo "installing Debian packages (xvfb, Mesa EGL/GL)"; \
	  apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq xvfb xauth libegl1 libgl1 libegl-mesa0 >/dev/null; \
	fi
	@if [ "$$(id -u)" = 0 ] && command -v apt-get >/dev/null && ! command -v chromium >/dev/null; then \
	  echo "installing Debian packages (chromium, for the three.js and Babylon.js client tests)"; \
	  apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq chromium >/dev/null; \
	fi
	@touch $@

.stamp-node:
	@if command -v npm >/dev/null; then PUPPETEER_SKIP_DOWNLOAD=1 npm install --prefix .node --no-save --no-audit --no-fund --loglevel=error gltf-validator three@0.187 puppeteer-core babylonjs@9.28.0 babylonjs-loaders@9.28.0 >/dev/null && echo "installed gltf-validator, three, puppeteer-core, babylonjs, babylonjs-loaders (npm)"; fi
	@touch $@

.stamp-venv: .stamp-apt .stamp-node pyproject.toml
	@test -x $(BIN)/python || $(PY) -m venv $(VENV)
	@$(BIN)/pip install -q --upgrade pip
	@$(BIN)/pip install -q -e ".[test]"
	@touch $@

run: setup
	@if [ -n "$$DISPLAY$$WAYLAND_DISPLAY" ]; then \
	  $(BIN)/iat view $(SCENE); \
	else \
	  echo "no display: rendering $(SCENE) headless instead (for the window: 'xvfb-run make run' or a desktop)"; \
	  $(BIN)/iat render $(SCENE) --mode iat -o out/default.png; \
	fi

test: setup
	$(BIN)/lint-imports --no-cache
	$(XVFB) $(BIN)/python -m pytest -q tests

lint: setup
	$(BIN)/ruff check iat viewer tests sample_models

bench: setup
	$(BIN)/iat bench

clean:
	rm -rf $(VENV) .stamp-* out
