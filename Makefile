# Two commands set everything up on a fresh machine: `make demo` and `make test`.
PYTHON ?= python3
VENV   ?= .venv
BIN    := $(VENV)/bin
STAMP  := $(VENV)/.flexreg-installed
DEMO   ?= demo-output
# test processes of make test (pytest-xdist; each test file runs whole in one of them)
TEST_WORKERS ?= 2

.PHONY: install demo test test-variants lint bench bench-registration bench-calibration bench-verdict bench-survey bench-clouds bench-compare bench-perf clean

install: $(STAMP)

$(STAMP): pyproject.toml scripts/ensure-system-libs.sh
	@bash scripts/ensure-system-libs.sh
	@test -x $(BIN)/python || $(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip
	$(BIN)/python -m pip install --quiet -e '.[dev]'
	@touch $(STAMP)

demo: $(STAMP)
	@bash scripts/ensure-system-libs.sh
	$(BIN)/flexreg info data/laserscan/laserscan-depth.png
	$(BIN)/flexreg project data/laserscan/laserscan-depth.png --out $(DEMO)/laserscan-range.png --overwrite
	$(BIN)/flexreg convert data/laserscan/laserscan-depth.png --kind flexion --n 5 --bits 8 --out $(DEMO)/laserscan-flexion5.png --overwrite
	$(BIN)/flexreg synth --scene room --stations 2 --resolution 1024x512 --seed 0 --out $(DEMO)/synth-room --overwrite
	$(BIN)/flexreg info $(DEMO)/synth-room/station_00.ptx
	$(BIN)/flexreg register $(DEMO)/synth-room/station_00.ptx $(DEMO)/synth-room/station_01.ptx \
		--truth $(DEMO)/synth-room/gt.json --out $(DEMO)/synth-room/T_station_00_station_01.json \
		--txt $(DEMO)/synth-room/T_station_00_station_01.txt --matches $(DEMO)/synth-room/matches.png \
		--overwrite
	$(BIN)/flexreg synth --scene room --stations 4 --resolution 512x256 --seed 0 --out $(DEMO)/survey-room --overwrite
	@# a survey exits 3 when it wrote its results but flags something for the surveyor to check
	$(BIN)/flexreg survey $(DEMO)/survey-room --out $(DEMO)/survey-room-survey \
		--merged $(DEMO)/survey-room-survey/merged.ply --voxel 0.05 --overwrite || test $$? -eq 3
	@echo "demo results written to $(DEMO)/ (the survey's report: $(DEMO)/survey-room-survey/report.html)"

test: $(STAMP)
	@bash scripts/ensure-system-libs.sh
	$(BIN)/python -m pytest -q -n $(TEST_WORKERS) --dist loadfile

# the numeric tests under the CPU variants of other machines (numpy SIMD caps, OpenBLAS core
# types, numba's target CPU, thread counts, rays moved by a few ulps): run it before resolving an
# issue that adds numeric tests (docs/determinism.md); about three times `make test`
test-variants: $(STAMP)
	@bash scripts/ensure-system-libs.sh
	TEST_WORKERS=$(TEST_WORKERS) bash scripts/test-variants.sh

lint: $(STAMP)
	$(BIN)/ruff check flexreg tests benchmarks
	$(BIN)/ruff format --check flexreg tests benchmarks
	$(BIN)/mypy

bench: $(STAMP)
	$(BIN)/python benchmarks/io.py

bench-registration: $(STAMP)
	$(BIN)/python benchmarks/registration.py

bench-calibration: $(STAMP)
	$(BIN)/python benchmarks/calibration.py

bench-verdict: $(STAMP)
	$(BIN)/python benchmarks/verdict.py --write-docs

bench-survey: $(STAMP)
	$(BIN)/python benchmarks/survey.py --write-docs

bench-clouds: $(STAMP)
	$(BIN)/python benchmarks/clouds.py --write-docs

bench-compare: $(STAMP)
	$(BIN)/flexreg bench --suite all --out bench-results

# memory and speed: whole-process peak RSS and time of `flexreg register` up to 8192x4096, one
# station's preparation, the call against Open3D FPFH + RANSAC + ICP (10-20 min, 3.5 GB of PTX
# pairs kept in benchmarks/results/perf-data)
bench-perf: $(STAMP)
	$(BIN)/python benchmarks/perf.py --write-docs

clean:
	rm -rf $(VENV) $(DEMO) .pytest_cache .ruff_cache .mypy_cache
